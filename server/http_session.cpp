#include "server/http_session.hpp"

#include "server/listener.hpp"
#include "server/static_files.hpp"
#include "server/websocket_session.hpp"

#include <boost/asio/dispatch.hpp>
#include <boost/asio/ip/address.hpp>
#include <boost/beast/_experimental/test/stream.hpp>
#include <boost/beast/websocket.hpp>
#include <nlohmann/json.hpp>
#include <spdlog/fmt/fmt.h>
#include <spdlog/spdlog.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <filesystem>

namespace volcast::server {

namespace beast = boost::beast;
namespace http = beast::http;
namespace net = boost::asio;

namespace {
// From the end of the headers to the end of the body (at most kMaxRequestBodyBytes).
constexpr auto kBodyTimeout = std::chrono::seconds(30);
// After an answer that closes the connection, what the client still sends is read and
// dropped for this long (nginx's lingering close): closing with unread input would reset
// the connection, and the client could lose the answer before reading it.
constexpr auto kLingerTimeout = std::chrono::seconds(2);
constexpr size_t kLingerBytes = 1 << 20;
// Free room in the read buffer while an upload's body arrives. Beast reads into the buffer's
// free capacity (at least 512 bytes, at most 64 KiB a read): after a request head the buffer
// has only a few hundred bytes, so a body read 512 bytes at a time (a read, a file write and a
// timer re-arm each: ~50 MiB/s over loopback); with 64 KiB free every read takes Beast's most.
constexpr size_t kUploadReadBytes = 64 * 1024;

// Shown at / while web/ has no index.html yet.
constexpr const char *kFallbackPage = R"(<!doctype html>
<html><head><meta charset="utf-8"><title>volcast</title></head>
<body><h1>volcast server</h1>
<p>The browser client (web/index.html) is not installed in this server's web root.
The WebSocket endpoint is <code>/ws</code>; see protocol/README.md. Health: <a href="/healthz">/healthz</a>,
<a href="/readyz">/readyz</a>, <a href="/metrics">/metrics</a>.</p></body></html>
)";

template <class Body>
void common(http::response<Body> &res, bool keepAlive) {
    res.set(http::field::server, "volcast/0.1.0");
    res.set("X-Content-Type-Options", "nosniff");
    res.set(http::field::cache_control, "no-cache");
    res.keep_alive(keepAlive);
}

http::response<http::string_body> textResponse(unsigned version, bool head, bool keepAlive, http::status status,
                                               std::string body,
                                               std::string_view type = "text/plain; charset=utf-8") {
    http::response<http::string_body> res{status, version};
    common(res, keepAlive);
    res.set(http::field::content_type, type);
    const size_t size = body.size();
    if (!head) res.body() = std::move(body);
    res.prepare_payload();
    if (head) res.content_length(size);
    return res;
}

http::response<http::string_body> textResponse(const http::request<http::string_body> &req, http::status status,
                                               std::string body, std::string_view type = "text/plain; charset=utf-8") {
    return textResponse(req.version(), req.method() == http::verb::head, req.keep_alive(), status, std::move(body),
                        type);
}

std::string lower(std::string_view s) {
    std::string out(s);
    std::transform(out.begin(), out.end(), out.begin(), [](unsigned char c) { return char(std::tolower(c)); });
    return out;
}

// Printable for a log line or an answer: at most 200 characters, controls replaced.
std::string printable(std::string_view s) {
    std::string out(s.substr(0, 200));
    for (char &c : out)
        if ((unsigned char)c < 0x20 || (unsigned char)c == 0x7f) c = '?';
    if (s.size() > 200) out += "...";
    return out;
}

// One line for an answer: line breaks and other controls become spaces (a loader's message
// may quote several lines of a parser's).
std::string oneLine(std::string_view s) {
    std::string out(s);
    for (char &c : out)
        if ((unsigned char)c < 0x20 || (unsigned char)c == 0x7f) c = ' ';
    return out;
}

int hexDigit(char c) {
    if (c >= '0' && c <= '9') return c - '0';
    if (c >= 'a' && c <= 'f') return c - 'a' + 10;
    if (c >= 'A' && c <= 'F') return c - 'A' + 10;
    return -1;
}

// Constant-time, so that the token cannot be guessed a character at a time from timings.
bool sameSecret(std::string_view given, std::string_view token) {
    if (given.size() != token.size() || token.empty()) return false;
    unsigned char diff = 0;
    for (size_t i = 0; i < token.size(); ++i) diff |= (unsigned char)(given[i] ^ token[i]);
    return diff == 0;
}

bool bearerMatches(std::string_view authorization, std::string_view token) {
    constexpr std::string_view kScheme = "bearer ";
    if (authorization.size() < kScheme.size() || lower(authorization.substr(0, kScheme.size())) != kScheme)
        return false;
    auto given = authorization.substr(kScheme.size());
    while (!given.empty() && given.front() == ' ') given.remove_prefix(1);
    return sameSecret(given, token);
}

// Status for a request the parser refused; `unparsed` is what of it is still in the buffer.
std::pair<http::status, std::string> parseRefusal(beast::error_code ec, std::string_view unparsed) {
    if (ec == http::error::body_limit)
        return {http::status::payload_too_large,
                "request body over " + std::to_string(kMaxRequestBodyBytes) + " bytes\n"};
    if (ec == http::error::header_limit) {
        // The parser takes the request line and the headers as one block: a request line
        // that alone passes the target limit is a URI too long, anything else too many headers.
        const size_t lineEnd = std::min(unparsed.find("\r\n"), unparsed.size());
        if (lineEnd > kMaxTargetBytes)
            return {http::status::uri_too_long, "request target over " + std::to_string(kMaxTargetBytes) + " bytes\n"};
        return {http::status::request_header_fields_too_large,
                "request headers over " + std::to_string(kMaxHeaderBytes) + " bytes\n"};
    }
    return {http::status::bad_request, "malformed request: " + ec.message() + "\n"};
}
} // namespace

