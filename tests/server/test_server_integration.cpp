// The server over loopback: an in-process server per test suite, driven by the C++ client
// library exactly as a script would drive it. Viewports are tiny (64²) and the volumes are
// built-in ones, so each test takes well under a few seconds on the 2-core PoCL machine.

#include "client/cpp/ws_client.hpp"
#include "renderer/make_frame_renderer.hpp"
#include "renderer/model/scene.hpp"
#include "renderer/io/volume_io.hpp"
#include "renderer/io/volume_source.hpp"
#include "server/frame_encoder.hpp"
#include "server/server.hpp"
#include "tests/server/child_process.hpp"
#include "tests/server/png_decode.hpp"
#include "tests/server/server_fixture.hpp"

#include <boost/asio/connect.hpp>
#include <boost/asio/ip/tcp.hpp>
#include <boost/beast/core.hpp>
#include <boost/beast/http.hpp>
#include <gtest/gtest.h>

#include <csignal>
#include <filesystem>
#include <fstream>
#include <set>
#include <sys/wait.h>
#include <thread>
#include <unistd.h>

namespace {

namespace fs = std::filesystem;
using namespace std::chrono_literals;
using nlohmann::json;
using volcast::client::Client;
using volcast::client::Message;
namespace protocol = volcast::protocol;
namespace http = boost::beast::http;

constexpr auto kTimeout = 20s;   // generous: a cold PoCL cache builds programs for seconds

// ---- helpers -------------------------------------------------------------------------

using volcast::test::HttpReply;
using volcast::test::httpGet;

using volcast::test::asError;

// Send a request and return its reply (text), keeping frames and other messages aside.
Message request(Client &c, json message, std::vector<Message> *skipped = nullptr) {
    const json id = message.at("id");
    c.sendText(message.dump());
    return volcast::client::waitForReply(c, id, kTimeout, skipped);
}

// Messages until a final frame; every frame in order. Fails the test on timeout.
std::vector<volcast::client::Frame> framesUntilFinal(Client &c, std::vector<Message> *texts = nullptr,
                                                     std::chrono::milliseconds timeout = kTimeout) {
    std::vector<volcast::client::Frame> frames;
    const auto deadline = std::chrono::steady_clock::now() + timeout;
    while (std::chrono::steady_clock::now() < deadline) {
        auto m = c.next(100ms);
        if (!m) continue;
        if (m->isFrame) {
            EXPECT_TRUE(m->decodeError.empty()) << m->decodeError;
            frames.push_back(m->frame);
            if (m->frame.header.final) return frames;
        } else if (texts) {
            texts->push_back(std::move(*m));
        } else if (auto *e = asError(*m)) {
            ADD_FAILURE() << "unexpected error: " << e->message;
        }
    }
    ADD_FAILURE() << "no final frame in time (" << frames.size() << " frames)";
    return frames;
}

using volcast::test::cameraAt;

using volcast::test::decodePng;

double metricValue(const std::string &text, const std::string &name) {
    const auto pos = text.find("\n" + name + " ");
    if (pos == std::string::npos) return -1;
    return std::stod(text.substr(pos + name.size() + 2));
}

// ---- the shared server ---------------------------------------------------------------

class ServerTest : public ::testing::Test {
  protected:
    static inline std::unique_ptr<volcast::server::Server> server;
    static inline fs::path tmp;

