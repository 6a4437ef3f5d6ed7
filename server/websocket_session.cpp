#include "server/websocket_session.hpp"

#include "protocol/protocol.hpp"
#include "renderer/io/volume_source.hpp"
#include "renderer/model/presets.hpp"
#include "renderer/reference/reference_renderer.hpp"
#include "renderer/model/slice.hpp"
#include "server/upload_ids.hpp"

#include <boost/asio/post.hpp>
#include <spdlog/fmt/fmt.h>
#include <spdlog/spdlog.h>

#include <chrono>

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
// clang before 17 deduces no aggregate template arguments (the fuzz build uses clang 14).
template <class... Ts>
Overloaded(Ts...) -> Overloaded<Ts...>;

// closed, operation_aborted and end_of_stream are normal endings, not failures.
void fail(beast::error_code ec, const char *what) {
    if (ec == net::error::operation_aborted || ec == websocket::error::closed || ec == net::error::eof ||
        ec == beast::error::timeout)
        return;
    spdlog::debug("websocket {}: {}", what, ec.message());
}

std::chrono::steady_clock::duration milliseconds(double ms) {
    return std::chrono::duration_cast<std::chrono::steady_clock::duration>(std::chrono::duration<double, std::milli>(ms));
}

std::string mib(double bytes) { return fmt::format("{:.0f} MiB", bytes / double(1 << 20)); }

// The levels a view of `size` renders: an explicit policy's one level (admission refuses it
// over a limit), or the automatic ladder lowered to fit the limits (quality_ladder.hpp).
std::vector<Level> ladderOf(const SessionScene &scene, const ServerConfig &config, const Volume *volume, ImageSize size) {
    const Quality &q = scene.scene().quality;
    if (scene.policy().mode == protocol::QualityMode::Explicit) return explicitLadder(q, config.jitterPasses);
    return fitToLimits(automaticLadder(q, config.jitterPasses), volume, size.width, size.height,
                       {double(config.maxSamplesPerFrame), double(config.maxRequestBytes)});
}
} // namespace

template <class F>
void WebsocketSession::guarded(const char *where, F &&f, const nlohmann::json &id) noexcept {
    try {
        f();
    } catch (const std::exception &e) {
        internalError(where, e.what(), id);
    } catch (...) {
        internalError(where, "an exception of unknown type", id);
    }
}

void WebsocketSession::internalError(const char *where, const std::string &what, const nlohmann::json &id) noexcept {
    try {
        spdlog::error("session {}: internal error in {}: {}", slot_, where, hideUploadIds(what));
        sendError({ErrorCode::Internal, std::string("internal error (") + where + "): " + protocol::quotableText(what, 500),
                   id, ""});
    } catch (...) {
        // Out of memory while answering: the session may hang, the server carries on.
    }
}

WebsocketSession::WebsocketSession(net::ip::tcp::socket &&socket, std::shared_ptr<SharedState> state)
    : ws_(std::move(socket)), state_(std::move(state)), helloTimer_(ws_.get_executor()),
      writeTimer_(ws_.get_executor()) {}

WebsocketSession::~WebsocketSession() {
    state_->scheduler().removeSession(slot_);
    state_->leave(this);
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
    // Without this, Linux autotunes the send buffer to megabytes on loopback, and a client that
    // stops reading is noticed (write timeout, unsent bytes) only after that much rendering.
    beast::error_code ignored;
    beast::get_lowest_layer(ws_).socket().set_option(net::socket_base::send_buffer_size(state_->config().sendBufferBytes),
                                                     ignored);
    ws_.async_accept(request, beast::bind_front_handler(&WebsocketSession::onAccept, shared_from_this()));
}

void WebsocketSession::onAccept(beast::error_code ec) {
    if (ec) return fail(ec, "accept");
    bool refused = false;
    guarded("accept", [&] {
        pending_ = state_->enterPending(this, weak_from_this());
        if (!pending_) {
            refused = true;
            state_->metrics().sessionRefused();
            const bool stopping = state_->stopping();
            const int limit = state_->config().maxPendingSessions;
            sendError({ErrorCode::Busy,
                       stopping ? "the server is shutting down"
                                : fmt::format("the server has {} connections that have not said hello yet, its limit "
                                              "(--max-pending-sessions); try again later",
                                              limit),
                       nullptr, ""});
            closeWith(stopping ? websocket::close_code::going_away : websocket::close_code::try_again_later,
                      stopping ? "server shutting down" : "too many connections before hello");
            return;
        }
        // The slot is taken only at hello, so a connection that never says hello costs no
        // session; the deadline frees its pending place too.
        helloTimer_.expires_after(milliseconds(state_->config().helloTimeoutMs));
        helloTimer_.async_wait([weak = weak_from_this()](beast::error_code e) {
            if (e) return;
            if (auto self = weak.lock()) self->guarded("hello deadline", [&] { self->onHelloTimeout(); });
        });
    });
    if (!refused) doRead();
}