std::optional<std::string> hostName(std::string_view value) {
    while (!value.empty() && (value.front() == ' ' || value.front() == '\t')) value.remove_prefix(1);
    while (!value.empty() && (value.back() == ' ' || value.back() == '\t')) value.remove_suffix(1);
    std::string_view host = value, port;
    if (value.starts_with('[')) {
        const size_t close = value.find(']');
        if (close == std::string_view::npos) return std::nullopt;
        host = value.substr(0, close + 1);
        const auto rest = value.substr(close + 1);
        if (!rest.empty()) {
            if (rest.front() != ':') return std::nullopt;
            port = rest.substr(1);
        }
        boost::system::error_code ec;
        net::ip::make_address_v6(std::string(host.substr(1, host.size() - 2)), ec);
        if (ec) return std::nullopt;
    } else {
        const size_t colon = value.find(':');
        if (colon != std::string_view::npos) {
            // A second colon: an IPv6 address without brackets, or garbage.
            if (value.find(':', colon + 1) != std::string_view::npos) return std::nullopt;
            host = value.substr(0, colon);
            port = value.substr(colon + 1);
        }
        if (host.ends_with('.')) host.remove_suffix(1);
        if (host.empty()) return std::nullopt;
        for (const char c : host)
            if (!std::isalnum((unsigned char)c) && c != '-' && c != '.' && c != '_') return std::nullopt;
    }
    if (port.size() > 5 || !std::all_of(port.begin(), port.end(), [](unsigned char c) { return std::isdigit(c); }))
        return std::nullopt;
    return lower(host);
}

