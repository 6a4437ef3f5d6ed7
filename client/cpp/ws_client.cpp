#include "client/cpp/ws_client.hpp"

#include <boost/asio/connect.hpp>
#include <boost/asio/io_context.hpp>
#include <boost/asio/ip/tcp.hpp>
#include <boost/asio/post.hpp>
#include <boost/beast/core.hpp>
#include <boost/beast/websocket.hpp>

#include <condition_variable>
#include <deque>
#include <mutex>
#include <thread>

namespace volcast::client {

namespace beast = boost::beast;
namespace websocket = beast::websocket;
namespace net = boost::asio;
using tcp = net::ip::tcp;

struct Client::Impl {
    net::io_context ioc;
    websocket::stream<beast::tcp_stream> ws{ioc};
    beast::flat_buffer buffer;
    std::thread thread;

    // Network thread only.
    std::deque<std::pair<bool, std::string>> outgoing;   // (binary, bytes)
    bool writing = false;
    bool reading = false;

    mutable std::mutex mutex;
    std::condition_variable cv;
    std::deque<Message> received;
    bool paused = false;
    bool isClosed = false;
    std::optional<CloseInfo> close;

    void doRead() {
        {
            std::lock_guard lock(mutex);
            if (paused || isClosed || reading) return;
        }
        reading = true;
        ws.async_read(buffer, [this](beast::error_code ec, size_t) { onRead(ec); });
    }

    void onRead(beast::error_code ec) {
        reading = false;
        if (ec) {
            std::lock_guard lock(mutex);
            isClosed = true;
            if (ws.reason().code != websocket::close_code::none || ec == websocket::error::closed)
                close = CloseInfo{int(ws.reason().code), std::string(ws.reason().reason.c_str())};
            cv.notify_all();
            return;
        }
        Message m;
        m.received = std::chrono::steady_clock::now();
        const auto data = buffer.cdata();
        const auto *bytes = static_cast<const uint8_t *>(data.data());
        if (ws.got_text()) {
            m.text.assign(reinterpret_cast<const char *>(bytes), data.size());
            try {
                m.decoded = protocol::parseServerMessage(m.text);
            } catch (const std::exception &e) {
                m.decodeError = e.what();
            }
        } else if (protocol::isSliceMessage({bytes, data.size()})) {
            m.isSlice = true;
            try {
                auto s = protocol::decodeSlice({bytes, data.size()});
                m.sliceHeader = std::move(s.header);
                m.slicePixels.assign(s.pixels.begin(), s.pixels.end());
            } catch (const std::exception &e) {
                m.decodeError = e.what();
            }
        } else {
            m.isFrame = true;
            try {
                auto f = protocol::decodeFrame({bytes, data.size()});
                m.frame.header = std::move(f.header);
                m.frame.image.assign(f.image.begin(), f.image.end());
            } catch (const std::exception &e) {
                m.decodeError = e.what();
            }
            m.frame.messageBytes = data.size();
        }
        buffer.consume(buffer.size());
        {
            std::lock_guard lock(mutex);
            received.push_back(std::move(m));
        }
        cv.notify_all();
        doRead();
    }

    void queue(bool binary, std::string bytes) {
        net::post(ioc, [this, binary, bytes = std::move(bytes)]() mutable {
            outgoing.emplace_back(binary, std::move(bytes));
            doWrite();
        });
    }

