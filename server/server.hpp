#pragma once
// The whole server in one object: shared state, listener and the threads running the
// network. volcast-server's main() and the integration tests both use it.

#include "server/config.hpp"
#include "server/listener.hpp"
#include "server/shared_state.hpp"

#include <boost/asio/io_context.hpp>

#include <memory>
#include <string>
#include <thread>
#include <vector>

namespace volcast::server {

class Server {
  public:
    // Opens the device, binds the port (0: any free one) and starts loading the default volume.
    explicit Server(ServerConfig config);
    ~Server();

    uint16_t port() const { return listener_->port(); }
    // The --metrics-bind listener's port; 0 when there is none.
    uint16_t metricsPort() const { return metricsListener_ ? metricsListener_->port() : 0; }
    SharedState &state() { return *state_; }
    // Start the network threads; returns at once.
    void start();
    // Tell every session why it closes, give them `grace` to finish the close handshake, then
    // stop rendering and the network. Any thread; idempotent.
    void stop(const std::string &reason, std::chrono::milliseconds grace = std::chrono::milliseconds(2000));
    // Block until stop() has finished.
    void wait();

  private:
    std::shared_ptr<SharedState> state_;
    boost::asio::io_context ioc_;
    std::shared_ptr<ConnectionLimiter> limiter_;   // shared by both listeners
    std::shared_ptr<Listener> listener_;
    std::shared_ptr<Listener> metricsListener_;   // --metrics-bind; null without it
    std::vector<std::thread> threads_;
    std::mutex mutex_;
    bool stopped_ = false;
};

} // namespace volcast::server
