// The client against a real Orthanc with its DICOMweb plugin (orthanc_fixture.hpp). The
// series are made here with known geometry (oblique, flipped), written by saveDicomSeries,
// uploaded over Orthanc's REST API, one of them transcoded by Orthanc to JPEG Lossless; the
// series retrieved over WADO-RS must load exactly as the written files do. Faults: wrong or
// missing credentials, unknown series, a byte limit, cancellation, Orthanc paused (SIGSTOP)
// and killed (SIGKILL) in the middle of a retrieval.

#include "dicomweb/dicomweb_client.hpp"
#include "orthanc_fixture.hpp"

#include "renderer/io/dicom_uncompressed.hpp"
#include "renderer/io/volume_io.hpp"
#include "renderer/model/volume.hpp"

#include <gtest/gtest.h>

#include <chrono>
#include <cmath>
#include <filesystem>
#include <memory>
#include <string>

using namespace volcast::dicomweb;
using volcast::test::OrthancProcess;
namespace fs = std::filesystem;

namespace {

#define EXPECT_CONTAINS(text, part) EXPECT_NE(std::string(text).find(part), std::string::npos) << (text)

// Rotation by `degrees` about a unit axis (Rodrigues).
volcast::Mat3d rotation(volcast::Vec3d axis, double degrees) {
    const double a = degrees * M_PI / 180, c = std::cos(a), s = std::sin(a);
    const double x = axis.x, y = axis.y, z = axis.z;
    volcast::Mat3d r;
    r.m = {c + x * x * (1 - c),     x * y * (1 - c) - z * s, x * z * (1 - c) + y * s,
           y * x * (1 - c) + z * s, c + y * y * (1 - c),     y * z * (1 - c) - x * s,
           z * x * (1 - c) - y * s, z * y * (1 - c) + x * s, c + z * z * (1 - c)};
    return r;
}

// An int16 CT-like volume whose every voxel differs from its neighbours, so that a slice out
// of order, a transposed slice or a flipped axis changes the voxels compared.
volcast::Volume makeVolume(volcast::Vec3i dims, const volcast::Mat3d &direction, int seed) {
    volcast::Volume v;
    v.name = "synthetic";
    v.dims = dims;
    v.spacing = {0.7, 0.8, 2.5};
    v.origin = {-100.25, -120.5, 50.75};
    v.direction = direction;
    v.voxels.resize(v.voxelCount());
    for (size_t i = 0; i < v.voxels.size(); ++i) v.voxels[i] = float(int((i * 37 + size_t(seed) * 101) % 3000) - 1024);
    return v;
}

struct SeriesOnPacs {
    std::string studyUid, seriesUid;
    fs::path written;     // the files saveDicomSeries wrote
    int64_t instances = 0;
    int64_t rows = 0, columns = 0;
};

// Uploads `folder`'s files, then has Orthanc rewrite their patient with the patient and study
// fields (saveDicomSeries writes none; `replace` must hold a PatientID); the original is
// dropped (KeepSource false). Orthanc gives the rewritten study and series new UIDs, which
// are returned. Uploads must not overlap: the files all arrive under the same empty patient.
SeriesOnPacs uploadSeries(const OrthancProcess &orthanc, const fs::path &folder, const nlohmann::json &replace,
                          const volcast::Volume &v) {
    std::string instance;
    for (const auto &entry : fs::directory_iterator(folder)) instance = orthanc.upload(entry.path());
    const std::string series = orthanc.rest("GET", "/instances/" + instance).at("ParentSeries");
    const std::string study = orthanc.rest("GET", "/series/" + series).at("ParentStudy");
    const std::string patient = orthanc.rest("GET", "/studies/" + study).at("ParentPatient");
    const nlohmann::json modify = {{"Replace", replace}, {"Force", true}, {"KeepSource", false}};
    const std::string newPatient = orthanc.rest("POST", "/patients/" + patient + "/modify", modify.dump()).at("ID");
    const std::string newStudy = orthanc.rest("GET", "/patients/" + newPatient).at("Studies").at(0);
    const nlohmann::json studyInfo = orthanc.rest("GET", "/studies/" + newStudy);
    const std::string newSeries = studyInfo.at("Series").at(0);
    SeriesOnPacs out;
    out.studyUid = studyInfo.at("MainDicomTags").at("StudyInstanceUID");
    out.seriesUid = orthanc.rest("GET", "/series/" + newSeries).at("MainDicomTags").at("SeriesInstanceUID");
    out.written = folder;
    out.instances = v.dims.z;
    out.rows = v.dims.y;
    out.columns = v.dims.x;
    return out;
}

// A fresh folder under the suite's work folder.
fs::path freshFolder(const fs::path &work, const std::string &name) {
    static int counter = 0;
    const fs::path p = work / (name + "_" + std::to_string(++counter));
    fs::remove_all(p);
    return p;
}

void expectSameVolume(const fs::path &retrieved, const fs::path &written) {
    const volcast::Volume got = volcast::loadVolume(retrieved);
    const volcast::Volume want = volcast::loadVolume(written);
    // Exact: both are the same decimal strings and int16 values, read by the same loader.
    EXPECT_EQ(got.dims, want.dims);
    EXPECT_EQ(got.spacing, want.spacing);
    EXPECT_EQ(got.origin, want.origin);
    EXPECT_EQ(got.direction, want.direction);
    EXPECT_EQ(got.sourceType, want.sourceType);
    EXPECT_TRUE(got.samples().toFloats() == want.samples().toFloats()) << "voxels differ";
}

size_t filesIn(const fs::path &folder) {
    if (!fs::exists(folder)) return 0;
    return size_t(std::distance(fs::directory_iterator(folder), fs::directory_iterator()));
}

// A series large enough (32 MiB) that Orthanc is still sending it when the test stops or
// kills it after the first instance: more than the loopback socket buffers hold.
volcast::Volume makeLargeVolume() { return makeVolume({512, 512, 64}, volcast::Mat3d::identity(), 3); }

} // namespace

