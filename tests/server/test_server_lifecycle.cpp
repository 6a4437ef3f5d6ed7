// The server's start and stop: the back end --device chooses (native by default without a
// GPU), the kernel cache checked at start on OpenCL, readiness that waits for a compiled
// ray-casting program, and SIGTERM that ends the process within its grace
// period whatever is running.

#include "client/cpp/ws_client.hpp"
#include "renderer/make_frame_renderer.hpp"
#include "server/server.hpp"
#include "tests/server/child_process.hpp"

#include <gtest/gtest.h>

#include <chrono>
#include <csignal>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <string>
#include <sys/wait.h>
#include <thread>
#include <unistd.h>
#include <vector>

namespace {

namespace fs = std::filesystem;
using namespace std::chrono_literals;
using nlohmann::json;
using volcast::client::Client;

using volcast::test::readAll;
using volcast::test::startServerProcess;
using volcast::test::waitForExit;
using volcast::test::waitForPort;

class ServerLifecycle : public ::testing::Test {
  protected:
    fs::path tmp;
    void SetUp() override {
        const auto *info = ::testing::UnitTest::GetInstance()->current_test_info();
        tmp = fs::temp_directory_path() / ("volcast_lifecycle_" + std::to_string(::getpid()) + "_" + info->name());
        fs::remove_all(tmp);
        fs::create_directories(tmp);
    }
    void TearDown() override { fs::remove_all(tmp); }
};

// A cache folder that cannot be created (its parent is a regular file: permission bits
// would not stop root) must be named, not reported as a missing OpenCL device. The cache is
// checked only when the server draws through OpenCL.
TEST_F(ServerLifecycle, UnwritableKernelCacheFailsNamingTheFolder) {
    std::ofstream(tmp / "file") << "a regular file, not a folder";
    const fs::path cache = tmp / "file" / "kcache";
    const pid_t pid = startServerProcess({"--port", "0", "--device", "opencl", "--kernel-cache", cache.string(),
                                   "--default-volume", ""},
                                  tmp / "log.txt");
    ASSERT_GT(pid, 0);
    const int status = waitForExit(pid, 30s);
    ASSERT_NE(status, -1) << "the server started with an unusable kernel cache";
    EXPECT_TRUE(WIFEXITED(status) && WEXITSTATUS(status) != 0);
    const std::string log = readAll(tmp / "log.txt");
    EXPECT_NE(log.find(cache.string()), std::string::npos) << log;
    EXPECT_NE(log.find("kernel cache"), std::string::npos) << log;
    EXPECT_EQ(log.find("no OpenCL device"), std::string::npos) << log;
}

// Started as a user starts it, with no --device, on a machine without an OpenCL GPU: the
// server draws through the native CPU path, says so at start, and neither opens OpenCL nor
// checks the kernel cache (an unusable one is no reason to refuse to start).
TEST_F(ServerLifecycle, DefaultsToTheNativePathWithoutAnOpenClGpu) {
    if (volcast::openClGpuPresent()) GTEST_SKIP() << "this machine has an OpenCL GPU: auto picks it";
    std::ofstream(tmp / "file") << "a regular file, not a folder";
    const fs::path portFile = tmp / "port";
    const pid_t pid = startServerProcess({"--port", "0", "--port-file", portFile.string(), "--kernel-cache",
                                   (tmp / "file" / "kcache").string(), "--default-volume", "builtin:sphere"},
                                  tmp / "log.txt");
    ASSERT_GT(pid, 0);
    const uint16_t port = waitForPort(portFile, 30s);
    ::kill(pid, port == 0 ? SIGKILL : SIGTERM);
    const int status = waitForExit(pid, 30s);
    const std::string log = readAll(tmp / "log.txt");
    ASSERT_NE(port, 0) << "the server did not start: " << log;
    EXPECT_NE(status, -1);
    EXPECT_NE(log.find("back end (--device auto): cpu: "), std::string::npos) << log;
    EXPECT_EQ(log.find("opencl"), std::string::npos) << log;
}

// A --device value that is none of the accepted forms stops the server at once, naming it.
TEST_F(ServerLifecycle, AnUnknownDeviceIsAClearError) {
    const pid_t pid = startServerProcess({"--port", "0", "--device", "cuda", "--default-volume", ""}, tmp / "log.txt");
    ASSERT_GT(pid, 0);
    const int status = waitForExit(pid, 30s);
    ASSERT_NE(status, -1) << "the server started with --device cuda";
    EXPECT_TRUE(WIFEXITED(status) && WEXITSTATUS(status) != 0);
    const std::string log = readAll(tmp / "log.txt");
    EXPECT_NE(log.find("'cuda'"), std::string::npos) << log;
    EXPECT_NE(log.find("opencl:<"), std::string::npos) << "the error does not list the accepted forms: " << log;
}

// Ready means a session's first frame does not wait for the program to build: whenever
// the server says ready on OpenCL, the device has built a program.
TEST_F(ServerLifecycle, ReadinessWaitsForACompiledKernel) {
    volcast::server::ServerConfig config;
    config.port = 0;
    config.device = "opencl";
    config.defaultVolume = "builtin:sphere";
    volcast::server::Server server(config);
    server.start();
    const auto deadline = std::chrono::steady_clock::now() + 60s;
    std::string reason = server.state().notReadyReason();
    while (!reason.empty() && std::chrono::steady_clock::now() < deadline) {
        std::this_thread::sleep_for(1ms);
        reason = server.state().notReadyReason();
    }
    ASSERT_TRUE(reason.empty()) << "not ready after 60 s: " << reason;
    EXPECT_GE(server.state().programsBuilt(), 1u) << "ready before any ray-casting program was built";
}

// A frame that takes minutes (explicit policy, tiny step, cubic and shaded, 1024²): SIGTERM
// must still end the process within the grace period (1.5 s here), exiting 0.
TEST_F(ServerLifecycle, SigtermExitsWithinTheGracePeriodDuringALongRender) {
    const fs::path portFile = tmp / "port";
    const pid_t pid = startServerProcess({"--port", "0", "--port-file", portFile.string(), "--default-volume",
                                   "builtin:sphere", "--shutdown-grace-ms", "1500", "--error-calibration", "false",
                                   "--log-level", "info"},
                                  tmp / "log.txt");
    ASSERT_GT(pid, 0);
    const uint16_t port = waitForPort(portFile, 30s);
    if (port == 0) ::kill(pid, SIGKILL);
    ASSERT_NE(port, 0) << "the server did not start: " << readAll(tmp / "log.txt");
    {
        Client c("127.0.0.1", port);
        c.sendText(json{{"type", "hello"}, {"id", 1}, {"protocol", 1}}.dump());
        c.sendText(json{{"type", "viewport"}, {"id", 2}, {"image", {{"width", 1024}, {"height", 1024}}}}.dump());
        c.sendText(json{{"type", "quality_policy"},
                        {"id", 3},
                        {"mode", "explicit"},
                        {"quality", {{"step", 0.02}, {"interpolation", "cubic"}, {"shading", true}}}}
                       .dump());
        c.sendText(json{{"type", "open_volume"}, {"id", 4}, {"name", "builtin:demo"}}.dump());
        // The state comes just before the frame's render starts.
        bool state = false;
        const auto until = std::chrono::steady_clock::now() + 30s;
        while (!state && std::chrono::steady_clock::now() < until)
            if (auto m = c.next(100ms); m && !m->isFrame) state = m->text.find("\"state\"") != std::string::npos;
        ASSERT_TRUE(state) << "no state for builtin:demo";
        std::this_thread::sleep_for(500ms);   // well inside the frame's render
        const auto start = std::chrono::steady_clock::now();
        ASSERT_EQ(::kill(pid, SIGTERM), 0);
        const int status = waitForExit(pid, 1500ms + 1s);
        const auto took = std::chrono::duration_cast<std::chrono::milliseconds>(std::chrono::steady_clock::now() - start);
        if (status == -1) {
            ::kill(pid, SIGKILL);
            ::waitpid(pid, nullptr, 0);
        }
        ASSERT_NE(status, -1) << "still running 2.5 s after SIGTERM; log:\n" << readAll(tmp / "log.txt");
        EXPECT_TRUE(WIFEXITED(status)) << status;
        EXPECT_EQ(WEXITSTATUS(status), 0);
        // The grace period itself: the watchdog fires at 90 % of it (server/main.cpp), and
        // the remaining 150 ms cover the flush, the exit and this loop's 10 ms polling.
        EXPECT_LE(took.count(), 1500) << readAll(tmp / "log.txt");
        // Either the render stopped at a unit boundary and the server stopped cleanly, or the
        // watchdog ended it and the log says what was still running. (Since the scheduler runs
        // bounded units, the first is what happens; the watchdog stays for what units do not
        // bound: a load inside one read, a preparation.)
        const std::string log = readAll(tmp / "log.txt");
        const bool watchdog = log.find("still not stopped") != std::string::npos;
        EXPECT_TRUE(watchdog ? log.find("render worker") != std::string::npos || log.find("loader") != std::string::npos
                             : log.find("[info] stopped") != std::string::npos)
            << log;
    }
}

// SIGTERM while a session's long preparation runs on the background worker (the B-spline
// coefficients of iguana_microct, 9.6 M voxels: seconds here) and the error calibration may
// be queued: the process exits 0 within the grace period (1.5 s).
TEST_F(ServerLifecycle, SigtermExitsWithinTheGracePeriodDuringALongPreparation) {
    const fs::path data = VOLCAST_DATA_DIR;
    if (!fs::exists(data / "MANIFEST.md")) GTEST_SKIP() << "no scans in " << data << " (tests/README.md)";
    const fs::path portFile = tmp / "port";
    const pid_t pid = startServerProcess({"--port", "0", "--port-file", portFile.string(), "--default-volume",
                                   "builtin:sphere", "--data", data.string(), "--shutdown-grace-ms", "1500",
                                   "--log-level", "info"},
                                  tmp / "log.txt");
    ASSERT_GT(pid, 0);
    const uint16_t port = waitForPort(portFile, 30s);
    if (port == 0) ::kill(pid, SIGKILL);
    ASSERT_NE(port, 0) << "the server did not start: " << readAll(tmp / "log.txt");
    {
        Client c("127.0.0.1", port);
        c.sendText(json{{"type", "hello"}, {"id", 1}, {"protocol", 1}}.dump());
        c.sendText(json{{"type", "viewport"}, {"id", 2}, {"image", {{"width", 256}, {"height", 256}}}}.dump());
        c.sendText(json{{"type", "quality_policy"},
                        {"id", 3},
                        {"mode", "automatic"},
                        {"quality", {{"interpolation", "cubic"}, {"shading", true}}}}
                       .dump());
        c.sendText(json{{"type", "open_volume"}, {"id", 4}, {"name", "iguana_microct.nhdr"}}.dump());
        // The progress message for the coefficients comes when their preparation is queued.
        bool preparing = false;
        const auto until = std::chrono::steady_clock::now() + 60s;
        while (!preparing && std::chrono::steady_clock::now() < until)
            if (auto m = c.next(100ms); m && !m->isFrame)
                preparing = m->text.find("bspline_coefficients") != std::string::npos &&
                            m->text.find("\"fraction\":0") != std::string::npos;
        if (!preparing) ::kill(pid, SIGKILL);
        ASSERT_TRUE(preparing) << "no progress for the B-spline coefficients; log:\n" << readAll(tmp / "log.txt");
        std::this_thread::sleep_for(300ms);   // inside the preparation (seconds long)
        const auto start = std::chrono::steady_clock::now();
        ASSERT_EQ(::kill(pid, SIGTERM), 0);
        const int status = waitForExit(pid, 1500ms + 1s);
        const auto took = std::chrono::duration_cast<std::chrono::milliseconds>(std::chrono::steady_clock::now() - start);
        if (status == -1) {
            ::kill(pid, SIGKILL);
            ::waitpid(pid, nullptr, 0);
        }
        ASSERT_NE(status, -1) << "still running 2.5 s after SIGTERM; log:\n" << readAll(tmp / "log.txt");
        EXPECT_TRUE(WIFEXITED(status)) << status;
        EXPECT_EQ(WEXITSTATUS(status), 0);
        // The grace period itself (the watchdog fires at 90 % of it, server/main.cpp).
        EXPECT_LE(took.count(), 1500) << readAll(tmp / "log.txt");
        // Within the grace period either way; the log tells whether the preparation stopped
        // at a cancellation point or the watchdog ended it (what still ran is named).
        const std::string log = readAll(tmp / "log.txt");
        const auto watchdog = log.find("still not stopped");
        std::cout << "exited " << took.count() << " ms after SIGTERM, "
                  << (watchdog == std::string::npos ? std::string("cleanly") : log.substr(watchdog, 200)) << std::endl;
    }
}

} // namespace
