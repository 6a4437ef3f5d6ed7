#include "server/websocket_session.hpp"

#include "protocol/protocol.hpp"
#include "renderer/volume_source.hpp"

#include <boost/asio/post.hpp>
#include <spdlog/spdlog.h>

namespace volcast::server {

namespace beast = boost::beast;
namespace http = beast::http;
namespace websocket = beast::websocket;
namespace net = boost::asio;
using protocol::ErrorCode;
using protocol::ProtocolError;

namespace {
template <class... Ts>
struct Overloaded : Ts... {
    using Ts::operator()...;
};

// closed, operation_aborted and end_of_stream are normal endings, not failures.
void fail(beast::error_code ec, const char *what) {
    if (ec == net::error::operation_aborted || ec == websocket::error::closed || ec == net::error::eof ||
        ec == beast::error::timeout)
        return;
    spdlog::debug("websocket {}: {}", what, ec.message());
}
} // namespace

WebsocketSession::WebsocketSession(net::ip::tcp::socket &&socket, std::shared_ptr<SharedState> state)
    : ws_(std::move(socket)), state_(std::move(state)) {}

WebsocketSession::~WebsocketSession() {
    state_->scheduler().removeSession(slot_);
    if (joined_) state_->leave(this);
    if (frame_) state_->metrics().setQueuedBytes(-int64_t(frame_->bytes.size()));
    if (frameInFlight_) state_->metrics().setQueuedBytes(-int64_t(frameInFlight_->bytes.size()));
}

void WebsocketSession::run(http::request<http::string_body> request) {
    ws_.set_option(websocket::stream_base::timeout::suggested(beast::role_type::server));
    // The WebSocket layer's own limit sits well above max_message_bytes, so that an oversized
    // request still reaches the parser and gets a too_large answer on a usable connection.
    ws_.read_message_max(std::max<size_t>(state_->config().maxMessageBytes * 16, 1 << 20));
    ws_.set_option(websocket::stream_base::decorator(
        [](websocket::response_type &res) { res.set(http::field::server, "volcast/0.1.0"); }));
    ws_.async_accept(request, beast::bind_front_handler(&WebsocketSession::onAccept, shared_from_this()));
}

void WebsocketSession::onAccept(beast::error_code ec) {
    if (ec) return fail(ec, "accept");
    joined_ = state_->join(this, weak_from_this());
    if (!joined_) {
        state_->metrics().sessionRefused();
        const bool stopping = state_->stopping();
        sendError({ErrorCode::Busy,
                   stopping ? "the server is shutting down"
                            : "the server is at its limit of " + std::to_string(state_->config().maxSessions) +
                                  " sessions; try again later",
                   nullptr, ""});
        closeWith(stopping ? websocket::close_code::going_away : websocket::close_code::try_again_later,
                  stopping ? "server shutting down" : "too many sessions");
        return;
    }
    auto weak = weak_from_this();
    auto executor = ws_.get_executor();
    slot_ = state_->scheduler().addSession(
        [weak, executor](RenderedFrame frame) {
            net::post(executor, [weak, f = std::make_shared<RenderedFrame>(std::move(frame))]() mutable {
                if (auto self = weak.lock()) self->onFrame(std::move(*f));
            });
        },
        [weak, executor](const std::string &message, const nlohmann::json &request) {
            net::post(executor, [weak, message, request] {
                if (auto self = weak.lock())
                    self->sendError({ErrorCode::RenderFailed, "rendering failed: " + message, request, ""});
            });
        },
        [weak, executor](const protocol::ProgressMessage &progress) {
            net::post(executor, [weak, progress] {
                if (auto self = weak.lock()) self->sendMessage(progress);
            });
        });
    doRead();
}

void WebsocketSession::doRead() {
    ws_.async_read(buffer_, beast::bind_front_handler(&WebsocketSession::onRead, shared_from_this()));
}

void WebsocketSession::onRead(beast::error_code ec, size_t) {
    if (ec) {
        if (ec == websocket::error::message_too_big)
            spdlog::info("session closed: a message over the WebSocket limit of {} bytes", ws_.read_message_max());
        return fail(ec, "read");
    }
    if (closing_) {
        // Requests after the close was sent are not answered.
    } else if (!ws_.got_text()) {
        sendError(protocol::binaryMessageError(buffer_.size()));
    } else {
        const auto data = buffer_.cdata();
        handle(std::string_view(static_cast<const char *>(data.data()), data.size()));
    }
    buffer_.consume(buffer_.size());
    // Keep reading while closing too: the peer's close frame arrives through a read.
    doRead();
}

void WebsocketSession::handle(std::string_view text) {
    protocol::Limits limits;
    limits.maxMessageBytes = state_->config().maxMessageBytes;
    auto parsed = protocol::parseClientMessage(text, limits);
    if (auto *e = std::get_if<ProtocolError>(&parsed)) return sendError(std::move(*e));
    const auto &message = std::get<protocol::ClientMessage>(parsed);
    const nlohmann::json id = protocol::requestIdOf(message);
    const std::string type(protocol::messageType(message));
    const auto error = [&](ErrorCode code, std::string what) { sendError({code, std::move(what), id, type}); };

    if (!helloDone_ && !std::holds_alternative<protocol::HelloRequest>(message))
        return error(ErrorCode::BadState, "send hello first");
    const auto needVolume = [&] {
        if (volume_) return true;
        error(ErrorCode::BadState, type + " needs an open volume (send open_volume first)");
        return false;
    };
    try {
        std::visit(
            Overloaded{
                [&](const protocol::HelloRequest &m) { onHello(m); },
                [&](const protocol::ListVolumesRequest &) {
                    protocol::VolumesMessage v;
                    v.id = id;
                    v.volumes = state_->registry().list();
                    sendMessage(v);
                },
                [&](const protocol::OpenVolumeRequest &m) { onOpenVolume(m); },
                [&](const protocol::CameraRequest &m) {
                    if (!needVolume()) return;
                    scene_.setCamera(m.camera);
                    submitView(id);
                },
                [&](const protocol::InteractionStartRequest &) {
                    interacting_ = true;
                    state_->scheduler().setInteracting(slot_, true);
                },
                [&](const protocol::InteractionEndRequest &) {
                    interacting_ = false;
                    state_->scheduler().setInteracting(slot_, false);
                },
                [&](const protocol::ViewportRequest &m) {
                    scene_.setViewport(m.image);
                    if (volume_) submitView(id);
                },
                [&](const protocol::TransferFunctionRequest &m) {
                    if (!needVolume()) return;
                    scene_.setTransferFunction(m.transferFunction);
                    submitView(id);
                },
                [&](const protocol::QualityPolicyRequest &m) {
                    scene_.setPolicy(m.policy);
                    if (volume_) submitView(id);
                },
                [&](const protocol::ClipPlanesRequest &m) {
                    if (!needVolume()) return;
                    scene_.setClipPlanes(m.clipPlanes);
                    submitView(id);
                },
                [&](const protocol::StillRequest &m) {
                    if (!needVolume()) return;
                    if (!m.image.is_null()) scene_.checkImage(m.image);
                    submitView(id, m.image.is_null() ? nlohmann::json(nlohmann::json::object()) : m.image);
                },
                [&](const protocol::GetStateRequest &) { sendMessage(stateMessage(id)); },
                [&](const protocol::CloseRequest &) {
                    closeWith(websocket::close_code::normal, "closed at the client's request");
                },
            },
            message);
    } catch (const SceneError &e) {
        error(ErrorCode::BadField, e.what());
    } catch (const std::exception &e) {
        // Caught once here, at the session boundary: the session and the server carry on.
        spdlog::error("internal error answering {}: {}", type, e.what());
        error(ErrorCode::Internal, std::string("internal error: ") + e.what());
    }
}

void WebsocketSession::onHello(const protocol::HelloRequest &m) {
    if (helloDone_) return sendError({ErrorCode::BadState, "hello was already sent", m.id, "hello"});
    const std::string &token = state_->config().token;
    if (!token.empty() && (!m.token || *m.token != token)) {
        sendError({ErrorCode::Unauthorized, m.token ? "wrong token" : "this server needs a token in hello", m.id, "hello"});
        closeWith(websocket::close_code::policy_error, "unauthorized");
        return;
    }
    helloDone_ = true;
    spdlog::info("session {}: hello from \"{}\"", slot_, m.client);
    protocol::ServerHello h;
    h.id = m.id;
    h.server = "volcast 0.1.0";
    h.device = state_->device();
    h.limits = state_->limits();
    sendMessage(h);
}

void WebsocketSession::onOpenVolume(const protocol::OpenVolumeRequest &m) {
    if (opening_)
        return sendError({ErrorCode::Busy, "a volume is being opened for this session already; wait for its state",
                          m.id, "open_volume"});
    opening_ = true;
    auto weak = weak_from_this();
    auto executor = ws_.get_executor();
    const nlohmann::json id = m.id;
    state_->registry().open(
        m.name,
        [weak, executor, id](const protocol::ProgressMessage &p) {
            protocol::ProgressMessage withId = p;
            withId.id = id;
            net::post(executor, [weak, withId] {
                if (auto self = weak.lock()) self->sendMessage(withId);
            });
        },
        [weak, executor, id](VolumeRegistry::Result result) {
            net::post(executor, [weak, id, result = std::move(result)]() mutable {
                if (auto self = weak.lock()) self->onOpened(id, std::move(result));
            });
        });
}

void WebsocketSession::onOpened(nlohmann::json id, VolumeRegistry::Result result) {
    opening_ = false;
    if (auto *e = std::get_if<ProtocolError>(&result)) {
        e->requestId = id;
        e->requestType = "open_volume";
        return sendError(*e);
    }
    volume_ = std::get<std::shared_ptr<VolumeEntry>>(result);
    scene_.openVolume(*volume_);
    sendMessage(stateMessage(id));
    submitView(id);
}

void WebsocketSession::submitView(const nlohmann::json &requestId, const nlohmann::json &stillImage) {
    lastRequest_ = requestId;
    const Scene scene = scene_.scene();
    auto job = std::make_shared<ViewJob>();
    job->renderer = rendererOf(volume_);
    job->volumeId = volume_->id;
    job->volumeName = volume_->name;
    job->transferFunction = resolvedTransferFunction(scene, volume_->volume->range);
    job->camera = scene.camera;
    job->cameraJson = nlohmann::json::parse(sceneToJson(scene)).at("camera");
    job->width = scene.width;
    job->height = scene.height;
    if (!stillImage.is_null()) {
        job->stillOnly = true;
        if (stillImage.contains("width")) {
            job->width = stillImage.at("width").get<int>();
            job->height = stillImage.at("height").get<int>();
        }
    }
    job->clipPlanes = scene.clipPlanes;
    const auto &policy = scene_.policy();
    const int passes = state_->config().jitterPasses;
    job->ladder = policy.mode == protocol::QualityMode::Explicit ? explicitLadder(scene.quality, passes)
                                                                 : automaticLadder(scene.quality, passes);
    job->targetFrameMs = scene_.policySent() ? policy.targetFrameMs : state_->config().defaultTargetFrameMs;
    job->request = requestId;
    state_->scheduler().submit(slot_, std::move(job));
}

protocol::StateMessage WebsocketSession::stateMessage(const nlohmann::json &id) const {
    protocol::StateMessage s;
    s.id = id;
    if (volume_) s.volume = volume_->info();
    s.scene = scene_.sceneJson();
    s.qualityPolicy = scene_.policy();
    if (!scene_.policySent()) s.qualityPolicy.targetFrameMs = state_->config().defaultTargetFrameMs;
    s.interacting = interacting_;
    return s;
}

void WebsocketSession::sendMessage(const protocol::ServerMessage &message) { sendText(protocol::toJsonText(message)); }

void WebsocketSession::sendError(ProtocolError error) {
    state_->metrics().error(std::string(protocol::errorCodeName(error.code)));
    sendText(protocol::toJsonText(protocol::ServerMessage(std::move(error))));
}

void WebsocketSession::sendText(std::string text) {
    if (closing_) return;   // the session is going: nothing more is sent
    if (texts_.size() >= kMaxQueuedTexts) {
        spdlog::warn("session {}: closing, {} replies unread", slot_, texts_.size());
        closeWith(websocket::close_code::policy_error, "too many unread replies: read the messages you are sent");
        return;
    }
    texts_.push_back(std::move(text));
    doWrite();
}

void WebsocketSession::onFrame(RenderedFrame frame) {
    if (closing_) {
        state_->scheduler().frameDone(slot_);
        return;
    }
    frame.header.seq = ++seq_;
    PendingFrame p;
    p.bytes = protocol::encodeFrame(frame.header, frame.image);
    p.level = frame.header.level;
    p.final = frame.header.final;
    p.renderMs = frame.header.renderMs;
    p.encodeMs = frame.header.encodeMs;
    state_->metrics().setQueuedBytes(int64_t(p.bytes.size()));
    if (frame_) state_->metrics().setQueuedBytes(-int64_t(frame_->bytes.size()));   // cannot happen: one in flight
    frame_ = std::move(p);
    doWrite();
}

void WebsocketSession::doWrite() {
    if (writing_ || closeStarted_) return;
    if (!texts_.empty()) {
        writing_ = true;
        textInFlight_ = std::move(texts_.front());
        texts_.pop_front();
        ws_.text(true);
        ws_.async_write(net::buffer(textInFlight_),
                        beast::bind_front_handler(&WebsocketSession::onWrite, shared_from_this()));
    } else if (frame_) {
        writing_ = true;
        frameInFlight_ = std::move(frame_);
        frame_.reset();
        ws_.binary(true);
        ws_.async_write(net::buffer(frameInFlight_->bytes),
                        beast::bind_front_handler(&WebsocketSession::onWrite, shared_from_this()));
    } else if (closing_) {
        closeStarted_ = true;
        ws_.async_close(closeReason_, [self = shared_from_this()](beast::error_code ec) { fail(ec, "close"); });
    }
}

void WebsocketSession::onWrite(beast::error_code ec, size_t) {
    writing_ = false;
    if (frameInFlight_) {
        const PendingFrame &f = *frameInFlight_;
        state_->metrics().setQueuedBytes(-int64_t(f.bytes.size()));
        if (!ec) state_->metrics().frameSent(f.level, f.final, f.renderMs / 1e3, f.encodeMs / 1e3, f.bytes.size());
        frameInFlight_.reset();
        state_->scheduler().frameDone(slot_);
    }
    if (ec) return fail(ec, "write");
    doWrite();
}

void WebsocketSession::closeWith(websocket::close_code code, std::string reason) {
    if (closing_) return;
    closing_ = true;
    state_->scheduler().removeSession(slot_);
    spdlog::info("session {}: closing ({})", slot_, reason);
    closeReason_ = websocket::close_reason(code, reason);
    // Text replies already queued go first (the error that explains the close, say); a frame
    // not yet written is dropped. doWrite closes once the queue is empty.
    if (frame_) {
        state_->metrics().setQueuedBytes(-int64_t(frame_->bytes.size()));
        frame_.reset();
    }
    doWrite();
}

void WebsocketSession::shutdown(std::string reason) {
    net::post(ws_.get_executor(), [self = shared_from_this(), reason = std::move(reason)] {
        self->closeWith(websocket::close_code::going_away, reason);
    });
}

} // namespace volcast::server