HttpEndpoint httpEndpointFor(const ServerConfig &config, std::string_view bindAddress, bool metricsOnly) {
    HttpEndpoint e;
    e.metricsOnly = metricsOnly;
    e.serveMetrics = metricsOnly || config.metricsBind.empty();
    if (!config.allowedHosts.empty()) {
        for (const auto &h : config.allowedHosts) {
            if (h == "*") return e.allowedHosts.clear(), e;
            // Given with a port or in upper case, it still names the same host.
            e.allowedHosts.push_back(hostName(h).value_or(lower(h)));
        }
        return e;
    }
    boost::system::error_code ec;
    const auto address = net::ip::make_address(std::string(bindAddress), ec);
    if (!ec && address.is_loopback()) e.allowedHosts = {"localhost", "127.0.0.1", "[::1]"};
    return e;
}

UploadName uploadNameOf(std::string_view target, std::string_view headerValue, bool headerPresent) {
    // The header is taken as it is: a browser sends the name's UTF-8 bytes there.
    if (headerPresent) return {std::string(headerValue), {}};
    const size_t q = target.find('?');
    if (q == std::string_view::npos) return {};
    std::string_view query = target.substr(q + 1);
    while (!query.empty()) {
        const size_t amp = query.find('&');
        const std::string_view pair = query.substr(0, amp);
        query = amp == std::string_view::npos ? std::string_view() : query.substr(amp + 1);
        if (!pair.starts_with("filename=")) continue;
        const std::string_view encoded = pair.substr(9);
        std::string name;
        for (size_t i = 0; i < encoded.size(); ++i) {
            if (encoded[i] == '+') {
                name += ' ';
            } else if (encoded[i] == '%') {
                const int hi = i + 2 < encoded.size() ? hexDigit(encoded[i + 1]) : -1;
                const int lo = i + 2 < encoded.size() ? hexDigit(encoded[i + 2]) : -1;
                if (hi < 0 || lo < 0) return {std::nullopt, "malformed ?filename=: bad percent-encoding"};
                name += char(hi * 16 + lo);
                i += 2;
            } else {
                name += encoded[i];
            }
        }
        return {std::move(name), {}};
    }
    return {};
}

template <class Stream>
BasicHttpSession<Stream>::BasicHttpSession(Stream &&stream, std::shared_ptr<SharedState> state,
                                           std::shared_ptr<const HttpEndpoint> endpoint,
                                           std::shared_ptr<ConnectionSlot> slot)
    : stream_(std::move(stream)), state_(std::move(state)), endpoint_(std::move(endpoint)), slot_(std::move(slot)) {}

template <class Stream>
void BasicHttpSession<Stream>::run() {
    net::dispatch(stream_.get_executor(), beast::bind_front_handler(&BasicHttpSession::doRead, this->shared_from_this()));
}

template <class Stream>
void BasicHttpSession<Stream>::doRead() {
    parser_.emplace();
    parser_->header_limit(uint32_t(kMaxHeaderBytes));
    // Set once the head says what the request is: an upload's limit is its own.
    parser_->body_limit(boost::none);
    // The headers must all be there in time (slowloris); also the keep-alive idle limit.
    if constexpr (std::is_same_v<Stream, beast::tcp_stream>)
        stream_.expires_after(std::chrono::milliseconds(state_->config().headerTimeoutMs));
    http::async_read_header(stream_, buffer_, *parser_,
                            beast::bind_front_handler(&BasicHttpSession::onHeader, this->shared_from_this()));
}

template <class Stream>
void BasicHttpSession<Stream>::onHeader(beast::error_code ec, size_t bytes) {
    if (ec) return onRead(ec, bytes);
    if (auto refusal = checkHeader()) {
        const auto &h = parser_->get();
        return refuse(refusal->first, std::move(refusal->second), h.version(), h.method() == http::verb::head);
    }
    {
        const auto &h = parser_->get();
        const std::string_view target = h.target();
        if (!endpoint_->metricsOnly && h.method() == http::verb::post &&
            target.substr(0, target.find('?')) == kUploadPath)
            return startUpload();
    }
    // Any other request carries a small body at most (only 405s carry one).
    if (const auto length = parser_->content_length(); length && *length > kMaxRequestBodyBytes)
        return refuse(http::status::payload_too_large,
                      "request body over " + std::to_string(kMaxRequestBodyBytes) + " bytes\n");
    parser_->body_limit(kMaxRequestBodyBytes);
    if (parser_->is_done()) return onRead({}, bytes);
    if constexpr (std::is_same_v<Stream, beast::tcp_stream>) stream_.expires_after(kBodyTimeout);
    http::async_read(stream_, buffer_, *parser_,
                     beast::bind_front_handler(&BasicHttpSession::onRead, this->shared_from_this()));
}

