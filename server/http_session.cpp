#include "server/http_session.hpp"

#include "server/static_files.hpp"
#include "server/websocket_session.hpp"

#include <boost/asio/dispatch.hpp>
#include <boost/beast/websocket.hpp>
#include <spdlog/spdlog.h>

#include <chrono>

namespace volcast::server {

namespace beast = boost::beast;
namespace http = beast::http;
namespace net = boost::asio;

namespace {
constexpr auto kReadTimeout = std::chrono::seconds(30);
constexpr size_t kMaxRequestBodyBytes = 64 * 1024;

// Shown at / while web/ has no index.html yet.
constexpr const char *kFallbackPage = R"(<!doctype html>
<html><head><meta charset="utf-8"><title>volcast</title></head>
<body><h1>volcast server</h1>
<p>The browser client (web/index.html) is not installed in this server's web root.
The WebSocket endpoint is <code>/ws</code>; see protocol/README.md. Health: <a href="/healthz">/healthz</a>,
<a href="/readyz">/readyz</a>, <a href="/metrics">/metrics</a>.</p></body></html>
)";

template <class Body>
void common(http::response<Body> &res, const http::request<http::string_body> &req) {
    res.set(http::field::server, "volcast/0.1.0");
    res.set("X-Content-Type-Options", "nosniff");
    res.set(http::field::cache_control, "no-cache");
    res.keep_alive(req.keep_alive());
}

http::response<http::string_body> textResponse(const http::request<http::string_body> &req, http::status status,
                                               std::string body, std::string_view type = "text/plain; charset=utf-8") {
    http::response<http::string_body> res{status, req.version()};
    common(res, req);
    res.set(http::field::content_type, type);
    res.body() = req.method() == http::verb::head ? std::string() : std::move(body);
    res.prepare_payload();
    if (req.method() == http::verb::head) res.content_length(body.size());
    return res;
}
} // namespace

HttpSession::HttpSession(net::ip::tcp::socket &&socket, std::shared_ptr<SharedState> state)
    : stream_(std::move(socket)), state_(std::move(state)) {}

void HttpSession::run() {
    net::dispatch(stream_.get_executor(), beast::bind_front_handler(&HttpSession::doRead, shared_from_this()));
}

void HttpSession::doRead() {
    parser_.emplace();
    parser_->body_limit(kMaxRequestBodyBytes);
    stream_.expires_after(kReadTimeout);
    http::async_read(stream_, buffer_, *parser_, beast::bind_front_handler(&HttpSession::onRead, shared_from_this()));
}

void HttpSession::onRead(beast::error_code ec, size_t) {
    if (ec == http::error::end_of_stream || ec == beast::error::timeout || ec == net::error::operation_aborted) {
        beast::error_code ignored;
        stream_.socket().shutdown(net::ip::tcp::socket::shutdown_send, ignored);
        return;
    }
    if (ec) {
        spdlog::debug("http read: {}", ec.message());
        return;
    }
    http::request<http::string_body> req = parser_->release();
    const std::string target(req.target());
    const std::string path = target.substr(0, target.find('?'));

    if (beast::websocket::is_upgrade(req)) {
        if (path != kWebSocketPath) {
            auto res = textResponse(req, http::status::not_found, "WebSocket sessions live at /ws\n");
            res.keep_alive(false);
            return http::async_write(stream_, std::move(res), [self = shared_from_this()](beast::error_code, size_t) {});
        }
        const std::string origin(req[http::field::origin]);
        if (!state_->originAllowed(origin)) {
            spdlog::warn("refused a WebSocket session from origin {}", origin);
            state_->metrics().sessionRefused();
            auto res = textResponse(req, http::status::forbidden,
                                    "origin " + origin + " is not allowed (server flag --allowed-origin)\n");
            res.keep_alive(false);
            return http::async_write(stream_, std::move(res), [self = shared_from_this()](beast::error_code, size_t) {});
        }
        // The WebSocket session takes the socket; its own timeouts replace the HTTP one.
        stream_.expires_never();
        std::make_shared<WebsocketSession>(stream_.release_socket(), state_)->run(std::move(req));
        return;
    }

    auto send = [this](auto &&res) {
        using Response = std::decay_t<decltype(res)>;
        auto sp = std::make_shared<Response>(std::forward<decltype(res)>(res));
        const bool keepAlive = sp->keep_alive();
        http::async_write(stream_, *sp,
                          [self = shared_from_this(), sp, keepAlive](beast::error_code wec, size_t bytes) {
                              self->onWrite(keepAlive, wec, bytes);
                          });
    };

    if (req.method() != http::verb::get && req.method() != http::verb::head) {
        auto res = textResponse(req, http::status::method_not_allowed, "only GET and HEAD\n");
        res.set(http::field::allow, "GET, HEAD");
        return send(std::move(res));
    }
    if (path == "/healthz") return send(textResponse(req, http::status::ok, "ok\n"));
    if (path == "/readyz") {
        const std::string why = state_->notReadyReason();
        return send(why.empty() ? textResponse(req, http::status::ok, "ready\n")
                                : textResponse(req, http::status::service_unavailable, "not ready: " + why + "\n"));
    }
    if (path == "/metrics")
        return send(textResponse(req, http::status::ok, state_->metrics().prometheusText(),
                                 "text/plain; version=0.0.4; charset=utf-8"));

    const auto file = resolveStaticFile(state_->config().webRoot, target);
    if (!file) {
        if (path == "/" || path == "/index.html")
            return send(textResponse(req, http::status::ok, kFallbackPage, "text/html; charset=utf-8"));
        return send(textResponse(req, http::status::not_found, "not found: " + path + "\n"));
    }
    http::file_body::value_type body;
    beast::error_code fec;
    body.open(file->c_str(), beast::file_mode::scan, fec);
    if (fec) return send(textResponse(req, http::status::not_found, "not found: " + path + "\n"));
    const auto size = body.size();
    if (req.method() == http::verb::head) {
        http::response<http::empty_body> res{http::status::ok, req.version()};
        common(res, req);
        res.set(http::field::content_type, mimeType(*file));
        res.content_length(size);
        return send(std::move(res));
    }
    http::response<http::file_body> res{std::piecewise_construct, std::make_tuple(std::move(body)),
                                        std::make_tuple(http::status::ok, req.version())};
    common(res, req);
    res.set(http::field::content_type, mimeType(*file));
    res.content_length(size);
    send(std::move(res));
}

void HttpSession::onWrite(bool keepAlive, beast::error_code ec, size_t) {
    if (ec) return;
    if (!keepAlive) {
        beast::error_code ignored;
        stream_.socket().shutdown(net::ip::tcp::socket::shutdown_send, ignored);
        return;
    }
    doRead();
}

} // namespace volcast::server
