// The server's DICOMweb sources end to end, against a real Orthanc (tests/dicomweb/
// orthanc_fixture.hpp): find_studies over WebSocket, open_volume of a dicomweb: name with its
// retrieval progress, the same volume as the same series read from files, and each failure a
// user can meet answered with an error that names it while the session carries on.

#include "renderer/io/volume_io.hpp"
#include "server_fixture.hpp"
#include "tests/dicom_tags.hpp"
#include "tests/dicomweb/hostile_server.hpp"
#include "tests/dicomweb/orthanc_fixture.hpp"

#include <gtest/gtest.h>

#include <algorithm>
#include <cctype>
#include <chrono>
#include <csignal>
#include <filesystem>
#include <fstream>
#include <memory>
#include <string>
#include <vector>

namespace {

namespace fs = std::filesystem;
using json = nlohmann::json;
using namespace std::chrono_literals;
using volcast::client::Client;
using volcast::client::Message;
using volcast::protocol::ErrorCode;

constexpr auto kTimeout = 60s;

// A 40 x 32 x 12 int16 series with an oblique, left-handed direction and known values: what
// comes back over DICOMweb must be this geometry and these voxels.
volcast::Volume knownVolume() {
    volcast::Volume v;
    v.dims = {40, 32, 12};
    v.spacing = {0.8, 0.7, 2.5};
    v.origin = {-20, 15.5, 100};
    const double c = std::cos(0.3), s = std::sin(0.3);
    // Columns are the voxel axes in LPS; the third is flipped (slices run towards inferior).
    v.direction.m = {c, -s, 0, s, c, 0, 0, 0, -1};
    v.voxels.resize(v.voxelCount());
    for (size_t i = 0; i < v.voxels.size(); ++i) v.voxels[i] = float(int(i % 2000) - 1000);
    return v;
}

struct Orthanc {
    volcast::test::OrthancProcess process;
    fs::path series;   // the DICOM files uploaded to it
    std::string studyUid, seriesUid;
};

class DicomWebSources : public ::testing::Test {
  protected:
    static inline std::unique_ptr<Orthanc> orthanc;
    static inline fs::path tmp;

    static void SetUpTestSuite() {
        if (const std::string missing = volcast::test::orthancMissing(); !missing.empty()) {
            FAIL() << missing;
        }
        tmp = fs::temp_directory_path() / ("volcast_dicomweb_server_test_" + std::to_string(::getpid()));
        fs::remove_all(tmp);
        fs::create_directories(tmp);
        orthanc = std::make_unique<Orthanc>();
        orthanc->series = tmp / "series";
        volcast::saveDicomSeries(knownVolume(), orthanc->series, volcast::VoxelType::Int16);
        std::string lastId;
        for (const auto &entry : fs::directory_iterator(orthanc->series)) lastId = orthanc->process.upload(entry.path());
        const json tags = orthanc->process.rest("GET", "/instances/" + lastId + "/simplified-tags");
        orthanc->studyUid = tags.at("StudyInstanceUID");
        orthanc->seriesUid = tags.at("SeriesInstanceUID");
    }
    static void TearDownTestSuite() {
        orthanc.reset();
        fs::remove_all(tmp);
    }

    // A server with one source, "pacs", on the suite's Orthanc.
    static std::unique_ptr<volcast::server::Server> serverWith(const std::string &authorization,
                                                               double budgetMiB = 512, double timeoutS = 10,
                                                               const std::string &dicomWebUrl = {}) {
        volcast::server::ServerConfig config;
        config.port = 0;
        config.defaultVolume = "";
        config.webRoot = tmp;
        config.errorCalibration = false;
        config.memoryBudgetBytes = uint64_t(budgetMiB * 1024 * 1024);
        config.dicomWebSources = {{"pacs", dicomWebUrl.empty() ? orthanc->process.dicomWebUrl() : dicomWebUrl, authorization}};
        config.dicomWebTimeoutS = timeoutS;
        auto server = std::make_unique<volcast::server::Server>(config);
        volcast::test::startAndWaitReady(*server, kTimeout);
        return server;
    }

