// The client against a hostile HTTP peer (hostile_server.hpp): malformed and truncated
// multipart bodies, parts that are not DICOM, redirects to another host, oversized, malformed
// and oddly typed JSON, silence, and a port where nothing listens. Each failure must be its
// own ErrorKind with a message naming what was wrong, and never the credentials.

#include "dicomweb/dicomweb_client.hpp"
#include "hostile_server.hpp"
#include "orthanc_fixture.hpp"

#include <gtest/gtest.h>

#include <chrono>
#include <filesystem>
#include <fstream>
#include <functional>
#include <string>

using namespace volcast::dicomweb;
using volcast::test::HostileServer;
using volcast::test::httpResponse;
namespace fs = std::filesystem;

namespace {

const std::string kStudy = "1.2.3";
const std::string kSeries = "1.2.3.4";
const std::string kAuthorization = "Bearer hostile-test-token-5f2a";

SourceConfig configFor(const HostileServer &server) {
    SourceConfig c;
    c.name = "hostile";
    c.baseUrl = server.url() + "/dicom-web";
    c.authorization = kAuthorization;
    c.connectTimeoutSeconds = 2;
    c.requestTimeoutSeconds = 5;
    c.lowSpeedSeconds = 2;
    return c;
}

struct Folder {
    fs::path path = fs::temp_directory_path() /
                    ("volcast-dicomweb-hostile-" + std::to_string(::getpid()) + "-" +
                     std::to_string(std::chrono::steady_clock::now().time_since_epoch().count()));
    ~Folder() { fs::remove_all(path); }
};

// The error retrieveSeries throws against `server` (the test fails when none is thrown).
DicomWebError retrieveError(const HostileServer &server, const fs::path &folder) {
    Client client(configFor(server));
    try {
        client.retrieveSeries(kStudy, kSeries, folder, 1 << 20, {}, {});
    } catch (const DicomWebError &e) {
        return e;
    }
    ADD_FAILURE() << "retrieveSeries succeeded";
    return DicomWebError(ErrorKind::Cancelled, "");
}

DicomWebError findError(const HostileServer &server, SourceConfig config = {}) {
    if (config.baseUrl.empty()) config = configFor(server);
    Client client(config);
    try {
        client.findStudies({});
    } catch (const DicomWebError &e) {
        return e;
    }
    ADD_FAILURE() << "findStudies succeeded";
    return DicomWebError(ErrorKind::Cancelled, "");
}

std::string multipartAnswer(const std::string &body, const std::string &boundary = "xyz") {
    return httpResponse(200, "multipart/related; type=\"application/dicom\"; boundary=" + boundary, body);
}

const std::string kGoodPart = "--xyz\r\nContent-Type: application/dicom\r\n\r\nDICM-one\r\n";

#define EXPECT_CONTAINS(text, part) EXPECT_NE(std::string(text).find(part), std::string::npos) << (text)

} // namespace

TEST(DicomWebHostile, MalformedMultipartDelimiterIsBadResponseNamingTheInstance) {
    HostileServer server([](int, const std::string &) {
        return multipartAnswer(kGoodPart + "--xyz garbage after the delimiter\r\n\r\nx\r\n--xyz--\r\n");
    });
    Folder folder;
    const DicomWebError e = retrieveError(server, folder.path);
    EXPECT_EQ(e.kind, ErrorKind::BadResponse) << e.what();
    EXPECT_CONTAINS(e.what(), "malformed multipart");
    EXPECT_CONTAINS(e.what(), "after instance 1");
    EXPECT_FALSE(fs::exists(folder.path)) << "the instance written before the failure must be removed";
    // What the request asked for: the WADO-RS series, multipart DICOM, with the credentials.
    const std::string request = server.requests().at(0);
    EXPECT_CONTAINS(request, "GET /dicom-web/studies/1.2.3/series/1.2.3.4 HTTP/1.1");
    EXPECT_CONTAINS(request, "Accept: multipart/related; type=\"application/dicom\"");
    EXPECT_CONTAINS(request, "Authorization: " + kAuthorization);
}

TEST(DicomWebHostile, BodyEndingWithoutItsClosingBoundaryIsATruncatedInstance) {
    HostileServer server([](int, const std::string &) {
        return multipartAnswer(kGoodPart + "--xyz\r\nContent-Type: application/dicom\r\n\r\nDICM-two, cut");
    });
    Folder folder;
    const DicomWebError e = retrieveError(server, folder.path);
    EXPECT_EQ(e.kind, ErrorKind::BadResponse);
    EXPECT_CONTAINS(e.what(), "at instance 2 (truncated)");
}

