#include "server/server.hpp"

#include <boost/asio/executor_work_guard.hpp>
#include <boost/asio/ip/address.hpp>
#include <spdlog/spdlog.h>

#include <stdexcept>

namespace volcast::server {

namespace net = boost::asio;

namespace {
// "127.0.0.1:9090", "[::1]:9090"; throws std::invalid_argument naming the flag.
net::ip::tcp::endpoint parseBind(const std::string &text) {
    const size_t colon = text.rfind(':');
    const auto fail = [&] { return std::invalid_argument("--metrics-bind " + text + ": expected ADDRESS:PORT"); };
    if (colon == std::string::npos || colon + 1 == text.size()) throw fail();
    std::string host = text.substr(0, colon);
    if (host.size() >= 2 && host.front() == '[' && host.back() == ']') host = host.substr(1, host.size() - 2);
    boost::system::error_code ec;
    const auto address = net::ip::make_address(host, ec);
    if (ec) throw fail();
    unsigned long port = 0;
    try {
        size_t used = 0;
        port = std::stoul(text.substr(colon + 1), &used);
        if (used != text.size() - colon - 1 || port > 65535) throw fail();
    } catch (const std::logic_error &) {
        throw fail();
    }
    return {address, uint16_t(port)};
}
} // namespace

Server::Server(ServerConfig config)
    : state_(std::make_shared<SharedState>(config)),
      ioc_(config.ioThreads) {
    limiter_ = std::make_shared<ConnectionLimiter>(size_t(config.maxConnectionsPerAddress));
    const auto address = net::ip::make_address(config.bindAddress);
    listener_ = std::make_shared<Listener>(
        ioc_, net::ip::tcp::endpoint{address, config.port}, state_,
        std::make_shared<HttpEndpoint>(httpEndpointFor(config, config.bindAddress, false)), limiter_);
    if (!config.metricsBind.empty()) {
        const auto endpoint = parseBind(config.metricsBind);
        metricsListener_ = std::make_shared<Listener>(
            ioc_, endpoint, state_,
            std::make_shared<HttpEndpoint>(httpEndpointFor(config, endpoint.address().to_string(), true)), limiter_);
    }
    state_->setPort(listener_->port());
    state_->preloadDefaultVolume();
}

Server::~Server() {
    stop("server stopping", std::chrono::milliseconds(500));
    wait();
}

void Server::start() {
    listener_->run();
    if (metricsListener_) metricsListener_->run();
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
    if (metricsListener_) metricsListener_->stop();
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
