#pragma once
// One client's WebSocket session (Beast advanced_server's websocket_session): reads text
// messages, answers them, keeps the session's scene, and submits views to the scheduler.
// Everything here runs on the session's strand; render threads only post frames to it.
//
// Writes: one in flight. Text replies wait in a bounded queue (they answer requests, so
// they are few; a client that sends requests but never reads its replies is closed when the
// queue passes kMaxQueuedTexts). Frames never queue: the scheduler renders a session's next
// frame only after this one was written (frameDone), so at most one frame per session is
// ever held, whatever the client's reading speed.

#include "server/render_scheduler.hpp"
#include "server/session_scene.hpp"
#include "server/shared_state.hpp"

#include <boost/beast/core.hpp>
#include <boost/beast/http.hpp>
#include <boost/beast/websocket.hpp>

#include <deque>
#include <memory>
#include <optional>
#include <string>

namespace volcast::server {

class WebsocketSession : public std::enable_shared_from_this<WebsocketSession> {
  public:
    static constexpr size_t kMaxQueuedTexts = 256;

    WebsocketSession(boost::asio::ip::tcp::socket &&socket, std::shared_ptr<SharedState> state);
    ~WebsocketSession();

    // Accept the upgrade request read by the HTTP session.
    void run(boost::beast::http::request<boost::beast::http::string_body> request);
    // Close with 1001 "going away" and this reason (server shutdown). Any thread.
    void shutdown(std::string reason);

  private:
    void onAccept(boost::beast::error_code ec);
    void doRead();
    void onRead(boost::beast::error_code ec, size_t bytes);
    void handle(std::string_view text);

    void sendText(std::string text);
    void sendMessage(const protocol::ServerMessage &message);
    void sendError(protocol::ProtocolError error);
    void onFrame(RenderedFrame frame);
    void doWrite();
    void onWrite(boost::beast::error_code ec, size_t bytes);
    void closeWith(boost::beast::websocket::close_code code, std::string reason);

    // Message handlers; each may throw SceneError (bad_field) or ProtocolError.
    void onHello(const protocol::HelloRequest &m);
    void onOpenVolume(const protocol::OpenVolumeRequest &m);
    void onOpened(nlohmann::json id, VolumeRegistry::Result result);
    void submitView(const nlohmann::json &requestId, const nlohmann::json &stillImage = nullptr);
    protocol::StateMessage stateMessage(const nlohmann::json &id) const;

    boost::beast::websocket::stream<boost::beast::tcp_stream> ws_;
    std::shared_ptr<SharedState> state_;
    boost::beast::flat_buffer buffer_;
    RenderScheduler::SlotId slot_ = 0;
    bool joined_ = false;

    // Outgoing.
    std::deque<std::string> texts_;
    struct PendingFrame {
        std::vector<uint8_t> bytes;
        int level = 0;
        bool final = false;
        double renderMs = 0, encodeMs = 0;
    };
    std::optional<PendingFrame> frame_;   // waiting for the socket
    std::string textInFlight_;
    std::optional<PendingFrame> frameInFlight_;
    bool writing_ = false;
    bool closing_ = false;        // a close was asked for: only queued text goes out
    bool closeStarted_ = false;   // async_close is under way
    boost::beast::websocket::close_reason closeReason_;
    uint64_t seq_ = 0;

    // Session.
    bool helloDone_ = false;
    bool opening_ = false;
    std::shared_ptr<VolumeEntry> volume_;
    SessionScene scene_;
    bool interacting_ = false;
    nlohmann::json lastRequest_;   // id of the latest scene-changing request
};

} // namespace volcast::server
