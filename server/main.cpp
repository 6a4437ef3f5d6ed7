// volcast-server: the rendering service. Flags and environment in server/README.md.

#include "server/config.hpp"
#include "server/server.hpp"

#include <boost/asio/signal_set.hpp>
#include <spdlog/spdlog.h>

#include <algorithm>
#include <chrono>
#include <csignal>
#include <cstdlib>
#include <thread>
#include <cstdio>
#include <fstream>
#include <iostream>

int main(int argc, char **argv) {
    int exitCode = 0;
    auto config = volcast::server::parseConfig(argc, argv, exitCode);
    if (!config) return exitCode;
    spdlog::set_level(spdlog::level::from_str(config->logLevel));
    try {
        volcast::server::Server server(*config);
        // Signals are waited for on a context of their own, so that stopping the server's
        // network from the handler cannot deadlock on it. As PID 1 in a container nothing
        // else would handle SIGTERM (docs/platform.md).
        boost::asio::io_context signals;
        boost::asio::signal_set set(signals, SIGINT, SIGTERM);
        set.async_wait([&](const boost::system::error_code &ec, int signal) {
            if (ec) return;
            // Whatever is still running (a long frame, a calibration, a load inside one read),
            // the process exits within the grace period: a watchdog that shares nothing with
            // the server but the note of what it is waiting for.
            const auto grace = std::chrono::milliseconds(config->shutdownGraceMs);
            // It fires at 75 % of the grace period: the rest is for its thread's wake-up, its log
            // line, the flush and the exit (tearing down a loaded volume's memory), so that the
            // process is gone within the period. At 90 % a fresh machine under load exited
            // 193 ms after the watchdog, 43 ms past a 1.5 s period.
            std::thread([grace, stage = server.shutdownStage()] {
                std::this_thread::sleep_for(grace * 3 / 4);
                spdlog::error("still not stopped {} ms after the signal, while {}; exiting now", (grace * 3 / 4).count(),
                              stage->get());
                spdlog::default_logger()->flush();
                std::_Exit(0);
            }).detach();
            // Sessions get at most half the grace period for their close handshake.
            server.stop(std::string("server shutting down (") + (signal == SIGTERM ? "SIGTERM" : "SIGINT") + ")",
                        std::min(std::chrono::milliseconds(2000), grace / 2));
        });
        server.start();
        const std::string host = config->bindAddress == "0.0.0.0" ? "127.0.0.1" : config->bindAddress;
        if (!config->portFile.empty()) {
            std::ofstream(config->portFile) << server.port() << '\n';
        }
        std::cout << "volcast-server: listening on http://" << host << ':' << server.port() << "/ (WebSocket ws://"
                  << host << ':' << server.port() << "/ws), device: " << server.state().device().name << std::endl;
        signals.run();
        server.wait();
        spdlog::info("stopped");
        return 0;
    } catch (const std::exception &e) {
        std::cerr << "volcast-server: " << e.what() << std::endl;
        return 1;
    }
}