template <class Stream>
std::optional<std::pair<http::status, std::string>> BasicHttpSession<Stream>::checkHeader() const {
    const auto &req = parser_->get();
    if (req.target().size() > kMaxTargetBytes)
        return std::pair{http::status::uri_too_long, "request target over " + std::to_string(kMaxTargetBytes) + " bytes\n"};
    const auto hosts = req.count(http::field::host);
    if (hosts > 1) return std::pair{http::status::bad_request, std::string("more than one Host header\n")};
    if (hosts == 0) {
        // HTTP/1.1 requires it (RFC 9112 §3.2); an HTTP/1.0 client may not know it.
        if (req.version() >= 11) return std::pair{http::status::bad_request, std::string("no Host header\n")};
        return std::nullopt;
    }
    const auto value = req[http::field::host];
    const auto name = hostName(value);
    if (!name) return std::pair{http::status::bad_request, "malformed Host header: " + printable(value) + "\n"};
    const auto &allowed = endpoint_->allowedHosts;
    // A page that rebinds its own DNS name to this server's address sends that name.
    if (!allowed.empty() && std::find(allowed.begin(), allowed.end(), *name) == allowed.end())
        return std::pair{http::status::misdirected_request,
                         "host " + printable(*name) + " is not served here (server flag --allowed-host)\n"};
    return std::nullopt;
}

template <class Stream>
void BasicHttpSession<Stream>::onRead(beast::error_code ec, size_t) {
    if (ec == http::error::end_of_stream || ec == net::error::operation_aborted || ec == net::error::eof ||
        ec == net::error::connection_reset || ec == http::error::partial_message) {
        return doClose();
    }
    if (ec == beast::error::timeout) {
        // Idle between requests is a normal end; part of a request is a client too slow.
        if (parser_->got_some())
            spdlog::debug("http: closed a connection that sent part of a request for too long");
        return doClose();
    }
    if (ec) {
        const auto data = buffer_.data();
        auto [status, message] =
            parseRefusal(ec, std::string_view(static_cast<const char *>(data.data()), data.size()));
        spdlog::debug("http: refused a request ({}): {}", int(status), message);
        return refuse(status, std::move(message));
    }
    handle(parser_->release());
}