// One Orthanc for the suite, with three series: an oblique one (DOE^JANE), the same
// transcoded to JPEG Lossless by Orthanc, and a flipped one (ROE^RICHARD); and a large one
// for the pause test, made when it runs.
class DicomWebOrthanc : public ::testing::Test {
  protected:
    static void SetUpTestSuite() {
        try {
            orthanc = std::make_unique<OrthancProcess>();
            work = fs::temp_directory_path() / ("volcast-dicomweb-test-" + std::to_string(::getpid()));
            fs::remove_all(work);
            fs::create_directories(work);

            const volcast::Volume obliqueVolume = makeVolume({7, 5, 4}, rotation({0.6, 0.0, 0.8}, 30), 1);
            volcast::saveDicomSeries(obliqueVolume, work / "written_oblique");
            oblique = uploadSeries(*orthanc, work / "written_oblique",
                                   {{"PatientName", "DOE^JANE"}, {"PatientID", "VC-0001"}, {"StudyDate", "20240315"},
                                    {"AccessionNumber", "ACC-0001"}, {"StudyDescription", "Synthetic oblique"},
                                    {"SeriesDescription", "oblique int16"}},
                                   obliqueVolume);
            // A flipped series (a left-handed direction): x reversed, so the slices are stacked
            // against the normal of their rows and columns.
            volcast::Mat3d flip;
            flip.m = {-1, 0, 0, 0, 1, 0, 0, 0, 1};
            const volcast::Volume flippedVolume = makeVolume({6, 8, 3}, flip, 2);
            volcast::saveDicomSeries(flippedVolume, work / "written_flipped");
            flipped = uploadSeries(*orthanc, work / "written_flipped",
                                   {{"PatientName", "ROE^RICHARD"}, {"PatientID", "VC-0002"}, {"StudyDate", "20230101"},
                                    {"StudyDescription", "Synthetic flipped"}},
                                   flippedVolume);
            // The oblique series transcoded by Orthanc to JPEG Lossless (1.2.840.10008.1.2.4.70):
            // a second transfer syntax, a new series in the same study.
            const nlohmann::json found = orthanc->rest(
                "POST", "/tools/lookup", oblique.seriesUid, "text/plain");
            const std::string seriesId = found.at(0).at("ID");
            const nlohmann::json transcode = {{"Transcode", "1.2.840.10008.1.2.4.70"},
                                              {"Replace", {{"SeriesDescription", "oblique JPEG lossless"}}}};
            const std::string jpegId = orthanc->rest("POST", "/series/" + seriesId + "/modify", transcode.dump()).at("ID");
            jpeg = oblique;
            jpeg.seriesUid = orthanc->rest("GET", "/series/" + jpegId).at("MainDicomTags").at("SeriesInstanceUID");
        } catch (const std::exception &e) {
            setupError = e.what();
            if (orthanc) setupError += "\nOrthanc's log:\n" + orthanc->log();
        }
    }
    static void TearDownTestSuite() {
        orthanc.reset();
        if (!work.empty()) fs::remove_all(work);
    }
    void SetUp() override {
        ASSERT_TRUE(setupError.empty()) << "the Orthanc fixture failed: " << setupError;
    }

