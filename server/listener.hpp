#pragma once
// Accepts TCP connections (Beast advanced_server's listener); each gets its own strand,
// TCP_NODELAY (PLATFORM.md: without it every frame waits ~40 ms for a delayed ACK) and an
// HttpSession, unless its address already has its cap of connections open. An accept error
// (EMFILE when the open-file limit is reached) backs off instead of retrying at once, and its
// log line is rate-limited.

#include "server/http_session.hpp"
#include "server/shared_state.hpp"

#include <boost/asio/ip/tcp.hpp>
#include <boost/asio/steady_timer.hpp>
#include <boost/beast/core.hpp>

#include <chrono>
#include <map>
#include <memory>
#include <mutex>
#include <vector>

namespace volcast::server {

// Open connections per remote IP address, HTTP and WebSocket alike, shared by all listeners.
class ConnectionLimiter : public std::enable_shared_from_this<ConnectionLimiter> {
  public:
    explicit ConnectionLimiter(size_t perAddress) : perAddress_(perAddress) {}   // 0: no cap
    // A slot for one more connection from `address`, or nullptr when it has its cap open.
    std::shared_ptr<ConnectionSlot> acquire(const boost::asio::ip::address &address);
    size_t openFrom(const boost::asio::ip::address &address);
    size_t perAddress() const { return perAddress_; }

  private:
    friend class ConnectionSlot;
    struct Entry {
        size_t http = 0;                                  // HTTP connections (their slots)
        std::vector<std::weak_ptr<void>> websockets;      // sessions the HTTP connections became
    };
    // Open connections of `e`, forgetting WebSocket sessions that have ended.
    static size_t count(Entry &e);

    const size_t perAddress_;
    std::mutex mutex_;
    std::map<boost::asio::ip::address, Entry> entries_;
};

// One connection counted by a ConnectionLimiter; released when destroyed, unless handed off
// to a WebSocket session, which then counts for as long as it exists.
class ConnectionSlot {
  public:
    ConnectionSlot(std::shared_ptr<ConnectionLimiter> limiter, boost::asio::ip::address address)
        : limiter_(std::move(limiter)), address_(std::move(address)) {}
    ~ConnectionSlot();
    ConnectionSlot(const ConnectionSlot &) = delete;
    ConnectionSlot &operator=(const ConnectionSlot &) = delete;
    void handOff(std::weak_ptr<void> websocket);

  private:
    std::shared_ptr<ConnectionLimiter> limiter_;
    boost::asio::ip::address address_;
    bool handedOff_ = false;
};

class Listener : public std::enable_shared_from_this<Listener> {
  public:
    // Binds and listens; throws boost::system::system_error naming the address on failure.
    Listener(boost::asio::io_context &ioc, boost::asio::ip::tcp::endpoint endpoint, std::shared_ptr<SharedState> state,
             std::shared_ptr<const HttpEndpoint> serves, std::shared_ptr<ConnectionLimiter> limiter);
    void run();
    void stop();   // stop accepting
    uint16_t port() const { return port_; }

    // Accept-error back-off: the first retry after kFirstBackoff, doubling up to kMaxBackoff,
    // back to none after a success. One log line a second at most.
    static constexpr std::chrono::milliseconds kFirstBackoff{50};
    static constexpr std::chrono::milliseconds kMaxBackoff{1000};
    static constexpr std::chrono::milliseconds kLogInterval{1000};

  private:
    void doAccept();
    void onAccept(boost::beast::error_code ec, boost::asio::ip::tcp::socket socket);
    void onAcceptError(boost::beast::error_code ec);
    void refuseOverCap(boost::asio::ip::tcp::socket &socket, const boost::asio::ip::address &address);

    boost::asio::io_context &ioc_;
    boost::asio::ip::tcp::acceptor acceptor_;
    boost::asio::steady_timer backoffTimer_;
    std::shared_ptr<SharedState> state_;
    std::shared_ptr<const HttpEndpoint> serves_;
    std::shared_ptr<ConnectionLimiter> limiter_;
    uint16_t port_ = 0;
    std::chrono::milliseconds backoff_{0};
    std::chrono::steady_clock::time_point lastErrorLog_{};
    size_t suppressedErrors_ = 0;
    std::chrono::steady_clock::time_point lastCapLog_{};
    size_t suppressedCaps_ = 0;
};

} // namespace volcast::server
