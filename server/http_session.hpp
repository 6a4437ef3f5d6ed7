#pragma once
// One HTTP connection (Beast advanced_server's http_session): answers GET/HEAD for the
// health endpoints, the metrics and the static files, and hands a WebSocket upgrade on /ws
// to a WebsocketSession.

#include "server/shared_state.hpp"

#include <boost/beast/core.hpp>
#include <boost/beast/http.hpp>

#include <memory>
#include <optional>

namespace volcast::server {

class HttpSession : public std::enable_shared_from_this<HttpSession> {
  public:
    static constexpr const char *kWebSocketPath = "/ws";

    HttpSession(boost::asio::ip::tcp::socket &&socket, std::shared_ptr<SharedState> state);
    void run();

  private:
    void doRead();
    void onRead(boost::beast::error_code ec, size_t bytes);
    void onWrite(bool keepAlive, boost::beast::error_code ec, size_t bytes);

    boost::beast::tcp_stream stream_;
    boost::beast::flat_buffer buffer_;
    std::shared_ptr<SharedState> state_;
    std::optional<boost::beast::http::request_parser<boost::beast::http::string_body>> parser_;
};

} // namespace volcast::server