void WebsocketSession::onHelloTimeout() {
    if (helloDone_ || closing_) return;
    const double ms = state_->config().helloTimeoutMs;
    spdlog::info("session: no hello within {:.0f} ms; closing", ms);
    sendError({ErrorCode::BadState,
               fmt::format("no hello within {:.0f} ms of connecting (the server's --hello-timeout-ms); closing", ms),
               nullptr, ""});
    closeWith(websocket::close_code::policy_error, "no hello in time");
}

void WebsocketSession::joinScheduler() {
    auto weak = weak_from_this();
    auto executor = ws_.get_executor();
    slot_ = state_->scheduler().addSession(
        [weak, executor](RenderedFrame frame) {
            net::post(executor, [weak, f = std::make_shared<RenderedFrame>(std::move(frame))]() mutable {
                if (auto self = weak.lock()) self->guarded("frame", [&] { self->onFrame(std::move(*f)); });
            });
        },
        [weak, executor](const std::string &message, const nlohmann::json &request) {
            net::post(executor, [weak, message, request] {
                if (auto self = weak.lock())
                    self->guarded("render_failed", [&] {
                        self->sendError({ErrorCode::RenderFailed, "rendering failed: " + message, request, ""});
                    });
            });
        },
        [weak, executor](const protocol::ProgressMessage &progress) {
            net::post(executor, [weak, progress] {
                if (auto self = weak.lock()) self->guarded("progress", [&] { self->sendMessage(progress); });
            });
        });
}

void WebsocketSession::doRead() {
    ws_.async_read(buffer_, beast::bind_front_handler(&WebsocketSession::onRead, shared_from_this()));
}

void WebsocketSession::onRead(beast::error_code ec, size_t) {
    if (ec) {
        if (ec == websocket::error::message_too_big)
            spdlog::info("session closed: a message over the WebSocket limit of {} bytes", ws_.read_message_max());
        // Beast checks text frames as they arrive: invalid UTF-8 fails the read and closes
        // with 1007 (protocol/README.md).
        if (ec == websocket::error::bad_frame_payload) spdlog::info("session closed: a text message that is not UTF-8");
        return fail(ec, "read");
    }
    guarded("read", [&] {
        if (closing_) {
            // Requests after the close was sent are not answered.
        } else if (!ws_.got_text()) {
            sendError(protocol::binaryMessageError(buffer_.size()));
        } else {
            const auto data = buffer_.cdata();
            handle(std::string_view(static_cast<const char *>(data.data()), data.size()));
        }
    });
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
                    if (DicomWebProvider *sources = state_->dicomWeb()) v.sources = sources->sources();
                    sendMessage(v);
                },
                [&](const protocol::FindStudiesRequest &m) { onFindStudies(m); },
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
                    SessionScene candidate = scene_;
                    candidate.setViewport(m.image);
                    admit(candidate, candidate.imageSize(), false);
                    scene_ = std::move(candidate);
                    if (volume_) submitView(id);
                },
                [&](const protocol::TransferFunctionRequest &m) {
                    if (!needVolume()) return;
                    scene_.setTransferFunction(m.transferFunction);
                    submitView(id);
                },
                [&](const protocol::QualityPolicyRequest &m) {
                    SessionScene candidate = scene_;
                    candidate.setPolicy(m.policy);
                    admit(candidate, candidate.imageSize(), false);
                    scene_ = std::move(candidate);
                    if (volume_) submitView(id);
                },
                [&](const protocol::ClipPlanesRequest &m) {
                    if (!needVolume()) return;
                    scene_.setClipPlanes(m.clipPlanes);
                    submitView(id);
                },
                [&](const protocol::StillRequest &m) {
                    if (!needVolume()) return;
                    submitView(id, m.image.is_null() ? scene_.imageSize() : scene_.readImageSize(m.image));
                },
                [&](const protocol::GetStateRequest &) { sendMessage(stateMessage(id)); },
                [&](const protocol::CloseRequest &) {
                    closeWith(websocket::close_code::normal, "closed at the client's request");
                },
                [&](const protocol::SliceRequest &m) {
                    if (needVolume()) onSlice(m);
                },
                [&](const protocol::ProbeRequest &m) {
                    if (needVolume()) onProbe(m);
                },
                [&](const protocol::RoiStatsRequest &m) {
                    if (needVolume()) onRoiStats(m);
                },
                [&](const protocol::PickRequest &m) {
                    if (needVolume()) onPick(m);
                },
            },
            message);
    } catch (const SceneError &e) {
        error(ErrorCode::BadField, e.what());
    } catch (const AdmissionError &e) {
        error(ErrorCode::TooLarge, e.what());
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
    if (!state_->join(this)) {
        state_->metrics().sessionRefused();
        const bool stopping = state_->stopping();
        sendError({ErrorCode::Busy,
                   stopping ? "the server is shutting down"
                            : fmt::format("the server is at its limit of {} sessions (--max-sessions); try again later",
                                          state_->config().maxSessions),
                   m.id, "hello"});
        closeWith(stopping ? websocket::close_code::going_away : websocket::close_code::try_again_later,
                  stopping ? "server shutting down" : "too many sessions");
        return;
    }
    pending_ = false;
    helloTimer_.cancel();
    joinScheduler();
    helloDone_ = true;
    spdlog::info("session {}: hello from \"{}\"", slot_, protocol::quotableText(m.client, 64));
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
                if (auto self = weak.lock()) self->guarded("progress", [&] { self->sendMessage(withId); }, withId.id);
            });
        },
        [weak, executor, id](VolumeRegistry::Result result) {
            net::post(executor, [weak, id, result = std::move(result)]() mutable {
                if (auto self = weak.lock()) self->guarded("open_volume", [&] { self->onOpened(id, std::move(result)); }, id);
            });
        },
        volume_,   // the volume this session gives up: it may be evicted to make room
        slot_);
}