TEST(DicomWebHostile, ConnectionClosedBeforeContentLengthIsTruncated) {
    HostileServer server([](int, const std::string &) {
        std::string answer = multipartAnswer(kGoodPart + "--xyz--\r\n");
        return answer.substr(0, answer.size() - 12);  // Content-Length promises 12 more bytes
    });
    Folder folder;
    const DicomWebError e = retrieveError(server, folder.path);
    EXPECT_TRUE(e.kind == ErrorKind::BadResponse || e.kind == ErrorKind::Unreachable) << e.what();
    EXPECT_CONTAINS(e.what(), "instance");
}

TEST(DicomWebHostile, PartsThatAreNotDicomAreRefused) {
    {
        HostileServer server([](int, const std::string &) {
            return multipartAnswer("--xyz\r\nContent-Type: text/html\r\n\r\n<html>\r\n--xyz--\r\n");
        });
        Folder folder;
        const DicomWebError e = retrieveError(server, folder.path);
        EXPECT_EQ(e.kind, ErrorKind::BadResponse);
        EXPECT_CONTAINS(e.what(), "instance 1 of series 1.2.3.4 as 'text/html', not application/dicom");
    }
    {
        HostileServer server([](int, const std::string &) { return multipartAnswer("--xyz\r\n\r\nDICM\r\n--xyz--\r\n"); });
        Folder folder;
        const DicomWebError e = retrieveError(server, folder.path);
        EXPECT_EQ(e.kind, ErrorKind::BadResponse);
        EXPECT_CONTAINS(e.what(), "without a Content-Type");
    }
    {
        HostileServer server([](int, const std::string &) { return httpResponse(200, "application/json", "[]"); });
        Folder folder;
        const DicomWebError e = retrieveError(server, folder.path);
        EXPECT_EQ(e.kind, ErrorKind::BadResponse);
        EXPECT_CONTAINS(e.what(), "Content-Type 'application/json'");
    }
    {
        HostileServer server([](int, const std::string &) {
            return httpResponse(200, "multipart/related; boundary=" + std::string(71, 'b'), "");
        });
        Folder folder;
        EXPECT_CONTAINS(retrieveError(server, folder.path).what(), "1 to 70 characters");
    }
}

TEST(DicomWebHostile, EmptyMultipartIsNotFoundAndAWrongCountIsBadResponse) {
    HostileServer server([](int, const std::string &) { return multipartAnswer(kGoodPart + "--xyz--\r\n"); });
    Folder folder;
    Client client(configFor(server));
    try {
        client.retrieveSeries(kStudy, kSeries, folder.path, 1 << 20, {}, {}, 2);
        FAIL() << "one instance of two was accepted";
    } catch (const DicomWebError &e) {
        EXPECT_EQ(e.kind, ErrorKind::BadResponse);
        EXPECT_CONTAINS(e.what(), "sent 1 instances of series 1.2.3.4, its metadata listed 2");
    }
    HostileServer empty([](int, const std::string &) { return multipartAnswer("--xyz--\r\n"); });
    const DicomWebError e = retrieveError(empty, folder.path);
    EXPECT_EQ(e.kind, ErrorKind::NotFound);
}

TEST(DicomWebHostile, RedirectToAnotherHostIsRefused) {
    uint16_t port = 0;
    HostileServer server([&](int, const std::string &) {
        // 127.0.0.2 is loopback too: another host by name, reachable, and still refused.
        return httpResponse(302, "", "", "Location: http://127.0.0.2:" + std::to_string(port) + "/dicom-web/studies\r\n");
    });
    port = server.port();
    const DicomWebError e = findError(server);
    EXPECT_EQ(e.kind, ErrorKind::BadResponse);
    EXPECT_CONTAINS(e.what(), "redirected GET /dicom-web/studies to another scheme, host or port (http://127.0.0.2:");
    EXPECT_EQ(server.requests().size(), 1u) << "the redirect must not be followed";

    HostileServer toHttps([](int, const std::string &) {
        return httpResponse(301, "", "", "Location: https://127.0.0.1/dicom-web/studies\r\n");
    });
    EXPECT_CONTAINS(findError(toHttps).what(), "another scheme, host or port");
}

