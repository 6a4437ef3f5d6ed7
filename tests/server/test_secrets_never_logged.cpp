// What only its holder may know never reaches a log or another's message: a DICOMweb source's
// credentials, even when the PACS echoes them back in every place the server quotes it, and
// an upload's id (and the server's token) at any log level. The server's log is captured by a
// sink added to spdlog's default logger, at trace level.

#include "server/upload_ids.hpp"
#include "renderer/io/volume_io.hpp"
#include "renderer/model/synthetic.hpp"
#include "server_fixture.hpp"
#include "tests/dicomweb/hostile_server.hpp"
#include "tests/dicomweb/orthanc_fixture.hpp"

#include <gtest/gtest.h>
#include <spdlog/sinks/ringbuffer_sink.h>
#include <spdlog/spdlog.h>

#include <algorithm>
#include <filesystem>
#include <fstream>
#include <functional>
#include <mutex>
#include <string>
#include <vector>

namespace {

namespace fs = std::filesystem;
using json = nlohmann::json;
using namespace std::chrono_literals;

constexpr auto kTimeout = 60s;

// Every line the default logger writes while it lives, at every level. Made before the server
// starts and dropped after it stops: spdlog's list of sinks is not guarded against threads.
class LogCapture {
  public:
    LogCapture() : sink_(std::make_shared<spdlog::sinks::ringbuffer_sink_mt>(100000)), level_(spdlog::get_level()) {
        sink_->set_level(spdlog::level::trace);
        spdlog::default_logger()->sinks().push_back(sink_);
        spdlog::set_level(spdlog::level::trace);
    }
    ~LogCapture() {
        auto &sinks = spdlog::default_logger()->sinks();
        sinks.erase(std::remove(sinks.begin(), sinks.end(), sink_), sinks.end());
        spdlog::set_level(level_);
    }
    LogCapture(const LogCapture &) = delete;
    LogCapture &operator=(const LogCapture &) = delete;
    std::vector<std::string> lines() const { return sink_->last_formatted(); }

  private:
    std::shared_ptr<spdlog::sinks::ringbuffer_sink_mt> sink_;
    spdlog::level::level_enum level_;
};

json ask(volcast::client::Client &c, const json &request) {
    c.sendText(request.dump());
    return json::parse(volcast::client::waitForReply(c, request.at("id"), kTimeout).text);
}

// A fake PACS (tests/dicomweb/hostile_server.hpp) that answers well everywhere but in one
// place, where it echoes back one form of the Authorization value it received
// (credentialEchoes): the place and the form are chosen by the test as it goes.
struct EchoingPacs {
    std::string place;
    size_t form = 0;
    std::mutex mutex;
    volcast::test::HostileServer server{[this](int, const std::string &request) { return answer(request); }};

    std::string answer(const std::string &request) {
        std::lock_guard lock(mutex);
        using volcast::test::httpResponse;
        const std::string echo =
            volcast::test::credentialEchoes(volcast::test::authorizationIn(request)).at(form);
        const bool search = request.find(" /dicom-web/studies?") != std::string::npos;
        const bool seriesRecord = request.find("/series?SeriesInstanceUID=") != std::string::npos;
        const bool instanceRecord = request.find("/instances?") != std::string::npos;
        if (search) {
            if (place == "search Content-Type") return httpResponse(200, "text/html; echo=" + echo, "[]");
            if (place == "search error body") return httpResponse(500, "text/plain", "you sent: " + echo);
            return httpResponse(200, "application/dicom+json", "[]");
        }
        if (seriesRecord) {
            if (place == "metadata Content-Type") return httpResponse(200, echo, "[]");
            if (place == "metadata error body")
                return httpResponse(403, "application/json", R"({"Message": "no", "Details": ")" + echo + "\"}");
            return httpResponse(200, "application/dicom+json",
                                R"([{"0020000E": {"vr": "UI", "Value": ["1.2.3.4"]}, "00201209": {"vr": "IS", "Value": [1]}}])");
        }
        if (instanceRecord)
            return httpResponse(200, "application/dicom+json",
                                R"([{"00280010": {"vr": "US", "Value": [4]}, "00280011": {"vr": "US", "Value": [4]}}])");
        if (place == "retrieval Content-Type") return httpResponse(200, "multipart/related; echo=" + echo, "--xyz--\r\n");
        return httpResponse(200, "multipart/related; type=\"application/dicom\"; boundary=xyz",
                            "--xyz\r\nContent-Type: " + echo + "\r\n\r\nDICM\r\n--xyz--\r\n");   // "part Content-Type"
    }
};