    // The server on its default back end (--device auto: the native CPU path on a machine
    // without an OpenCL GPU); ServerOnOpenClTest repeats some tests with --device opencl.
    static void SetUpTestSuite() { startSharedServer("auto"); }
    static void startSharedServer(const std::string &device) {
        tmp = fs::temp_directory_path() / ("volcast_server_test_" + std::to_string(::getpid()));
        fs::remove_all(tmp);
        fs::create_directories(tmp / "data" / "ct");
        fs::create_directories(tmp / "outside");
        fs::create_directories(tmp / "web" / "app");
        std::ofstream(tmp / "outside" / "secret.nrrd") << "NRRD0004\n";
        std::ofstream(tmp / "data" / "ct" / "broken.nrrd") << "NRRD0004\ntype: float\n";   // truncated header
        {
            // A real file for the loading progress: 16-bit, gzip, like most scans.
            volcast::Volume scan;
            scan.dims = {48, 40, 32};
            scan.voxels.resize(scan.voxelCount());
            for (size_t i = 0; i < scan.voxels.size(); ++i) scan.voxels[i] = float(i % 997);
            volcast::saveVolume(scan, tmp / "data" / "ct" / "scan.nrrd", {volcast::VoxelType::Int16, true});
        }
        fs::create_symlink(tmp / "outside" / "secret.nrrd", tmp / "data" / "escape.nrrd");
        std::ofstream(tmp / "web" / "index.html") << "<!doctype html><title>volcast</title>";
        std::ofstream(tmp / "web" / "app" / "main.js") << "export const x = 1;";
        std::ofstream(tmp / "secret.txt") << "not for the web";
        fs::create_symlink(tmp / "secret.txt", tmp / "web" / "leak.txt");

        volcast::server::ServerConfig config;
        config.port = 0;
        config.dataDirs = {tmp / "data"};
        config.webRoot = tmp / "web";
        config.idleMs = 100;
        config.ioThreads = 2;
        config.device = device;
        // ClientThatStopsReadingStallsNoOneAndHoldsOneFrame pauses a reader for longer than
        // the default write timeout and expects it back: closing stuck readers is checked in
        // test_ws_hardening.cpp.
        config.writeTimeoutMs = 120000;
        server = std::make_unique<volcast::server::Server>(config);
        volcast::test::startAndWaitReady(*server, kTimeout);
    }
    static void TearDownTestSuite() {
        server.reset();
        fs::remove_all(tmp);
    }

    uint16_t port() const { return server->port(); }

