#include "server/shared_state.hpp"

#include "renderer/scene.hpp"
#include "server/websocket_session.hpp"

#include <spdlog/spdlog.h>

namespace volcast::server {

SharedState::SharedState(ServerConfig config) : config_(std::move(config)) {
    cl_ = std::make_unique<OpenClContext>(DeviceOptions{config_.device, config_.kernelCacheDir});
    device_.name = cl_->deviceName();
    const auto type = cl_->device().getInfo<CL_DEVICE_TYPE>();
    device_.type = (type & CL_DEVICE_TYPE_GPU)           ? "gpu"
                   : (type & CL_DEVICE_TYPE_CPU)         ? "cpu"
                   : (type & CL_DEVICE_TYPE_ACCELERATOR) ? "accelerator"
                                                         : "other";
    registry_ = std::make_unique<VolumeRegistry>(config_.dataDirs, config_.memoryBudgetBytes, *cl_, metrics_);
    scheduler_ = std::make_unique<RenderScheduler>(metrics_, SchedulerOptions{config_.idleMs, config_.errorCalibration, config_.defaultTargetFrameMs});
}

SharedState::~SharedState() { stopWorkers(); }

void SharedState::stopWorkers() {
    if (scheduler_) scheduler_->stop();
    if (registry_) registry_->stop();
}

protocol::ServerLimits SharedState::limits() const {
    protocol::ServerLimits l;
    l.maxMessageBytes = config_.maxMessageBytes;
    l.maxImageSide = kMaxImageSide;
    l.maxImagePixels = kMaxImagePixels;
    return l;
}

bool SharedState::join(WebsocketSession *session, std::weak_ptr<WebsocketSession> weak) {
    std::lock_guard lock(mutex_);
    if (stopping_ || int(sessions_.size()) >= config_.maxSessions) return false;
    sessions_[session] = std::move(weak);
    metrics_.sessionOpened();
    return true;
}

void SharedState::leave(WebsocketSession *session) {
    std::lock_guard lock(mutex_);
    if (sessions_.erase(session)) metrics_.sessionClosed();
}

void SharedState::closeAll(const std::string &reason) {
    std::vector<std::shared_ptr<WebsocketSession>> open;
    {
        std::lock_guard lock(mutex_);
        stopping_ = true;
        for (auto &[p, weak] : sessions_)
            if (auto s = weak.lock()) open.push_back(std::move(s));
    }
    for (auto &s : open) s->shutdown(reason);
}

void SharedState::preloadDefaultVolume() {
    if (config_.defaultVolume.empty()) return;
    registry_->open(
        config_.defaultVolume, [](const protocol::ProgressMessage &) {},
        [this](VolumeRegistry::Result result) {
            std::lock_guard lock(mutex_);
            if (auto *e = std::get_if<std::shared_ptr<VolumeEntry>>(&result)) {
                defaultVolume_ = *e;
            } else {
                defaultVolumeError_ = std::get<protocol::ProtocolError>(result).message;
                spdlog::error("default volume {}: {}", config_.defaultVolume, defaultVolumeError_);
            }
        });
}

std::string SharedState::notReadyReason() const {
    std::lock_guard lock(mutex_);
    if (stopping_) return "shutting down";
    if (config_.defaultVolume.empty()) return "";
    if (!defaultVolumeError_.empty()) return "default volume failed to load: " + defaultVolumeError_;
    if (!defaultVolume_) return "default volume " + config_.defaultVolume + " still loading";
    return "";
}

bool SharedState::originAllowed(std::string_view origin) const {
    // Non-browser clients send no Origin; browsers always do, and cross-site pages must not
    // drive a server on someone's loopback.
    if (origin.empty()) return true;
    if (config_.allowedOrigins.empty()) {
        const std::string p = std::to_string(port_.load());
        for (const std::string host : {"127.0.0.1", "localhost", "[::1]"})
            if (origin == "http://" + host + ":" + p) return true;
        return false;
    }
    for (const auto &o : config_.allowedOrigins)
        if (o == "*" || o == origin) return true;
    return false;
}

} // namespace volcast::server