void WebsocketSession::onFindStudies(const protocol::FindStudiesRequest &m) {
    DicomWebProvider *sources = state_->dicomWeb();
    if (!sources)
        return sendError({ErrorCode::NotFound,
                          "this server has no DICOMweb source (volcast-server --dicomweb NAME=URL adds one)", m.id,
                          "find_studies"});
    // One search at a time per session: a user who searches again waits for the first answer,
    // and one session cannot fill the queue of a source that every session shares.
    if (searching_)
        return sendError({ErrorCode::Busy, "a study search is under way for this session already; wait for its answer",
                          m.id, "find_studies"});
    searching_ = true;
    auto weak = weak_from_this();
    auto executor = ws_.get_executor();
    const nlohmann::json id = m.id;
    sources->findStudies(m, slot_, [weak, executor, id](DicomWebProvider::StudiesResult result) {
        net::post(executor, [weak, id, result = std::move(result)]() mutable {
            if (auto self = weak.lock())
                self->guarded("find_studies", [&] {
                    self->searching_ = false;
                    if (auto *e = std::get_if<ProtocolError>(&result)) return self->sendError(std::move(*e));
                    self->sendMessage(std::get<protocol::StudiesMessage>(result));
                }, id);
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
    try {
        submitView(id);
    } catch (const AdmissionError &e) {
        // The viewport and policy were set before a volume could be judged: the volume is
        // open, its view is not rendered until a smaller viewport or cheaper policy comes.
        sendError({ErrorCode::TooLarge, e.what(), id, "open_volume"});
    }
}

void WebsocketSession::admit(const SessionScene &candidate, ImageSize size, bool still) const {
    const ServerConfig &config = state_->config();
    const int width = size.width, height = size.height;
    const std::vector<Level> ladder = ladderOf(candidate, config, volume_ ? volume_->volume.get() : nullptr, size);
    const int64_t pixels = int64_t(width) * height;
    if (still && pixels > config.maxStillPixels)
        throw AdmissionError(fmt::format("a still of {}x{} is {} pixels, over the server's limit of {} "
                                         "(--max-still-pixels)",
                                         width, height, pixels, config.maxStillPixels));
    // A still renders only the final level; a view may render any of them.
    const size_t first = still ? ladder.size() - 1 : 0;
    for (size_t i = first; i < ladder.size(); ++i) {
        const Level &level = ladder[i];
        const double scale = level.quality.imageScale;
        const double bytes = requestBytes(level, width, height);
        if (bytes > double(config.maxRequestBytes))
            throw AdmissionError(fmt::format("a frame of {}x{} at image scale {} with {} pass(es) needs {} of image "
                                             "buffers (width x height x 16 bytes x passes), over the server's limit "
                                             "of {} (--max-request-mib)",
                                             width, height, scale, level.passes, mib(bytes),
                                             mib(double(config.maxRequestBytes))));
        if (!volume_) continue;
        const double samples = predictedSamples(*volume_->volume, level.quality, width, height);
        if (samples > double(config.maxSamplesPerFrame)) {
            const double rays = double(width) * height * scale * scale;
            throw AdmissionError(fmt::format("a frame of this view at step {} is predicted to take {:.3g} samples "
                                             "({:.3g} rays x {:.3g} samples per ray), over the server's limit of "
                                             "{:.3g} (--max-samples-per-frame); use a larger step, a coarser "
                                             "mip level or a smaller image",
                                             level.quality.step, samples, rays, samples / rays,
                                             double(config.maxSamplesPerFrame)));
        }
    }
}

void WebsocketSession::submitView(const nlohmann::json &requestId, std::optional<ImageSize> still) {
    const Scene &scene = scene_.scene();
    auto job = std::make_shared<ViewJob>();
    job->renderer = rendererOf(volume_);
    job->volumeId = volume_->id;
    job->volumeName = volume_->name;
    job->transferFunction = resolvedTransferFunction(scene, volume_->volume->range);
    job->camera = scene.camera;
    job->cameraJson = cameraToJson(scene.camera);
    const ImageSize size = still.value_or(scene_.imageSize());
    job->width = size.width;
    job->height = size.height;
    job->stillOnly = still.has_value();
    // Checked before anything is handed to the renderer; the view in the scheduler stays.
    admit(scene_, size, job->stillOnly);
    job->clipPlanes = scene.clipPlanes;
    const auto &policy = scene_.policy();
    job->ladder = ladderOf(scene_, state_->config(), volume_->volume.get(), size);
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
    const size_t limit = state_->config().maxUnsentBytes;
    if (texts_.size() >= kMaxQueuedTexts || unsentBytes_ + text.size() > limit)
        return dropConnection(fmt::format("{} replies ({} bytes) unsent, over the limit of {} replies or {} bytes "
                                 "(--max-unsent-bytes)",
                                 texts_.size(), unsentBytes_, kMaxQueuedTexts, limit));
    unsentBytes_ += text.size();
    texts_.push_back(std::move(text));
    doWrite();
}

void WebsocketSession::onSlice(const protocol::SliceRequest &m) {
    auto weak = weak_from_this();
    auto executor = ws_.get_executor();
    auto refusal = state_->slices().submit(slot_, volume_->volume, m, [weak, executor](SliceService::Answer answer) {
        net::post(executor, [weak, a = std::make_shared<SliceService::Answer>(std::move(answer))] {
            auto self = weak.lock();
            if (!self) return;
            self->guarded("slice", [&] {
                if (auto *bytes = std::get_if<std::vector<uint8_t>>(a.get())) self->sendBinary(std::move(*bytes));
                else if (auto *e = std::get_if<ProtocolError>(a.get())) self->sendError(std::move(*e));
            });
        });
    }, scene_.scene().quality.orientationCorrection);   // slices show the volume where its frames do
    if (refusal) sendError(std::move(*refusal));
}

namespace {
// "HU" when the volume's values are Hounsfield units: the modality chosen for it is CT in
// Hounsfield units (not CT stored as grey values, renderer/model/presets.hpp); else raw data units (null).
std::optional<std::string> valueUnit(const VolumeEntry &entry) {
    if (chooseModality(*entry.volume, entry.name).hounsfield) return std::string("HU");
    return std::nullopt;
}
} // namespace

void WebsocketSession::onProbe(const protocol::ProbeRequest &m) {
    // One trilinear sample: answered here, on the strand, at once.
    protocol::ProbeMessage answer;
    answer.id = m.id;
    answer.point = m.point;
    const std::optional<double> value = probeValue(
        *volume_->volume, {m.point[0], m.point[1], m.point[2]}, scene_.scene().quality.orientationCorrection);
    answer.inside = value.has_value();
    answer.value = value;
    answer.unit = valueUnit(*volume_);
    sendMessage(answer);
}

void WebsocketSession::submitMeasurement(const nlohmann::json &id, std::string_view type,
                                         std::function<SliceService::Answer()> work) {
    auto weak = weak_from_this();
    auto executor = ws_.get_executor();
    auto refusal = state_->slices().submitTask(slot_, id, type, std::move(work),
                                               [weak, executor](SliceService::Answer answer) {
        net::post(executor, [weak, a = std::make_shared<SliceService::Answer>(std::move(answer))] {
            auto self = weak.lock();
            if (!self) return;
            self->guarded("measurement", [&] {
                if (auto *text = std::get_if<std::string>(a.get())) self->sendText(std::move(*text));
                else if (auto *e = std::get_if<ProtocolError>(a.get())) self->sendError(std::move(*e));
            });
        });
    });
    if (refusal) sendError(std::move(*refusal));
}

void WebsocketSession::onRoiStats(const protocol::RoiStatsRequest &m) {
    RoiGeometry roi;
    roi.axis = parseSliceAxis(m.axis).value_or(SliceAxis::Axial);   // the parser allowed only the three
    roi.center = {m.center[0], m.center[1], m.center[2]};
    roi.a = m.radii[0];
    roi.b = m.radii[1];
    roi.shape = parseRoiShape(m.shape).value_or(RoiShape::Ellipse);
    const nlohmann::json id = m.id;
    submitMeasurement(id, "roi_stats", [volume = volume_->volume, roi, id, unit = valueUnit(*volume_),
                                        correction = scene_.scene().quality.orientationCorrection]() -> SliceService::Answer {
        RoiStats stats;
        try {
            stats = roiStats(*volume, roi, correction);
        } catch (const std::invalid_argument &e) {
            return ProtocolError{ErrorCode::BadField, e.what(), id, "roi_stats"};
        } catch (const std::length_error &e) {
            return ProtocolError{ErrorCode::TooLarge, e.what(), id, "roi_stats"};
        }
        protocol::RoiStatsMessage answer;
        answer.id = id;
        answer.samples = stats.samples;
        answer.areaMm2 = stats.area;
        if (stats.samples > 0) {
            answer.mean = stats.mean;
            answer.std = stats.std;
            answer.min = stats.min;
            answer.max = stats.max;
        }
        answer.unit = unit;
        return protocol::toJsonText(answer);
    });
}

void WebsocketSession::onPick(const protocol::PickRequest &m) {
    const Scene &scene = scene_.scene();
    // The ray is cast through the view the session's frames show: its camera, transfer function
    // (the projection's grey ramp under MIP / MinIP), clip planes, crop box and orientation
    // correction, trilinear. The client's image only gives the pixel's place and the aspect.
    const Ray ray = RayGenerator(scene.camera, m.width, m.height).rayThrough(m.x, m.y);
    const nlohmann::json id = m.id;
    submitMeasurement(id, "pick", [volume = volume_->volume, ray, id, quality = scene.quality,
                                   clip = scene.clipPlanes,
                                   tf = resolvedTransferFunction(scene, volume_->volume->range)]() -> SliceService::Answer {
        ReferenceRenderer reference(*volume, tf, Reconstruction::Linear);
        reference.setQuality(quality);
        // 1e-5 of opacity: the crossing is placed within one accepted interval, far finer than a voxel.
        const RayPick pick = reference.pick(ray, clip, 0.5, 1e-5);
        protocol::PickMessage answer;
        answer.id = id;
        answer.hit = pick.hit;
        if (pick.hit) answer.point = std::array<double, 3>{pick.point.x, pick.point.y, pick.point.z};
        answer.opacity = pick.opacity;
        return protocol::toJsonText(answer);
    });
}

void WebsocketSession::sendBinary(std::vector<uint8_t> bytes) {
    if (closing_) return;
    const size_t limit = state_->config().maxUnsentBytes;
    if (texts_.size() + binaries_.size() >= kMaxQueuedTexts || unsentBytes_ + bytes.size() > limit)
        return dropConnection(fmt::format("a slice of {} bytes on top of {} unsent bytes is over the limit of {} "
                                          "(--max-unsent-bytes)",
                                          bytes.size(), unsentBytes_, limit));
    unsentBytes_ += bytes.size();
    binaries_.emplace_back(bytes.begin(), bytes.end());
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
    const size_t limit = state_->config().maxUnsentBytes;
    if (unsentBytes_ + p.bytes.size() > limit)
        return dropConnection(fmt::format("a frame of {} bytes on top of {} unsent bytes is over the limit of {} "
                                 "(--max-unsent-bytes)",
                                 p.bytes.size(), unsentBytes_, limit));
    unsentBytes_ += p.bytes.size();
    state_->metrics().setQueuedBytes(int64_t(p.bytes.size()));
    frame_ = std::move(p);   // never one there already: the scheduler waits for frameDone
    doWrite();
}

void WebsocketSession::doWrite() {
    if (writing_ || closeStarted_) return;
    if (!texts_.empty()) {
        writing_ = true;
        textInFlight_ = std::move(texts_.front());
        texts_.pop_front();
        ws_.text(true);
        armWriteTimer();
        ws_.async_write(net::buffer(textInFlight_),
                        beast::bind_front_handler(&WebsocketSession::onWrite, shared_from_this()));
    } else if (!binaries_.empty()) {
        // A slice message travels like a text (textInFlight_ holds its bytes), only binary.
        writing_ = true;
        textInFlight_ = std::move(binaries_.front());
        binaries_.pop_front();
        ws_.binary(true);
        armWriteTimer();
        ws_.async_write(net::buffer(textInFlight_),
                        beast::bind_front_handler(&WebsocketSession::onWrite, shared_from_this()));
    } else if (frame_) {
        writing_ = true;
        frameInFlight_ = std::move(frame_);
        frame_.reset();
        ws_.binary(true);
        armWriteTimer();
        ws_.async_write(net::buffer(frameInFlight_->bytes),
                        beast::bind_front_handler(&WebsocketSession::onWrite, shared_from_this()));
    } else if (closing_) {
        closeStarted_ = true;
        writing_ = true;   // the close handshake is guarded by the write timer too
        armWriteTimer();
        ws_.async_close(closeReason_, [self = shared_from_this()](beast::error_code ec) {
            ++self->writeSerial_;
            self->writeTimer_.cancel();
            self->writing_ = false;
            fail(ec, "close");
        });
    }
}

void WebsocketSession::onWrite(beast::error_code ec, size_t) {
    guarded("write", [&] {
        writing_ = false;
        ++writeSerial_;   // the timer now guards nothing
        writeTimer_.cancel();
        if (frameInFlight_) {
            const PendingFrame &f = *frameInFlight_;
            unsentBytes_ -= f.bytes.size();
            state_->metrics().setQueuedBytes(-int64_t(f.bytes.size()));
            if (!ec) state_->metrics().frameSent(f.level, f.final, f.renderMs / 1e3, f.encodeMs / 1e3, f.bytes.size());
            frameInFlight_.reset();
            state_->scheduler().frameDone(slot_);
        } else {
            unsentBytes_ -= textInFlight_.size();
            textInFlight_.clear();
        }
        if (ec) return fail(ec, "write");
        doWrite();
    });
}

void WebsocketSession::armWriteTimer() {
    const uint64_t serial = ++writeSerial_;
    writeTimer_.expires_after(milliseconds(state_->config().writeTimeoutMs));
    writeTimer_.async_wait([weak = weak_from_this(), serial](beast::error_code ec) {
        if (ec) return;
        if (auto self = weak.lock()) self->guarded("write deadline", [&] { self->onWriteTimeout(serial); });
    });
}

void WebsocketSession::onWriteTimeout(uint64_t serial) {
    if (serial != writeSerial_ || !writing_) return;   // that write has completed meanwhile
    dropConnection(fmt::format("a write has not completed in {:.0f} ms (--write-timeout-ms)", state_->config().writeTimeoutMs));
}

void WebsocketSession::dropConnection(const std::string &why) {
    if (!beast::get_lowest_layer(ws_).socket().is_open()) return;   // dropped already
    spdlog::warn("session {}: closing the connection: the client does not read ({})", slot_, why);
    // The peer is not reading, so a close frame would wait behind what is unsent: the
    // socket is closed outright, which fails the pending read and write and ends the session.
    closing_ = true;
    closeStarted_ = true;
    state_->scheduler().removeSession(slot_);
    if (frame_) {
        unsentBytes_ -= frame_->bytes.size();
        state_->metrics().setQueuedBytes(-int64_t(frame_->bytes.size()));
        frame_.reset();
    }
    for (const std::string &t : texts_) unsentBytes_ -= t.size();
    texts_.clear();
    beast::get_lowest_layer(ws_).close();
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
        unsentBytes_ -= frame_->bytes.size();
        state_->metrics().setQueuedBytes(-int64_t(frame_->bytes.size()));
        frame_.reset();
    }
    doWrite();
}

void WebsocketSession::shutdown(std::string reason) {
    net::post(ws_.get_executor(), [self = shared_from_this(), reason = std::move(reason)] {
        self->guarded("shutdown", [&] { self->closeWith(websocket::close_code::going_away, reason); });
    });
}

} // namespace volcast::server