    static std::string seriesName() {
        return "dicomweb:pacs/" + orthanc->studyUid + "/" + orthanc->seriesUid;
    }
};

Message ask(Client &c, const json &request) {
    c.sendText(request.dump());
    return volcast::client::waitForReply(c, request.at("id"), kTimeout);
}

// The error a reply is; fails the test (naming the reply) when it is none.
volcast::protocol::ProtocolError errorIn(const Message &m) {
    if (const auto *e = volcast::test::asError(m)) return *e;
    ADD_FAILURE() << "expected an error, got " << m.text;
    return {};
}

// The session still answers, and opens a built-in volume: a failure lost nothing.
void expectSessionCarriesOn(Client &c) {
    const Message state = ask(c, {{"type", "open_volume"}, {"id", "after"}, {"name", "builtin:sphere"}});
    EXPECT_TRUE(state.decoded && std::holds_alternative<volcast::protocol::StateMessage>(*state.decoded))
        << "after the failure the session should open another volume: " << state.text;
}

TEST_F(DicomWebSources, AreListedAndSearchFindsTheStudyWithItsSeries) {
    auto server = serverWith(volcast::test::OrthancProcess::authorization());
    auto c = volcast::test::helloClient(server->port(), "gtest", kTimeout);
    const json volumes = json::parse(ask(*c, {{"type", "list_volumes"}, {"id", 2}}).text);
    ASSERT_EQ(volumes.at("sources"), json::parse(R"([{"name": "pacs", "kind": "dicomweb"}])")) << volumes.dump();
    for (const auto &v : volumes.at("volumes"))
        EXPECT_FALSE(v.at("name").get<std::string>().starts_with("dicomweb:")) << "series are found, not listed";

    const Message found = ask(*c, {{"type", "find_studies"}, {"id", 3}, {"source", "pacs"}, {"filters", {{"modality", "CT"}}}});
    const json studies = json::parse(found.text);
    ASSERT_EQ(studies.at("type"), "studies") << found.text;
    ASSERT_EQ(studies.at("studies").size(), 1u) << found.text;
    const json &study = studies.at("studies")[0];
    EXPECT_EQ(study.at("study_uid"), orthanc->studyUid);
    ASSERT_EQ(study.at("series").size(), 1u);
    EXPECT_EQ(study.at("series")[0].at("modality"), "CT");
    EXPECT_EQ(study.at("series")[0].at("instances"), 12) << "one instance per slice";
    EXPECT_EQ(study.at("series")[0].at("volume"), seriesName());

    const Message none =
        ask(*c, {{"type", "find_studies"}, {"id", 4}, {"source", "pacs"}, {"filters", {{"modality", "MR"}}}});
    EXPECT_EQ(json::parse(none.text).at("studies"), json::array()) << "no MR study was stored: " << none.text;
}

TEST_F(DicomWebSources, OpenedSeriesEqualsTheSameSeriesReadFromFiles) {
    auto server = serverWith(volcast::test::OrthancProcess::authorization());
    auto c = volcast::test::helloClient(server->port(), "gtest", kTimeout);
    c->sendText(json{{"type", "viewport"}, {"id", 2}, {"image", {{"width", 32}, {"height", 32}}}}.dump());
    c->sendText(json{{"type", "open_volume"}, {"id", 3}, {"name", seriesName()}}.dump());
    std::vector<volcast::protocol::ProgressMessage> retrieving;
    std::optional<Message> state;
    const auto deadline = std::chrono::steady_clock::now() + kTimeout;
    while (!state && std::chrono::steady_clock::now() < deadline) {
        const auto m = c->next(1000ms);
        if (!m || !m->decoded) continue;
        ASSERT_EQ(volcast::test::asError(*m), nullptr) << m->text;
        if (const auto *p = std::get_if<volcast::protocol::ProgressMessage>(&*m->decoded))
            if (p->stage == volcast::protocol::ProgressStage::Retrieving) retrieving.push_back(*p);
        if (std::holds_alternative<volcast::protocol::StateMessage>(*m->decoded)) state = *m;
    }
    ASSERT_TRUE(state) << "no state within the time limit";
    ASSERT_FALSE(retrieving.empty()) << "a retrieval reports its progress";
    const auto &last = retrieving.back();
    ASSERT_TRUE(last.instances) << "retrieving progress counts instances";
    EXPECT_EQ((*last.instances)[0], 12);
    EXPECT_EQ((*last.instances)[1], 12);
    EXPECT_GT(last.bytes.value_or(0), 12u * 40 * 32 * 2) << "at least the pixel data arrived";

    // The reference: the uploaded files read by the same loader.
    const volcast::Volume files = volcast::loadVolume(orthanc->series);
    const json volume = json::parse(state->text).at("volume");
    EXPECT_EQ(volume.at("name"), seriesName());
    EXPECT_EQ(volume.at("dims"), json({files.dims.x, files.dims.y, files.dims.z}));
    EXPECT_EQ(volume.at("voxel_type"), "int16");
    EXPECT_EQ(volume.at("orientation_known"), true) << "DICOM names its patient axes";
    for (int a = 0; a < 3; ++a) {
        // JSON carries doubles exactly; the loader reads both copies of the same header text.
        EXPECT_EQ(volume.at("spacing")[a].get<double>(), files.spacing[a]) << "axis " << a;
        EXPECT_EQ(volume.at("origin")[a].get<double>(), files.origin[a]) << "axis " << a;
        for (int b = 0; b < 3; ++b) EXPECT_EQ(volume.at("direction")[a][b].get<double>(), files.direction(a, b));
    }
    EXPECT_EQ(volume.at("value_range"), json({files.range.min, files.range.max}));
    EXPECT_EQ(volume.at("histogram").at("counts"), json(files.histogram.counts))
        << "the same voxels give the same histogram";
    EXPECT_EQ(volume.at("modality").at("name"), "CT");
}

TEST_F(DicomWebSources, UnknownSourcesSeriesAndMalformedNamesAreRefusedByName) {
    auto server = serverWith(volcast::test::OrthancProcess::authorization());
    auto c = volcast::test::helloClient(server->port(), "gtest", kTimeout);
    const auto opening = [&](const std::string &name, const std::string &id) {
        return errorIn(ask(*c, {{"type", "open_volume"}, {"id", id}, {"name", name}}));
    };
    auto e = opening("dicomweb:elsewhere/1.2.3/1.2.4", "a");
    EXPECT_EQ(e.code, ErrorCode::NotFound);
    EXPECT_NE(e.message.find("no DICOMweb source named \"elsewhere\""), std::string::npos) << e.message;
    e = opening("dicomweb:pacs/" + orthanc->studyUid + "/1.2.3.999", "b");
    EXPECT_EQ(e.code, ErrorCode::NotFound) << e.message;
    EXPECT_NE(e.message.find("1.2.3.999"), std::string::npos) << "names the series: " << e.message;
    e = opening("dicomweb:pacs/1.2.x/1.2.3", "c");
    EXPECT_EQ(e.code, ErrorCode::BadVolumeName) << e.message;
    e = opening("dicomweb:pacs/1.2.3", "d");
    EXPECT_EQ(e.code, ErrorCode::BadVolumeName) << e.message;
    e = errorIn(ask(*c, {{"type", "find_studies"}, {"id", "e"}, {"source", "elsewhere"}}));
    EXPECT_EQ(e.code, ErrorCode::NotFound) << e.message;
    expectSessionCarriesOn(*c);
}

TEST_F(DicomWebSources, RefusedCredentialsAreNamedAndNeverEchoed) {
    const std::string wrong = "Basic " + volcast::test::base64("volcast:not-the-password");
    auto server = serverWith(wrong);
    auto c = volcast::test::helloClient(server->port(), "gtest", kTimeout);
    auto e = errorIn(ask(*c, {{"type", "find_studies"}, {"id", 2}, {"source", "pacs"}}));
    EXPECT_EQ(e.code, ErrorCode::SourceFailed);
    EXPECT_NE(e.message.find("401"), std::string::npos) << "names the source's answer: " << e.message;
    EXPECT_EQ(e.message.find(wrong.substr(6)), std::string::npos) << "never quotes the credential";
    e = errorIn(ask(*c, {{"type", "open_volume"}, {"id", 3}, {"name", seriesName()}}));
    EXPECT_EQ(e.code, ErrorCode::LoadFailed);
    EXPECT_NE(e.message.find("401"), std::string::npos) << e.message;
    expectSessionCarriesOn(*c);
}

TEST_F(DicomWebSources, ASeriesTooLargeForTheBudgetIsRefusedBeforeRetrieval) {
    // 12 slices of 40 x 32 are 61 KiB as float32; a 64 KiB budget holds at most 43 KiB of them
    // (the registry keeps a third of the budget for mip levels and coefficients).
    auto server = serverWith(volcast::test::OrthancProcess::authorization(), 64.0 / 1024);
    auto c = volcast::test::helloClient(server->port(), "gtest", kTimeout);
    c->sendText(json{{"type", "open_volume"}, {"id", 2}, {"name", seriesName()}}.dump());
    std::vector<Message> before;
    const Message reply = volcast::client::waitForReply(*c, 2, kTimeout, &before);
    const auto e = errorIn(reply);
    EXPECT_EQ(e.code, ErrorCode::LoadFailed);
    EXPECT_NE(e.message.find("not retrieved"), std::string::npos) << e.message;
    for (const Message &m : before)
        EXPECT_EQ(m.text.find("\"instances\""), std::string::npos) << "no instance was retrieved: " << m.text;
}

TEST_F(DicomWebSources, APacsThatStopsAnsweringFailsTheSearchInTimeAndOthersCarryOn) {
    auto server = serverWith(volcast::test::OrthancProcess::authorization(), 512, 2);
    auto c = volcast::test::helloClient(server->port(), "gtest", kTimeout);
    auto other = volcast::test::helloClient(server->port(), "gtest-other", kTimeout);
    orthanc->process.signal(SIGSTOP);
    c->sendText(json{{"type", "find_studies"}, {"id", 2}, {"source", "pacs"}}.dump());
    // Another session is not held up by the stalled search.
    const auto started = std::chrono::steady_clock::now();
    expectSessionCarriesOn(*other);
    EXPECT_LT(std::chrono::steady_clock::now() - started, 1500ms) << "a stalled PACS delayed another session";
    const Message reply = volcast::client::waitForReply(*c, 2, kTimeout);
    orthanc->process.signal(SIGCONT);
    const auto e = errorIn(reply);
    EXPECT_EQ(e.code, ErrorCode::SourceFailed) << e.message;
    EXPECT_LT(std::chrono::steady_clock::now() - started, 20s) << "the search timed out late: " << e.message;
    expectSessionCarriesOn(*c);
}

// A PACS that answers another series than the one asked for: here a proxy in front of the
// suite's Orthanc that serves its series under another SeriesInstanceUID in the request. The
// instances carry their own UIDs, and the load refuses them rather than show them as the
// series requested.
TEST_F(DicomWebSources, APacsAnsweringAnotherSeriesThanRequestedIsRefusedNamingIt) {
    const std::string asked = "1.2.826.0.1.3680043.2.1125.424242";   // a series the PACS does not hold
    volcast::dicomweb::HttpOptions toOrthanc;
    toOrthanc.sourceName = "test Orthanc";
    toOrthanc.authorization = volcast::test::OrthancProcess::authorization();
    toOrthanc.connectTimeoutSeconds = 2;
    toOrthanc.requestTimeoutSeconds = 30;
    volcast::test::HostileServer pacs([&](int, const std::string &request) {
        // "GET TARGET HTTP/1.1", the asked series replaced by the stored one, passed on with
        // the request's Accept.
        std::string target = request.substr(4, request.find(' ', 4) - 4);
        for (size_t at; (at = target.find(asked)) != std::string::npos;) target.replace(at, asked.size(), orthanc->seriesUid);
        std::string accept;
        std::string lowered = request;
        std::transform(lowered.begin(), lowered.end(), lowered.begin(), [](unsigned char ch) { return char(std::tolower(ch)); });
        if (const size_t at = lowered.find("\r\naccept:"); at != std::string::npos) {
            const size_t from = at + 10, to = request.find("\r\n", from);
            accept = request.substr(from, to - from);
            accept.erase(0, accept.find_first_not_of(' '));
        }
        try {
            const auto r = volcast::dicomweb::HttpClient(toOrthanc).get(orthanc->process.url() + target, accept, 64 << 20);
            return volcast::test::httpResponse(int(r.status), r.contentType, r.body);
        } catch (const std::exception &e) {
            return volcast::test::httpResponse(502, "text/plain", e.what());
        }
    });
    auto server = serverWith("Basic eA==", 512, 10, pacs.url() + "/dicom-web");
    auto c = volcast::test::helloClient(server->port(), "gtest", kTimeout);
    const std::string name = "dicomweb:pacs/" + orthanc->studyUid + "/" + asked;
    const auto e = errorIn(ask(*c, {{"type", "open_volume"}, {"id", 2}, {"name", name}}));
    EXPECT_EQ(e.code, ErrorCode::LoadFailed) << e.message;
    EXPECT_NE(e.message.find(name), std::string::npos) << "names the volume: " << e.message;
    EXPECT_NE(e.message.find("is not of the requested series (its SeriesInstanceUID is another)"), std::string::npos)
        << e.message;
    EXPECT_NE(e.message.find("instance "), std::string::npos) << "names the instance: " << e.message;
    expectSessionCarriesOn(*c);
}

// A series as scanners send it: an axial stack and a localizer of another size under one
// SeriesInstanceUID, stored in the suite's Orthanc as one series (modality OT, so that the
// search for CT studies above still finds the suite's study alone).
TEST_F(DicomWebSources, ASeriesWithALocalizerIsRefusedOfferingItsStacksAndAnOfferedNameOpensThatStack) {
    const auto slices = [](int64_t size, int64_t count, const fs::path &folder) {
        volcast::Volume v;
        v.dims = {size, size, count};
        v.spacing = {1, 1, 2};
        v.voxels.resize(v.voxelCount());
        for (size_t i = 0; i < v.voxels.size(); ++i) v.voxels[i] = float(int(i % 300) - 100);
        volcast::saveDicomSeries(v, folder, volcast::VoxelType::Int16);
    };
    const fs::path folder = tmp / "with_localizer";
    slices(16, 6, folder);
    slices(32, 1, tmp / "localizer");
    fs::rename(tmp / "localizer" / "slice_0000.dcm", folder / "slice_localizer.dcm");
    const std::string study = "1.2.826.0.1.3680043.2.1125.77", series = study + ".2";
    std::string lastId;
    for (const auto &entry : fs::directory_iterator(folder)) {
        using namespace volcast::dicom_tags;
        setTags(entry.path(), {{kStudyUid, study}, {kSeriesUid, series}, {kFrameOfReferenceUid, study + ".3"},
                               {{0x0008, 0x0060}, "OT"}});
        lastId = orthanc->process.upload(entry.path());
    }
    const json stored = orthanc->process.rest("GET", "/instances/" + lastId + "/series");
    ASSERT_EQ(stored.at("Instances").size(), 7u) << "Orthanc keeps the localizer in the series: " << stored.dump();

    auto server = serverWith(volcast::test::OrthancProcess::authorization());
    auto c = volcast::test::helloClient(server->port(), "gtest", kTimeout);
    const std::string name = "dicomweb:pacs/" + study + "/" + series;
    const auto e = errorIn(ask(*c, {{"type", "open_volume"}, {"id", 2}, {"name", name}}));
    EXPECT_EQ(e.code, ErrorCode::LoadFailed) << e.message;
    EXPECT_NE(e.message.find("holds a localizer besides 6 axial slices: open stack 1 for the 6 slices"),
              std::string::npos)
        << e.message;
    using volcast::protocol::StackOffer;
    EXPECT_EQ(e.stacks, (std::vector<StackOffer>{{name + "#stack=1", 6, 16, 16, "axial", false},
                                                 {name + "#stack=2", 1, 32, 32, "axial", true}}))
        << e.message;
    ASSERT_FALSE(e.stacks.empty());
    const Message state = ask(*c, {{"type", "open_volume"}, {"id", 3}, {"name", e.stacks[0].volume}});
    ASSERT_EQ(volcast::test::asError(state), nullptr) << state.text;
    const json volume = json::parse(state.text).at("volume");
    EXPECT_EQ(volume.at("name"), name + "#stack=1");
    EXPECT_EQ(volume.at("dims"), json({16, 16, 6})) << "the axial stack alone";
    // A stack the series does not hold: refused naming how many it holds.
    const auto none = errorIn(ask(*c, {{"type", "open_volume"}, {"id", 4}, {"name", name + "#stack=3"}}));
    EXPECT_NE(none.message.find("holds 2 stacks, so no stack 3"), std::string::npos) << none.message;
    expectSessionCarriesOn(*c);
}

TEST(DicomWebSourceFlags, AreCheckedAtStartAndNeverQuoteACredential) {
    using volcast::server::parseDicomWebSources;
    const fs::path folder = fs::temp_directory_path() / ("volcast_dicomweb_flags_" + std::to_string(::getpid()));
    fs::create_directories(folder);
    std::ofstream(folder / "good.auth") << "Bearer s3cr3t-token\r\n";
    std::ofstream(folder / "empty.auth") << "\n";
    std::ofstream(folder / "control.auth") << "Bearer a\x01" "b\n";

    const auto sources = parseDicomWebSources({"pacs=https://pacs.example.org/dicom-web/", "b=http://127.0.0.1:8042/x"},
                                              {"pacs=" + (folder / "good.auth").string()});
    ASSERT_EQ(sources.size(), 2u);
    EXPECT_EQ(sources[0].url, "https://pacs.example.org/dicom-web") << "a trailing slash is dropped";
    EXPECT_EQ(sources[0].authorization, "Bearer s3cr3t-token") << "the first line, without its line end";
    EXPECT_EQ(sources[1].authorization, "");

    const auto refused = [&](std::vector<std::string> s, std::vector<std::string> a, const std::string &says) {
        try {
            parseDicomWebSources(s, a);
            ADD_FAILURE() << "accepted, should say: " << says;
        } catch (const std::invalid_argument &e) {
            const std::string what = e.what();
            EXPECT_NE(what.find(says), std::string::npos) << what;
            EXPECT_EQ(what.find("s3cr3t"), std::string::npos) << "quotes the credential: " << what;
        }
    };
    refused({"pacs"}, {}, "expected NAME=URL");
    refused({"=http://x"}, {}, "expected NAME=URL");
    refused({"pa/cs=http://x"}, {}, "may hold only letters");
    refused({"pacs=ftp://x/dicom-web"}, {}, "must start with http:// or https://");
    refused({"pacs=http://user:pw@x/dicom-web"}, {}, "--dicomweb-auth");
    refused({"pacs=http://x/a b"}, {}, "space or control character");
    refused({"pacs=http://x", "pacs=http://y"}, {}, "given twice");
    refused({"pacs=http://x"}, {"other=" + (folder / "good.auth").string()}, "no --dicomweb source named \"other\"");
    refused({"pacs=http://x"}, {"pacs=" + (folder / "missing.auth").string()}, "cannot read");
    refused({"pacs=http://x"}, {"pacs=" + (folder / "empty.auth").string()}, "is empty");
    refused({"pacs=http://x"}, {"pacs=" + (folder / "control.auth").string()}, "control character");
    fs::remove_all(folder);
}

} // namespace
