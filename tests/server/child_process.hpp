#pragma once
// The server executable as a child process, for the tests of the process itself (SIGTERM,
// start-up errors): start it, read the port it chose, wait for its exit.

#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <string>
#include <thread>
#include <vector>

namespace volcast::test {

// The server executable (VOLCAST_SERVER_EXE) with `args`; its stdout and stderr go to `log`,
// or to this test's own output when `log` is empty. Returns its pid.
inline pid_t startServerProcess(std::vector<std::string> args, const std::filesystem::path &log = {}) {
    const pid_t pid = ::fork();
    if (pid == 0) {
        if (!log.empty()) {
            if (FILE *f = std::freopen(log.c_str(), "w", stdout)) (void)f;
            ::dup2(::fileno(stdout), 2);
        }
        std::vector<char *> argv{const_cast<char *>(VOLCAST_SERVER_EXE)};
        for (auto &a : args) argv.push_back(a.data());
        argv.push_back(nullptr);
        ::execv(VOLCAST_SERVER_EXE, argv.data());
        ::_exit(127);
    }
    return pid;
}

// The port the server wrote to its --port-file, or 0 if none came within `timeout`.
inline uint16_t waitForPort(const std::filesystem::path &portFile, std::chrono::milliseconds timeout) {
    const auto deadline = std::chrono::steady_clock::now() + timeout;
    while (std::chrono::steady_clock::now() < deadline) {
        std::ifstream in(portFile);
        int p = 0;
        if (in >> p) return uint16_t(p);
        std::this_thread::sleep_for(std::chrono::milliseconds(20));
    }
    return 0;
}

// Exit status once the process ends, or -1 if it is still running after `timeout`.
inline int waitForExit(pid_t pid, std::chrono::milliseconds timeout) {
    const auto deadline = std::chrono::steady_clock::now() + timeout;
    int status = 0;
    while (std::chrono::steady_clock::now() < deadline) {
        if (::waitpid(pid, &status, WNOHANG) == pid) return status;
        std::this_thread::sleep_for(std::chrono::milliseconds(10));
    }
    return -1;
}

inline std::string readAll(const std::filesystem::path &p) {
    std::ifstream in(p);
    return {std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>()};
}

} // namespace volcast::test
