#pragma once
// A C++ client for volcast's WebSocket protocol, for scripts and the integration tests:
// connect, send requests, and take what the server sends (text messages decoded with
// protocol/, frames decoded into header and image) from a queue, with a timeout.
//
// A network thread of its own runs the socket; the caller's thread only queues sends and
// waits on received messages, so a test can stop reading (pauseReading) to play a slow
// client while the server keeps writing. Lives outside protocol/ so that the message
// code there stays free of networking.

#include "protocol/protocol.hpp"

#include <chrono>
#include <cstdint>
#include <memory>
#include <optional>
#include <string>
#include <vector>

namespace volcast::client {

struct Frame {
    protocol::FrameHeader header;
    std::vector<uint8_t> image;   // the encoded image (JPEG or PNG)
    size_t messageBytes = 0;      // the whole binary message
};

struct Message {
    std::chrono::steady_clock::time_point received;
    bool isFrame = false;
    std::string text;                                  // a text message as received
    std::optional<protocol::ServerMessage> decoded;    // text: nullopt if it did not decode
    std::string decodeError;
    Frame frame;                                       // isFrame
    // A slice message (VCS1, the answer to a `slice` request); isFrame stays false.
    bool isSlice = false;
    protocol::SliceHeader sliceHeader;
    std::vector<uint8_t> slicePixels;                  // width x height bytes of 8-bit grey
};

struct CloseInfo {
    int code = 0;          // WebSocket close code (1000 normal, 1001 going away, ...)
    std::string reason;
};

class Client {
  public:
    // Connects and completes the WebSocket handshake; throws std::runtime_error naming the
    // host, port and what failed. `origin` is sent as the Origin header when not empty.
    // `receiveBufferBytes` > 0 caps the socket's receive buffer (SO_RCVBUF, set before the
    // connection, so that the window the kernel offers stays that small): a paused client then
    // backs the server's writes up after that much, as a slow link would, instead of after the
    // megabytes loopback buffers grow to.
    Client(const std::string &host, uint16_t port, const std::string &path = "/ws", const std::string &origin = "",
           int receiveBufferBytes = 0);
    ~Client();
    Client(const Client &) = delete;
    Client &operator=(const Client &) = delete;

    void send(const protocol::ClientMessage &message);
    void sendText(std::string text);
    void sendBinary(std::vector<uint8_t> bytes);

    // The next message, or nullopt after `timeout` or once the connection is closed and drained.
    std::optional<Message> next(std::chrono::milliseconds timeout);
    // Stop reading from the socket (the server's writes then back up), and start again.
    void pauseReading();
    void resumeReading();

    // Close with 1000 and wait (up to timeout) for the server's close.
    void close(std::chrono::milliseconds timeout = std::chrono::milliseconds(2000));
    bool closed() const;
    // How the server closed the connection, once it did.
    std::optional<CloseInfo> closeInfo() const;

  private:
    struct Impl;
    std::unique_ptr<Impl> impl_;
};

// Convenience for scripts: wait for the text reply whose id is `id` (an error reply too),
// keeping every other message in `skipped` when given. Throws std::runtime_error on timeout.
Message waitForReply(Client &client, const nlohmann::json &id, std::chrono::milliseconds timeout,
                     std::vector<Message> *skipped = nullptr);

} // namespace volcast::client
