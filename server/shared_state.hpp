#pragma once
// What every session shares (Beast chat-multi's shared_state): the configuration, the
// back end that draws frames (--device: the native CPU path, or an OpenCL device), the volume registry, the render scheduler, the metrics, and the open
// WebSocket sessions (to refuse past their limits and to close them all at shutdown).
//
// A connection is *pending* from the WebSocket handshake until its hello succeeds (with the
// token, when one is set), and only then *joined*: max_sessions counts joined sessions only,
// so connections that never say hello cannot keep clients with the token out; pending ones
// have their own bound (max_pending_sessions) and a hello deadline.

#include "protocol/server_messages.hpp"
#include "renderer/make_frame_renderer.hpp"
#include "renderer/opencl/opencl_context.hpp"
#include "server/config.hpp"
#include "server/dicomweb_provider.hpp"
#include "server/metrics.hpp"
#include "server/render_scheduler.hpp"
#include "server/slice_service.hpp"
#include "server/upload_store.hpp"
#include "server/volume_registry.hpp"

#include <atomic>
#include <map>
#include <memory>
#include <mutex>
#include <string>
#include <thread>

namespace volcast::server {

class WebsocketSession;

class SharedState {
  public:
    // Chooses the back end from config.device (DeviceChoice) and, only when that is OpenCL,
    // opens the device and checks its kernel cache (throws OpenClError naming what failed;
    // std::invalid_argument for a device value that is none of the accepted forms).
    explicit SharedState(ServerConfig config);
    ~SharedState();

    const ServerConfig &config() const { return config_; }
    Metrics &metrics() { return metrics_; }
    VolumeRegistry &registry() { return *registry_; }
    RenderScheduler &scheduler() { return *scheduler_; }
    SliceService &slices() { return *slices_; }
    // Uploaded volumes (POST /api/volumes); also the registry's provider of "upload:" names.
    UploadStore &uploads() { return *uploads_; }
    std::shared_ptr<UploadStore> uploadStore() const { return uploads_; }
    // The DICOMweb sources; null when none is configured.
    DicomWebProvider *dicomWeb() { return dicomWeb_.get(); }
    const protocol::DeviceInfo &device() const { return device_; }
    protocol::ServerLimits limits() const;
    uint16_t port() const { return port_; }
    void setPort(uint16_t p) { port_ = p; }

    // A new connection, before hello. False when it would be one over max_pending_sessions,
    // or the server is stopping.
    bool enterPending(WebsocketSession *session, std::weak_ptr<WebsocketSession> weak);
    // Hello succeeded: from pending to joined. False (and still pending) when it would be one
    // over max_sessions, or the server is stopping.
    bool join(WebsocketSession *session);
    // The connection is gone (pending or joined).
    void leave(WebsocketSession *session);
    // Tell every session why it is closing (WebSocket close 1001 with `reason`).
    void closeAll(const std::string &reason);
    bool stopping() const { return stopping_; }

    // Start loading the default volume, then draw a tiny warm-up frame of it with the chosen
    // back end (of an 8³ volume when there is no default volume; on OpenCL this builds the
    // ray-casting program): /readyz reports ready once both are done.
    void preloadDefaultVolume();
    // The back end that draws every volume's frames: "cpu: …" (native) or "opencl: <device>".
    const std::string &backEnd() const { return backEnd_; }
    // True when frames are drawn through OpenCL.
    bool usesOpenCl() const { return cl_ != nullptr; }
    // Programs the OpenCL device has built; 0 on the native path (tests: readiness on OpenCL
    // implies at least one).
    size_t programsBuilt() const { return cl_ ? cl_->programsBuilt() : 0; }
    // Warm-up frames drawn (tests: readiness implies one, on either back end).
    int warmUpFrames() const { return warmUpFrames_; }
    // Empty when ready, else why not.
    std::string notReadyReason() const;
    bool originAllowed(std::string_view origin) const;
    // Stop rendering and loading (after the sessions were told).
    void stopWorkers();

  private:
    ServerConfig config_;
    Metrics metrics_;
    std::shared_ptr<OpenClContext> cl_;   // null on the native CPU path
    std::string backEnd_;
    protocol::DeviceInfo device_;
    std::shared_ptr<DicomWebProvider> dicomWeb_;
    std::unique_ptr<VolumeRegistry> registry_;
    std::unique_ptr<RenderScheduler> scheduler_;
    std::unique_ptr<SliceService> slices_;
    std::atomic<uint16_t> port_{0};

    mutable std::mutex mutex_;
    std::map<WebsocketSession *, std::weak_ptr<WebsocketSession>> pending_, sessions_;
    std::atomic<bool> stopping_{false};
    std::shared_ptr<VolumeEntry> defaultVolume_;   // held, so never evicted
    std::string defaultVolumeError_;
    void warmUp(std::shared_ptr<VolumeEntry> entry);
    void startWarmUp(std::shared_ptr<VolumeEntry> entry);   // with mutex_ held
    std::thread warmUp_;
    bool kernelReady_ = false;
    std::atomic<int> warmUpFrames_{0};
    std::string kernelError_;
    // Last, so that it is made once config_ is, and goes first: its worker parses files.
    std::shared_ptr<UploadStore> uploads_ = std::make_shared<UploadStore>(config_);
};

} // namespace volcast::server