TEST(DicomWebHostile, SameOriginRedirectsAreFollowedAtMostThreeTimes) {
    HostileServer twice([](int index, const std::string &) {
        if (index < 2) return httpResponse(307, "", "", "Location: /dicom-web/elsewhere" + std::to_string(index) + "\r\n");
        return httpResponse(200, "application/dicom+json", "[]");
    });
    Client client(configFor(twice));
    EXPECT_TRUE(client.findStudies({}).empty());
    ASSERT_EQ(twice.requests().size(), 3u);
    EXPECT_CONTAINS(twice.requests()[2], "GET /dicom-web/elsewhere1 ");
    EXPECT_CONTAINS(twice.requests()[2], "Authorization: " + kAuthorization);

    HostileServer forever([](int, const std::string &) { return httpResponse(302, "", "", "Location: /again\r\n"); });
    const DicomWebError e = findError(forever);
    EXPECT_EQ(e.kind, ErrorKind::BadResponse);
    EXPECT_CONTAINS(e.what(), "more than 3 times");
    EXPECT_EQ(forever.requests().size(), 4u);
}

TEST(DicomWebHostile, DicomJsonOfWrongTypesIsReadDefensively) {
    // Attributes missing, of the wrong JSON type, empty Value arrays, PN as text, IS as text,
    // datasets that are not objects, and UIDs that are not UIDs (those studies are left out).
    const std::string studies = R"([
        {"0020000D": {"vr": "UI", "Value": ["1.2.3"]},
         "00100010": {"vr": "PN", "Value": [{"Ideographic": "x"}]},
         "00100020": {"vr": "LO", "Value": [42]},
         "00080020": {"vr": "DA", "Value": []},
         "00081030": {"vr": "LO", "Value": "not an array"},
         "00080050": "not an object",
         "00080061": {"vr": "CS", "Value": ["CT", 7, null, "MR"]}},
        {"0020000D": {"vr": "UI", "Value": [123]}},
        {"0020000D": {"vr": "UI", "Value": ["1.2/../x"]}},
        {"0020000D": {"vr": "UI"}},
        5, null, "text", [],
        {"0020000D": {"Value": ["4.5.6"]}, "00100010": {"Value": ["DOE^TEXT   "]}}
    ])";
    const std::string series = R"([
        {"0020000E": {"Value": ["1.2.3.4"]}, "00080060": {"Value": ["CT"]}, "00201209": {"Value": ["12"]}},
        {"0020000E": {"Value": ["1.2.3.5"]}, "00201209": {"Value": [-3]}, "0008103E": {"Value": [{"a": 1}]}},
        {"0020000E": {"Value": [1.5]}},
        {"00201209": {"Value": [1]}}
    ])";
    HostileServer server([&](int, const std::string &request) {
        const bool seriesQuery = request.find("/series?") != std::string::npos;
        return httpResponse(200, "application/dicom+json; charset=utf-8", seriesQuery ? series : studies);
    });
    Client client(configFor(server));
    const auto found = client.findStudies({});
    ASSERT_EQ(found.size(), 2u);
    EXPECT_EQ(found[0].studyUid, "1.2.3");
    EXPECT_EQ(found[0].patientName, "");
    EXPECT_EQ(found[0].patientId, "42");
    EXPECT_EQ(found[0].studyDate, "");
    EXPECT_EQ(found[0].description, "");
    EXPECT_EQ(found[0].accessionNumber, "");
    EXPECT_EQ(found[0].modalities, (std::vector<std::string>{"CT", "MR"}));
    ASSERT_EQ(found[0].series.size(), 2u);
    EXPECT_EQ(found[0].series[0].seriesUid, "1.2.3.4");
    EXPECT_EQ(found[0].series[0].modality, "CT");
    EXPECT_EQ(found[0].series[0].instances, 12);
    EXPECT_EQ(found[0].series[1].instances, 0) << "a negative count is no count";
    EXPECT_EQ(found[0].series[1].description, "");
    EXPECT_EQ(found[1].studyUid, "4.5.6");
    EXPECT_EQ(found[1].patientName, "DOE^TEXT") << "PN sent as text, DICOM padding trimmed";
}