    // The 32 MiB series, made and uploaded only by the test that needs it: ctest runs each
    // test in a process of its own, and this costs seconds.
    static const SeriesOnPacs &largeSeries() {
        if (large.seriesUid.empty()) {
            const volcast::Volume largeVolume = makeLargeVolume();
            volcast::saveDicomSeries(largeVolume, work / "written_large");
            large = uploadSeries(*orthanc, work / "written_large",
                                 {{"PatientName", "LARGE^SERIES"}, {"PatientID", "VC-0003"}, {"StudyDate", "20220202"}},
                                 largeVolume);
        }
        return large;
    }

    static SourceConfig config() {
        SourceConfig c;
        c.name = "orthanc";
        c.baseUrl = orthanc->dicomWebUrl();
        c.authorization = OrthancProcess::authorization();
        c.connectTimeoutSeconds = 2;
        c.requestTimeoutSeconds = 10;
        c.lowSpeedSeconds = 5;
        return c;
    }

    static inline std::unique_ptr<OrthancProcess> orthanc;
    static inline fs::path work;
    static inline SeriesOnPacs oblique, flipped, jpeg, large;
    static inline std::string setupError;
};

TEST_F(DicomWebOrthanc, FindsAStudyByPatientNameWildcardWithItsSeries) {
    Client client(config());
    StudyQuery q;
    q.patientName = "DOE*";
    const auto studies = client.findStudies(q);
    ASSERT_EQ(studies.size(), 1u);
    const StudyRecord &s = studies[0];
    EXPECT_EQ(s.studyUid, oblique.studyUid);
    EXPECT_EQ(s.patientName, "DOE^JANE");
    EXPECT_EQ(s.patientId, "VC-0001");
    EXPECT_EQ(s.studyDate, "20240315");
    EXPECT_EQ(s.accessionNumber, "ACC-0001");
    EXPECT_EQ(s.description, "Synthetic oblique");
    EXPECT_EQ(s.modalities, std::vector<std::string>{"CT"});
    ASSERT_EQ(s.series.size(), 2u) << "the int16 series and its JPEG Lossless copy";
    for (const SeriesRecord &series : s.series) {
        EXPECT_TRUE(series.seriesUid == oblique.seriesUid || series.seriesUid == jpeg.seriesUid) << series.seriesUid;
        EXPECT_EQ(series.modality, "CT");
        EXPECT_EQ(series.instances, oblique.instances);
        EXPECT_EQ(series.description,
                  series.seriesUid == oblique.seriesUid ? "oblique int16" : "oblique JPEG lossless");
    }
    q.patientName = "D?E^JANE";  // '?' matches one character
    ASSERT_EQ(client.findStudies(q).size(), 1u);
}

TEST_F(DicomWebOrthanc, FindsStudiesByPatientIdModalityAndDateRange) {
    Client client(config());
    StudyQuery byId;
    byId.patientId = "VC-0002";
    auto studies = client.findStudies(byId);
    ASSERT_EQ(studies.size(), 1u);
    EXPECT_EQ(studies[0].studyUid, flipped.studyUid);
    ASSERT_EQ(studies[0].series.size(), 1u);
    EXPECT_EQ(studies[0].series[0].seriesUid, flipped.seriesUid);

    StudyQuery byDate;
    byDate.modality = "CT";
    byDate.studyDate = "20240101-20241231";
    studies = client.findStudies(byDate);
    ASSERT_EQ(studies.size(), 1u);
    EXPECT_EQ(studies[0].studyUid, oblique.studyUid);
    byDate.studyDate = "-20231231";
    ASSERT_EQ(client.findStudies(byDate).size(), 1u);
    EXPECT_EQ(client.findStudies(byDate)[0].patientName, "ROE^RICHARD");
    byDate.studyDate = "20230101";
    ASSERT_EQ(client.findStudies(byDate).size(), 1u);

    StudyQuery mr;
    mr.modality = "MR";
    EXPECT_TRUE(client.findStudies(mr).empty());
    StudyQuery limited;
    limited.limit = 1;
    EXPECT_EQ(client.findStudies(limited).size(), 1u) << "two studies match no filter; limit 1 gives one";
    StudyQuery nobody;
    nobody.patientName = "NOBODY*";
    EXPECT_TRUE(client.findStudies(nobody).empty());
}