template <class Stream>
void BasicHttpSession<Stream>::handle(Request &&req) {
    const std::string target(req.target());
    const std::string path = target.substr(0, target.find('?'));

    if (endpoint_->metricsOnly && path != "/metrics" && path != "/healthz" && path != "/readyz") {
        auto res = textResponse(req, http::status::not_found,
                                "not found: " + printable(path) + " (this port serves /metrics, /healthz and /readyz)\n");
        if (beast::websocket::is_upgrade(req)) res.keep_alive(false);
        return send(std::move(res));
    }
    if (beast::websocket::is_upgrade(req)) {
        if (path != kWebSocketPath) {
            auto res = textResponse(req, http::status::not_found, "WebSocket sessions live at /ws\n");
            res.keep_alive(false);
            return send(std::move(res));
        }
        const std::string origin(req[http::field::origin]);
        if (!state_->originAllowed(origin)) {
            spdlog::warn("refused a WebSocket session from origin {}", printable(origin));
            state_->metrics().sessionRefused();
            auto res = textResponse(req, http::status::forbidden,
                                    "origin " + printable(origin) + " is not allowed (server flag --allowed-origin)\n");
            res.keep_alive(false);
            return send(std::move(res));
        }
        return handOff(std::move(req));
    }

    if (path == kUploadPath) {
        auto res = textResponse(req, http::status::method_not_allowed, "uploads are POST requests\n");
        res.set(http::field::allow, "POST");
        return send(std::move(res));
    }
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
    if (path == "/metrics" && endpoint_->serveMetrics) {
        // The metrics listener is the private alternative to the token; on the main port the
        // token guards them as it guards sessions.
        const std::string &token = state_->config().token;
        if (!endpoint_->metricsOnly && !token.empty() && !bearerMatches(req[http::field::authorization], token)) {
            auto res = textResponse(req, http::status::unauthorized,
                                    "/metrics needs the server's token: Authorization: Bearer <token>\n");
            res.set(http::field::www_authenticate, "Bearer realm=\"volcast\"");
            return send(std::move(res));
        }
        return send(textResponse(req, http::status::ok, state_->metrics().prometheusText(),
                                 "text/plain; version=0.0.4; charset=utf-8"));
    }

    const auto file = resolveStaticFile(state_->config().webRoot, target);
    if (!file) {
        if (path == "/" || path == "/index.html")
            return send(textResponse(req, http::status::ok, kFallbackPage, "text/html; charset=utf-8"));
        return send(textResponse(req, http::status::not_found, "not found: " + printable(path) + "\n"));
    }
    http::file_body::value_type body;
    beast::error_code fec;
    body.open(file->c_str(), beast::file_mode::scan, fec);
    if (fec) return send(textResponse(req, http::status::not_found, "not found: " + printable(path) + "\n"));
    const auto size = body.size();
    if (req.method() == http::verb::head) {
        http::response<http::empty_body> res{http::status::ok, req.version()};
        common(res, req.keep_alive());
        res.set(http::field::content_type, mimeType(*file));
        res.content_length(size);
        return send(std::move(res));
    }
    http::response<http::file_body> res{std::piecewise_construct, std::make_tuple(std::move(body)),
                                        std::make_tuple(http::status::ok, req.version())};
    common(res, req.keep_alive());
    res.set(http::field::content_type, mimeType(*file));
    res.content_length(size);
    send(std::move(res));
}

template <class Stream>
std::string BasicHttpSession<Stream>::peerAddress() const {
    if constexpr (std::is_same_v<Stream, beast::tcp_stream>) {
        beast::error_code ec;
        const auto endpoint = stream_.socket().remote_endpoint(ec);
        if (!ec) return endpoint.address().to_string();
    }
    return "unknown";
}