TEST(DicomWebHostile, MalformedDeepOrMistypedJsonIsBadResponse) {
    for (const auto &[type, body, expected] :
         std::vector<std::tuple<std::string, std::string, std::string>>{
             {"application/dicom+json", "[{\"0020000D\": ", "malformed JSON"},
             {"application/dicom+json", std::string(100000, '[') + std::string(100000, ']'), "nested deeper than"},
             {"application/dicom+json", "{\"not\": \"an array\"}", "not an array"},
             {"text/html", "<html>", "Content-Type 'text/html'"}}) {
        HostileServer server([&](int, const std::string &) { return httpResponse(200, type, body); });
        const DicomWebError e = findError(server);
        EXPECT_EQ(e.kind, ErrorKind::BadResponse) << e.what();
        EXPECT_CONTAINS(e.what(), expected);
    }
}

TEST(DicomWebHostile, QidoAnswerPastItsLimitIsTooLarge) {
    const std::string big = "[" + std::string(3000, ' ') + "]";
    HostileServer announced([&](int, const std::string &) { return httpResponse(200, "application/dicom+json", big); });
    SourceConfig config = configFor(announced);
    config.maxQueryBytes = 1000;
    DicomWebError e = findError(announced, config);
    EXPECT_EQ(e.kind, ErrorKind::TooLarge) << e.what();
    EXPECT_CONTAINS(e.what(), "1000 bytes");
    // Without a Content-Length (the body ends at close): counted as it arrives.
    HostileServer unannounced([&](int, const std::string &) {
        return "HTTP/1.1 200 OK\r\nConnection: close\r\nContent-Type: application/dicom+json\r\n\r\n" + big;
    });
    config = configFor(unannounced);
    config.maxQueryBytes = 1000;
    e = findError(unannounced, config);
    EXPECT_EQ(e.kind, ErrorKind::TooLarge) << e.what();
}

TEST(DicomWebHostile, StatusesMapToTheirKindsAndTheCredentialsAreNeverQuoted) {
    for (const auto &[status, kind] : std::vector<std::pair<int, ErrorKind>>{{401, ErrorKind::Unauthorized},
                                                                          {403, ErrorKind::Forbidden},
                                                                          {404, ErrorKind::NotFound},
                                                                          {500, ErrorKind::BadResponse},
                                                                          {503, ErrorKind::Unreachable}}) {
        // The server echoes the request, Authorization header included, as its error body.
        HostileServer server([&, s = status](int, const std::string &request) {
            return httpResponse(s, "text/plain", "you sent: " + request);
        });
        const DicomWebError e = findError(server);
        EXPECT_EQ(e.kind, kind) << status << ": " << e.what();
        EXPECT_CONTAINS(e.what(), "HTTP " + std::to_string(status));
        EXPECT_CONTAINS(e.what(), "DICOMweb source 'hostile'");
        EXPECT_EQ(std::string(e.what()).find("hostile-test-token"), std::string::npos) << e.what();
        EXPECT_EQ(std::string(e.what()).find("PatientName"), std::string::npos)
            << "the query string is not quoted: " << e.what();
    }
}

