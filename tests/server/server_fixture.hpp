#pragma once
// Helpers shared by the server's test files: an in-process server started and ready, a
// client that said hello, a GET, a request sent byte for byte as given (for the malformed
// ones no client library would write), and a camera orbiting the demo.

#include "client/cpp/ws_client.hpp"
#include "server/server.hpp"

#include <gtest/gtest.h>

#include <boost/asio/ip/tcp.hpp>
#include <boost/beast/core.hpp>
#include <boost/beast/http.hpp>

#include <nlohmann/json.hpp>

#include <chrono>
#include <cmath>
#include <memory>
#include <optional>
#include <string>
#include <thread>
#include <variant>

namespace volcast::test {

// Starts `server` and waits until it is ready (its default volume in memory) or `timeout`
// has passed; a test then sees what is not ready in its own failures.
inline void startAndWaitReady(server::Server &server, std::chrono::milliseconds timeout) {
    server.start();
    const auto deadline = std::chrono::steady_clock::now() + timeout;
    while (!server.state().notReadyReason().empty() && std::chrono::steady_clock::now() < deadline)
        std::this_thread::sleep_for(std::chrono::milliseconds(20));
}

// The error a message is, or null.
inline const protocol::ProtocolError *asError(const client::Message &m) {
    return m.decoded ? std::get_if<protocol::ProtocolError>(&*m.decoded) : nullptr;
}

// A client on loopback `port` that has said hello (request id 1) as `clientName`; the test
// fails if the answer is not the server's hello.
inline std::unique_ptr<client::Client> helloClient(uint16_t port, const std::string &clientName,
                                                   std::chrono::milliseconds timeout, int receiveBufferBytes = 0) {
    auto c = std::make_unique<client::Client>("127.0.0.1", port, "/ws", "", receiveBufferBytes);
    c->sendText(nlohmann::json{{"type", "hello"}, {"id", 1}, {"protocol", 1}, {"client", clientName}}.dump());
    const client::Message hello = client::waitForReply(*c, 1, timeout);
    EXPECT_TRUE(hello.decoded && std::holds_alternative<protocol::ServerHello>(*hello.decoded)) << hello.text;
    return c;
}

// A scene-file camera on a circle around the demo volume's centre (63.5³), angleDeg around y.
inline nlohmann::json cameraAt(double angleDeg) {
    const double a = angleDeg * M_PI / 180.0, r = 420;
    return {{"eye", {63.5 + r * std::sin(a), 63.5 + 250, 63.5 + r * std::cos(a)}},
            {"target", {63.5, 63.5, 63.5}},
            {"up", {0, 1, 0}},
            {"projection", "perspective"},
            {"fov_y_deg", 30}};
}

struct HttpReply {
    int status = 0;
    std::string contentType;
    std::string body;
};

inline HttpReply httpGet(uint16_t port, const std::string &target, const std::string &host = "127.0.0.1") {
    namespace http = boost::beast::http;
    boost::asio::io_context ioc;
    boost::asio::ip::tcp::resolver resolver(ioc);
    boost::beast::tcp_stream stream(ioc);
    stream.connect(resolver.resolve("127.0.0.1", std::to_string(port)));
    http::request<http::empty_body> req{http::verb::get, target, 11};
    req.set(http::field::host, host);
    http::write(stream, req);
    boost::beast::flat_buffer buffer;
    http::response<http::string_body> res;
    http::read(stream, buffer, res);
    return {int(res.result_int()), std::string(res[http::field::content_type]), res.body()};
}

// What the server answered to bytes written as they are.
struct RawExchange {
    // No value when the server closed (or timed out) without a whole response.
    std::optional<boost::beast::http::response<boost::beast::http::string_body>> response;
    std::string error;          // why there is no response
    bool closedAfter = false;   // the server closed the connection after a response without keep-alive
};

// Connect (from the local address `from` when given: 127.0.0.2, 127.0.0.3, ... are each
// another client to the server), write `bytes`, read one response and see whether the
// connection closes after it (within `timeout`).
inline RawExchange rawExchange(uint16_t port, const std::string &bytes,
                               std::chrono::milliseconds timeout = std::chrono::seconds(5), const std::string &from = {}) {
    namespace http = boost::beast::http;
    boost::asio::io_context ioc;
    boost::beast::tcp_stream stream(ioc);
    if (!from.empty()) {
        stream.socket().open(boost::asio::ip::tcp::v4());
        stream.socket().bind(boost::asio::ip::tcp::endpoint(boost::asio::ip::make_address(from), 0));
    }
    stream.connect(boost::asio::ip::tcp::endpoint(boost::asio::ip::make_address("127.0.0.1"), port));
    stream.expires_after(timeout);
    RawExchange out;
    boost::beast::error_code ec;
    boost::asio::write(stream, boost::asio::buffer(bytes), ec);
    // A write error (the server closed early) still leaves its answer to read.
    boost::beast::flat_buffer buffer;
    http::response_parser<http::string_body> parser;
    parser.body_limit(1 << 20);
    http::read(stream, buffer, parser, ec);
    if (ec) {
        out.error = ec.message();
        return out;
    }
    out.response = parser.release();
    // A kept-alive connection stays open: nothing to wait for.
    if (out.response->keep_alive()) return out;
    char byte = 0;
    stream.read_some(boost::asio::buffer(&byte, 1), ec);
    out.closedAfter = ec == boost::asio::error::eof || ec == boost::asio::error::connection_reset;
    return out;
}

} // namespace volcast::test
