#include "server/shared_state.hpp"

#include "renderer/model/scene.hpp"
#include "renderer/model/transfer_function.hpp"
#include "server/websocket_session.hpp"

#include <spdlog/spdlog.h>

#include <cerrno>
#include <cstdlib>
#include <cstring>
#include <stdexcept>

namespace volcast::server {

namespace {
// A new folder only this process's user can read (mkdtemp makes it 0700), under $TMPDIR.
std::filesystem::path privateTemporaryFolder(const std::string &stem) {
    const char *tmp = std::getenv("TMPDIR");
    std::string pattern = std::string(tmp && *tmp ? tmp : "/tmp") + "/" + stem + "-XXXXXX";
    if (!::mkdtemp(pattern.data()))
        throw std::runtime_error("cannot create a private folder " + pattern + ": " + std::strerror(errno));
    return pattern;
}
} // namespace

SharedState::SharedState(ServerConfig config) : config_(std::move(config)) {
    cl_ = openContextFor(DeviceChoice::parse(config_.device), config_.kernelCacheDir);
    backEnd_ = backEndDescription(cl_);
    // Clients see the back end's description as the device's name ("cpu: AVX3, …" for the
    // native path, "opencl: <device>"), so they can tell the native path from PoCL's CPU device.
    device_.name = backEnd_;
    device_.type = "cpu";
    if (cl_) {
        const auto type = cl_->device().getInfo<CL_DEVICE_TYPE>();
        device_.type = (type & CL_DEVICE_TYPE_GPU)           ? "gpu"
                       : (type & CL_DEVICE_TYPE_CPU)         ? "cpu"
                       : (type & CL_DEVICE_TYPE_ACCELERATOR) ? "accelerator"
                                                             : "other";
    }
    spdlog::info("back end (--device {}): {}", DeviceChoice::parse(config_.device).text(), backEnd_);
    metrics_.setBackEnd(backEnd_, device_.type);
    registry_ = std::make_unique<VolumeRegistry>(config_.dataDirs, config_.memoryBudgetBytes, cl_, metrics_,
                                                 config_.loadTimeoutS, config_.dicomWebRetrievals);
    registry_->addProvider(uploads_);
    // An upload that expired or was evicted leaves memory too, once no session holds it.
    uploads_->setForgetHook([registry = registry_.get()](const std::string &name) { registry->forget(name); });
    if (!config_.dicomWebSources.empty()) {
        std::vector<dicomweb::SourceConfig> sources;
        for (const auto &s : config_.dicomWebSources) {
            dicomweb::SourceConfig source;
            source.name = s.name;
            source.baseUrl = s.url;
            source.authorization = s.authorization;
            source.requestTimeoutSeconds = config_.dicomWebTimeoutS;
            source.lowSpeedSeconds = config_.dicomWebTimeoutS;
            sources.push_back(std::move(source));
            spdlog::info("DICOMweb source {}: {}{}", s.name, s.url, s.authorization.empty() ? "" : " (with credentials)");
        }
        dicomWeb_ = std::make_shared<DicomWebProvider>(std::move(sources), privateTemporaryFolder("volcast-dicomweb"),
                                                       config_.dicomWebCacheBytes, config_.dicomWebSearches);
        registry_->addProvider(dicomWeb_);
    }
    scheduler_ = std::make_unique<RenderScheduler>(metrics_, SchedulerOptions{config_.idleMs, config_.errorCalibration, config_.defaultTargetFrameMs,
                                                                            config_.restRefinementS * 1000});
    slices_ = std::make_unique<SliceService>(config_.maxStillPixels);
}

SharedState::~SharedState() {
    stopWorkers();
    uploads_->setForgetHook(nullptr);   // the registry goes first; the store may outlive it in its providers
}

void SharedState::stopWorkers() {
    if (scheduler_) scheduler_->stop();
    if (slices_) slices_->stop();
    if (registry_) registry_->stop();
    std::thread warmUp;
    {
        std::lock_guard lock(mutex_);
        stopping_ = true;   // no warm-up starts after this
        warmUp = std::move(warmUp_);
    }
    if (warmUp.joinable() && warmUp.get_id() != std::this_thread::get_id()) warmUp.join();
}

protocol::ServerLimits SharedState::limits() const {
    protocol::ServerLimits l;
    l.maxMessageBytes = config_.maxMessageBytes;
    l.maxImageSide = kMaxImageSide;
    l.maxImagePixels = kMaxImagePixels;
    l.maxSamplesPerFrame = config_.maxSamplesPerFrame;
    l.maxStillPixels = config_.maxStillPixels;
    l.maxRequestBytes = int64_t(config_.maxRequestBytes);
    return l;
}

bool SharedState::enterPending(WebsocketSession *session, std::weak_ptr<WebsocketSession> weak) {
    std::lock_guard lock(mutex_);
    if (stopping_ || int(pending_.size()) >= config_.maxPendingSessions) return false;
    pending_[session] = std::move(weak);
    return true;
}

bool SharedState::join(WebsocketSession *session) {
    std::lock_guard lock(mutex_);
    const auto it = pending_.find(session);
    if (stopping_ || it == pending_.end() || int(sessions_.size()) >= config_.maxSessions) return false;
    sessions_[session] = std::move(it->second);
    pending_.erase(it);
    metrics_.sessionOpened();
    return true;
}

void SharedState::leave(WebsocketSession *session) {
    std::lock_guard lock(mutex_);
    pending_.erase(session);
    if (sessions_.erase(session)) metrics_.sessionClosed();
}

void SharedState::closeAll(const std::string &reason) {
    std::vector<std::shared_ptr<WebsocketSession>> open;
    {
        std::lock_guard lock(mutex_);
        stopping_ = true;
        for (const auto *group : {&pending_, &sessions_})
            for (auto &[p, weak] : *group)
                if (auto s = weak.lock()) open.push_back(std::move(s));
    }
    for (auto &s : open) s->shutdown(reason);
}

void SharedState::preloadDefaultVolume() {
    if (config_.defaultVolume.empty()) {
        std::lock_guard lock(mutex_);
        startWarmUp(nullptr);
        return;
    }
    registry_->open(
        config_.defaultVolume, [](const protocol::ProgressMessage &) {},
        [this](VolumeRegistry::Result result) {
            std::lock_guard lock(mutex_);
            if (auto *e = std::get_if<std::shared_ptr<VolumeEntry>>(&result)) {
                defaultVolume_ = *e;
                startWarmUp(defaultVolume_);
            } else {
                defaultVolumeError_ = std::get<protocol::ProtocolError>(result).message;
                spdlog::error("default volume {}: {}", config_.defaultVolume, defaultVolumeError_);
            }
        });
}

void SharedState::startWarmUp(std::shared_ptr<VolumeEntry> entry) {
    if (stopping_ || warmUp_.joinable()) return;
    warmUp_ = std::thread([this, entry = std::move(entry)] { warmUp(entry); });
}

void SharedState::warmUp(std::shared_ptr<VolumeEntry> entry) {
    // A frame at 8 x 8 pixels by the chosen back end: cheap, but on OpenCL it builds the
    // ray-casting program (seconds with a cold PoCL cache), which the first session would
    // otherwise wait for.
    try {
        std::unique_ptr<FrameRenderer> own;
        if (!entry) {
            Volume tiny;
            tiny.name = "warm-up";
            tiny.dims = {8, 8, 8};
            tiny.voxels.resize(tiny.voxelCount());
            for (size_t i = 0; i < tiny.voxels.size(); ++i) tiny.voxels[i] = float(i % 7);
            computeStatistics(tiny);
            own = makeFrameRenderer(cl_, std::make_shared<const Volume>(std::move(tiny)));
        }
        FrameRenderer &renderer = entry ? *entry->renderer : *own;
        const Volume &v = renderer.volume();
        Camera camera;
        camera.target = v.center();
        camera.eye = camera.target + Vec3d(0, 0, 3 * length(v.extent()));
        renderer.render({presetTransferFunction("mr", v.range), camera, 8, 8, Quality{}, {}});
        ++warmUpFrames_;
        std::lock_guard lock(mutex_);
        kernelReady_ = true;
    } catch (const std::exception &e) {
        spdlog::error("warm-up render failed: {}", e.what());
        std::lock_guard lock(mutex_);
        kernelError_ = e.what();
    }
}

std::string SharedState::notReadyReason() const {
    std::lock_guard lock(mutex_);
    if (stopping_) return "shutting down";
    if (!config_.defaultVolume.empty()) {
        if (!defaultVolumeError_.empty()) return "default volume failed to load: " + defaultVolumeError_;
        if (!defaultVolume_) return "default volume " + config_.defaultVolume + " still loading";
    }
    if (!kernelError_.empty()) return "the ray-casting program failed to build or run: " + kernelError_;
    if (!kernelReady_) return "the ray-casting program is still being built";
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