// A PACS that echoes the Authorization value it received, in each form (hostile_server.hpp's
// credentialEchoes), in each place the client quotes what a server sent: a QIDO answer's
// Content-Type, the series-size metadata answer's, a WADO answer's, one multipart part's, and
// an error body (plain and Orthanc's JSON "Details"). The message must say what was wrong and
// hold no form of the credentials.
TEST(DicomWebHostile, CredentialsEchoedInAnyFormAndPlaceAreNeverQuoted) {
    const std::string authorization = "Basic " + volcast::test::base64("reader:s3cret/P@ss+w=rd!-long-enough-for-a-40-character-quote-to-cut-it");
    const auto echoesOf = [](const std::string &request) {
        return volcast::test::credentialEchoes(volcast::test::authorizationIn(request));
    };
    const size_t forms = volcast::test::credentialEchoes(authorization).size();
    const std::string instanceJson = R"([{"00280010": {"vr": "US", "Value": [4]}, "00280011": {"vr": "US", "Value": [4]}}])";
    struct Place {
        std::string name;
        std::string says;   // what the message must still say
        std::function<std::string(const std::string &echo, const std::string &request)> answer;
        std::function<void(Client &, const fs::path &)> call;
    };
    const auto search = [](Client &c, const fs::path &) { c.findStudies({}); };
    const auto measure = [](Client &c, const fs::path &) { c.seriesSize(kStudy, kSeries); };
    const auto retrieve = [](Client &c, const fs::path &folder) { c.retrieveSeries(kStudy, kSeries, folder, 1 << 20, {}, {}); };
    const std::vector<Place> places{
        {"a QIDO answer's Content-Type", "Content-Type",
         [](const std::string &echo, const std::string &) { return httpResponse(200, "text/plain; echo=" + echo, "[]"); },
         search},
        {"the series-size metadata answer's Content-Type", "Content-Type",
         [&](const std::string &echo, const std::string &request) {
             if (request.find("/instances?") != std::string::npos) return httpResponse(200, "application/dicom+json", instanceJson);
             return httpResponse(200, echo + "; type=json", "[]");
         },
         measure},
        {"a WADO answer's Content-Type", "Content-Type",
         [](const std::string &echo, const std::string &) { return httpResponse(200, echo, "--xyz--\r\n"); }, retrieve},
        {"a multipart part's Content-Type", "instance 1",
         [](const std::string &echo, const std::string &) {
             return multipartAnswer("--xyz\r\nContent-Type: " + echo + "\r\n\r\nDICM\r\n--xyz--\r\n");
         },
         retrieve},
        {"an error body", "HTTP 500",
         [](const std::string &echo, const std::string &) { return httpResponse(500, "text/plain", "you sent: " + echo); },
         search},
        {"an error body's JSON Details", "HTTP 403",
         [](const std::string &echo, const std::string &) {
             return httpResponse(403, "application/json", R"({"Message": "no", "Details": ")" + echo + "\"}");
         },
         retrieve},
    };
    for (const Place &place : places) {
        for (size_t form = 0; form < forms; ++form) {
            HostileServer server([&](int, const std::string &request) {
                return place.answer(echoesOf(request).at(form), request);
            });
            SourceConfig config = configFor(server);
            config.authorization = authorization;
            Client client(config);
            Folder folder;
            std::string message;
            try {
                place.call(client, folder.path);
                ADD_FAILURE() << place.name << ", form " << form << ": the call succeeded";
            } catch (const DicomWebError &e) {
                message = e.what();
            }
            const std::string echo = volcast::test::echoIn(message, volcast::test::credentialEchoes(authorization));
            EXPECT_EQ(echo, "") << place.name << " quoted the credentials (form " << form << "): " << message;
            EXPECT_EQ(message.find("s3cret"), std::string::npos) << place.name << ": " << message;
            EXPECT_NE(message.find(place.says), std::string::npos)
                << place.name << ": the message no longer says what was wrong: " << message;
        }
    }
}

TEST(DicomWebHostile, SilentServerTimesOutWithinTheLowSpeedLimit) {
    HostileServer server([](int, const std::string &) { return std::string(); });
    SourceConfig config = configFor(server);
    config.lowSpeedSeconds = 1;
    config.requestTimeoutSeconds = 20;
    const auto start = std::chrono::steady_clock::now();
    const DicomWebError e = findError(server, config);
    const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    EXPECT_EQ(e.kind, ErrorKind::Timeout) << e.what();
    // curl checks the speed once a second: the 1 s limit ends the request within 1-3 s.
    EXPECT_LT(seconds, 5.0);
}

TEST(DicomWebHostile, PortWithNothingListeningIsUnreachable) {
    const uint16_t port = volcast::test::freeLoopbackPort();
    SourceConfig config;
    config.name = "nobody";
    config.baseUrl = "http://127.0.0.1:" + std::to_string(port) + "/dicom-web";
    Client client(config);
    try {
        client.findStudies({});
        FAIL() << "a closed port answered";
    } catch (const DicomWebError &e) {
        EXPECT_EQ(e.kind, ErrorKind::Unreachable) << e.what();
        EXPECT_CONTAINS(e.what(), "DICOMweb source 'nobody' is unreachable (GET /dicom-web/studies)");
    }
}

TEST(DicomWebHostile, FolderHoldingFilesIsRefusedBeforeAnyRequest) {
    // Files of an earlier retrieval would be loaded as part of the new series.
    HostileServer server([](int, const std::string &) { return multipartAnswer(kGoodPart + "--xyz--\r\n"); });
    Folder folder;
    fs::create_directories(folder.path);
    std::ofstream(folder.path / "instance_00007.dcm") << "stale";
    const DicomWebError e = retrieveError(server, folder.path);
    EXPECT_EQ(e.kind, ErrorKind::Storage) << e.what();
    EXPECT_CONTAINS(e.what(), "is not empty");
    EXPECT_TRUE(server.requests().empty());
    EXPECT_TRUE(fs::exists(folder.path / "instance_00007.dcm")) << "files it did not write are left alone";
}
