#pragma once
// Accepts TCP connections (Beast advanced_server's listener); each gets its own strand,
// TCP_NODELAY (docs/platform.md: without it every frame waits ~40 ms for a delayed ACK) and an
// HttpSession.

#include "server/shared_state.hpp"

#include <boost/asio/ip/tcp.hpp>
#include <boost/beast/core.hpp>

#include <memory>

namespace volcast::server {

class Listener : public std::enable_shared_from_this<Listener> {
  public:
    // Binds and listens; throws boost::system::system_error naming the address on failure.
    Listener(boost::asio::io_context &ioc, boost::asio::ip::tcp::endpoint endpoint, std::shared_ptr<SharedState> state);
    void run();
    void stop();   // stop accepting
    uint16_t port() const { return port_; }

  private:
    void doAccept();
    void onAccept(boost::beast::error_code ec, boost::asio::ip::tcp::socket socket);

    boost::asio::io_context &ioc_;
    boost::asio::ip::tcp::acceptor acceptor_;
    std::shared_ptr<SharedState> state_;
    uint16_t port_ = 0;
};

} // namespace volcast::server