template <class Stream>
void BasicHttpSession<Stream>::startUpload() {
    const auto &req = parser_->get();
    const unsigned version = req.version();
    const std::string &token = state_->config().token;
    if (!token.empty() && !bearerMatches(req[http::field::authorization], token)) {
        auto res = textResponse(version, false, false, http::status::unauthorized,
                                "uploads need the server's token: Authorization: Bearer <token>\n");
        res.set(http::field::www_authenticate, "Bearer realm=\"volcast\"");
        return send(std::move(res));
    }
    const auto header = req.find("X-Volcast-Filename");
    const bool named = header != req.end();
    const UploadName given = uploadNameOf(req.target(), named ? std::string_view(header->value()) : std::string_view(),
                                          named);
    if (!given.error.empty()) return refuse(http::status::bad_request, given.error + "\n", version);
    if (!given.name)
        return refuse(http::status::bad_request,
                      "no file name: send it in the X-Volcast-Filename header or as ?filename=\n", version);
    const std::string &name = *given.name;
    if (const auto problem = uploadFilenameProblem(name))
        return refuse(http::status::bad_request, *problem + "\n", version);
    // Checked UTF-8 without controls above: quoting it whole is safe.
    if (!uploadExtension(name))
        return refuse(http::status::unsupported_media_type,
                      "unsupported file type \"" + name +
                          "\": upload .nrrd, .nii, .nii.gz, .mha or .zip (a DICOM series)\n",
                      version);
    UploadStore &store = state_->uploads();
    const uint64_t limit = store.maxUploadBytes();
    const std::optional<uint64_t> length =
        parser_->content_length() ? std::optional<uint64_t>(*parser_->content_length()) : std::nullopt;
    const bool chunked = parser_->chunked();
    // Refused from the head alone: not a byte of such a body is read.
    if (length && *length > limit)
        return refuse(http::status::payload_too_large,
                      fmt::format("upload of {} bytes is over the limit of {} MiB (server flag --max-upload-mib)\n",
                                  *length, limit >> 20),
                      version);
    if (!chunked && length.value_or(0) == 0)
        return refuse(http::status::bad_request, "the upload is empty: send the file as the request body\n", version);
    auto begun = store.begin(ClientIdentity::ofAddress(peerAddress()), name, chunked ? std::optional<uint64_t>() : length);
    if (const auto *refusal = std::get_if<UploadRefusal>(&begun))
        return refuse(http::status(refusal->status), oneLine(refusal->message) + "\n", version);
    pendingUpload_ = std::get<std::shared_ptr<UploadStore::Pending>>(std::move(begun));
    const bool expectContinue = beast::iequals(req[http::field::expect], "100-continue");

    upload_.emplace(std::move(*parser_));
    upload_->body_limit(limit);
    buffer_.reserve(buffer_.size() + kUploadReadBytes);
    beast::error_code fec;
    upload_->get().body().open(pendingUpload_->file().c_str(), beast::file_mode::write_new, fec);
    if (fec) {
        spdlog::error("uploads: cannot write {}: {}", pendingUpload_->file().string(), fec.message());
        pendingUpload_.reset();
        return refuse(http::status::internal_server_error, "cannot store the upload\n", version);
    }
    readingBody_ = true;
    ++uploadRound_;
    if (expectContinue) {
        // curl asks before sending a body over 1 MiB, and waits a second for this otherwise.
        auto res = std::make_shared<http::response<http::empty_body>>(http::status::continue_, version);
        http::async_write(stream_, *res, [self = this->shared_from_this(), res](beast::error_code ec, size_t) {
            if (ec) return self->doClose();
            self->readUploadBody();
        });
        return;
    }
    readUploadBody();
}

template <class Stream>
void BasicHttpSession<Stream>::readUploadBody() {
    if constexpr (std::is_same_v<Stream, beast::tcp_stream>) {
        // The stream's own timeout would close the socket, leaving no way to answer: a timer
        // of ours cancels the read instead, and the answer is a 408.
        stream_.expires_never();
        if (!silence_) silence_.emplace(stream_.get_executor());
        if (windowRound_ != uploadRound_) {
            // Started with the body's first read (after a 100 Continue), once per upload.
            windowRound_ = uploadRound_;
            if (!rateWindow_) rateWindow_.emplace(stream_.get_executor());
            windowBytes_ = 0;
            armRateWindow(uploadRound_);
        }
        silence_->expires_after(std::chrono::milliseconds(state_->config().headerTimeoutMs));
        silence_->async_wait([self = this->shared_from_this()](beast::error_code ec) {
            if (ec) return;
            self->silent_ = true;
            beast::error_code ignored;
            self->stream_.socket().cancel(ignored);
        });
    }
    http::async_read_some(stream_, buffer_, *upload_,
                          beast::bind_front_handler(&BasicHttpSession::onUploadBody, this->shared_from_this()));
}

template <class Stream>
void BasicHttpSession<Stream>::armRateWindow(uint64_t round) {
    const ServerConfig &config = state_->config();
    rateWindow_->expires_after(
        std::chrono::duration_cast<std::chrono::steady_clock::duration>(std::chrono::duration<double>(config.uploadRateWindowS)));
    rateWindow_->async_wait([self = this->shared_from_this(), round](beast::error_code ec) {
        if (ec || !self->readingBody_ || round != self->uploadRound_) return;
        const ServerConfig &c = self->state_->config();
        if (double(self->windowBytes_) < c.uploadMinBytesPerS * c.uploadRateWindowS) {
            // As for silence: the read is cancelled, and its handler answers 408.
            self->tooSlow_ = true;
            if constexpr (std::is_same_v<Stream, beast::tcp_stream>) {
                beast::error_code ignored;
                self->stream_.socket().cancel(ignored);
            }
            return;
        }
        self->windowBytes_ = 0;
        self->armRateWindow(round);
    });
}