TEST_F(DicomWebOrthanc, SeriesSizeMatchesTheWrittenGeometry) {
    Client client(config());
    const SeriesSize size = client.seriesSize(oblique.studyUid, oblique.seriesUid);
    EXPECT_EQ(size.instances, oblique.instances);
    EXPECT_EQ(size.rows, oblique.rows);
    EXPECT_EQ(size.columns, oblique.columns);
    EXPECT_EQ(size.float32Bytes, uint64_t(oblique.instances * oblique.rows * oblique.columns * 4));
}

TEST_F(DicomWebOrthanc, RetrievedObliqueSeriesLoadsExactlyAsTheWrittenFiles) {
    Client client(config());
    const fs::path folder = freshFolder(work, "retrieved");
    std::vector<RetrieveProgress> steps;
    const RetrieveProgress done = client.retrieveSeries(
        oblique.studyUid, oblique.seriesUid, folder, 64 << 20, [&](const RetrieveProgress &p) { steps.push_back(p); },
        [] { return false; }, oblique.instances);
    EXPECT_EQ(done.instancesDone, oblique.instances);
    EXPECT_EQ(filesIn(folder), size_t(oblique.instances));
    EXPECT_TRUE(fs::exists(folder / "instance_00000.dcm"));
    // Progress after each instance, counting up to the total, bytes growing.
    ASSERT_EQ(steps.size(), size_t(oblique.instances));
    for (size_t i = 0; i < steps.size(); ++i) {
        EXPECT_EQ(steps[i].instancesDone, int64_t(i + 1));
        EXPECT_EQ(steps[i].instancesTotal, oblique.instances);
        if (i > 0) {
            EXPECT_GT(steps[i].bytes, steps[i - 1].bytes);
        }
    }
    EXPECT_EQ(steps.back().bytes, done.bytes);
    expectSameVolume(folder, oblique.written);
}

TEST_F(DicomWebOrthanc, RetrievedFlippedSeriesLoadsExactlyAsTheWrittenFiles) {
    Client client(config());
    const fs::path folder = freshFolder(work, "retrieved");
    client.retrieveSeries(flipped.studyUid, flipped.seriesUid, folder, 64 << 20, {}, {});
    EXPECT_EQ(filesIn(folder), size_t(flipped.instances));
    expectSameVolume(folder, flipped.written);
}

TEST_F(DicomWebOrthanc, RetrievedJpegLosslessSeriesLoadsExactlyAsTheWrittenFiles) {
    Client client(config());
    const fs::path folder = freshFolder(work, "retrieved");
    client.retrieveSeries(jpeg.studyUid, jpeg.seriesUid, folder, 64 << 20, {}, {}, jpeg.instances);
    // Orthanc stores the series as JPEG Lossless; asked without a transfer-syntax parameter,
    // WADO-RS sends DICOMweb's default, Explicit VR Little Endian, so Orthanc decodes it on
    // the way out.
    const nlohmann::json stored = orthanc->rest("POST", "/tools/lookup", jpeg.seriesUid, "text/plain");
    const std::string seriesId = stored.at(0).at("ID");
    const std::string instance = orthanc->rest("GET", "/series/" + seriesId).at("Instances").at(0);
    HttpOptions o;
    o.authorization = OrthancProcess::authorization();
    const std::string syntax =
        HttpClient(o).get(orthanc->url() + "/instances/" + instance + "/metadata/TransferSyntax", "text/plain", 1024).body;
    EXPECT_EQ(syntax, "1.2.840.10008.1.2.4.70") << "Orthanc did not transcode the series it stores";
    std::ifstream in(folder / "instance_00000.dcm", std::ios::binary);
    const std::string bytes{std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>()};
    EXPECT_NE(bytes.find("1.2.840.10008.1.2.1"), std::string::npos) << "not sent as Explicit VR Little Endian";
    // Read straight from the files in explicit VR; the written series, in implicit VR, too.
    std::string why;
    EXPECT_TRUE(volcast::io::scanUncompressedSeries(folder, why)) << why;
    expectSameVolume(folder, oblique.written);
}

