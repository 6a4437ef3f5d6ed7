// Uploads (POST /api/volumes, server/upload_store.hpp) against a real server over loopback:
// each request is written byte for byte as a client would (or an attacker), and every
// refusal is checked for its status, its words and that the server still answers. Also the
// parts under it: the loader's parseInChild (a checker that crashes on a NRRD file) and the
// zip unpacker against hostile archives.

#include "client/cpp/ws_client.hpp"
#include "renderer/io/volume_io.hpp"
#include "renderer/io/zip_extract.hpp"
#include "renderer/model/synthetic.hpp"
#include "server/http_session.hpp"
#include "server/server.hpp"
#include "server/upload_store.hpp"
#include "tests/dicom_tags.hpp"
#include "tests/server/child_process.hpp"
#include "tests/server/server_fixture.hpp"
#include "util/utf8.hpp"

#include <gtest/gtest.h>
#include <spdlog/fmt/fmt.h>
#include <zip.h>

#include <boost/asio/write.hpp>

#include <csignal>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <mutex>
#include <regex>
#include <sys/stat.h>
#include <sys/wait.h>
#include <thread>
#include <unistd.h>

namespace {

namespace fs = std::filesystem;
using json = nlohmann::json;
using namespace std::chrono_literals;
using volcast::test::rawExchange;
using volcast::test::RawExchange;

constexpr auto kStartTimeout = 20s;
// A parse in the checker process, then here: well under a second for these small files on an
// idle machine; the shared 2-core build machine can be much slower.
constexpr auto kUploadTimeout = 60s;
constexpr const char *kToken = "upload-test-token";
constexpr uint64_t kMaxUploadBytes = uint64_t(1) << 20;
constexpr int kHeaderTimeoutMs = 1000;
const volcast::Vec3i kDims{20, 16, 12};

std::string readFile(const fs::path &p) {
    std::ifstream in(p, std::ios::binary);
    return {std::istreambuf_iterator<char>(in), {}};
}

volcast::Volume testVolume() {
    return volcast::makeGaussianBlob(kDims, {1.0, 1.5, 2.0}, 4.0, 1000.0).volume;
}

// A request head for an upload; `filename` goes in X-Volcast-Filename unless empty.
std::string uploadHead(const std::string &filename, uint64_t length, const std::string &token = kToken,
                       const std::string &target = "/api/volumes") {
    std::string r = "POST " + target + " HTTP/1.1\r\nHost: 127.0.0.1\r\n";
    if (!token.empty()) r += "Authorization: Bearer " + token + "\r\n";
    if (!filename.empty()) r += "X-Volcast-Filename: " + filename + "\r\n";
    return r + "Content-Length: " + std::to_string(length) + "\r\n\r\n";
}

// rawExchange from the local address `from`: each 127.0.0.x is another client (identity).
RawExchange rawExchangeFrom(const std::string &from, uint16_t port, const std::string &bytes,
                            std::chrono::milliseconds timeout) {
    return rawExchange(port, bytes, timeout, from);
}

// A connection from `from` that has sent `bytes` and is left open.
std::unique_ptr<boost::beast::tcp_stream> openFrom(boost::asio::io_context &ioc, const std::string &from, uint16_t port,
                                                   const std::string &bytes) {
    auto s = std::make_unique<boost::beast::tcp_stream>(ioc);
    s->socket().open(boost::asio::ip::tcp::v4());
    s->socket().bind(boost::asio::ip::tcp::endpoint(boost::asio::ip::make_address(from), 0));
    s->connect(boost::asio::ip::tcp::endpoint(boost::asio::ip::make_address("127.0.0.1"), port));
    boost::asio::write(*s, boost::asio::buffer(bytes));
    return s;
}

// A chunked upload request of `body` in 64 KiB chunks.
std::string chunkedUpload(const std::string &filename, const std::string &body) {
    std::string r = "POST /api/volumes HTTP/1.1\r\nHost: 127.0.0.1\r\nAuthorization: Bearer " + std::string(kToken) +
                    "\r\nX-Volcast-Filename: " + filename + "\r\nTransfer-Encoding: chunked\r\n\r\n";
    for (size_t at = 0; at < body.size(); at += 64 * 1024) {
        const std::string piece = body.substr(at, 64 * 1024);
        r += fmt::format("{:x}\r\n", piece.size()) + piece + "\r\n";
    }
    return r + "0\r\n\r\n";
}

// Regular files under `folder`, at any depth.
size_t filesUnder(const fs::path &folder) {
    size_t n = 0;
    for (const auto &e : fs::recursive_directory_iterator(folder))
        if (e.is_regular_file()) ++n;
    return n;
}

int statusOf(const RawExchange &x) { return x.response ? int(x.response->result_int()) : 0; }
std::string describe(const RawExchange &x) {
    return x.response ? std::to_string(x.response->result_int()) + " " + x.response->body() : "no response: " + x.error;
}

// A .zip holding `files` under their own names (the server ignores them).
void writeZip(const fs::path &zipPath, const std::vector<std::pair<std::string, std::string>> &files) {
    int error = 0;
    zip_t *z = zip_open(zipPath.c_str(), ZIP_CREATE | ZIP_TRUNCATE, &error);
    ASSERT_NE(z, nullptr) << "libzip cannot create " << zipPath;
    for (const auto &[name, bytes] : files) {
        // libzip frees the copy it is given (freep = 1) once the archive is written.
        void *copy = std::malloc(bytes.size() ? bytes.size() : 1);
        std::memcpy(copy, bytes.data(), bytes.size());
        zip_source_t *source = zip_source_buffer(z, copy, bytes.size(), 1);
        ASSERT_NE(source, nullptr);
        ASSERT_GE(zip_file_add(z, name.c_str(), source, ZIP_FL_OVERWRITE), 0) << zip_strerror(z);
    }
    ASSERT_EQ(zip_close(z), 0) << "libzip cannot write " << zipPath;
}

class Upload : public ::testing::Test {
  protected:
    static inline std::unique_ptr<volcast::server::Server> server;
    static inline fs::path tmp;

    static volcast::server::ServerConfig config() {
        volcast::server::ServerConfig c;
        c.port = 0;
        c.webRoot = tmp / "web";
        c.defaultVolume = "";
        c.token = kToken;
        c.maxUploadBytes = kMaxUploadBytes;
        c.headerTimeoutMs = kHeaderTimeoutMs;
        c.device = "cpu";
        return c;
    }
    static void SetUpTestSuite() {
        tmp = fs::temp_directory_path() / ("volcast_upload_" + std::to_string(::getpid()));
        fs::remove_all(tmp);
        fs::create_directories(tmp / "web");
        server = std::make_unique<volcast::server::Server>(config());
        volcast::test::startAndWaitReady(*server, kStartTimeout);
    }
    static void TearDownTestSuite() {
        server.reset();
        fs::remove_all(tmp);
    }

    uint16_t port() const { return server->port(); }

