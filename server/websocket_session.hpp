#pragma once
// One client's WebSocket session (Beast advanced_server's websocket_session): reads text
// messages, answers them, keeps the session's scene, and submits views to the scheduler.
// Everything here runs on the session's strand; render threads only post frames to it.
//
// Admission: a connection is pending until its hello succeeds (with the token, when the
// server has one); only then does it count against max_sessions and get a render slot. A
// pending connection that has not said hello within hello_timeout_ms is closed (1008).
// Every view is checked against the admission limits (samples per frame, still pixels,
// image memory) before any work starts; a view over one gets too_large naming the limit,
// and a viewport or quality policy refused that way leaves the scene as it was.
//
// Writes: one in flight. Text replies wait in a bounded queue (they answer requests, so
// they are few). Frames never queue: the scheduler renders a session's next frame only after
// this one was written (frameDone), so at most one frame per session is ever held, whatever
// the client's reading speed. A client that does not read is closed: when its unsent bytes
// (queued replies and the frame) pass max_unsent_bytes or kMaxQueuedTexts replies, or when
// one write has not completed within write_timeout_ms (a timer on the strand; the socket is
// then closed outright, as a close frame could not get through either). A small kernel send
// buffer makes a stuck reader show up after little wasted rendering.
//
// Exceptions: every handler run by Asio (accept, read, write, timers, posted frames and
// loading results) catches at its top (guarded): logged, answered `internal` where there is
// a request to answer, and the session and the server carry on.

#include "server/render_scheduler.hpp"
#include "server/session_scene.hpp"
#include "server/shared_state.hpp"

#include <boost/asio/steady_timer.hpp>
#include <boost/beast/core.hpp>
#include <boost/beast/http.hpp>
#include <boost/beast/websocket.hpp>

#include <deque>
#include <functional>
#include <memory>
#include <optional>
#include <stdexcept>
#include <string>

namespace volcast::server {

class WebsocketSession : public std::enable_shared_from_this<WebsocketSession> {
  public:
    static constexpr size_t kMaxQueuedTexts = 256;
    // A view over an admission limit; handle() answers it with too_large.
    struct AdmissionError : std::runtime_error {
        using std::runtime_error::runtime_error;
    };

    WebsocketSession(boost::asio::ip::tcp::socket &&socket, std::shared_ptr<SharedState> state);
    ~WebsocketSession();

    // Accept the upgrade request read by the HTTP session.
    void run(boost::beast::http::request<boost::beast::http::string_body> request);
    // Close with 1001 "going away" and this reason (server shutdown). Any thread.
    void shutdown(std::string reason);

  private:
    // Runs f; anything it throws is logged and answered `internal` (to request `id`).
    template <class F>
    void guarded(const char *where, F &&f, const nlohmann::json &id = nullptr) noexcept;
    void internalError(const char *where, const std::string &what, const nlohmann::json &id) noexcept;

    void onAccept(boost::beast::error_code ec);
    void onHelloTimeout();
    void doRead();
    void onRead(boost::beast::error_code ec, size_t bytes);
    void handle(std::string_view text);

    void sendText(std::string text);
    void sendMessage(const protocol::ServerMessage &message);
    void sendError(protocol::ProtocolError error);
    // A binary message other than a frame (a slice message): queued after the texts.
    void sendBinary(std::vector<uint8_t> bytes);
    void onSlice(const protocol::SliceRequest &m);   // server/slice_service.hpp answers it
    // Measurements (protocol/README.md): a probe is answered at once; roi_stats and pick run on
    // the slice service's thread (submitMeasurement), the session's scene as it is now.
    void onProbe(const protocol::ProbeRequest &m);
    void onRoiStats(const protocol::RoiStatsRequest &m);
    void onPick(const protocol::PickRequest &m);
    void submitMeasurement(const nlohmann::json &id, std::string_view type,
                           std::function<SliceService::Answer()> work);
    void onFrame(RenderedFrame frame);
    void doWrite();
    void onWrite(boost::beast::error_code ec, size_t bytes);
    void armWriteTimer();
    void onWriteTimeout(uint64_t serial);
    void closeWith(boost::beast::websocket::close_code code, std::string reason);
    // The client does not read: close the socket without a close handshake.
    void dropConnection(const std::string &why);

    // Message handlers; each may throw SceneError (bad_field) or ProtocolError.
    void onHello(const protocol::HelloRequest &m);
    void onOpenVolume(const protocol::OpenVolumeRequest &m);
    void onFindStudies(const protocol::FindStudiesRequest &m);   // answered from its source's search lane
    void onOpened(nlohmann::json id, VolumeRegistry::Result result);
    void joinScheduler();
    // Throws AdmissionError (too_large, naming the limit and its flag) when a view of
    // `candidate` at width x height (a still: its final level only) would go over a limit.
    // Without an open volume only the limits that do not depend on it are checked.
    void admit(const SessionScene &candidate, ImageSize size, bool still) const;
    // still: render only the final level, at this size.
    void submitView(const nlohmann::json &requestId, std::optional<ImageSize> still = std::nullopt);
    protocol::StateMessage stateMessage(const nlohmann::json &id) const;

    boost::beast::websocket::stream<boost::beast::tcp_stream> ws_;
    std::shared_ptr<SharedState> state_;
    boost::beast::flat_buffer buffer_;
    boost::asio::steady_timer helloTimer_;
    boost::asio::steady_timer writeTimer_;
    uint64_t writeSerial_ = 0;      // which write the write timer is guarding
    RenderScheduler::SlotId slot_ = 0;   // 0: no render slot (before hello)
    bool pending_ = false;          // counted as pending in SharedState (before hello)

    // Outgoing.
    std::deque<std::string> texts_;
    std::deque<std::string> binaries_;   // slice messages, written like texts but binary
    struct PendingFrame {
        std::vector<uint8_t> bytes;
        int level = 0;
        bool final = false;
        double renderMs = 0, encodeMs = 0;
    };
    std::optional<PendingFrame> frame_;   // waiting for the socket
    std::string textInFlight_;
    std::optional<PendingFrame> frameInFlight_;
    size_t unsentBytes_ = 0;        // queued and in-flight texts and frames
    bool writing_ = false;
    bool closing_ = false;        // a close was asked for: only queued text goes out
    bool closeStarted_ = false;   // async_close is under way
    boost::beast::websocket::close_reason closeReason_;
    uint64_t seq_ = 0;

    // Session.
    bool helloDone_ = false;
    bool opening_ = false;
    bool searching_ = false;        // a find_studies is waiting for its source
    std::shared_ptr<VolumeEntry> volume_;
    SessionScene scene_;
    bool interacting_ = false;
};

} // namespace volcast::server
