#pragma once
// What every session shares (Beast chat-multi's shared_state): the configuration, the
// OpenCL device, the volume registry, the render scheduler, the metrics, and the set of
// open WebSocket sessions (to refuse past max_sessions and to close them all at shutdown).

#include "protocol/server_messages.hpp"
#include "renderer/opencl/opencl_context.hpp"
#include "server/config.hpp"
#include "server/metrics.hpp"
#include "server/render_scheduler.hpp"
#include "server/volume_registry.hpp"

#include <atomic>
#include <map>
#include <memory>
#include <mutex>
#include <string>

namespace volcast::server {

class WebsocketSession;

class SharedState {
  public:
    // Opens the OpenCL device (throws OpenClError naming it if there is none).
    explicit SharedState(ServerConfig config);
    ~SharedState();

    const ServerConfig &config() const { return config_; }
    Metrics &metrics() { return metrics_; }
    VolumeRegistry &registry() { return *registry_; }
    RenderScheduler &scheduler() { return *scheduler_; }
    const protocol::DeviceInfo &device() const { return device_; }
    protocol::ServerLimits limits() const;
    uint16_t port() const { return port_; }
    void setPort(uint16_t p) { port_ = p; }

    // False when the session would be one over max_sessions, or the server is stopping.
    bool join(WebsocketSession *session, std::weak_ptr<WebsocketSession> weak);
    void leave(WebsocketSession *session);
    // Tell every session why it is closing (WebSocket close 1001 with `reason`).
    void closeAll(const std::string &reason);
    bool stopping() const { return stopping_; }

    // Start loading the default volume; /readyz reports ready once it is in memory.
    void preloadDefaultVolume();
    // Empty when ready, else why not.
    std::string notReadyReason() const;
    bool originAllowed(std::string_view origin) const;
    // Stop rendering and loading (after the sessions were told).
    void stopWorkers();

  private:
    ServerConfig config_;
    Metrics metrics_;
    std::unique_ptr<OpenClContext> cl_;
    protocol::DeviceInfo device_;
    std::unique_ptr<VolumeRegistry> registry_;
    std::unique_ptr<RenderScheduler> scheduler_;
    std::atomic<uint16_t> port_{0};

    mutable std::mutex mutex_;
    std::map<WebsocketSession *, std::weak_ptr<WebsocketSession>> sessions_;
    std::atomic<bool> stopping_{false};
    std::shared_ptr<VolumeEntry> defaultVolume_;   // held, so never evicted
    std::string defaultVolumeError_;
};

} // namespace volcast::server
