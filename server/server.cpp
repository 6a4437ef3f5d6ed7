#include "server/server.hpp"

#include <boost/asio/executor_work_guard.hpp>
#include <boost/asio/ip/address.hpp>
#include <spdlog/spdlog.h>

namespace volcast::server {

namespace net = boost::asio;

Server::Server(ServerConfig config)
    : state_(std::make_shared<SharedState>(config)),
      ioc_(config.ioThreads) {
    const auto address = net::ip::make_address(config.bindAddress);
    listener_ = std::make_shared<Listener>(ioc_, net::ip::tcp::endpoint{address, config.port}, state_);
    state_->setPort(listener_->port());
    state_->preloadDefaultVolume();
}

Server::~Server() {
    stop("server stopping", std::chrono::milliseconds(500));
    wait();
}

void Server::start() {
    listener_->run();
    const int n = std::max(1, state_->config().ioThreads);
    for (int i = 0; i < n; ++i) threads_.emplace_back([this] { ioc_.run(); });
}

void Server::stop(const std::string &reason, std::chrono::milliseconds grace) {
    {
        std::lock_guard lock(mutex_);
        if (stopped_) return;
        stopped_ = true;
    }
    spdlog::info("stopping: {}", reason);
    listener_->stop();
    state_->closeAll(reason);
    // Sessions end once their close handshake is done; a client that stopped reading never
    // finishes it, so the network is stopped after the grace period in any case.
    const auto deadline = std::chrono::steady_clock::now() + grace;
    while (state_->metrics().sessions() > 0 && std::chrono::steady_clock::now() < deadline)
        std::this_thread::sleep_for(std::chrono::milliseconds(10));
    state_->stopWorkers();
    ioc_.stop();
}

void Server::wait() {
    for (auto &t : threads_)
        if (t.joinable() && t.get_id() != std::this_thread::get_id()) t.join();
}

} // namespace volcast::server