    RawExchange upload(const std::string &filename, const std::string &body, const std::string &token = kToken) {
        return rawExchange(port(), uploadHead(filename, body.size(), token) + body, kUploadTimeout);
    }
    // A file of the test volume in `ext`'s format, as the loader's own writer makes it.
    std::string volumeFile(const std::string &ext, bool compress = false) {
        const fs::path p = tmp / ("volume" + ext);
        volcast::saveVolume(testVolume(), p, {volcast::VoxelType::Int16, compress});
        return readFile(p);
    }
    // A 201 for `body` named `filename`: its JSON, checked.
    json accepted(const std::string &filename, const std::string &body) {
        const auto x = upload(filename, body);
        EXPECT_EQ(statusOf(x), 201) << describe(x);
        if (statusOf(x) != 201) return json();
        EXPECT_EQ(x.response->at(boost::beast::http::field::content_type), "application/json");
        const json j = json::parse(x.response->body());
        EXPECT_TRUE(std::regex_match(j.at("volume").get<std::string>(), std::regex("upload:[0-9a-f]{32}"))) << j;
        EXPECT_EQ(j.at("filename"), filename);
        EXPECT_EQ(j.at("bytes"), body.size());
        EXPECT_EQ(j.at("dims"), json::array({kDims.x, kDims.y, kDims.z})) << j;
        EXPECT_EQ(j.at("voxel_type"), "int16") << j;
        EXPECT_GT(j.at("expires_in_s").get<double>(), 0);
        return j;
    }
    void expectAlive() {
        const auto reply = volcast::test::httpGet(port(), "/healthz");
        EXPECT_EQ(reply.status, 200) << reply.body;
    }
    // A refusal: `status`, `why` in its one line, and no server path in it.
    void expectRefused(const RawExchange &x, int status, const std::string &why) {
        ASSERT_EQ(statusOf(x), status) << describe(x);
        const std::string &body = x.response->body();
        EXPECT_NE(body.find(why), std::string::npos) << body;
        EXPECT_EQ(body.find(server->state().uploads().folder().string()), std::string::npos) << "a server path: " << body;
        EXPECT_EQ(body.find("/tmp"), std::string::npos) << "a server path: " << body;
        EXPECT_EQ(std::count(body.begin(), body.end(), '\n'), 1) << "not one line: " << body;
        expectAlive();
    }
};

TEST_F(Upload, NrrdNiftiAndMetaImageAre201WithTheirDims) {
    accepted("scan.nrrd", volumeFile(".nrrd"));
    accepted("Scan.NII.GZ", volumeFile(".nii.gz"));
    accepted("scan.nii", volumeFile(".nii"));
    accepted("scan.mha", volumeFile(".mha", true));
}

TEST_F(Upload, AnUploadOpensByItsNameWithItsDims) {
    const json j = accepted("open-me.nii.gz", volumeFile(".nii.gz"));
    ASSERT_TRUE(j.contains("volume"));
    volcast::client::Client c("127.0.0.1", port());
    c.sendText(json{{"type", "hello"}, {"id", 1}, {"protocol", 1}, {"client", "gtest"}, {"token", kToken}}.dump());
    volcast::client::waitForReply(c, 1, kUploadTimeout);
    c.sendText(json{{"type", "open_volume"}, {"id", 2}, {"name", j.at("volume")}}.dump());
    const auto state = volcast::client::waitForReply(c, 2, kUploadTimeout);
    const json s = json::parse(state.text);
    ASSERT_EQ(s.at("type"), "state") << state.text;
    EXPECT_EQ(s.at("volume").at("dims"), json::array({kDims.x, kDims.y, kDims.z})) << state.text;
    // A well-formed id that was never handed out, and a malformed one: not found, saying why.
    for (const std::string name : {"upload:0123456789abcdef0123456789abcdef", "upload:XYZ"}) {
        c.sendText(json{{"type", "open_volume"}, {"id", 3}, {"name", name}}.dump());
        const auto refused = volcast::client::waitForReply(c, 3, kUploadTimeout);
        EXPECT_NE(refused.text.find("not_found"), std::string::npos) << refused.text;
        EXPECT_NE(refused.text.find("uploads expire after"), std::string::npos) << refused.text;
    }
}

TEST_F(Upload, ZipOfADicomSeriesIs201) {
    const fs::path series = tmp / "series";
    volcast::saveDicomSeries(testVolume(), series, volcast::VoxelType::Int16);
    std::vector<std::pair<std::string, std::string>> files;
    // Folders and odd names inside the archive: the server uses none of them.
    for (const auto &e : fs::directory_iterator(series))
        files.emplace_back("study/series/../" + e.path().filename().string(), readFile(e.path()));
    writeZip(tmp / "series.zip", files);
    accepted("series.zip", readFile(tmp / "series.zip"));
}

TEST_F(Upload, ZipOfASeriesWithAnotherPatientsInstanceIs422NamingIt) {
    const fs::path series = tmp / "mixed";
    volcast::saveDicomSeries(testVolume(), series, volcast::VoxelType::Int16);
    volcast::dicom_tags::makeAnotherPatients(series / "slice_0002.dcm");
    std::vector<std::pair<std::string, std::string>> files;
    for (const auto &e : fs::directory_iterator(series)) files.emplace_back(e.path().filename().string(), readFile(e.path()));
    writeZip(tmp / "mixed.zip", files);
    const auto x = upload("mixed.zip", readFile(tmp / "mixed.zip"));
    expectRefused(x, 422, "belongs to another patient (PatientID differs from the series' first instance");
    ASSERT_TRUE(x.response);
    EXPECT_NE(x.response->body().find("instance 3 ("), std::string::npos) << "names the instance: " << x.response->body();
    EXPECT_EQ(x.response->body().find("OTHER-PATIENT-7"), std::string::npos) << "quotes a PatientID";
}

TEST_F(Upload, GarbageIs422NamingTheFileAndTheServerCarriesOn) {
    std::string garbage(4096, '\0');
    for (size_t i = 0; i < garbage.size(); ++i) garbage[i] = char((i * 2654435761u) >> 13);
    expectRefused(upload("junk.nrrd", garbage), 422, "junk.nrrd");
    expectRefused(upload("junk.nii.gz", garbage), 422, "junk.nii.gz");
    expectRefused(upload("junk.zip", garbage), 422, "not a valid zip archive");
}

TEST_F(Upload, NrrdPromisingMoreDataThanItHoldsIs422) {
    std::string nrrd = volumeFile(".nrrd");
    nrrd.resize(nrrd.size() - 1000);
    expectRefused(upload("short.nrrd", nrrd), 422, "short.nrrd");
}

TEST_F(Upload, ContentLengthOverTheLimitIs413BeforeAnyBodyByte) {
    // Only the head is sent: the answer cannot wait for a body.
    const auto x = rawExchange(port(), uploadHead("big.nrrd", kMaxUploadBytes + 1), 10s);
    ASSERT_EQ(statusOf(x), 413) << describe(x);
    EXPECT_NE(x.response->body().find("--max-upload-mib"), std::string::npos) << x.response->body();
    EXPECT_TRUE(x.closedAfter);
    expectAlive();
}

TEST_F(Upload, ChunkedBodyIsTakenAndOverTheLimitIs413) {
    const std::string nrrd = volumeFile(".nrrd");
    std::string request = "POST /api/volumes?filename=chunked%20scan.nrrd HTTP/1.1\r\nHost: 127.0.0.1\r\nAuthorization: "
                          "Bearer " + std::string(kToken) + "\r\nTransfer-Encoding: chunked\r\n\r\n";
    for (size_t at = 0; at < nrrd.size(); at += 1000) {
        const std::string piece = nrrd.substr(at, 1000);
        char size[16];
        std::snprintf(size, sizeof size, "%zx", piece.size());
        request += std::string(size) + "\r\n" + piece + "\r\n";
    }
    request += "0\r\n\r\n";
    const auto ok = rawExchange(port(), request, kUploadTimeout);
    ASSERT_EQ(statusOf(ok), 201) << describe(ok);
    EXPECT_EQ(json::parse(ok.response->body()).at("filename"), "chunked scan.nrrd");

    std::string big = "POST /api/volumes HTTP/1.1\r\nHost: 127.0.0.1\r\nAuthorization: Bearer " + std::string(kToken) +
                      "\r\nX-Volcast-Filename: big.nrrd\r\nTransfer-Encoding: chunked\r\n\r\n";
    const std::string piece(64 * 1024, 'x');
    for (uint64_t sent = 0; sent <= kMaxUploadBytes; sent += piece.size()) big += "10000\r\n" + piece + "\r\n";
    const auto refused = rawExchange(port(), big, kUploadTimeout);
    ASSERT_EQ(statusOf(refused), 413) << describe(refused);
    expectAlive();
}

TEST_F(Upload, NameAndTokenRefusals) {
    const std::string nrrd = volumeFile(".nrrd");
    expectRefused(upload("scan.png", nrrd), 415, "scan.png");
    expectRefused(upload("", nrrd), 400, "X-Volcast-Filename");
    expectRefused(upload("a/b.nrrd", nrrd), 400, "'/'");
    expectRefused(upload("bad\xff\xfe.nrrd", nrrd), 400, "UTF-8");
    expectRefused(upload(std::string(300, 'a') + ".nrrd", nrrd), 400, "over 255");
    expectRefused(rawExchange(port(), uploadHead("", 4, kToken, "/api/volumes?filename=%zz.nrrd") + "abcd"), 400,
                  "percent-encoding");
    const auto noToken = upload("scan.nrrd", nrrd, "");
    expectRefused(noToken, 401, "Authorization: Bearer");
    EXPECT_NE(noToken.response->at(boost::beast::http::field::www_authenticate).find("Bearer"), std::string::npos);
    expectRefused(upload("scan.nrrd", nrrd, "wrong-token"), 401, "token");
    expectRefused(rawExchange(port(), uploadHead("empty.nrrd", 0)), 400, "empty");
    EXPECT_EQ(volcast::test::httpGet(port(), "/api/volumes").status, 405);
}

TEST_F(Upload, IdsAreDistinct32HexCharacters) {
    const std::string nrrd = volumeFile(".nrrd");
    const json a = accepted("a.nrrd", nrrd), b = accepted("a.nrrd", nrrd);
    ASSERT_TRUE(a.contains("volume") && b.contains("volume"));
    EXPECT_NE(a.at("volume"), b.at("volume"));
}

TEST_F(Upload, BodyThatStopsArrivingIs408) {
    const auto started = std::chrono::steady_clock::now();
    const auto x = rawExchange(port(), uploadHead("slow.nrrd", 1000) + "NRRD0004\n", 10s);
    expectRefused(x, 408, "stopped arriving");
    EXPECT_GE(std::chrono::steady_clock::now() - started, std::chrono::milliseconds(kHeaderTimeoutMs));
}

TEST_F(Upload, ThirdUploadAtOnceFromOneAddressIs429) {
    // Two uploads under way (their heads and a few bytes sent), then a third.
    boost::asio::io_context ioc;
    std::vector<std::unique_ptr<boost::beast::tcp_stream>> open;
    for (int i = 0; i < 2; ++i) {
        auto s = std::make_unique<boost::beast::tcp_stream>(ioc);
        s->connect(boost::asio::ip::tcp::endpoint(boost::asio::ip::make_address("127.0.0.1"), port()));
        boost::asio::write(*s, boost::asio::buffer(uploadHead("held.nrrd", 1000) + "NRRD"));
        open.push_back(std::move(s));
    }
    std::this_thread::sleep_for(100ms);   // both heads read (the timeout is 1 s)
    expectRefused(upload("third.nrrd", volumeFile(".nrrd")), 429, "--max-uploads-per-address");
    open.clear();
    std::this_thread::sleep_for(200ms);
    accepted("after.nrrd", volumeFile(".nrrd"));
}

TEST_F(Upload, LargeBodyIsStoredWholeAndAccepted) {
    // 64 MiB: a body read in many pieces; every byte must land in the file, in order.
    constexpr volcast::Vec3i kLargeDims{256, 256, 512};
    const size_t voxels = size_t(kLargeDims.x) * size_t(kLargeDims.y) * size_t(kLargeDims.z);
    std::string nrrd = fmt::format("NRRD0004\ntype: short\ndimension: 3\nsizes: {} {} {}\nencoding: raw\n"
                                   "endian: little\n\n",
                                   kLargeDims.x, kLargeDims.y, kLargeDims.z);
    const size_t headerBytes = nrrd.size();
    nrrd.resize(headerBytes + voxels * 2);
    // No two neighbouring 64 KiB stretches alike: a piece lost, doubled or moved changes the file.
    for (size_t i = 0; i < voxels; ++i) {
        const auto v = uint16_t(((i * 40503u) >> 4) & 0x0fffu);
        nrrd[headerBytes + 2 * i] = char(v & 0xff);
        nrrd[headerBytes + 2 * i + 1] = char(v >> 8);
    }
    auto c = config();
    c.maxUploadBytes = uint64_t(128) << 20;
    volcast::server::Server s(c);
    volcast::test::startAndWaitReady(s, kStartTimeout);
    const auto x = rawExchange(s.port(), uploadHead("large.nrrd", nrrd.size()) + nrrd, kUploadTimeout);
    ASSERT_EQ(statusOf(x), 201) << describe(x);
    const json j = json::parse(x.response->body());
    EXPECT_EQ(j.at("bytes"), nrrd.size()) << j;
    EXPECT_EQ(j.at("dims"), json::array({kLargeDims.x, kLargeDims.y, kLargeDims.z})) << j;
    std::vector<fs::path> stored;
    for (const auto &e : fs::recursive_directory_iterator(s.state().uploads().folder()))
        if (e.is_regular_file()) stored.push_back(e.path());
    ASSERT_EQ(stored.size(), 1u) << "one upload, one file in the upload folder: its parse";
    // What the upload keeps is the checker's parse of the body: its samples are the body's.
    const volcast::Volume v = volcast::loadParsedVolume(stored.front(), "large.nrrd");
    ASSERT_EQ(v.dims, kLargeDims);
    ASSERT_EQ(v.narrow.bytes, 2) << "int16 samples are held as 16-bit";
    size_t differing = 0;
    for (size_t i = 0; i < voxels; ++i) {
        const auto want = uint16_t(((i * 40503u) >> 4) & 0x0fffu);
        uint16_t got;
        std::memcpy(&got, v.narrowVoxels.data() + 2 * i, 2);
        if (float(got) + v.narrow.offset != float(want)) ++differing;
    }
    EXPECT_EQ(differing, 0u) << "samples of the kept parse differ from the body sent";
}

TEST_F(Upload, ExpiredUploadIsNotFoundAndDeleted) {
    auto c = config();
    c.uploadTtlSeconds = 0.5;
    volcast::server::Server shortLived(c);
    volcast::test::startAndWaitReady(shortLived, kStartTimeout);
    const std::string nrrd = volumeFile(".nrrd");
    const auto x = rawExchange(shortLived.port(), uploadHead("brief.nrrd", nrrd.size()) + nrrd, kUploadTimeout);
    ASSERT_EQ(statusOf(x), 201) << describe(x);
    const std::string name = json::parse(x.response->body()).at("volume");
    auto &store = shortLived.state().uploads();
    EXPECT_FALSE(store.check(name).has_value()) << "a fresh upload is not found";
    std::this_thread::sleep_for(800ms);
    const auto gone = store.check(name);
    ASSERT_TRUE(gone.has_value());
    EXPECT_EQ(gone->code, volcast::protocol::ErrorCode::NotFound);
    EXPECT_NE(gone->message.find("uploads expire after"), std::string::npos) << gone->message;
    EXPECT_EQ(store.count(), 0u);
    EXPECT_TRUE(fs::is_empty(store.folder())) << "an expired upload's file is still on disk";
}

TEST_F(Upload, UploadFolderIsPrivateAndGoneAfterTheServerStops) {
    fs::path folder;
    {
        volcast::server::Server s(config());
        volcast::test::startAndWaitReady(s, kStartTimeout);
        folder = s.state().uploads().folder();
        struct stat st{};
        ASSERT_EQ(::stat(folder.c_str(), &st), 0);
        EXPECT_EQ(st.st_mode & 0777, 0700u) << "the upload folder is readable by others";
        const std::string nrrd = volumeFile(".nrrd");
        const auto x = rawExchange(s.port(), uploadHead("kept.nrrd", nrrd.size()) + nrrd, kUploadTimeout);
        ASSERT_EQ(statusOf(x), 201) << describe(x);
        EXPECT_FALSE(fs::is_empty(folder));
    }
    EXPECT_FALSE(fs::exists(folder)) << folder << " outlived the server";
}

TEST_F(Upload, GivenUploadDirLosesOnlyItsOwnLeftoversAtStart) {
    const fs::path dir = tmp / "given-uploads";
    fs::create_directories(dir / "0123456789abcdef0123456789abcdef");
    std::ofstream(dir / "keep-me.txt") << "not an upload";
    auto c = config();
    c.uploadDir = dir;
    {
        volcast::server::Server s(c);
        EXPECT_FALSE(fs::exists(dir / "0123456789abcdef0123456789abcdef")) << "a leftover upload survived the start";
        EXPECT_TRUE(fs::exists(dir / "keep-me.txt")) << "a file the server did not make was deleted";
    }
    EXPECT_TRUE(fs::exists(dir)) << "a folder the server was given was deleted";
}

// ---- storage that no client can take from another ---------------------------------------

// Eight request heads declaring the largest upload, from four addresses, held open: they
// reserve nothing until bytes arrive, so they neither evict another client's kept upload nor
// refuse another client's new one (before, each head reserved its whole declared length).
TEST_F(Upload, HeadsAloneFromManyAddressesNeitherEvictNorBlockAnotherClientsUpload) {
    auto c = config();
    c.maxUploadStorageBytes = 2 * kMaxUploadBytes;
    c.headerTimeoutMs = 30000;   // the heads stay held for the whole test
    volcast::server::Server s(c);
    volcast::test::startAndWaitReady(s, kStartTimeout);
    const std::string nrrd = volumeFile(".nrrd");
    const auto kept = rawExchangeFrom("127.0.0.2", s.port(), uploadHead("victim.nrrd", nrrd.size()) + nrrd, kUploadTimeout);
    ASSERT_EQ(statusOf(kept), 201) << describe(kept);
    const std::string victim = json::parse(kept.response->body()).at("volume");

    boost::asio::io_context ioc;
    std::vector<std::unique_ptr<boost::beast::tcp_stream>> held;
    for (const char *from : {"127.0.0.3", "127.0.0.4", "127.0.0.5", "127.0.0.6"})
        for (int i = 0; i < 2; ++i) held.push_back(openFrom(ioc, from, s.port(), uploadHead("held.nrrd", kMaxUploadBytes)));
    std::this_thread::sleep_for(300ms);   // every head read and begun

    auto &store = s.state().uploads();
    EXPECT_FALSE(store.check(victim).has_value()) << "a kept upload was evicted by request heads of other clients";
    const auto other = rawExchangeFrom("127.0.0.7", s.port(), uploadHead("other.nrrd", nrrd.size()) + nrrd, kUploadTimeout);
    EXPECT_EQ(statusOf(other), 201) << "another client's upload is refused while the heads are held: " << describe(other);
    EXPECT_FALSE(store.check(victim).has_value()) << "the kept upload did not survive";
}

// With the storage full of one client's upload, another client's upload is refused naming
// that the storage is full, and the kept one survives; its own client may replace it.
TEST_F(Upload, AKeptUploadIsNeverEvictedForAnotherClientButItsOwnClientMayReplaceIt) {
    auto c = config();
    // Room for one parse of the test volume (its int16 samples and a header of ~200 bytes),
    // not for that and the file of another.
    const uint64_t parsedBytes = uint64_t(kDims.x * kDims.y * kDims.z) * 2 + 256;
    c.maxUploadStorageBytes = parsedBytes + parsedBytes / 2;
    volcast::server::Server s(c);
    volcast::test::startAndWaitReady(s, kStartTimeout);
    const std::string nrrd = volumeFile(".nrrd");
    const auto request = uploadHead("scan.nrrd", nrrd.size()) + nrrd;
    const auto first = rawExchangeFrom("127.0.0.2", s.port(), request, kUploadTimeout);
    ASSERT_EQ(statusOf(first), 201) << describe(first);
    const std::string firstName = json::parse(first.response->body()).at("volume");
    auto &store = s.state().uploads();

    const auto other = rawExchangeFrom("127.0.0.3", s.port(), request, kUploadTimeout);
    ASSERT_EQ(statusOf(other), 507) << describe(other);
    EXPECT_NE(other.response->body().find("storage is full"), std::string::npos) << other.response->body();
    EXPECT_NE(other.response->body().find("--max-upload-storage-mib"), std::string::npos) << other.response->body();
    EXPECT_FALSE(store.check(firstName).has_value()) << "another client's upload evicted the kept one";
    EXPECT_EQ(filesUnder(store.folder()), 1u) << "the refused upload left a file behind";

    const auto again = rawExchangeFrom("127.0.0.2", s.port(), request, kUploadTimeout);
    ASSERT_EQ(statusOf(again), 201) << "its own client cannot replace its upload: " << describe(again);
    EXPECT_TRUE(store.check(firstName).has_value()) << "the client's older upload was not the one replaced";
    EXPECT_FALSE(store.check(json::parse(again.response->body()).at("volume")).has_value());
}

// A chunked body declares no length: its bytes count as they arrive, and it is refused as soon
// as they pass the client's quota, its part deleted.
TEST_F(Upload, ChunkedBodyPastTheClientsQuotaIs507AndItsPartIsDeleted) {
    auto c = config();
    c.maxUploadBytes = 4 * kMaxUploadBytes;
    c.uploadQuotaBytes = kMaxUploadBytes;
    volcast::server::Server s(c);
    volcast::test::startAndWaitReady(s, kStartTimeout);
    // Half a MiB past the quota: within what the server reads and drops after its answer.
    const auto x = rawExchangeFrom("127.0.0.2", s.port(), chunkedUpload("big.nrrd", std::string(kMaxUploadBytes * 3 / 2, 'x')),
                                   kUploadTimeout);
    ASSERT_EQ(statusOf(x), 507) << describe(x);
    EXPECT_NE(x.response->body().find("--upload-quota-mib"), std::string::npos) << x.response->body();
    EXPECT_EQ(filesUnder(s.state().uploads().folder()), 0u) << "the refused chunked body is still on disk";
    // The quota is the client's own: another client's upload is taken.
    const std::string nrrd = volumeFile(".nrrd");
    const auto other = rawExchangeFrom("127.0.0.3", s.port(), chunkedUpload("small.nrrd", nrrd), kUploadTimeout);
    EXPECT_EQ(statusOf(other), 201) << describe(other);
}

TEST_F(Upload, EmptyChunkedBodyIs400) {
    const std::string request = "POST /api/volumes HTTP/1.1\r\nHost: 127.0.0.1\r\nAuthorization: Bearer " +
                                std::string(kToken) +
                                "\r\nX-Volcast-Filename: empty.nrrd\r\nTransfer-Encoding: chunked\r\n\r\n0\r\n\r\n";
    expectRefused(rawExchange(port(), request, kUploadTimeout), 400, "empty");
}

// A body that keeps arriving, a byte at a time, is cut once a rate window ends under the
// minimum (each byte comes well within the silence timeout, which alone never cuts it).
TEST_F(Upload, ADripIsCutWith408WithinTheRateWindow) {
    auto c = config();
    c.uploadRateWindowS = 1;
    c.uploadMinBytesPerS = 100;
    volcast::server::Server s(c);
    volcast::test::startAndWaitReady(s, kStartTimeout);
    boost::asio::io_context ioc;
    const auto started = std::chrono::steady_clock::now();
    auto stream = openFrom(ioc, "127.0.0.2", s.port(), uploadHead("drip.nrrd", 1000));
    // 5 bytes a second, for up to 10 s: the answer should come after the first window (1 s).
    boost::beast::error_code unused;
    while (std::chrono::steady_clock::now() - started < 10s && stream->socket().available(unused) == 0) {
        boost::beast::error_code ec;
        boost::asio::write(*stream, boost::asio::buffer("N", 1), ec);
        std::this_thread::sleep_for(200ms);
    }
    const auto elapsed = std::chrono::steady_clock::now() - started;
    boost::beast::flat_buffer buffer;
    boost::beast::http::response<boost::beast::http::string_body> response;
    boost::beast::error_code ec;
    stream->expires_after(5s);
    boost::beast::http::read(*stream, buffer, response, ec);
    ASSERT_FALSE(ec) << "no answer to the drip within 10 s: " << ec.message();
    EXPECT_EQ(response.result_int(), 408u) << response.body();
    EXPECT_NE(response.body().find("too slowly"), std::string::npos) << response.body();
    // One window of 1 s, then the 200 ms step of this loop, with 2 s for a loaded machine.
    EXPECT_LT(elapsed, 3200ms) << "the drip was not cut within its window";
    EXPECT_EQ(filesUnder(s.state().uploads().folder()), 0u) << "the cut upload's part is still on disk";
}

// A gzip NRRD of a few KiB that parses to 8 MiB, against a quota of 4 MiB: the checker
// refuses it before writing its parse, and another client's kept upload stays.
TEST_F(Upload, GzipNrrdExpandingPastTheRoomLeftIs507AndEvictsNoOne) {
    auto c = config();
    c.uploadQuotaBytes = uint64_t(4) << 20;
    // Room for the parse of the bomb alone but not beside the kept upload: what once made the
    // parse evict it.
    c.maxUploadStorageBytes = (uint64_t(8) << 20) + 4096;
    volcast::server::Server s(c);
    volcast::test::startAndWaitReady(s, kStartTimeout);
    const std::string nrrd = volumeFile(".nrrd");
    const auto kept = rawExchangeFrom("127.0.0.2", s.port(), uploadHead("victim.nrrd", nrrd.size()) + nrrd, kUploadTimeout);
    ASSERT_EQ(statusOf(kept), 201) << describe(kept);
    const std::string victim = json::parse(kept.response->body()).at("volume");

    // 256 x 256 x 128 uint8: 8 MiB of samples, nearly all zero, so gzip makes them a few KiB.
    const fs::path bomb = tmp / "bomb.nrrd";
    volcast::saveVolume(volcast::makeGaussianBlob({256, 256, 128}, {1, 1, 1}, 2.0, 200.0).volume, bomb,
                        {volcast::VoxelType::UInt8, true});
    const std::string body = readFile(bomb);
    ASSERT_LT(body.size(), kMaxUploadBytes) << "the compressed file is not small";
    const auto x = rawExchangeFrom("127.0.0.3", s.port(), uploadHead("bomb.nrrd", body.size()) + body, kUploadTimeout);
    ASSERT_EQ(statusOf(x), 507) << describe(x);
    EXPECT_NE(x.response->body().find("would need 8.0 MiB of upload storage once parsed; 4.0 MiB left"),
              std::string::npos)
        << x.response->body();
    EXPECT_NE(x.response->body().find("bomb.nrrd"), std::string::npos) << x.response->body();
    auto &store = s.state().uploads();
    EXPECT_FALSE(store.check(victim).has_value()) << "another client's parse evicted the kept upload";
    EXPECT_EQ(filesUnder(store.folder()), 1u) << "only the kept upload's parse stays on disk";
}

// Many uploads from one client, one from another, with one parse worker: the other client's
// upload is parsed next, not after the whole queue. The checker waits behind a gate (a file
// the test makes) so that the queue is built before any parse ends.
TEST_F(Upload, AnotherClientsUploadIsParsedBeforeOneClientsQueue) {
    const fs::path gate = tmp / "parse-gate";
    const fs::path checker = tmp / "gated-checker.sh";
    std::ofstream(checker) << "#!/bin/sh\nwhile [ ! -e '" << gate.string() << "' ]; do sleep 0.02; done\nexec '"
                           << VOLCAST_DICOM_CHECK_EXE << "' \"$@\"\n";
    fs::permissions(checker, fs::perms::owner_all);
    ::setenv("VOLCAST_DICOM_CHECK", checker.c_str(), 1);
    struct Unset {
        ~Unset() { ::unsetenv("VOLCAST_DICOM_CHECK"); }
    } unset;
    auto c = config();
    c.uploadParseWorkers = 1;
    c.maxUploadsPerAddress = 8;
    volcast::server::Server s(c);
    volcast::test::startAndWaitReady(s, kStartTimeout);
    auto &store = s.state().uploads();
    const std::string nrrd = volumeFile(".nrrd");
    std::mutex mutex;
    std::vector<std::string> finished;
    std::vector<std::thread> clients;
    const auto send = [&](const std::string &from, const std::string &label) {
        clients.emplace_back([&, from, label] {
            const auto x = rawExchangeFrom(from, s.port(), uploadHead(label + ".nrrd", nrrd.size()) + nrrd, kUploadTimeout);
            std::lock_guard lock(mutex);
            finished.push_back(statusOf(x) == 201 ? label : label + " (" + describe(x) + ")");
        });
    };
    const auto waitQueued = [&](size_t n) {
        const auto until = std::chrono::steady_clock::now() + kUploadTimeout;
        while (store.queued() < n && std::chrono::steady_clock::now() < until) std::this_thread::sleep_for(10ms);
        return store.queued();
    };
    for (int i = 1; i <= 4; ++i) send("127.0.0.2", "a" + std::to_string(i));
    EXPECT_EQ(waitQueued(3), 3u) << "one of the first client's uploads parsing, three queued";
    send("127.0.0.3", "b");
    EXPECT_EQ(waitQueued(4), 4u);
    std::ofstream(gate) << "open";
    for (auto &t : clients) t.join();
    ASSERT_EQ(finished.size(), 5u);
    const auto b = std::find(finished.begin(), finished.end(), "b");
    ASSERT_NE(b, finished.end()) << "the other client's upload failed: " << ::testing::PrintToString(finished);
    // First the upload that was parsing when it came, then it: none of the queued three before it.
    EXPECT_EQ(b - finished.begin(), 1) << "finished in the order " << ::testing::PrintToString(finished);
    fs::remove(gate);
}

// ---- the parts under the route ---------------------------------------------------------

// A checker that crashes on everything: with parseInChild, a NRRD file (which never reaches
// GDCM) is parsed by it first and refused with its signal; the caller survives.
TEST(UploadParts, ParseInChildRefusesWhatCrashesTheCheckerAndTheCallerSurvives) {
    const fs::path dir = fs::temp_directory_path() / ("volcast_parse_in_child_" + std::to_string(::getpid()));
    fs::create_directories(dir);
    const fs::path checker = dir / "crashing-checker.sh";
    std::ofstream(checker) << "#!/bin/sh\nkill -SEGV $$\n";
    fs::permissions(checker, fs::perms::owner_all);
    volcast::saveVolume(testVolume(), dir / "v.nrrd", {volcast::VoxelType::Int16, false});
    ::setenv("VOLCAST_DICOM_CHECK", checker.c_str(), 1);
    volcast::LoadOptions options;
    options.parseInChild = true;
    std::string message;
    try {
        volcast::loadVolume(dir / "v.nrrd", options);
    } catch (const volcast::VolumeLoadError &e) {
        message = e.what();
    }
    // Without the option, the same file never goes near the checker.
    std::string direct;
    try {
        EXPECT_EQ(volcast::loadVolume(dir / "v.nrrd").dims.x, kDims.x);
    } catch (const std::exception &e) {
        direct = e.what();
    }
    ::unsetenv("VOLCAST_DICOM_CHECK");
    fs::remove_all(dir);
    EXPECT_NE(message.find("SIGSEGV"), std::string::npos) << "not refused with the child's signal: " << message;
    EXPECT_NE(message.find("v.nrrd"), std::string::npos) << message;
    EXPECT_EQ(direct, "") << "a NRRD load without parseInChild went through the checker";
}

// The file is parsed once, in the child, which hands the volume back; a child that a hostile
// file took over could hand back anything, so a damaged hand-back is refused, never trusted.
TEST(UploadParts, ParseInChildTakesTheChildsVolumeAndRefusesADamagedOne) {
    const fs::path dir = fs::temp_directory_path() / ("volcast_child_result_" + std::to_string(::getpid()));
    fs::create_directories(dir);
    volcast::saveVolume(testVolume(), dir / "v.nrrd", {volcast::VoxelType::Int16, false});
    volcast::LoadOptions options;
    options.parseInChild = true;
    const volcast::Volume direct = volcast::loadVolume(dir / "v.nrrd");
    const volcast::Volume viaChild = volcast::loadVolume(dir / "v.nrrd", options);
    EXPECT_EQ(viaChild.dims, direct.dims);
    EXPECT_EQ(viaChild.spacing, direct.spacing);
    EXPECT_EQ(viaChild.direction, direct.direction);
    EXPECT_EQ(viaChild.sourceType, direct.sourceType);
    EXPECT_EQ(viaChild.narrow.bytes, direct.narrow.bytes);
    EXPECT_EQ(viaChild.narrowVoxels, direct.narrowVoxels) << "the same samples, bit for bit";
    EXPECT_EQ(viaChild.histogram.counts, direct.histogram.counts);

    // A checker that claims success and writes garbage where the volume should be (its last
    // argument is the result file).
    const fs::path liar = dir / "lying-checker.sh";
    std::ofstream(liar) << "#!/bin/sh\nfor last; do :; done\nprintf 'volcast-checked\\000garbage' > \"$last\"\nexit 0\n";
    fs::permissions(liar, fs::perms::owner_all);
    ::setenv("VOLCAST_DICOM_CHECK", liar.c_str(), 1);
    std::string message;
    try {
        volcast::loadVolume(dir / "v.nrrd", options);
    } catch (const volcast::VolumeLoadError &e) {
        message = e.what();
    }
    ::unsetenv("VOLCAST_DICOM_CHECK");
    fs::remove_all(dir);
    EXPECT_NE(message.find("damaged result"), std::string::npos) << "a damaged hand-back was not refused: " << message;
}

// An upload is parsed once: parseToKeep leaves the child's hand-back in a file of its own and
// loadParsedVolume reads it later as loadVolume with parseInChild would have loaded the file;
// a refused file leaves nothing behind, and a kept file damaged since is refused, not trusted.
TEST(UploadParts, ParsedOnceAndKeptLoadsAsTheFileDoes) {
    const fs::path dir = fs::temp_directory_path() / ("volcast_kept_parse_" + std::to_string(::getpid()));
    fs::remove_all(dir);
    fs::create_directories(dir);
    volcast::saveVolume(testVolume(), dir / "v.nrrd", {volcast::VoxelType::Int16, false});
    const volcast::Volume direct = volcast::loadVolume(dir / "v.nrrd");
    const volcast::ParsedVolumeSummary summary = volcast::parseToKeep(dir / "v.nrrd", dir / "kept");
    EXPECT_EQ(summary.dims, (std::array<int64_t, 3>{direct.dims.x, direct.dims.y, direct.dims.z}));
    EXPECT_EQ(summary.sourceType, direct.sourceType);
    const volcast::Volume kept = volcast::loadParsedVolume(dir / "kept", "upload:x");
    EXPECT_EQ(kept.dims, direct.dims);
    EXPECT_EQ(kept.spacing, direct.spacing);
    EXPECT_EQ(kept.direction, direct.direction);
    EXPECT_EQ(kept.narrowVoxels, direct.narrowVoxels) << "the same samples, bit for bit";
    EXPECT_EQ(kept.histogram.counts, direct.histogram.counts) << "statistics computed again on loading";
    EXPECT_EQ(kept.range.min, direct.range.min);
    EXPECT_EQ(kept.range.max, direct.range.max);

    EXPECT_THROW(volcast::parseToKeep(dir / "v.nrrd", dir / "kept"), volcast::VolumeLoadError)
        << "an existing file is never written over";
    std::ofstream(dir / "bad.nrrd") << "NRRD0004\ntype: short\ndimension: 3\nsizes: 4 4\n\n";
    EXPECT_THROW(volcast::parseToKeep(dir / "bad.nrrd", dir / "kept-bad"), volcast::VolumeLoadError);
    EXPECT_FALSE(fs::exists(dir / "kept-bad")) << "a refused file leaves no kept parse";

    fs::resize_file(dir / "kept", fs::file_size(dir / "kept") - 1);
    std::string message;
    try {
        volcast::loadParsedVolume(dir / "kept", "upload:x");
    } catch (const volcast::VolumeLoadError &e) {
        message = e.what();
    }
    fs::remove_all(dir);
    EXPECT_NE(message.find("damaged result"), std::string::npos) << "a cut kept parse was not refused: " << message;
    EXPECT_NE(message.find("upload:x"), std::string::npos) << "the message names the volume as shown: " << message;
}

// The room left is given to the checker, which refuses a volume whose hand-back would be larger
// before writing any of it: the kept file never grows past the room.
TEST(UploadParts, CheckerRefusesAParseOverTheRoomLeftBeforeWritingIt) {
    const fs::path dir = fs::temp_directory_path() / ("volcast_result_limit_" + std::to_string(::getpid()));
    fs::remove_all(dir);
    fs::create_directories(dir);
    volcast::saveVolume(testVolume(), dir / "v.nrrd", {volcast::VoxelType::Int16, false});
    volcast::LoadOptions options;
    options.maxResultBytes = 1000;   // the test volume's int16 samples alone are 7680 bytes
    std::string message;
    try {
        volcast::parseToKeep(dir / "v.nrrd", dir / "kept", options);
    } catch (const volcast::VolumeOverResultLimit &e) {
        message = e.what();
        EXPECT_GT(e.needed, 7680u);
        EXPECT_EQ(e.limit, 1000u);
    }
    EXPECT_NE(message.find("would need 7.7 KiB of upload storage once parsed; 1000 bytes left"), std::string::npos)
        << "not refused naming the room: " << message;
    EXPECT_FALSE(fs::exists(dir / "kept")) << "a refused parse left its file";
    // The checker itself, given the limit, leaves its result file as it found it: empty.
    std::ofstream(dir / "result").close();
    const std::string command = fmt::format("'{}' '{}' 1000000000 32768 60 1000000000 '{}' max-result-bytes=1000 "
                                            ">/dev/null 2>&1",
                                            VOLCAST_DICOM_CHECK_EXE, (dir / "v.nrrd").string(), (dir / "result").string());
    const int status = std::system(command.c_str());
    EXPECT_TRUE(WIFEXITED(status) && WEXITSTATUS(status) == 1) << "the checker did not refuse (status " << status << ")";
    EXPECT_EQ(fs::file_size(dir / "result"), 0u) << "the checker wrote past its limit";
    // With room enough it writes the parse.
    const std::string roomy = fmt::format("'{}' '{}' 1000000000 32768 60 1000000000 '{}' max-result-bytes=100000 "
                                          ">/dev/null 2>&1",
                                          VOLCAST_DICOM_CHECK_EXE, (dir / "v.nrrd").string(), (dir / "result").string());
    EXPECT_EQ(std::system(roomy.c_str()), 0);
    EXPECT_GT(fs::file_size(dir / "result"), 7680u);
    fs::remove_all(dir);
}

class ZipParts : public ::testing::Test {
  protected:
    fs::path dir;
    void SetUp() override {
        dir = fs::temp_directory_path() /
              ("volcast_zip_" + std::to_string(::getpid()) + "_" +
               ::testing::UnitTest::GetInstance()->current_test_info()->name());
        fs::remove_all(dir);
        fs::create_directories(dir / "out");
    }
    void TearDown() override { fs::remove_all(dir); }
    std::string refusal(const fs::path &zip, const volcast::ZipLimits &limits = {}) {
        try {
            volcast::extractZip(zip, dir / "out", limits, "upload.zip");
        } catch (const volcast::ZipError &e) {
            return e.what();
        }
        return "";
    }
};

TEST_F(ZipParts, EntryNamesAreIgnoredAndOnlyRegularFilesComeOut) {
    writeZip(dir / "a.zip", {{"../../escape.dcm", "one"}, {"/abs/path.dcm", "two"}, {"folder/", ""}});
    EXPECT_EQ(volcast::extractZip(dir / "a.zip", dir / "out", {}, "a.zip"), 2);
    std::vector<std::string> names;
    for (const auto &e : fs::directory_iterator(dir / "out")) names.push_back(e.path().filename().string());
    std::sort(names.begin(), names.end());
    EXPECT_EQ(names, (std::vector<std::string>{"entry_00000", "entry_00001"}));
    EXPECT_FALSE(fs::exists(dir / "escape.dcm"));
    EXPECT_EQ(readFile(dir / "out" / "entry_00001"), "two");
}

TEST_F(ZipParts, SymbolicLinkEntryIsRefused) {
    writeZip(dir / "link.zip", {{"link", "/etc/passwd"}});
    int error = 0;
    zip_t *z = zip_open((dir / "link.zip").c_str(), 0, &error);
    ASSERT_NE(z, nullptr);
    ASSERT_EQ(zip_file_set_external_attributes(z, 0, 0, ZIP_OPSYS_UNIX, (0120777u) << 16), 0);
    ASSERT_EQ(zip_close(z), 0);
    EXPECT_NE(refusal(dir / "link.zip").find("symbolic link"), std::string::npos);
}

TEST_F(ZipParts, BombsAndLimitsAreRefused) {
    // 8 MiB of zeros deflate to ~8 KiB: a ratio of ~1000.
    writeZip(dir / "zeros.zip", {{"zeros", std::string(8 << 20, '\0')}});
    volcast::ZipLimits ratio;
    ratio.maxRatio = 100;
    EXPECT_NE(refusal(dir / "zeros.zip", ratio).find("zip bomb"), std::string::npos);
    volcast::ZipLimits bytes;
    bytes.maxBytes = 1 << 20;
    EXPECT_NE(refusal(dir / "zeros.zip", bytes).find("more than the limit"), std::string::npos);
    writeZip(dir / "many.zip", {{"a", "1"}, {"b", "2"}, {"c", "3"}});
    volcast::ZipLimits entries;
    entries.maxEntries = 2;
    EXPECT_NE(refusal(dir / "many.zip", entries).find("3 entries"), std::string::npos);
    std::ofstream(dir / "not.zip") << "PK\x03\x04 this is no archive";
    const std::string notZip = refusal(dir / "not.zip");
    EXPECT_NE(notZip.find("upload.zip: is not a valid zip archive"), std::string::npos) << notZip;
}

TEST(UploadParts, FilenameRulesAndExtensions) {
    using volcast::server::uploadExtension;
    using volcast::server::uploadFilenameProblem;
    EXPECT_FALSE(uploadFilenameProblem("Brain scan é.nii.gz"));
    for (const std::string &bad : {std::string(""), std::string("a\\b.nrrd"), std::string("a\0b.nrrd", 8),
                                  std::string("a\tb.nrrd"), std::string("\xc0\xaf.nrrd"), std::string("\xed\xa0\x80.nrrd"),
                                  std::string("\xe2\x82.nrrd"), std::string(256, 'x')})
        EXPECT_TRUE(uploadFilenameProblem(bad)) << bad;
    EXPECT_EQ(uploadExtension("A.NII.GZ"), ".nii.gz");
    EXPECT_EQ(uploadExtension("a.nii"), ".nii");
    EXPECT_EQ(uploadExtension("x.Zip"), ".zip");
    EXPECT_FALSE(uploadExtension(".nrrd"));
    EXPECT_FALSE(uploadExtension("a.nhdr"));
    EXPECT_FALSE(uploadExtension("a.gz"));
    EXPECT_EQ(volcast::server::uploadNameOf("/api/volumes?x=1&filename=a%20b+c.nrrd", "", false).name, "a b c.nrrd");
    EXPECT_EQ(volcast::server::uploadNameOf("/api/volumes?filename=q.nrrd", "h.nrrd", true).name, "h.nrrd");
    EXPECT_FALSE(volcast::server::uploadNameOf("/api/volumes", "", false).name);
}

// ---- a refused file is parsed in the checker only -------------------------------------

// A NRRD of float32 `sizes` whose bzip2 data is a stream of 1 MiB of zeros (45 bytes, from
// Python's bz2.compress(bytes(1 << 20), 9)). The loader counts a gzip stream's bytes before
// reading (and refuses a short one), but not bzip2's: ITK takes and fills room for the whole
// volume before NrrdIO says it cannot decode bzip2. With sizes 1024 1024 680: 2.7 GiB from
// 132 bytes.
std::string bzip2BombNrrd(const std::string &sizes) {
    static const unsigned char kZeros[] = {
        0x42, 0x5a, 0x68, 0x39, 0x31, 0x41, 0x59, 0x26, 0x53, 0x59, 0x38, 0x57, 0x1c, 0xe5, 0x00,
        0x08, 0x08, 0x40, 0x00, 0xc0, 0x04, 0x00, 0x08, 0x20, 0x00, 0x30, 0xcc, 0x05, 0x29, 0xa6,
        0x08, 0x06, 0xc4, 0x20, 0x1e, 0x2e, 0xe4, 0x8a, 0x70, 0xa1, 0x20, 0x70, 0xae, 0x39, 0xca};
    return "NRRD0004\ntype: float\ndimension: 3\nsizes: " + sizes + "\nendian: little\nencoding: bzip2\n\n" +
           std::string(reinterpret_cast<const char *>(kZeros), sizeof kZeros);
}

// A memory figure of a process from /proc/PID/status ("VmHWM": its peak resident set,
// "VmRSS"), in KiB; -1 when not found.
int64_t statusKiB(pid_t pid, const std::string &field) {
    std::ifstream in("/proc/" + std::to_string(pid) + "/status");
    for (std::string line; std::getline(in, line);)
        if (line.starts_with(field + ":")) return std::stoll(line.substr(field.size() + 1));
    return -1;
}

// The process's peak resident set from now on: Linux resets VmHWM to VmRSS on "5" written to
// clear_refs; where that is not allowed, the peak so far (a test that then cannot see a rise
// below it, but never fails wrongly).
int64_t peakFromNow(pid_t pid) {
    std::ofstream("/proc/" + std::to_string(pid) + "/clear_refs") << "5";
    return statusKiB(pid, "VmHWM");
}

// What the caller may add to its peak while the checker parses and refuses a file: a pipe's
// reads and a few small allocations, KiB; 64 MiB is a quarter of the smallest volume parsed
// below, so a parse of it in the caller cannot hide under it.
constexpr int64_t kCallerSlackKiB = 64 * 1024;

// The checker refuses the bomb; the caller throws the checker's words and never parses the
// file itself, so its own peak memory stays where it was. A refusal's words are the same as
// the load in this process gives (the loader's own, through the checker).
TEST(UploadParts, ARefusedFileIsNotParsedAgainByTheCaller) {
    const fs::path dir = fs::temp_directory_path() / ("volcast_refused_once_" + std::to_string(::getpid()));
    fs::remove_all(dir);
    fs::create_directories(dir);
    std::ofstream(dir / "bomb.nrrd", std::ios::binary) << bzip2BombNrrd("512 512 256");  // 256 MiB as float32
    volcast::LoadOptions options;
    options.parseInChild = true;
    const int64_t before = peakFromNow(::getpid());
    std::string message;
    try {
        volcast::parseToKeep(dir / "bomb.nrrd", dir / "kept", options);
    } catch (const volcast::VolumeLoadError &e) {
        message = e.what();
    }
    const int64_t after = statusKiB(::getpid(), "VmHWM");
    ASSERT_GT(before, 0) << "no VmHWM in /proc/self/status";
    EXPECT_LE(after - before, kCallerSlackKiB)
        << "this process's peak grew by " << (after - before) << " KiB while a 256 MiB volume was refused: it "
        << "parsed the file itself";
    EXPECT_TRUE(message.starts_with((dir / "bomb.nrrd").string() + ": ")) << message;
    EXPECT_NE(message.find("bzip2"), std::string::npos) << "the refusal does not name the problem: " << message;
    EXPECT_FALSE(fs::exists(dir / "kept"));

    std::ofstream(dir / "bad.nrrd") << "NRRD0004\ntype: short\ndimension: 3\nsizes: 4 4\n\n";
    std::string inChild, here;
    try {
        volcast::parseToKeep(dir / "bad.nrrd", dir / "kept", options);
    } catch (const volcast::VolumeLoadError &e) {
        inChild = e.what();
    }
    try {
        volcast::loadVolume(dir / "bad.nrrd");
    } catch (const volcast::VolumeLoadError &e) {
        here = e.what();
    }
    fs::remove_all(dir);
    EXPECT_FALSE(here.empty());
    EXPECT_EQ(inChild, here) << "the checker's refusal is not the loader's own words";
}

// A checker that refuses everything (exit status 1): the file is refused, never loaded here
// instead; a refusal line is taken as the hostile text it may be (one line, bounded, no
// control characters, valid UTF-8, starting with the file's path) and keeps its kind.
TEST(UploadParts, TheCheckersRefusalIsReadAsHostileTextAndTheFileIsNotLoadedHere) {
    const fs::path dir = fs::temp_directory_path() / ("volcast_refusal_text_" + std::to_string(::getpid()));
    fs::remove_all(dir);
    fs::create_directories(dir);
    volcast::saveVolume(testVolume(), dir / "v.nrrd", {volcast::VoxelType::Int16, false});
    volcast::LoadOptions options;
    options.parseInChild = true;
    const auto refusal = [&](const std::string &script) -> std::pair<std::string, uint64_t> {
        const fs::path checker = dir / "refusing-checker.sh";
        fs::remove(checker);
        std::ofstream(checker) << "#!/bin/sh\n" << script << "\nexit 1\n";
        fs::permissions(checker, fs::perms::owner_all);
        ::setenv("VOLCAST_DICOM_CHECK", checker.c_str(), 1);
        std::pair<std::string, uint64_t> got{"(loaded)", 0};
        try {
            volcast::loadVolume(dir / "v.nrrd", options);
        } catch (const volcast::VolumeTooLarge &e) {
            got = {e.what(), e.bytes};
        } catch (const volcast::VolumeLoadError &e) {
            got = {e.what(), 0};
        }
        ::unsetenv("VOLCAST_DICOM_CHECK");
        return got;
    };
    const auto silent = refusal("");
    const auto hostile =
        refusal(R"(printf '\037L 123456 %s: too large\033[2J\tto \302\233 load \377 here\nsecond line\n' "$1" >&2)");
    const auto anonymous = refusal(R"(printf '\037R 0 no path here\n' >&2)");
    const auto endless = refusal(R"(printf '\037R 0 ' >&2; head -c 100000 /dev/zero | tr '\0' x >&2)");
    fs::remove_all(dir);

    EXPECT_NE(silent.first.find("was refused by the parser in its separate process"), std::string::npos)
        << "a file the checker refused was not refused: " << silent.first;
    const std::string &m = hostile.first;
    EXPECT_EQ(hostile.second, 123456u) << "the kind of the refusal was lost: " << m;
    EXPECT_TRUE(m.starts_with((dir / "v.nrrd").string() + ": too large")) << m;
    EXPECT_NE(m.find("load"), std::string::npos) << m;
    EXPECT_NE(m.find("here"), std::string::npos) << m;
    EXPECT_EQ(m.find("second line"), std::string::npos) << "more than the refusal's line: " << m;
    EXPECT_EQ(m.find("\xC2\x9B"), std::string::npos) << "a C1 control character in: " << m;
    EXPECT_TRUE(volcast::json_fields::isValidUtf8(m)) << m;
    for (char c : m) EXPECT_FALSE(static_cast<unsigned char>(c) < 0x20 || c == 0x7f) << "a control character in: " << m;
    EXPECT_TRUE(anonymous.first.starts_with((dir / "v.nrrd").string() + ": no path here")) << anonymous.first;
    // 2 KiB (the caller's bound on a refusal) with the path and the ellipsis.
    EXPECT_LE(endless.first.size(), 2048u + 3u) << "an unbounded refusal: " << endless.first.size() << " bytes";
    EXPECT_NE(endless.first.find("xxxx"), std::string::npos) << endless.first.substr(0, 200);
}

// The 132-byte bzip2 NRRD of a 2.7 GiB volume, uploaded to the real server executable: the
// checker refuses it and the server process's own peak memory stays where it was (before, the
// server parsed a refused file again for its words: 2.8 GiB and 2.2 s of its CPU).
TEST(UploadServerProcess, ARefusedBombIsParsedInTheCheckerNotInTheServer) {
    const fs::path tmp = fs::temp_directory_path() / ("volcast_upload_process_" + std::to_string(::getpid()));
    fs::remove_all(tmp);
    fs::create_directories(tmp);
    const fs::path portFile = tmp / "port";
    const pid_t pid = volcast::test::startServerProcess(
        {"--port", "0", "--port-file", portFile.string(), "--default-volume", "", "--device", "cpu",
         "--error-calibration", "false", "--memory-budget-mib", "4096", "--upload-dir", (tmp / "uploads").string()},
        tmp / "log.txt");
    ASSERT_GT(pid, 0);
    const uint16_t port = volcast::test::waitForPort(portFile, std::chrono::milliseconds(kStartTimeout));
    if (port == 0) ::kill(pid, SIGKILL);
    ASSERT_NE(port, 0) << "the server did not start: " << volcast::test::readAll(tmp / "log.txt");
    const auto deadline = std::chrono::steady_clock::now() + kStartTimeout;
    while (volcast::test::httpGet(port, "/healthz").status != 200 && std::chrono::steady_clock::now() < deadline)
        std::this_thread::sleep_for(50ms);

    const std::string bomb = bzip2BombNrrd("1024 1024 680");
    const int64_t before = peakFromNow(pid);
    const auto x = rawExchange(port, uploadHead("bomb.nrrd", bomb.size(), "") + bomb, kUploadTimeout);
    const int64_t after = statusKiB(pid, "VmHWM");
    ::kill(pid, SIGTERM);
    if (volcast::test::waitForExit(pid, std::chrono::milliseconds(10s)) == -1) {
        ::kill(pid, SIGKILL);
        ::waitpid(pid, nullptr, 0);
    }
    const std::string log = volcast::test::readAll(tmp / "log.txt");
    fs::remove_all(tmp);
    ASSERT_EQ(statusOf(x), 422) << describe(x) << "\n" << log;
    EXPECT_NE(x.response->body().find("bomb.nrrd: "), std::string::npos) << x.response->body();
    EXPECT_NE(x.response->body().find("bzip2"), std::string::npos) << "the problem is not named: " << x.response->body();
    ASSERT_GT(before, 0);
    EXPECT_LE(after - before, kCallerSlackKiB) << "the server's peak grew by " << (after - before)
                                               << " KiB while it refused a 2.7 GiB volume: it parsed the file itself";
}

// Python's zipfile.writestr gives each entry the mode 0600 and no file-type bits: a regular
// file, not "a symbolic link or special file". The series in such a zip loads.
TEST_F(ZipParts, EntriesWithoutFileTypeBitsAreRegularFilesAndTheSeriesLoads) {
    volcast::saveDicomSeries(testVolume(), dir / "series", volcast::VoxelType::Int16);
    std::vector<std::pair<std::string, std::string>> files;
    for (const auto &e : fs::directory_iterator(dir / "series"))
        files.emplace_back(e.path().filename().string(), readFile(e.path()));
    writeZip(dir / "python.zip", files);
    int error = 0;
    zip_t *z = zip_open((dir / "python.zip").c_str(), 0, &error);
    ASSERT_NE(z, nullptr);
    for (zip_uint64_t i = 0; i < files.size(); ++i)
        ASSERT_EQ(zip_file_set_external_attributes(z, i, 0, ZIP_OPSYS_UNIX, 0600u << 16), 0) << zip_strerror(z);
    ASSERT_EQ(zip_close(z), 0);
    EXPECT_EQ(refusal(dir / "python.zip"), "");
    std::string refused;
    try {
        EXPECT_EQ(volcast::loadVolume(dir / "python.zip").dims, kDims);
    } catch (const volcast::VolumeLoadError &e) {
        refused = e.what();
    }
    EXPECT_EQ(refused, "");
}

// An upload must carry its data: a NRRD naming a data file is refused, whether it names the
// file itself (the server keeps an upload as "volume.nrrd"; its last 8 bytes would be the
// voxels) or any other.
TEST_F(Upload, NrrdNamingADataFileIs422AnUploadCarriesItsData) {
    for (const std::string dataFile : {"volume.nrrd", "other.raw"}) {
        const std::string nrrd = "NRRD0004\ntype: uint8\ndimension: 3\nsizes: 2 2 2\nencoding: raw\nbyte skip: -1\n"
                                 "data file: " + dataFile + "\n\n" + std::string(8, '\1');
        expectRefused(upload("detached.nrrd", nrrd), 422, "an upload must carry its data");
    }
}

} // namespace