    void doWrite() {
        if (writing || outgoing.empty()) return;
        writing = true;
        ws.binary(outgoing.front().first);
        ws.async_write(net::buffer(outgoing.front().second), [this](beast::error_code ec, size_t) {
            writing = false;
            outgoing.pop_front();
            if (!ec) doWrite();
        });
    }
};

Client::Client(const std::string &host, uint16_t port, const std::string &path, const std::string &origin,
               int receiveBufferBytes)
    : impl_(std::make_unique<Impl>()) {
    try {
        tcp::resolver resolver(impl_->ioc);
        auto &layer = beast::get_lowest_layer(impl_->ws);
        layer.expires_after(std::chrono::seconds(10));
        const auto endpoints = resolver.resolve(host, std::to_string(port));
        if (receiveBufferBytes > 0) {
            // One endpoint, opened here: connecting to a range would close and reopen the
            // socket, losing the option.
            const tcp::endpoint endpoint = *endpoints.begin();
            layer.socket().open(endpoint.protocol());
            layer.socket().set_option(net::socket_base::receive_buffer_size(receiveBufferBytes));
            layer.connect(endpoint);
        } else {
            layer.connect(endpoints);
        }
        layer.socket().set_option(tcp::no_delay(true));
        impl_->ws.set_option(websocket::stream_base::decorator([origin](websocket::request_type &req) {
            req.set(beast::http::field::user_agent, "volcast-client/0.1.0");
            if (!origin.empty()) req.set(beast::http::field::origin, origin);
        }));
        impl_->ws.handshake(host + ":" + std::to_string(port), path);
        layer.expires_never();
        impl_->ws.read_message_max(512u << 20);   // frames of large stills
    } catch (const std::exception &e) {
        throw std::runtime_error("connecting to ws://" + host + ":" + std::to_string(port) + path + ": " + e.what());
    }
    net::post(impl_->ioc, [this] { impl_->doRead(); });
    impl_->thread = std::thread([this] {
        auto guard = net::make_work_guard(impl_->ioc);
        impl_->ioc.run();
    });
}

Client::~Client() {
    if (!closed()) {
        try {
            close(std::chrono::milliseconds(500));
        } catch (...) {
        }
    }
    impl_->ioc.stop();
    if (impl_->thread.joinable()) impl_->thread.join();
}

void Client::send(const protocol::ClientMessage &message) { sendText(protocol::toJsonText(message)); }
void Client::sendText(std::string text) { impl_->queue(false, std::move(text)); }
void Client::sendBinary(std::vector<uint8_t> bytes) { impl_->queue(true, std::string(bytes.begin(), bytes.end())); }

std::optional<Message> Client::next(std::chrono::milliseconds timeout) {
    std::unique_lock lock(impl_->mutex);
    impl_->cv.wait_for(lock, timeout, [&] { return !impl_->received.empty() || impl_->isClosed; });
    if (impl_->received.empty()) return std::nullopt;
    Message m = std::move(impl_->received.front());
    impl_->received.pop_front();
    return m;
}

void Client::pauseReading() {
    std::lock_guard lock(impl_->mutex);
    impl_->paused = true;
}

void Client::resumeReading() {
    {
        std::lock_guard lock(impl_->mutex);
        impl_->paused = false;
    }
    net::post(impl_->ioc, [this] { impl_->doRead(); });
}

void Client::close(std::chrono::milliseconds timeout) {
    net::post(impl_->ioc, [this] {
        impl_->ws.async_close(websocket::close_code::normal, [](beast::error_code) {});
    });
    resumeReading();   // the server's close frame arrives through a read
    std::unique_lock lock(impl_->mutex);
    impl_->cv.wait_for(lock, timeout, [&] { return impl_->isClosed; });
}

bool Client::closed() const {
    std::lock_guard lock(impl_->mutex);
    return impl_->isClosed;
}

std::optional<CloseInfo> Client::closeInfo() const {
    std::lock_guard lock(impl_->mutex);
    return impl_->close;
}

Message waitForReply(Client &client, const nlohmann::json &id, std::chrono::milliseconds timeout,
                     std::vector<Message> *skipped) {
    const auto deadline = std::chrono::steady_clock::now() + timeout;
    for (;;) {
        const auto left = std::chrono::duration_cast<std::chrono::milliseconds>(deadline - std::chrono::steady_clock::now());
        auto m = client.next(std::max(left, std::chrono::milliseconds(0)));
        if (!m) throw std::runtime_error("no reply to request " + id.dump() + " in time");
        if (!m->isFrame && m->decoded) {
            const bool matches = std::visit(
                [&](const auto &msg) {
                    using T = std::decay_t<decltype(msg)>;
                    if constexpr (std::is_same_v<T, protocol::ProtocolError>) return msg.requestId == id;
                    else if constexpr (std::is_same_v<T, protocol::ProgressMessage>) return false;
                    else return msg.id == id;
                },
                *m->decoded);
            if (matches) return std::move(*m);
        }
        if (skipped) skipped->push_back(std::move(*m));
    }
}

} // namespace volcast::client
