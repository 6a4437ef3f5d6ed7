// WebSocket sessions under hostile or careless clients: text that is not UTF-8, connections
// that never say hello, requests whose work has no bound, and clients that stop reading.
// Each test runs its own in-process server with the limits it exercises set small, so that
// it takes seconds; the built-in demo volume (128³) and 64² viewports keep renders cheap.

#include "tests/server/server_fixture.hpp"
#include "client/cpp/ws_client.hpp"
#include "server/server.hpp"

#include <boost/asio/connect.hpp>
#include <boost/asio/ip/tcp.hpp>
#include <boost/beast/core.hpp>
#include <boost/beast/websocket.hpp>
#include <gtest/gtest.h>

#include <cmath>
#include <iostream>
#include <optional>
#include <sstream>
#include <thread>

namespace {

using namespace std::chrono_literals;
using nlohmann::json;
using volcast::client::Client;
using volcast::client::Message;
namespace protocol = volcast::protocol;
namespace net = boost::asio;
namespace websocket = boost::beast::websocket;
using Clock = std::chrono::steady_clock;

constexpr auto kTimeout = 20s;   // generous: a cold PoCL cache builds programs for seconds

std::unique_ptr<volcast::server::Server> startServer(volcast::server::ServerConfig config) {
    config.port = 0;
    config.idleMs = 100;
    config.defaultVolume = "builtin:demo";
    config.errorCalibration = false;   // keeps the worker's time for the frames measured here
    auto server = std::make_unique<volcast::server::Server>(config);
    volcast::test::startAndWaitReady(*server, kTimeout);
    return server;
}

using volcast::test::asError;

Message request(Client &c, const json &message, std::vector<Message> *skipped = nullptr) {
    c.sendText(message.dump());
    return volcast::client::waitForReply(c, message.at("id"), kTimeout, skipped);
}

// The error answering `message`; fails the test (with what came instead) if it is not one.
protocol::ProtocolError errorFor(Client &c, const json &message) {
    const Message reply = request(c, message);
    const auto *e = asError(reply);
    if (!e) {
        ADD_FAILURE() << message.dump() << " was not refused; the reply: " << reply.text;
        return {};
    }
    return *e;
}

bool isHello(const Message &m) { return m.decoded && std::holds_alternative<protocol::ServerHello>(*m.decoded); }

json hello(int id, const std::string &token = "") {
    json h{{"type", "hello"}, {"id", id}, {"protocol", 1}, {"client", "gtest"}};
    if (!token.empty()) h["token"] = token;
    return h;
}

using volcast::test::cameraAt;

// A session past hello with the demo open at side², after its first final frame.
std::unique_ptr<Client> openDemo(uint16_t port, int side, const std::string &token = "") {
    auto c = std::make_unique<Client>("127.0.0.1", port);
    const Message h = request(*c, hello(1, token));
    EXPECT_TRUE(isHello(h)) << h.text;
    c->sendText(json{{"type", "viewport"}, {"id", 2}, {"image", {{"width", side}, {"height", side}}}}.dump());
    const Message state = request(*c, {{"type", "open_volume"}, {"id", 3}, {"name", "builtin:demo"}});
    EXPECT_NE(state.text.find("\"type\":\"state\""), std::string::npos) << state.text;
    return c;
}

// Frames until the final frame of request `id`; false (and a test failure) on timeout.
bool finalFrameOf(Client &c, const json &id, std::chrono::milliseconds timeout, int *frames = nullptr) {
    const auto deadline = Clock::now() + timeout;
    while (Clock::now() < deadline) {
        auto m = c.next(50ms);
        if (!m) continue;
        if (!m->isFrame) {
            if (const auto *e = asError(*m)) ADD_FAILURE() << "unexpected error: " << e->message;
            continue;
        }
        if (frames) ++*frames;
        if (m->frame.header.final && m->frame.header.request == id) return true;
    }
    ADD_FAILURE() << "no final frame of request " << id.dump() << " within " << timeout.count() << " ms";
    return false;
}

// Waits until the client sees the server close the connection; its close code, or 0.
int closeCodeWithin(Client &c, std::chrono::milliseconds timeout, std::vector<Message> *texts = nullptr) {
    const auto deadline = Clock::now() + timeout;
    while (!c.closed() && Clock::now() < deadline) {
        if (auto m = c.next(50ms); m && texts && !m->isFrame) texts->push_back(std::move(*m));
    }
    while (auto m = c.next(0ms))
        if (texts && !m->isFrame) texts->push_back(std::move(*m));
    const auto info = c.closeInfo();
    return c.closed() && info ? info->code : 0;
}

// The sum of every sample of a Prometheus metric (all label sets).
double metricSum(const std::string &text, const std::string &name) {
    std::istringstream in(text);
    double sum = 0;
    for (std::string line; std::getline(in, line);)
        if (line.starts_with(name + " ") || line.starts_with(name + "{")) sum += std::stod(line.substr(line.rfind(' ') + 1));
    return sum;
}

// ---- UTF-8 -----------------------------------------------------------------------------

// A crash once: a 2-byte text message "é" before hello, without a token, aborted the
// server (the malformed_json message quoted a cut UTF-8 sequence and serialising it threw).
TEST(WsHardening, NonAsciiGarbageGetsMalformedJsonAndInvalidUtf8Closes1007) {
    volcast::server::ServerConfig config;
    config.token = "secret";
    auto server = startServer(config);
    {
        Client c("127.0.0.1", server->port());
        for (const std::string text : {"\xC3\xA9", "\xE2\x82\xAC", "\xC3\xA9\xC3\xA9{", "[\"\xE2\x82\xAC\"", "{\"\xC3\xA9\":"}) {
            c.sendText(text);
            const Message reply = volcast::client::waitForReply(c, nullptr, kTimeout);
            const auto *e = asError(reply);
            ASSERT_NE(e, nullptr) << reply.text;
            EXPECT_EQ(protocol::errorCodeName(e->code), "malformed_json") << e->message;
            EXPECT_TRUE(protocol::isValidUtf8(reply.text));
        }
        // Still the same session: hello with the token is answered.
        EXPECT_TRUE(isHello(request(c, hello(7, "secret"))));
    }
    {
        // Not UTF-8 at all: the WebSocket layer (Beast validates text frames) fails the
        // connection with 1007, as RFC 6455 asks; there is no request to answer.
        Client c("127.0.0.1", server->port());
        c.sendText("{\"type\": \"hello\", \"client\": \"\xC3\"}");
        EXPECT_EQ(closeCodeWithin(c, 5s), 1007);
    }
    // The server is up and serves the next client.
    Client after("127.0.0.1", server->port());
    EXPECT_TRUE(isHello(request(after, hello(1, "secret"))));
}

// ---- hello deadline and session slots --------------------------------------------------

TEST(WsHardening, SilentConnectionsTakeNoSessionAndAreClosedAtTheHelloDeadline) {
    volcast::server::ServerConfig config;
    config.token = "secret";
    config.maxSessions = 2;
    config.maxPendingSessions = 32;
    config.helloTimeoutMs = 1500;
    auto server = startServer(config);
    const auto opened = Clock::now();
    std::vector<std::unique_ptr<Client>> silent;
    for (int i = 0; i < 16; ++i) silent.push_back(std::make_unique<Client>("127.0.0.1", server->port()));

    // Before the fix the 16 held every session slot: both got busy.
    Client a("127.0.0.1", server->port()), b("127.0.0.1", server->port());
    EXPECT_TRUE(isHello(request(a, hello(1, "secret"))));
    EXPECT_TRUE(isHello(request(b, hello(1, "secret"))));
    // max_sessions still holds for clients past hello.
    Client third("127.0.0.1", server->port());
    const auto busy = errorFor(third, hello(1, "secret"));
    EXPECT_EQ(protocol::errorCodeName(busy.code), "busy") << busy.message;
    EXPECT_NE(busy.message.find("--max-sessions"), std::string::npos) << busy.message;
    EXPECT_EQ(closeCodeWithin(third, 5s), 1013);

    // Every silent connection is closed at the deadline (1.5 s here), with 1008 and an error
    // naming it; 3 s of slack for a loaded 2-core machine.
    for (auto &c : silent) {
        std::vector<Message> texts;
        EXPECT_EQ(closeCodeWithin(*c, 5s, &texts), 1008);
        ASSERT_FALSE(texts.empty());
        const auto *e = asError(texts.front());
        ASSERT_NE(e, nullptr) << texts.front().text;
        EXPECT_NE(e->message.find("--hello-timeout-ms"), std::string::npos) << e->message;
    }
    const double waited = std::chrono::duration<double>(Clock::now() - opened).count();
    EXPECT_GE(waited, 1.4) << "closed before the deadline";
    EXPECT_LT(waited, 1.5 + 3.0);
    // The sessions past hello were not touched by the deadline.
    EXPECT_FALSE(a.closed());
    EXPECT_NE(request(a, {{"type", "get_state"}, {"id", 2}}).text.find("\"state\""), std::string::npos);
    EXPECT_EQ(server->state().metrics().sessions(), 2);
}

TEST(WsHardening, ConnectionsBeforeHelloAreBoundedSeparately) {
    volcast::server::ServerConfig config;
    config.maxPendingSessions = 4;
    config.helloTimeoutMs = 60000;
    auto server = startServer(config);
    std::vector<std::unique_ptr<Client>> silent;
    for (int i = 0; i < 4; ++i) silent.push_back(std::make_unique<Client>("127.0.0.1", server->port()));
    std::this_thread::sleep_for(200ms);   // the server registers each after its handshake
    Client over("127.0.0.1", server->port());
    std::vector<Message> texts;
    EXPECT_EQ(closeCodeWithin(over, 5s, &texts), 1013);
    ASSERT_FALSE(texts.empty());
    const auto *e = asError(texts.front());
    ASSERT_NE(e, nullptr) << texts.front().text;
    EXPECT_EQ(protocol::errorCodeName(e->code), "busy");
    EXPECT_NE(e->message.find("--max-pending-sessions"), std::string::npos) << e->message;
    // One of them saying hello frees a pending place.
    EXPECT_TRUE(isHello(request(*silent[0], hello(1))));
    std::this_thread::sleep_for(100ms);
    Client next("127.0.0.1", server->port());
    EXPECT_TRUE(isHello(request(next, hello(1))));
}

// ---- admission control -----------------------------------------------------------------

TEST(WsHardening, UnboundedRequestsAreRefusedNamingTheLimitWhileOthersRender) {
    volcast::server::ServerConfig config;   // the default limits, but for image memory:
    config.maxRequestBytes = 32 << 20;      // 32 MiB, so that a 2048² viewport is over it
    auto server = startServer(config);
    auto a = openDemo(server->port(), 128);
    auto b = openDemo(server->port(), 64);
    ASSERT_TRUE(finalFrameOf(*b, 3, kTimeout));
    ASSERT_TRUE(finalFrameOf(*a, 3, kTimeout));
    // Explicit quality is refused over a limit (the automatic policy is lowered to fit it
    // instead: TheAutomaticPolicyRendersAnyWindowWithinTheLimits).
    a->sendText(json{{"type", "quality_policy"}, {"id", 9}, {"mode", "explicit"}, {"quality", {{"step", 1}}}}.dump());
    ASSERT_TRUE(finalFrameOf(*a, 9, kTimeout));
    const json before = json::parse(request(*a, {{"type", "get_state"}, {"id", 10}}).text);

    // An absurd step, as a browser field can send: 0.0002 on the demo (diagonal 222 voxels)
    // at 128² is 128² rays x 1.1e6 samples per ray = 1.8e10 predicted samples, over the 2^32
    // default. (A step of 0.001 at a browser's ~900 x 700 predicts 1.4e11.)
    const json tiny = {{"type", "quality_policy"}, {"id", 11}, {"mode", "explicit"},
                       {"quality", {{"step", 0.0002}}}};
    const auto e1 = errorFor(*a, tiny);
    EXPECT_EQ(protocol::errorCodeName(e1.code), "too_large") << e1.message;
    EXPECT_NE(e1.message.find("--max-samples-per-frame"), std::string::npos) << e1.message;
    const auto e3 = errorFor(*a, {{"type", "still"}, {"id", 13}, {"image", {{"width", 8192}, {"height", 8192}}}});
    EXPECT_EQ(protocol::errorCodeName(e3.code), "too_large") << e3.message;
    EXPECT_NE(e3.message.find("--max-still-pixels"), std::string::npos) << e3.message;
    const auto e4 = errorFor(*a, {{"type", "viewport"}, {"id", 14}, {"image", {{"width", 2048}, {"height", 2048}}}});
    EXPECT_EQ(protocol::errorCodeName(e4.code), "too_large") << e4.message;
    EXPECT_NE(e4.message.find("--max-request-mib"), std::string::npos) << e4.message;
    const auto e5 = errorFor(*a, {{"type", "viewport"}, {"id", 15}, {"image", {{"width", 8192}, {"height", 8192}}}});
    EXPECT_EQ(protocol::errorCodeName(e5.code), "too_large") << e5.message;

    // Nothing of the refused requests was kept.
    const json after = json::parse(request(*a, {{"type", "get_state"}, {"id", 16}}).text);
    EXPECT_EQ(after.at("scene"), before.at("scene"));
    EXPECT_EQ(after.at("quality_policy"), before.at("quality_policy"));

    // B renders promptly meanwhile: the refused work never reached the renderer (before the
    // fix, step 0.001 gave every other session no frame for 39 s).
    for (int i = 0; i < 3; ++i) {
        const auto t0 = Clock::now();
        b->sendText(json{{"type", "camera"}, {"id", 100 + i}, {"camera", cameraAt(20.0 * i)}}.dump());
        ASSERT_TRUE(finalFrameOf(*b, 100 + i, 10s));
        EXPECT_LT(Clock::now() - t0, 5s);
    }
    // And A still works, at its old viewport (128²).
    a->sendText(json{{"type", "camera"}, {"id", 17}, {"camera", cameraAt(45)}}.dump());
    EXPECT_TRUE(finalFrameOf(*a, 17, 10s));

    // The limits are in hello for clients to check before sending.
    Client c("127.0.0.1", server->port());
    const json h = json::parse(request(c, hello(1)).text);
    EXPECT_EQ(h.at("limits").at("max_samples_per_frame"), server->state().config().maxSamplesPerFrame);
    EXPECT_EQ(h.at("limits").at("max_still_pixels"), server->state().config().maxStillPixels);
    EXPECT_EQ(h.at("limits").at("max_request_bytes"), 32 << 20);
}

// The automatic policy never meets a refusal: each level is lowered (image scale, then step)
// until it fits --max-samples-per-frame and --max-request-mib, and every frame of such a
// level says so in its header. A 3840×2160 viewport gets its final frame.
TEST(WsHardening, TheAutomaticPolicyRendersAnyWindowWithinTheLimits) {
    volcast::server::ServerConfig config;
    config.maxSamplesPerFrame = int64_t(1) << 28;   // 2.7e8: the demo (diagonal 222 voxels) at
    config.maxRequestBytes = 64 << 20;              // 3840×2160, step 0.5, predicts 3.7e9
    auto server = startServer(config);
    auto a = openDemo(server->port(), 64);
    ASSERT_TRUE(finalFrameOf(*a, 3, kTimeout));
    a->sendText(json{{"type", "viewport"}, {"id", 4}, {"image", {{"width", 3840}, {"height", 2160}}}}.dump());
    a->sendText(json{{"type", "quality_policy"}, {"id", 5}, {"mode", "automatic"}, {"quality", {{"step", 0.5}}}}.dump());
    const auto deadline = Clock::now() + 60s;
    std::optional<protocol::FrameHeader> final;
    int limitedFrames = 0;
    while (Clock::now() < deadline && !final) {
        auto m = a->next(50ms);
        if (!m) continue;
        if (const auto *e = asError(*m)) {
            ADD_FAILURE() << "refused: " << e->message;
            break;
        }
        if (!m->isFrame || m->frame.header.request != json(5)) continue;
        const auto &h = m->frame.header;
        // Every frame stays within both limits, as the server predicts them (quality_ladder.hpp).
        const double scale = h.quality.at("image_scale").get<double>(), step = h.quality.at("step").get<double>();
        const double rays = 3840.0 * 2160.0 * scale * scale;
        const double samples = rays * std::sqrt(3.0 * 128 * 128) / step * (h.quality.at("shading").get<bool>() ? 3 : 1);
        EXPECT_LE(samples, double(config.maxSamplesPerFrame)) << h.quality.dump();
        const double passes = h.final && h.quality.value("jitter", false) ? config.jitterPasses : 1;
        EXPECT_LE(rays * 16.0 * passes, double(config.maxRequestBytes)) << h.quality.dump();
        // Sent as rendered (raysForScale a side), with the view's size beside it.
        EXPECT_EQ(h.width, std::max(1, int(std::lround(3840 * scale)))) << h.quality.dump();
        EXPECT_EQ(h.height, std::max(1, int(std::lround(2160 * scale)))) << h.quality.dump();
        EXPECT_EQ(h.viewWidth, 3840);
        EXPECT_EQ(h.viewHeight, 2160);
        if (!h.limited.empty()) {
            ++limitedFrames;
            EXPECT_NE(h.limited.find("to stay within the server's"), std::string::npos) << h.limited;
        }
        if (h.final) final = h;
    }
    ASSERT_TRUE(final.has_value()) << "no final frame of the 3840x2160 view";
    EXPECT_LT(final->quality.at("image_scale").get<double>(), 1);
    EXPECT_NE(final->limited.find("image scale"), std::string::npos) << final->limited;
    EXPECT_GT(limitedFrames, 0);
    // The same view with explicit quality is refused, naming the limit.
    const auto e = errorFor(*a, {{"type", "quality_policy"}, {"id", 6}, {"mode", "explicit"}, {"quality", {{"step", 0.5}}}});
    EXPECT_EQ(protocol::errorCodeName(e.code), "too_large") << e.message;
    EXPECT_NE(e.message.find("--max-"), std::string::npos) << e.message;
}

// ---- slow readers ------------------------------------------------------------------------

TEST(WsHardening, ClientThatStopsReadingIsClosedAtTheWriteTimeoutAndFreesItsSlot) {
    volcast::server::ServerConfig config;
    config.writeTimeoutMs = 1500;
    config.sendBufferBytes = 32 * 1024;
    auto server = startServer(config);
    auto b = openDemo(server->port(), 64);
    ASSERT_TRUE(finalFrameOf(*b, 3, kTimeout));

    // A: a raw WebSocket with a small receive buffer, so that little is in flight once it
    // stops reading (the C++ client's kernel buffer would autotune to megabytes).
    net::io_context ioc;
    net::ip::tcp::socket socket(ioc);
    socket.open(net::ip::tcp::v4());
    constexpr int kReceiveBuffer = 16 * 1024;
    socket.set_option(net::socket_base::receive_buffer_size(kReceiveBuffer));
    socket.connect({net::ip::make_address("127.0.0.1"), server->port()});
    websocket::stream<net::ip::tcp::socket> a(std::move(socket));
    a.handshake("127.0.0.1", "/ws");
    a.text(true);
    const auto sendA = [&](const json &m) {
        boost::beast::error_code ec;
        a.write(net::buffer(m.dump()), ec);
        return !ec;
    };
    sendA(hello(1));
    sendA({{"type", "viewport"}, {"id", 2}, {"image", {{"width", 256}, {"height", 256}}}});
    sendA({{"type", "open_volume"}, {"id", 3}, {"name", "builtin:demo"}});
    for (bool state = false; !state;) {   // read up to the state; then never again
        boost::beast::flat_buffer buffer;
        a.read(buffer);
        state = a.got_text() && boost::beast::buffers_to_string(buffer.data()).find("\"state\"") != std::string::npos;
    }
    const std::string metrics0 = server->state().metrics().prometheusText();
    const double frameBytes0 = metricSum(metrics0, "volcast_frame_bytes_total");
    ASSERT_EQ(server->state().metrics().sessions(), 2);

    // A keeps asking for new views and reads nothing: every view's frame is rendered only
    // once the previous one was written, so frames stop once the buffers are full, and the
    // stuck write closes A after the write timeout.
    const auto stopped = Clock::now();
    std::optional<Clock::time_point> closedAt;
    for (int i = 0; Clock::now() - stopped < 15s; ++i) {
        if (!sendA({{"type", "camera"}, {"id", 100 + i}, {"camera", cameraAt(2.0 * i)}})) {}
        if (server->state().metrics().sessions() == 1) {
            closedAt = Clock::now();
            break;
        }
        std::this_thread::sleep_for(20ms);
    }
    ASSERT_TRUE(closedAt) << "the session that stopped reading was not closed within 15 s";
    // Closed within the write timeout plus the time to fill the buffers and a loaded
    // machine's slack (renders of 256² take ~0.1 s here; a few seconds in all is plenty).
    EXPECT_LT(*closedAt - stopped, 1500ms + 6s);

    // What was written for A after it stopped: bounded by the buffers between the server's
    // writes and A's reads (both kernels' socket buffers, which Linux doubles, and one frame
    // Beast holds), not by how long A kept asking. B was idle meanwhile.
    const std::string metrics1 = server->state().metrics().prometheusText();
    const double writtenForA = metricSum(metrics1, "volcast_frame_bytes_total") - frameBytes0;
    EXPECT_LT(writtenForA, 2.0 * (config.sendBufferBytes + kReceiveBuffer) + 512 * 1024)
        << "bytes of frames written for a client that did not read";
    std::cout << "the reader that stopped was closed after "
              << std::chrono::duration<double>(*closedAt - stopped).count() << " s; " << writtenForA
              << " bytes of frames were written for it after it stopped\n";

    // Its render slot is free and B keeps rendering.
    for (int i = 0; i < 3; ++i) {
        b->sendText(json{{"type", "camera"}, {"id", 200 + i}, {"camera", cameraAt(30.0 * i)}}.dump());
        ASSERT_TRUE(finalFrameOf(*b, 200 + i, 10s));
    }
    // The counter moves in the server's write handler, which may run just after the client has
    // read the frame: let the last write's handler run before taking the count.
    std::this_thread::sleep_for(300ms);
    const double framesAfter = metricSum(server->state().metrics().prometheusText(), "volcast_frames_total");
    std::this_thread::sleep_for(500ms);
    EXPECT_EQ(metricSum(server->state().metrics().prometheusText(), "volcast_frames_total"), framesAfter)
        << "frames are still being written after every session went idle";
}

TEST(WsHardening, RepliesPastTheUnsentByteLimitCloseTheSession) {
    volcast::server::ServerConfig config;
    config.maxUnsentBytes = 64 * 1024;
    config.sendBufferBytes = 16 * 1024;
    config.writeTimeoutMs = 60000;   // the byte limit, not the timeout, is what this checks
    auto server = startServer(config);
    Client c("127.0.0.1", server->port());
    ASSERT_TRUE(isHello(request(c, hello(1))));
    c.pauseReading();
    // Each volumes reply is ~1 KB; the client's own kernel buffer takes some megabytes first.
    for (int i = 0; i < 20000 && !c.closed(); ++i) {
        c.sendText(json{{"type", "list_volumes"}, {"id", i}}.dump());
        if (i % 500 == 499 && server->state().metrics().sessions() == 0) break;
    }
    const auto deadline = Clock::now() + 10s;
    while (server->state().metrics().sessions() != 0 && Clock::now() < deadline) std::this_thread::sleep_for(50ms);
    EXPECT_EQ(server->state().metrics().sessions(), 0) << "a client that reads no replies was not closed";
}

} // namespace
