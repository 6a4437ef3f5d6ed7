#include "server/listener.hpp"

#include <boost/asio/strand.hpp>
#include <spdlog/spdlog.h>

#include <algorithm>

namespace volcast::server {

namespace net = boost::asio;
using tcp = net::ip::tcp;

// ---- ConnectionLimiter ----------------------------------------------------------------

size_t ConnectionLimiter::count(Entry &e) {
    std::erase_if(e.websockets, [](const std::weak_ptr<void> &w) { return w.expired(); });
    return e.http + e.websockets.size();
}

std::shared_ptr<ConnectionSlot> ConnectionLimiter::acquire(const net::ip::address &address) {
    std::lock_guard lock(mutex_);
    Entry &e = entries_[address];
    if (perAddress_ > 0 && count(e) >= perAddress_) return nullptr;
    ++e.http;
    return std::make_shared<ConnectionSlot>(shared_from_this(), address);
}

size_t ConnectionLimiter::openFrom(const net::ip::address &address) {
    std::lock_guard lock(mutex_);
    const auto it = entries_.find(address);
    return it == entries_.end() ? 0 : count(it->second);
}

ConnectionSlot::~ConnectionSlot() {
    if (handedOff_) return;
    std::lock_guard lock(limiter_->mutex_);
    const auto it = limiter_->entries_.find(address_);
    if (it == limiter_->entries_.end()) return;
    --it->second.http;
    if (ConnectionLimiter::count(it->second) == 0) limiter_->entries_.erase(it);
}

void ConnectionSlot::handOff(std::weak_ptr<void> websocket) {
    std::lock_guard lock(limiter_->mutex_);
    ConnectionLimiter::Entry &e = limiter_->entries_[address_];
    --e.http;
    e.websockets.push_back(std::move(websocket));
    handedOff_ = true;
}

// ---- Listener -------------------------------------------------------------------------

Listener::Listener(net::io_context &ioc, tcp::endpoint endpoint, std::shared_ptr<SharedState> state,
                   std::shared_ptr<const HttpEndpoint> serves, std::shared_ptr<ConnectionLimiter> limiter)
    : ioc_(ioc), acceptor_(net::make_strand(ioc)), backoffTimer_(acceptor_.get_executor()), state_(std::move(state)),
      serves_(std::move(serves)), limiter_(std::move(limiter)) {
    acceptor_.open(endpoint.protocol());
    acceptor_.set_option(net::socket_base::reuse_address(true));
    acceptor_.bind(endpoint);
    acceptor_.listen(net::socket_base::max_listen_connections);
    port_ = acceptor_.local_endpoint().port();
}

void Listener::run() { doAccept(); }

void Listener::stop() {
    net::post(acceptor_.get_executor(), [self = shared_from_this()] {
        boost::system::error_code ignored;
        self->acceptor_.close(ignored);
        self->backoffTimer_.cancel();
    });
}

void Listener::doAccept() {
    acceptor_.async_accept(net::make_strand(ioc_), boost::beast::bind_front_handler(&Listener::onAccept, shared_from_this()));
}

void Listener::onAccept(boost::beast::error_code ec, tcp::socket socket) {
    if (ec == net::error::operation_aborted || !acceptor_.is_open()) return;
    if (ec) return onAcceptError(ec);
    backoff_ = std::chrono::milliseconds(0);
    boost::system::error_code endpointError;
    const auto remote = socket.remote_endpoint(endpointError);
    // Reset by the peer before we got to it: nothing to serve.
    if (endpointError) return doAccept();
    auto slot = limiter_->acquire(remote.address());
    if (!slot) {
        refuseOverCap(socket, remote.address());
        return doAccept();
    }
    boost::system::error_code ignored;
    socket.set_option(tcp::no_delay(true), ignored);
    std::make_shared<HttpSession>(boost::beast::tcp_stream(std::move(socket)), state_, serves_, std::move(slot))->run();
    doAccept();
}

void Listener::onAcceptError(boost::beast::error_code ec) {
    // Retrying at once would fail at once while the cause (most often EMFILE: the open-file
    // limit) lasts, spinning a core and flooding the log; the connection waits in the backlog.
    backoff_ = std::clamp(backoff_ * 2, kFirstBackoff, kMaxBackoff);
    const auto now = std::chrono::steady_clock::now();
    if (now - lastErrorLog_ >= kLogInterval) {
        spdlog::warn("accept on port {}: {} ({} more since the last report); retrying in {} ms", port_, ec.message(),
                     suppressedErrors_, backoff_.count());
        lastErrorLog_ = now;
        suppressedErrors_ = 0;
    } else {
        ++suppressedErrors_;
    }
    backoffTimer_.expires_after(backoff_);
    backoffTimer_.async_wait([self = shared_from_this()](boost::beast::error_code wec) {
        if (wec || !self->acceptor_.is_open()) return;
        self->doAccept();
    });
}

void Listener::refuseOverCap(tcp::socket &socket, const net::ip::address &address) {
    const auto now = std::chrono::steady_clock::now();
    if (now - lastCapLog_ >= kLogInterval) {
        spdlog::warn("refused a connection from {}: it has {} open (--max-connections-per-address; {} more refused "
                     "since the last report)",
                     address.to_string(), limiter_->perAddress(), suppressedCaps_);
        lastCapLog_ = now;
        suppressedCaps_ = 0;
    } else {
        ++suppressedCaps_;
    }
    // A fresh socket's send buffer takes these few bytes at once, so the answer costs no
    // session and no wait; whatever the client sent is left unread.
    static constexpr std::string_view kAnswer = "HTTP/1.1 503 Service Unavailable\r\n"
                                                "Content-Type: text/plain; charset=utf-8\r\n"
                                                "Retry-After: 5\r\n"
                                                "Connection: close\r\n"
                                                "Content-Length: 71\r\n"
                                                "\r\n"
                                                "too many connections from your address (--max-connections-per-address)\n";
    static_assert(kAnswer.size() - kAnswer.find("\r\n\r\n") - 4 == 71);
    boost::system::error_code ignored;
    socket.non_blocking(true, ignored);
    socket.write_some(net::buffer(kAnswer.data(), kAnswer.size()), ignored);
    socket.shutdown(tcp::socket::shutdown_both, ignored);
    socket.close(ignored);
}

} // namespace volcast::server