TEST(SecretsNeverLogged, DicomWebCredentialsEchoedByThePacsReachNoClientAndNoLogLine) {
    const fs::path folder = fs::temp_directory_path() / ("volcast_secrets_" + std::to_string(::getpid()));
    fs::remove_all(folder);
    fs::create_directories(folder);
    const std::string authorization = "Basic " + volcast::test::base64("reader:s3cret/P@ss+w=rd!-long-enough-for-a-40-character-quote-to-cut-it");
    std::ofstream(folder / "pacs.auth") << authorization << "\n";
    const std::vector<std::string> echoes = volcast::test::credentialEchoes(authorization);

    EchoingPacs pacs;
    LogCapture log;
    std::vector<std::string> messages;
    {
        volcast::server::ServerConfig config;
        config.port = 0;
        config.defaultVolume = "";
        config.webRoot = folder;
        config.errorCalibration = false;
        config.device = "cpu";
        config.dicomWebTimeoutS = 10;
        // As --dicomweb and --dicomweb-auth give them.
        config.dicomWebSources = volcast::server::parseDicomWebSources(
            {"pacs=" + pacs.server.url() + "/dicom-web"}, {"pacs=" + (folder / "pacs.auth").string()});
        volcast::server::Server server(config);
        volcast::test::startAndWaitReady(server, kTimeout);
        auto c = volcast::test::helloClient(server.port(), "gtest", kTimeout);
        int id = 2;
        for (const std::string place : {"search Content-Type", "search error body", "metadata Content-Type",
                                        "metadata error body", "retrieval Content-Type", "part Content-Type"}) {
            for (size_t form = 0; form < echoes.size(); ++form) {
                {
                    std::lock_guard lock(pacs.mutex);
                    pacs.place = place;
                    pacs.form = form;
                }
                const bool search = place.starts_with("search");
                const json reply =
                    search ? ask(*c, {{"type", "find_studies"}, {"id", id++}, {"source", "pacs"}})
                           : ask(*c, {{"type", "open_volume"}, {"id", id++}, {"name", "dicomweb:pacs/1.2.3/1.2.3.4"}});
                EXPECT_EQ(reply.value("type", ""), "error") << place << ": " << reply.dump();
                EXPECT_EQ(reply.value("code", ""), search ? "source_failed" : "load_failed") << place << ": " << reply.dump();
                const std::string message = reply.value("message", "");
                EXPECT_EQ(volcast::test::echoIn(message, echoes), "")
                    << place << ", form " << form << ": the client's message quotes the credentials: " << message;
                messages.push_back(message);
            }
        }
    }
    const std::vector<std::string> lines = log.lines();
    size_t quotingThePacs = 0;
    for (const std::string &line : lines) {
        EXPECT_EQ(volcast::test::echoIn(line, echoes), "") << "a log line quotes the credentials: " << line;
        EXPECT_EQ(line.find("s3cret"), std::string::npos) << "a log line quotes the password: " << line;
        if (line.find("DICOMweb source 'pacs'") != std::string::npos && line.find("[credentials]") != std::string::npos)
            ++quotingThePacs;
    }
    // The failures were logged, each with the PACS's words and the credentials cut out: the
    // log was captured and the checks above had something to check.
    EXPECT_GE(quotingThePacs, echoes.size()) << "too few log lines quote the PACS; the log held " << lines.size() << " lines";
    fs::remove_all(folder);
}