TEST_F(DicomWebOrthanc, WrongOrMissingCredentialsAreUnauthorized) {
    SourceConfig wrong = config();
    wrong.authorization = "Basic " + volcast::test::base64("volcast:wrong-password-7731");
    try {
        Client(wrong).findStudies({});
        FAIL() << "wrong credentials were accepted";
    } catch (const DicomWebError &e) {
        EXPECT_EQ(e.kind, ErrorKind::Unauthorized);
        EXPECT_CONTAINS(e.what(), "DICOMweb source 'orthanc' refused the credentials (HTTP 401) for GET /dicom-web/studies");
        EXPECT_EQ(std::string(e.what()).find(wrong.authorization.substr(6)), std::string::npos) << "credentials quoted";
    }
    SourceConfig none = config();
    none.authorization.clear();
    try {
        Client(none).retrieveSeries(oblique.studyUid, oblique.seriesUid, freshFolder(work, "x"), 1 << 20, {}, {});
        FAIL() << "no credentials were accepted";
    } catch (const DicomWebError &e) {
        EXPECT_EQ(e.kind, ErrorKind::Unauthorized);
        EXPECT_CONTAINS(e.what(), "none are configured");
    }
}

// Orthanc answers QIDO-RS for an unknown series with an empty list (200 []), and WADO-RS
// with 404: both come out as NotFound.
TEST_F(DicomWebOrthanc, UnknownSeriesIsNotFound) {
    Client client(config());
    try {
        client.seriesSize(oblique.studyUid, "1.2.999.1");
        FAIL() << "an unknown series has a size";
    } catch (const DicomWebError &e) {
        EXPECT_EQ(e.kind, ErrorKind::NotFound);
        EXPECT_CONTAINS(e.what(), "has no instances of series 1.2.999.1");
    }
    const fs::path folder = freshFolder(work, "unknown");
    try {
        client.retrieveSeries(oblique.studyUid, "1.2.999.1", folder, 1 << 20, {}, {});
        FAIL() << "an unknown series was retrieved";
    } catch (const DicomWebError &e) {
        EXPECT_EQ(e.kind, ErrorKind::NotFound);
        EXPECT_CONTAINS(e.what(), "(HTTP 404)");
        EXPECT_CONTAINS(e.what(), "/series/1.2.999.1");
    }
    EXPECT_FALSE(fs::exists(folder)) << "the folder made for it is removed";
}

TEST_F(DicomWebOrthanc, SeriesPastTheByteLimitIsTooLargeAndLeavesNoFile) {
    Client client(config());
    const fs::path folder = freshFolder(work, "limited");
    try {
        client.retrieveSeries(oblique.studyUid, oblique.seriesUid, folder, 1000, {}, {});
        FAIL() << "the limit was ignored";
    } catch (const DicomWebError &e) {
        EXPECT_EQ(e.kind, ErrorKind::TooLarge);
        EXPECT_CONTAINS(e.what(), "larger than the 1000 bytes allowed (at instance 1)");
    }
    EXPECT_EQ(filesIn(folder), 0u);
}

TEST_F(DicomWebOrthanc, CancelledRetrievalStopsAndLeavesNoFile) {
    Client client(config());
    const fs::path folder = freshFolder(work, "cancelled");
    int64_t done = 0;
    try {
        client.retrieveSeries(
            oblique.studyUid, oblique.seriesUid, folder, 64 << 20, [&](const RetrieveProgress &p) { done = p.instancesDone; },
            [&] { return done >= 1; });
        FAIL() << "the retrieval was not cancelled";
    } catch (const DicomWebError &e) {
        EXPECT_EQ(e.kind, ErrorKind::Cancelled) << e.what();
    }
    EXPECT_EQ(filesIn(folder), 0u);
}