    // A client that said hello and opened `volume` with a side² viewport (receive buffer:
    // Client's constructor); returns the state.
    std::unique_ptr<Client> openSession(const std::string &volume, json *stateOut = nullptr, int side = 64,
                                        int receiveBufferBytes = 0) {
        auto c = volcast::test::helloClient(port(), "gtest", kTimeout, receiveBufferBytes);
        c->sendText(json{{"type", "viewport"}, {"id", 2}, {"image", {{"width", side}, {"height", side}}}}.dump());
        const Message state = request(*c, {{"type", "open_volume"}, {"id", 3}, {"name", volume}});
        EXPECT_TRUE(state.decoded && std::holds_alternative<protocol::StateMessage>(*state.decoded)) << state.text;
        if (stateOut) *stateOut = json::parse(state.text);
        return c;
    }
};

// ---- HTTP ---------------------------------------------------------------------------

TEST_F(ServerTest, HealthReadinessAndMetrics) {
    EXPECT_EQ(httpGet(port(), "/healthz").status, 200);
    const HttpReply ready = httpGet(port(), "/readyz");
    EXPECT_EQ(ready.status, 200) << ready.body;
    const HttpReply metrics = httpGet(port(), "/metrics");
    EXPECT_EQ(metrics.status, 200);
    EXPECT_NE(metrics.contentType.find("text/plain"), std::string::npos);
    for (const char *name : {"volcast_sessions", "volcast_frames_dropped_stale_total", "volcast_render_seconds_bucket",
                             "volcast_encode_seconds_count", "volcast_volume_memory_bytes"})
        EXPECT_NE(metrics.body.find(name), std::string::npos) << name;
    // The demo volume (128³ float32) is in memory and counted.
    EXPECT_GT(metricValue(metrics.body, "volcast_volume_memory_bytes"), 128.0 * 128 * 128 * 4);
}

TEST_F(ServerTest, ServesStaticFilesWithTypesAndRefusesTraversal) {
    const HttpReply index = httpGet(port(), "/");
    EXPECT_EQ(index.status, 200);
    EXPECT_EQ(index.contentType, "text/html; charset=utf-8");
    EXPECT_NE(index.body.find("<title>volcast</title>"), std::string::npos);
    const HttpReply js = httpGet(port(), "/app/main.js?v=1");
    EXPECT_EQ(js.status, 200);
    EXPECT_EQ(js.contentType, "text/javascript; charset=utf-8");
    // Out of the web root by "..", encoded "..", and a symbolic link: all refused alike.
    for (const char *target : {"/../secret.txt", "/app/../../secret.txt", "/%2e%2e/secret.txt", "/leak.txt",
                               "/app/..%2f..%2fsecret.txt", "/missing.html"}) {
        const HttpReply r = httpGet(port(), target);
        EXPECT_EQ(r.status, 404) << target;
        EXPECT_EQ(r.body.find("not for the web"), std::string::npos) << target;
    }
}

// ---- sessions -----------------------------------------------------------------------

// The ladder ends in a final frame equal to the scene rendered directly by the back end the
// server chose (ServerTest: default; ServerOnOpenClTest: --device opencl).
void expectFinalFrameMatchesTheRenderer(Client &c, const json &state, const volcast::server::SharedState &shared);

TEST_F(ServerTest, FinalFrameMatchesTheRendererExactly) {
    json state;
    auto c = openSession("builtin:demo", &state);
    expectFinalFrameMatchesTheRenderer(*c, state, server->state());
}

void expectFinalFrameMatchesTheRenderer(Client &client, const json &state, const volcast::server::SharedState &shared) {
    Client *c = &client;
    const auto frames = framesUntilFinal(*c);
    ASSERT_FALSE(frames.empty());
    // The ladder: levels rising, only the last frame final and PNG, the others JPEG.
    for (size_t i = 0; i < frames.size(); ++i) {
        EXPECT_EQ(frames[i].header.seq, frames[0].header.seq + i);
        EXPECT_EQ(frames[i].header.request, json(3));
        if (i > 0) {
            EXPECT_GT(frames[i].header.level, frames[i - 1].header.level);
        }
        EXPECT_EQ(frames[i].header.final, i + 1 == frames.size());
        EXPECT_EQ(frames[i].header.codec, frames[i].header.final ? protocol::Codec::Png : protocol::Codec::Jpeg);
    }
    const auto &final = frames.back();
    ASSERT_EQ(final.header.width, 64);

    // Render the state's scene directly with the same renderer and convert it the same way.
    const volcast::Scene scene = volcast::parseScene(state.at("scene").dump());
    const auto loaded = volcast::loadSceneVolume(scene.volume);
    const auto renderer = volcast::makeFrameRenderer(volcast::DeviceChoice::parse(shared.config().device),
                                                     std::make_shared<const volcast::Volume>(loaded.volume));
    ASSERT_EQ(renderer->description(), shared.backEnd());
    const volcast::Image image = renderer->render({volcast::resolvedTransferFunction(scene, loaded.volume.range),
                                                 scene.camera, scene.width, scene.height, scene.quality,
                                                 scene.clipPlanes});
    const std::vector<uint8_t> expected = volcast::server::toStraightRgba8(image);
    int w = 0, h = 0, channels = 0;
    const std::vector<uint8_t> got = decodePng(final.image, w, h, channels);
    ASSERT_EQ(w, 64);
    ASSERT_EQ(h, 64);
    ASSERT_EQ(channels, 4);
    // PNG is lossless and both back ends are deterministic for the same scene on the same device,
    // so the bytes agree exactly; 1/255 is allowed only for a last-bit difference in the
    // float image should the device ever reorder its arithmetic.
    int worst = 0;
    for (size_t i = 0; i < got.size(); ++i) worst = std::max(worst, std::abs(int(got[i]) - int(expected[i])));
    EXPECT_LE(worst, 1);
}

// With the default --device (auto), a machine without an OpenCL GPU draws through the native
// CPU path, opens no OpenCL device, and says so in hello, the start-up choice and /metrics.
TEST_F(ServerTest, DefaultDeviceIsTheNativePathWithoutAnOpenClGpu) {
    const auto &state = server->state();
    EXPECT_EQ(state.config().device, "auto");
    auto c = std::make_unique<Client>("127.0.0.1", port());
    const Message hello = request(*c, {{"type", "hello"}, {"id", 1}, {"protocol", 1}, {"client", "gtest"}});
    ASSERT_TRUE(hello.decoded && std::holds_alternative<protocol::ServerHello>(*hello.decoded)) << hello.text;
    const auto &device = std::get<protocol::ServerHello>(*hello.decoded).device;
    EXPECT_EQ(device.name, state.backEnd());
    EXPECT_GE(state.warmUpFrames(), 1) << "ready without a warm-up frame";
    const HttpReply metrics = httpGet(port(), "/metrics");
    EXPECT_NE(metrics.body.find("volcast_back_end_info{back_end=\"" + state.backEnd() + "\",type=\"" + device.type + "\"} 1"),
              std::string::npos)
        << metrics.body;
    if (volcast::openClGpuPresent()) {
        EXPECT_EQ(state.backEnd().rfind("opencl: ", 0), 0u) << state.backEnd();
        EXPECT_EQ(device.type, "gpu");
        return;
    }
    EXPECT_EQ(state.backEnd().rfind("cpu: ", 0), 0u) << "no OpenCL GPU here, yet the server draws on " << state.backEnd();
    EXPECT_EQ(device.type, "cpu");
    EXPECT_FALSE(state.usesOpenCl());
    EXPECT_EQ(state.programsBuilt(), 0u) << "the native path built an OpenCL program";
}

// The same server on --device opencl (PoCL here): the OpenCL path stays covered end to end.
class ServerOnOpenClTest : public ServerTest {
  protected:
    static void SetUpTestSuite() { startSharedServer("opencl"); }
};

TEST_F(ServerOnOpenClTest, FinalFrameMatchesTheOpenClRendererExactly) {
    const auto &state = server->state();
    ASSERT_TRUE(state.notReadyReason().empty()) << state.notReadyReason();
    EXPECT_TRUE(state.usesOpenCl());
    EXPECT_EQ(state.backEnd().rfind("opencl: ", 0), 0u) << state.backEnd();
    EXPECT_GE(state.programsBuilt(), 1u) << "ready before the warm-up frame built a ray-casting program";
    json scene;
    auto c = openSession("builtin:demo", &scene);
    expectFinalFrameMatchesTheRenderer(*c, scene, state);
}

TEST_F(ServerTest, DragDropsStaleRequestsThenRefinesToFinal) {
    auto c = openSession("builtin:demo");
    framesUntilFinal(*c);   // the opening ladder
    c->sendText(R"({"type":"interaction_start","id":"drag"})");
    constexpr int kMoves = 12;
    for (int i = 0; i < kMoves; ++i)
        c->sendText(json{{"type", "camera"}, {"id", 100 + i}, {"camera", cameraAt(5.0 * i)}}.dump());
    std::this_thread::sleep_for(300ms);   // still dragging, pointer at rest longer than idle: refinement may start
    c->sendText(R"({"type":"interaction_end","id":"drop"})");
    const auto frames = framesUntilFinal(*c);
    std::set<int> answered;
    int lastRequest = 0;
    uint64_t lastSeq = 0;
    for (const auto &f : frames) {
        const int r = f.header.request.get<int>();
        EXPECT_GE(r, lastRequest) << "frames out of order";
        EXPECT_GT(f.header.seq, lastSeq);
        lastRequest = r;
        lastSeq = f.header.seq;
        answered.insert(r);
    }
    // Latest wins: the burst of moves arrives faster than frames render, so most are skipped.
    EXPECT_LT(answered.size(), size_t(kMoves));
    EXPECT_EQ(frames.back().header.request, json(100 + kMoves - 1));
    EXPECT_TRUE(frames.back().header.final);
    EXPECT_EQ(frames.back().header.camera, cameraAt(5.0 * (kMoves - 1)));
}

TEST_F(ServerTest, NewInputCancelsRefinementWithinOneLevel) {
    auto c = openSession("builtin:demo", nullptr, 160);
    // A slow final level (fine step) so that refinement is still under way when input comes.
    request(*c, {{"type", "get_state"}, {"id", 4}});
    c->sendText(R"({"type":"quality_policy","id":5,"mode":"automatic","quality":{"step":0.1}})");
    // Wait for the first refined (level >= 1) frame of request 5.
    int refinedLevel = -1;
    const auto deadline = std::chrono::steady_clock::now() + kTimeout;
    while (refinedLevel < 1 && std::chrono::steady_clock::now() < deadline) {
        auto m = c->next(100ms);
        if (m && m->isFrame && m->frame.header.request == json(5)) {
            ASSERT_FALSE(m->frame.header.final) << "the ladder finished before the test could interrupt it";
            refinedLevel = m->frame.header.level;
        }
    }
    ASSERT_GE(refinedLevel, 1);
    c->sendText(json{{"type", "camera"}, {"id", 6}, {"camera", cameraAt(40)}}.dump());
    const auto frames = framesUntilFinal(*c);
    int oldFrames = 0;
    for (const auto &f : frames) {
        if (f.header.request != json(5)) continue;
        ++oldFrames;
        EXPECT_FALSE(f.header.final);
    }
    // At most the frame that was in flight; it is normally dropped as stale.
    EXPECT_LE(oldFrames, 1);
    EXPECT_EQ(frames.back().header.request, json(6));
}

TEST_F(ServerTest, TwoSessionsOpeningOneVolumeLoadItOnce) {
    const uint64_t before = server->state().metrics().volumeLoads();
    Client a("127.0.0.1", port()), b("127.0.0.1", port());
    for (Client *c : {&a, &b}) request(*c, {{"type", "hello"}, {"id", 1}, {"protocol", 1}});
    a.sendText(R"({"type":"open_volume","id":2,"name":"builtin:sphere"})");
    b.sendText(R"({"type":"open_volume","id":2,"name":"builtin:sphere"})");
    for (Client *c : {&a, &b}) {
        const Message state = volcast::client::waitForReply(*c, 2, kTimeout);
        ASSERT_TRUE(state.decoded && std::holds_alternative<protocol::StateMessage>(*state.decoded)) << state.text;
        EXPECT_EQ(json::parse(state.text).at("volume").at("name"), "builtin:sphere");
    }
    EXPECT_EQ(server->state().metrics().volumeLoads(), before + 1);
}

TEST_F(ServerTest, OpeningAFileStreamsItsLoadingProgressBeforeTheState) {
    Client c("127.0.0.1", port());
    request(c, {{"type", "hello"}, {"id", 1}, {"protocol", 1}});
    c.sendText(R"({"type":"open_volume","id":2,"name":"ct/scan.nrrd"})");
    std::vector<protocol::ProgressMessage> progress;
    bool gotState = false;
    const auto deadline = std::chrono::steady_clock::now() + kTimeout;
    while (!gotState && std::chrono::steady_clock::now() < deadline) {
        const auto m = c.next(1000ms);
        if (!m || !m->decoded) continue;
        if (const auto *p = std::get_if<protocol::ProgressMessage>(&*m->decoded)) progress.push_back(*p);
        gotState = std::holds_alternative<protocol::StateMessage>(*m->decoded);
    }
    ASSERT_TRUE(gotState);
    // Loading from 0 to 1 through the loader's named steps, then the upload; never backwards.
    std::set<std::string> tasks;
    double lastLoading = -1;
    bool uploaded = false;
    for (const auto &p : progress) {
        EXPECT_EQ(p.volume, "ct/scan.nrrd");
        if (p.stage == protocol::ProgressStage::Loading) {
            EXPECT_FALSE(uploaded) << "loading after the upload began";
            EXPECT_GE(p.fraction, lastLoading);
            lastLoading = p.fraction;
            if (!p.task.empty()) tasks.insert(p.task);
        } else if (p.stage == protocol::ProgressStage::Uploading) {
            uploaded = true;
        }
    }
    EXPECT_EQ(lastLoading, 1.0);
    EXPECT_TRUE(uploaded);
    for (const char *task : {"reading header", "checking data", "reading voxels", "converting", "statistics"})
        EXPECT_TRUE(tasks.count(task)) << task;
}

TEST_F(ServerTest, BadInputGetsItsErrorCodeAndTheSessionCarriesOn) {
    Client c("127.0.0.1", port());
    auto expectCode = [&](const std::string &text, const std::string &code, const json &id) {
        c.sendText(text);
        const Message reply = volcast::client::waitForReply(c, id, kTimeout);
        const auto *e = asError(reply);
        ASSERT_NE(e, nullptr) << text << " -> " << reply.text;
        EXPECT_EQ(protocol::errorCodeName(e->code), code) << text << " -> " << e->message;
    };
    expectCode(R"({"type":"camera","id":1,"camera":{}})", "bad_state", 1);   // before hello
    request(c, {{"type", "hello"}, {"id", 2}, {"protocol", 1}});
    expectCode(R"({"type":"hello",)", "malformed_json", nullptr);
    expectCode(R"({"type":"rotate","id":3})", "unknown_type", 3);
    expectCode(R"({"type":"camera","id":4,"camera":"front"})", "bad_field", 4);
    expectCode(R"({"type":"open_volume","id":5,"name":7})", "bad_field", 5);
    expectCode(json{{"type", "list_volumes"}, {"id", 6}, {"pad", std::string(100000, 'x')}}.dump(), "too_large", nullptr);
    expectCode(R"({"type":"open_volume","id":7,"name":"no_such_scan.nrrd"})", "not_found", 7);
    expectCode(R"({"type":"open_volume","id":8,"name":"../outside/secret.nrrd"})", "bad_volume_name", 8);
    expectCode(R"({"type":"open_volume","id":9,"name":"/etc/passwd"})", "bad_volume_name", 9);
    expectCode(R"({"type":"open_volume","id":10,"name":"escape.nrrd"})", "not_found", 10);   // link out of the folder
    expectCode(R"({"type":"open_volume","id":11,"name":"ct/broken.nrrd"})", "load_failed", 11);
    expectCode(R"({"type":"camera","id":12,"camera":{"eye":[0,0,1],"target":[0,0,0],"up":[0,1,0],"projection":"perspective","fov_y_deg":30}})",
               "bad_state", 12);   // no volume yet
    expectCode(R"({"type":"viewport","id":13,"image":{"width":0,"height":64}})", "bad_field", 13);

    // Still usable: the listing hides the escaping link, and a volume opens and renders.
    const Message list = request(c, {{"type", "list_volumes"}, {"id", 14}});
    const json volumes = json::parse(list.text).at("volumes");
    std::set<std::string> names;
    for (const auto &v : volumes) names.insert(v.at("name").get<std::string>());
    EXPECT_TRUE(names.count("builtin:demo"));
    EXPECT_TRUE(names.count("ct/broken.nrrd"));
    EXPECT_FALSE(names.count("escape.nrrd"));
    c.sendText(R"({"type":"viewport","id":15,"image":{"width":48,"height":48}})");
    request(c, {{"type", "open_volume"}, {"id", 16}, {"name", "builtin:demo"}});
    // A camera the scene parser refuses changes nothing; the next good one renders.
    expectCode(R"({"type":"camera","id":17,"camera":{"eye":[63.5,600,63.5],"target":[63.5,63.5,63.5],"up":[0,1,0],"projection":"perspective","fov_y_deg":30}})",
               "bad_field", 17);
    c.sendText(json{{"type", "camera"}, {"id", 18}, {"camera", cameraAt(10)}}.dump());
    const auto frames = framesUntilFinal(c);
    ASSERT_FALSE(frames.empty());
    EXPECT_EQ(frames.back().header.request, json(18));
    EXPECT_EQ(frames.back().header.width, 48);
}

TEST_F(ServerTest, ClientThatStopsReadingStallsNoOneAndHoldsOneFrame) {
    // A: large frames (a 1024² viewport) and a small receive buffer, then stops reading while
    // its camera keeps moving, until the server holds one of its frames unwritten. On loopback
    // the kernel's send buffer grows to megabytes (its segments are 64 KiB), so that takes
    // tens of frames; the rate they render at does not matter.
    auto a = openSession("builtin:demo", nullptr, 1024, 16 * 1024);
    auto b = openSession("builtin:demo");
    framesUntilFinal(*b);
    a->pauseReading();
    const auto queued = [&] { return metricValue(httpGet(port(), "/metrics").body, "volcast_outgoing_queue_bytes"); };
    // Held, not merely being written: still queued 200 ms later, with nothing new sent.
    const auto held = [&] {
        if (queued() <= 0) return false;
        std::this_thread::sleep_for(200ms);
        return queued() > 0;
    };
    bool stuck = false;
    const auto fillBy = std::chrono::steady_clock::now() + 30s;
    for (int i = 0; !stuck && std::chrono::steady_clock::now() < fillBy; ++i) {
        a->sendText(json{{"type", "camera"}, {"id", 1000 + i}, {"camera", cameraAt(0.5 * i)}}.dump());
        std::this_thread::sleep_for(10ms);
        if (i % 10 == 9) stuck = held();
    }
    ASSERT_TRUE(stuck) << "A's socket never backed up within 30 s: the test could not play a stuck reader";

    // Now 40 views while A is stuck.
    double maxQueued = 0;
    for (int i = 0; i < 40; ++i) {
        a->sendText(json{{"type", "camera"}, {"id", 100 + i}, {"camera", cameraAt(3.0 * i)}}.dump());
        std::this_thread::sleep_for(10ms);
        if (i % 8 == 7) maxQueued = std::max(maxQueued, queued());
    }
    // B keeps getting every view to its final frame promptly.
    for (int i = 0; i < 4; ++i) {
        const auto t0 = std::chrono::steady_clock::now();
        b->sendText(json{{"type", "camera"}, {"id", 200 + i}, {"camera", cameraAt(90.0 + 7 * i)}}.dump());
        const auto frames = framesUntilFinal(*b, nullptr, 10s);
        ASSERT_FALSE(frames.empty());
        EXPECT_EQ(frames.back().header.request, json(200 + i));
        EXPECT_LT(std::chrono::steady_clock::now() - t0, 8s);
        maxQueued = std::max(maxQueued, queued());
    }
    // The server holds one unwritten frame for A (a 1024² JPEG is < 0.2 MiB), no backlog.
    EXPECT_GT(maxQueued, 0);
    EXPECT_LT(maxQueued, 1.0 * 1024 * 1024);
    // A, reading again, gets what its buffers held, the held frame, then the newest view: of
    // the 40 views sent while it was stuck, only the last one is rendered at all.
    a->resumeReading();
    std::vector<volcast::client::Frame> framesA;
    const auto deadline = std::chrono::steady_clock::now() + kTimeout;
    while (std::chrono::steady_clock::now() < deadline) {
        auto m = a->next(100ms);
        if (!m || !m->isFrame) continue;
        framesA.push_back(m->frame);
        if (m->frame.header.final && m->frame.header.request == json(139)) break;
    }
    ASSERT_FALSE(framesA.empty());
    EXPECT_EQ(framesA.back().header.request, json(139));
    EXPECT_TRUE(framesA.back().header.final);
    std::set<int> stuckViews;
    for (const auto &f : framesA)
        if (const int id = f.header.request.get<int>(); id >= 100 && id < 140) stuckViews.insert(id);
    EXPECT_EQ(stuckViews, std::set<int>{139}) << "views rendered while A was not reading";
}

// ---- the executable under SIGTERM ----------------------------------------------------

// The orientation correction (quality.orientation_correction in the quality policy) is the
// session's: its frames show the volume mirrored, camera and transfer function changes keep
// it, the state reports it, and a matrix that is not a signed permutation is refused by name
// and changes nothing.
TEST_F(ServerTest, TheSessionKeepsTheOrientationCorrectionAndItsFramesAreMirrored) {
    auto c = openSession("builtin:demo");
    framesUntilFinal(*c);
    // Looking down −z at the demo's centre with y up: image x is world +x, so flipping x
    // (left/right) mirrors the frame about its vertical centre line.
    const json camera = {{"eye", {63.5, 63.5, 400}}, {"target", {63.5, 63.5, 63.5}}, {"up", {0, 1, 0}},
                         {"projection", "perspective"}, {"fov_y_deg", 30}};
    c->sendText(json{{"type", "camera"}, {"id", 10}, {"camera", camera}}.dump());
    const auto plain = framesUntilFinal(*c);
    ASSERT_FALSE(plain.empty());
    const json flipX = {{-1, 0, 0}, {0, 1, 0}, {0, 0, 1}};
    c->sendText(json{{"type", "quality_policy"}, {"id", 11}, {"mode", "automatic"},
                     {"quality", {{"orientation_correction", flipX}}}}.dump());
    const auto flipped = framesUntilFinal(*c);
    ASSERT_FALSE(flipped.empty());
    EXPECT_EQ(flipped.back().header.request, json(11));

    int w = 0, h = 0, ch = 0;
    const std::vector<uint8_t> a = decodePng(plain.back().image, w, h, ch);
    const std::vector<uint8_t> b = decodePng(flipped.back().image, w, h, ch);
    ASSERT_EQ(a.size(), b.size());
    int worstMirror = 0, worstSame = 0;
    for (int y = 0; y < h; ++y)
        for (int x = 0; x < w; ++x)
            for (int k = 0; k < ch; ++k) {
                const int got = b[size_t((y * w + x) * ch + k)];
                worstMirror = std::max(worstMirror, std::abs(got - int(a[size_t((y * w + (w - 1 - x)) * ch + k)])));
                worstSame = std::max(worstSame, std::abs(got - int(a[size_t((y * w + x) * ch + k)])));
            }
    // The same rays through the mirrored volume, in float32: a last-bit difference may round
    // one 8-bit value the other way (straight alpha divides by a small alpha at the edges).
    EXPECT_LE(worstMirror, 2) << "the flipped frame is not the mirror image of the unflipped one";
    EXPECT_GT(worstSame, 20) << "the flip changed nothing: the demo seen this way is symmetric, the test cannot tell";

    // Camera and transfer function changes keep it; the state says it.
    c->sendText(json{{"type", "camera"}, {"id", 12}, {"camera", cameraAt(20)}}.dump());
    c->sendText(json{{"type", "transfer_function"}, {"id", 13}, {"transfer_function", {{"preset", "ct_bone"}}}}.dump());
    framesUntilFinal(*c);
    const json state = json::parse(request(*c, {{"type", "get_state"}, {"id", 14}}).text);
    EXPECT_EQ(state.at("scene").at("quality").value("orientation_correction", json()), flipX) << state.dump();
    // The scene as the state gives it is a scene file that keeps the correction.
    EXPECT_EQ(volcast::parseScene(state.at("scene").dump()).quality.orientationCorrection,
              (volcast::OrientationCorrection{{-1, 0, 0, 0, 1, 0, 0, 0, 1}}));

    // A shear is refused, naming the field; the correction stays.
    const Message refused = request(*c, {{"type", "quality_policy"}, {"id", 15}, {"mode", "automatic"},
                                        {"quality", {{"orientation_correction", {{1, 1, 0}, {0, 1, 0}, {0, 0, 1}}}}}});
    const auto *e = asError(refused);
    ASSERT_NE(e, nullptr) << refused.text;
    EXPECT_EQ(protocol::errorCodeName(e->code), "bad_field");
    EXPECT_NE(e->message.find("quality.orientation_correction"), std::string::npos) << e->message;
    const json after = json::parse(request(*c, {{"type", "get_state"}, {"id", 16}}).text);
    EXPECT_EQ(after.at("scene").at("quality").value("orientation_correction", json()), flipX) << after.dump();
}

TEST(ServerProcess, SigtermClosesSessionsWithAReasonAndExitsZero) {
    const fs::path portFile = fs::temp_directory_path() / ("volcast_port_" + std::to_string(::getpid()));
    fs::remove(portFile);
    const pid_t pid = volcast::test::startServerProcess(
        {"--port", "0", "--port-file", portFile.string(), "--default-volume", "builtin:sphere", "--log-level", "warn"});
    ASSERT_GE(pid, 0);
    const uint16_t port = volcast::test::waitForPort(portFile, kTimeout);
    ASSERT_NE(port, 0) << "the server did not start";
    {
        Client c("127.0.0.1", port);
        request(c, {{"type", "hello"}, {"id", 1}, {"protocol", 1}});
        ASSERT_EQ(::kill(pid, SIGTERM), 0);
        const auto until = std::chrono::steady_clock::now() + 10s;
        while (!c.closed() && std::chrono::steady_clock::now() < until) c.next(100ms);
        ASSERT_TRUE(c.closed());
        const auto info = c.closeInfo();
        ASSERT_TRUE(info.has_value());
        EXPECT_EQ(info->code, 1001);   // going away
        EXPECT_NE(info->reason.find("SIGTERM"), std::string::npos) << info->reason;
    }
    int status = 0;
    ASSERT_EQ(::waitpid(pid, &status, 0), pid);
    EXPECT_TRUE(WIFEXITED(status));
    EXPECT_EQ(WEXITSTATUS(status), 0);
    fs::remove(portFile);
}

} // namespace