TEST(SecretsNeverLogged, AnUploadsIdAndTheTokenReachNoLogLineAtAnyLevel) {
    const std::string token = "secrets-test-token-8c1e";
    const fs::path folder = fs::temp_directory_path() / ("volcast_secrets_upload_" + std::to_string(::getpid()));
    fs::remove_all(folder);
    fs::create_directories(folder);
    const fs::path file = folder / "scan.nrrd";
    volcast::saveVolume(volcast::makeGaussianBlob({12, 10, 8}, {1.0, 1.0, 1.0}, 3.0, 1000.0).volume, file,
                        {volcast::VoxelType::Int16, false});
    std::ifstream in(file, std::ios::binary);
    const std::string body{std::istreambuf_iterator<char>(in), {}};

    LogCapture log;
    std::string volume;
    {
        volcast::server::ServerConfig config;
        config.port = 0;
        config.defaultVolume = "";
        config.webRoot = folder;
        config.errorCalibration = false;
        config.device = "cpu";
        config.token = token;
        volcast::server::Server server(config);
        volcast::test::startAndWaitReady(server, kTimeout);
        const auto x = volcast::test::rawExchange(
            server.port(),
            "POST /api/volumes HTTP/1.1\r\nHost: 127.0.0.1\r\nAuthorization: Bearer " + token +
                "\r\nX-Volcast-Filename: scan.nrrd\r\nContent-Length: " + std::to_string(body.size()) + "\r\n\r\n" + body,
            kTimeout);
        ASSERT_TRUE(x.response) << x.error;
        ASSERT_EQ(x.response->result_int(), 201u) << x.response->body();
        volume = json::parse(x.response->body()).at("volume");
        // Every path the loaders log of an upload's file lies in its folder: named by the id's
        // SHA-256, never by the id.
        const std::string id = volume.substr(std::string("upload:").size());
        std::vector<std::string> names;
        for (const auto &entry : fs::recursive_directory_iterator(server.state().uploads().folder()))
            names.push_back(entry.path().filename().string());
        EXPECT_NE(std::find(names.begin(), names.end(), volcast::server::sha256Hex(id)), names.end())
            << "no folder named by the id's SHA-256";
        for (const std::string &name : names)
            EXPECT_EQ(name.find(id), std::string::npos) << "a file or folder of the upload is named by its id: " << name;
        volcast::client::Client c("127.0.0.1", server.port());
        EXPECT_EQ(ask(c, {{"type", "hello"}, {"id", 1}, {"protocol", 1}, {"client", "gtest"}, {"token", token}})
                      .value("type", ""),
                  "hello");
        const json state = ask(c, {{"type", "open_volume"}, {"id", 2}, {"name", volume}});
        EXPECT_EQ(state.value("type", ""), "state") << state.dump();
    }
    const std::string id = volume.substr(std::string("upload:").size());
    const std::string shortForm = "upload:#" + volcast::server::sha256Hex(id).substr(0, 8);
    const std::vector<std::string> lines = log.lines();
    bool kept = false, loaded = false;
    for (const std::string &line : lines) {
        EXPECT_EQ(line.find(id), std::string::npos) << "a log line holds the upload's id: " << line;
        EXPECT_EQ(line.find(token), std::string::npos) << "a log line holds the token: " << line;
        kept = kept || (line.find("kept " + shortForm) != std::string::npos);
        loaded = loaded || (line.find("loaded volume " + shortForm) != std::string::npos);
    }
    // The upload is still told apart in the log, by the short hash of its id.
    EXPECT_TRUE(kept) << "no 'kept " << shortForm << "' among the " << lines.size() << " log lines";
    EXPECT_TRUE(loaded) << "no 'loaded volume " << shortForm << "' among the " << lines.size() << " log lines";
    fs::remove_all(folder);
}

} // namespace