TEST_F(DicomWebOrthanc, ExpectedInstanceCountThatDiffersIsBadResponse) {
    Client client(config());
    try {
        client.retrieveSeries(oblique.studyUid, oblique.seriesUid, freshFolder(work, "count"), 64 << 20, {}, {},
                              oblique.instances + 1);
        FAIL() << "a series shorter than its metadata was accepted";
    } catch (const DicomWebError &e) {
        EXPECT_EQ(e.kind, ErrorKind::BadResponse);
        EXPECT_CONTAINS(e.what(), "its metadata listed " + std::to_string(oblique.instances + 1));
    }
}

// Orthanc stopped with SIGSTOP after the first instance: the transfer stalls, and the
// low-speed limit (2 s here) ends it as Timeout; continued, Orthanc serves the next request.
TEST_F(DicomWebOrthanc, PausedOrthancIsATimeoutWithinTheLowSpeedLimit) {
    SourceConfig c = config();
    c.lowSpeedSeconds = 2;
    Client client(c);
    const fs::path folder = freshFolder(work, "paused");
    bool paused = false;
    std::chrono::steady_clock::time_point pausedAt;
    try {
        const SeriesOnPacs &series = largeSeries();
        client.retrieveSeries(series.studyUid, series.seriesUid, folder, 1 << 30, [&](const RetrieveProgress &) {
            if (paused) return;
            orthanc->signal(SIGSTOP);
            paused = true;
            pausedAt = std::chrono::steady_clock::now();
        }, {});
        orthanc->signal(SIGCONT);
        FAIL() << "the whole series arrived although Orthanc was stopped after its first instance";
    } catch (const DicomWebError &e) {
        orthanc->signal(SIGCONT);
        const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - pausedAt).count();
        EXPECT_EQ(e.kind, ErrorKind::Timeout) << e.what();
        EXPECT_CONTAINS(e.what(), "instance");
        // The limit is 2 s of less than 1 KiB/s, checked at least once a second, after the
        // bytes already in the socket buffers have arrived: 2 to 4 s; 8 s is far from both.
        EXPECT_GE(seconds, 1.5);
        EXPECT_LT(seconds, 8.0);
    }
    EXPECT_EQ(filesIn(folder), 0u);
    EXPECT_EQ(Client(config()).seriesSize(oblique.studyUid, oblique.seriesUid).instances, oblique.instances)
        << "Orthanc carries on once continued";
}

// Orthanc killed (SIGKILL) after the first instance of a series it is still sending: the
// retrieval fails naming the instance it was in, and no file is left. Its own Orthanc.
TEST(DicomWebOrthancKilled, OrthancKilledMidRetrievalFailsNamingTheInstance) {
    ASSERT_EQ(volcast::test::orthancMissing(), "");
    OrthancProcess orthanc;
    const fs::path work = fs::temp_directory_path() / ("volcast-dicomweb-killed-" + std::to_string(::getpid()));
    fs::remove_all(work);
    const volcast::Volume v = makeLargeVolume();
    volcast::saveDicomSeries(v, work / "written");
    const SeriesOnPacs series = uploadSeries(orthanc, work / "written", {{"PatientName", "KILLED^SERIES"}, {"PatientID", "VC-0004"}}, v);

    SourceConfig c;
    c.name = "doomed";
    c.baseUrl = orthanc.dicomWebUrl();
    c.authorization = OrthancProcess::authorization();
    c.lowSpeedSeconds = 5;
    bool killed = false;
    try {
        Client(c).retrieveSeries(series.studyUid, series.seriesUid, work / "retrieved", 1 << 30,
                                 [&](const RetrieveProgress &) {
                                     if (!killed) orthanc.signal(SIGKILL);
                                     killed = true;
                                 },
                                 {});
        FAIL() << "the whole series arrived although Orthanc was killed after its first instance";
    } catch (const DicomWebError &e) {
        EXPECT_TRUE(e.kind == ErrorKind::BadResponse || e.kind == ErrorKind::Unreachable)
            << errorKindName(e.kind) << ": " << e.what();
        EXPECT_CONTAINS(e.what(), "instance");
        EXPECT_CONTAINS(e.what(), "DICOMweb source 'doomed'");
    }
    EXPECT_EQ(filesIn(work / "retrieved"), 0u);
    fs::remove_all(work);
}