template <class Stream>
void BasicHttpSession<Stream>::endUploadBody() {
    readingBody_ = false;
    if (silence_) silence_->cancel();
    if (rateWindow_) rateWindow_->cancel();
}

template <class Stream>
void BasicHttpSession<Stream>::onUploadBody(beast::error_code ec, size_t bytes) {
    if (silence_) silence_->cancel();
    windowBytes_ += bytes;
    const unsigned version = upload_->get().version();
    if (silent_) {
        endUploadBody();
        pendingUpload_.reset();
        return refuse(http::status::request_timeout,
                      fmt::format("the upload stopped arriving: no bytes for {} ms (server flag --header-timeout-ms)\n",
                                  state_->config().headerTimeoutMs),
                      version);
    }
    if (tooSlow_) {
        endUploadBody();
        pendingUpload_.reset();
        const ServerConfig &c = state_->config();
        return refuse(http::status::request_timeout,
                      fmt::format("the upload arrived too slowly: {} bytes in {:g} s, under the minimum of {:g} bytes "
                                  "per second (server flags --upload-min-bytes-per-s, --upload-rate-window-s)\n",
                                  windowBytes_, c.uploadRateWindowS, c.uploadMinBytesPerS),
                      version);
    }
    if (ec) endUploadBody();
    if (ec == http::error::body_limit) {
        pendingUpload_.reset();
        return refuse(http::status::payload_too_large,
                      fmt::format("upload over the limit of {} MiB (server flag --max-upload-mib)\n",
                                  state_->uploads().maxUploadBytes() >> 20),
                      version);
    }
    if (ec == http::error::end_of_stream || ec == http::error::partial_message || ec == net::error::eof ||
        ec == net::error::connection_reset || ec == net::error::operation_aborted) {
        // The client went away: the part it sent is deleted with the pending upload.
        pendingUpload_.reset();
        return doClose();
    }
    if (ec) {
        pendingUpload_.reset();
        return refuse(http::status::bad_request, "malformed upload body: " + ec.message() + "\n", version);
    }
    // What reached the file counts against the storage now, however the body is framed.
    beast::error_code sizeError;
    const uint64_t written = upload_->get().body().file().size(sizeError);
    if (!sizeError) {
        if (const auto refusal = state_->uploads().reserve(*pendingUpload_, written)) {
            endUploadBody();
            upload_->get().body().close();
            pendingUpload_.reset();   // the part written is deleted with it
            return refuse(http::status(refusal->status), oneLine(refusal->message) + "\n", version);
        }
    }
    if (!upload_->is_done()) return readUploadBody();
    endUploadBody();
    upload_->get().body().close();
    // The connection may stay open for more requests: the upload's read room goes back.
    buffer_.shrink_to_fit();
    if (!sizeError && written == 0) {
        // A chunked body of no chunks (a Content-Length of 0 is refused from the head).
        pendingUpload_.reset();
        return refuse(http::status::bad_request, "the upload is empty: send the file as the request body\n", version);
    }
    // The answer comes back to this connection's strand; the parse never runs on a network thread.
    // The callback moves its hold on this session into the posted handler: the store's worker
    // must not drop the last reference, which could take the whole server state with it on
    // the worker itself (whose destructor joins that very thread).
    state_->uploads().finish(std::move(pendingUpload_), sizeError ? 0 : written,
                             [self = this->shared_from_this()](UploadStore::Result result) mutable {
                                 auto executor = self->stream_.get_executor();
                                 net::post(executor, [self = std::move(self), result = std::move(result)]() mutable {
                                     self->onUploadChecked(std::move(result));
                                 });
                             });
}

