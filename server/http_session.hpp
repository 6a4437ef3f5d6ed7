#pragma once
// One HTTP connection (Beast advanced_server's http_session): answers GET/HEAD for the
// health endpoints, the metrics and the static files, takes uploads (POST /api/volumes,
// UploadStore), and hands a WebSocket upgrade on /ws to a WebsocketSession. Every bad request
// gets its status (400, 405, 413, 414, 421, 431) with a line saying what was wrong, then the
// connection closes.
//
// Generic over its stream so that a fuzz target can drive it with beast::test::stream; the
// server uses HttpSession (a tcp_stream). Only a tcp_stream has timeouts and can become a
// WebSocket: over any other stream an upgrade that passes every check is answered 501, so
// the refusals (404, 403) stay reachable without a socket.

#include "server/shared_state.hpp"
#include "server/upload_store.hpp"

#include <boost/asio/steady_timer.hpp>
#include <boost/beast/core.hpp>
#include <boost/beast/http.hpp>

#include <array>
#include <memory>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

namespace volcast::server {

class ConnectionSlot;

// What one listening address serves.
struct HttpEndpoint {
    // The --metrics-bind listener: /metrics, /healthz and /readyz only, /metrics without the token.
    bool metricsOnly = false;
    // False on the main port once a metrics listener exists.
    bool serveMetrics = true;
    // Host names (lower case, no port) accepted; empty: any.
    std::vector<std::string> allowedHosts;
};

// The endpoint a listener bound to `bindAddress` serves: config.allowedHosts, or by default
// only loopback names on a loopback address (DNS rebinding) and any name otherwise.
HttpEndpoint httpEndpointFor(const ServerConfig &config, std::string_view bindAddress, bool metricsOnly);

// The host name of a Host header value, lower case, without port or trailing dot
// ("[::1]" keeps its brackets); nullopt when the value is not a valid host[:port].
std::optional<std::string> hostName(std::string_view hostHeader);

// Request limits, as nginx's defaults order them (large_client_header_buffers 8k for a
// request line, 16 KiB for all headers, a small body: only 405s carry one).
inline constexpr size_t kMaxTargetBytes = 8 * 1024;
inline constexpr size_t kMaxHeaderBytes = 16 * 1024;
inline constexpr size_t kMaxRequestBodyBytes = 64 * 1024;

// Uploads: POST here, the file as the body (server/README.md, "HTTP").
inline constexpr const char *kUploadPath = "/api/volumes";
// The upload's file name: the X-Volcast-Filename header as it is, else `?filename=`
// percent-decoded; nullopt when neither is there; an error message for a bad encoding.
struct UploadName {
    std::optional<std::string> name;
    std::string error;
};
UploadName uploadNameOf(std::string_view target, std::string_view headerValue, bool headerPresent);

template <class Stream>
class BasicHttpSession : public std::enable_shared_from_this<BasicHttpSession<Stream>> {
  public:
    static constexpr const char *kWebSocketPath = "/ws";

    // `slot` counts this connection against its address's cap (none for a fuzzed stream).
    BasicHttpSession(Stream &&stream, std::shared_ptr<SharedState> state, std::shared_ptr<const HttpEndpoint> endpoint,
                     std::shared_ptr<ConnectionSlot> slot = nullptr);
    void run();

  private:
    using Request = boost::beast::http::request<boost::beast::http::string_body>;

    void doRead();
    void onHeader(boost::beast::error_code ec, size_t bytes);
    void onRead(boost::beast::error_code ec, size_t bytes);
    void handle(Request &&req);
    void handOff(Request &&req);
    // Answer with `status` and `message`, then close.
    void refuse(boost::beast::http::status status, std::string message, unsigned version = 11, bool head = false);
    template <class Response>
    void send(Response &&res);
    void onWrite(bool keepAlive, boost::beast::error_code ec, size_t bytes);
    void doClose();
    void onDrain(boost::beast::error_code ec, size_t bytes);
    // Why the request head is refused (status, message), or nullopt.
    std::optional<std::pair<boost::beast::http::status, std::string>> checkHeader() const;

    // POST /api/volumes: the head's checks, then the body streamed into the upload's file,
    // its bytes reserved in the store as they arrive (507 past the room), each read within the
    // header timeout and each --upload-rate-window-s bringing the minimum rate (408 when the
    // body stops arriving or drips), then the parse on a parse worker of the store, answered
    // back on this connection's strand.
    void startUpload();
    void readUploadBody();
    void armRateWindow(uint64_t round);
    // The body is read, refused or abandoned: its timers stop.
    void endUploadBody();
    void onUploadBody(boost::beast::error_code ec, size_t bytes);
    void onUploadChecked(UploadStore::Result result);
    std::string peerAddress() const;

    Stream stream_;
    boost::beast::flat_buffer buffer_;
    std::shared_ptr<SharedState> state_;
    std::shared_ptr<const HttpEndpoint> endpoint_;
    std::shared_ptr<ConnectionSlot> slot_;
    std::optional<boost::beast::http::request_parser<boost::beast::http::string_body>> parser_;
    std::array<char, 4096> drain_{};
    size_t drained_ = 0;

    using UploadParser = boost::beast::http::request_parser<boost::beast::http::file_body>;
    std::optional<UploadParser> upload_;
    std::shared_ptr<UploadStore::Pending> pendingUpload_;
    std::optional<boost::asio::steady_timer> silence_;   // a tcp_stream's upload body only
    bool silent_ = false;                               // the silence timer fired
    std::optional<boost::asio::steady_timer> rateWindow_;   // a tcp_stream's upload body only
    uint64_t windowBytes_ = 0;                          // bytes read in the current rate window
    bool tooSlow_ = false;                              // a rate window ended under the minimum
    bool readingBody_ = false;
    // Which upload on this connection the body and the rate window belong to: a window timer
    // of an earlier upload that fired just as it ended is ignored.
    uint64_t uploadRound_ = 0, windowRound_ = 0;
};

// http_session.cpp instantiates it for these two streams only.
using HttpSession = BasicHttpSession<boost::beast::tcp_stream>;
extern template class BasicHttpSession<boost::beast::tcp_stream>;
// and BasicHttpSession<boost::beast::test::stream> (<boost/beast/_experimental/test/stream.hpp>).

} // namespace volcast::server