template <class Stream>
void BasicHttpSession<Stream>::onUploadChecked(UploadStore::Result result) {
    const auto &req = upload_->get();
    const unsigned version = req.version();
    const bool keepAlive = req.keep_alive();
    upload_.reset();
    if (const auto *accepted = std::get_if<UploadStore::Accepted>(&result)) {
        const nlohmann::json body = {{"volume", accepted->volume},
                                     {"filename", accepted->filename},
                                     {"bytes", accepted->bytes},
                                     {"expires_in_s", std::lround(accepted->expiresInSeconds)},
                                     {"dims", accepted->dims},
                                     {"voxel_type", accepted->voxelType}};
        return send(textResponse(version, false, keepAlive, http::status::created,
                                 body.dump(-1, ' ', false, nlohmann::json::error_handler_t::replace) + "\n",
                                 "application/json"));
    }
    const auto &refusal = std::get<UploadRefusal>(result);
    send(textResponse(version, false, keepAlive, http::status(refusal.status), oneLine(refusal.message) + "\n"));
}

template <class Stream>
void BasicHttpSession<Stream>::handOff(Request &&req) {
    if constexpr (std::is_same_v<Stream, beast::tcp_stream>) {
        // The WebSocket session takes the socket; its own timeouts replace the HTTP ones.
        stream_.expires_never();
        auto session = std::make_shared<WebsocketSession>(stream_.release_socket(), state_);
        if (slot_) slot_->handOff(session);
        session->run(std::move(req));
    } else {
        // Only a socket can carry a WebsocketSession.
        auto res = textResponse(req, http::status::not_implemented, "no WebSocket over this stream\n");
        res.keep_alive(false);
        send(std::move(res));
    }
}

template <class Stream>
void BasicHttpSession<Stream>::refuse(http::status status, std::string message, unsigned version, bool head) {
    send(textResponse(version, head, false, status, std::move(message)));
}

template <class Stream>
template <class Response>
void BasicHttpSession<Stream>::send(Response &&res) {
    // The response lives until its write completes: the write only refers to it.
    auto sp = std::make_shared<std::decay_t<Response>>(std::forward<Response>(res));
    const bool keepAlive = sp->keep_alive();
    if constexpr (std::is_same_v<Stream, beast::tcp_stream>) stream_.expires_after(kBodyTimeout);
    http::async_write(stream_, *sp, [self = this->shared_from_this(), sp, keepAlive](beast::error_code ec, size_t bytes) {
        self->onWrite(keepAlive, ec, bytes);
    });
}

template <class Stream>
void BasicHttpSession<Stream>::onWrite(bool keepAlive, beast::error_code ec, size_t) {
    if (ec) return;
    if (!keepAlive) return doClose();
    doRead();
}

template <class Stream>
void BasicHttpSession<Stream>::doClose() {
    beast::error_code ignored;
    if constexpr (std::is_same_v<Stream, beast::tcp_stream>) {
        stream_.socket().shutdown(net::ip::tcp::socket::shutdown_send, ignored);
        stream_.expires_after(kLingerTimeout);
        stream_.async_read_some(net::buffer(drain_),
                                beast::bind_front_handler(&BasicHttpSession::onDrain, this->shared_from_this()));
    } else {
        stream_.close();
    }
}

template <class Stream>
void BasicHttpSession<Stream>::onDrain(beast::error_code ec, size_t bytes) {
    drained_ += bytes;
    // Ends on the client's close, an error, the linger timeout or enough bytes dropped;
    // the socket closes with the last reference to this session.
    if (ec || drained_ >= kLingerBytes) return;
    stream_.async_read_some(net::buffer(drain_),
                            beast::bind_front_handler(&BasicHttpSession::onDrain, this->shared_from_this()));
}

template class BasicHttpSession<beast::tcp_stream>;
template class BasicHttpSession<beast::test::stream>;

} // namespace volcast::server
