#pragma once
// A real Orthanc PACS for the DICOMweb tests: /usr/sbin/Orthanc (Debian package `orthanc`)
// with the DICOMweb plugin (package `orthanc-dicomweb`), started as a child process on
// 127.0.0.1 with a free HTTP port, HTTP Basic authentication on, no DICOM port, its storage
// and index in a temporary folder. Stopped (SIGCONT, SIGTERM, then SIGKILL) and its folder
// removed when the object goes. deploy/install.sh installs both packages.

#include "dicomweb/http_client.hpp"

#include <arpa/inet.h>
#include <fcntl.h>
#include <netinet/in.h>
#include <signal.h>
#include <spawn.h>
#include <sys/socket.h>
#include <sys/wait.h>
#include <unistd.h>

#include <nlohmann/json.hpp>

#include <chrono>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <stdexcept>
#include <string>
#include <thread>
#include <vector>

extern char **environ;

namespace volcast::test {

inline constexpr const char *kOrthancBinary = "/usr/sbin/Orthanc";
inline constexpr const char *kOrthancDicomWebPlugin = "/usr/share/orthanc/plugins/libOrthancDicomWeb.so";

// "" when Orthanc and its DICOMweb plugin are installed, else what to install.
inline std::string orthancMissing() {
    if (!std::filesystem::exists(kOrthancBinary))
        return std::string(kOrthancBinary) + " is missing: install the Debian package 'orthanc' (deploy/install.sh does)";
    if (!std::filesystem::exists(kOrthancDicomWebPlugin))
        return std::string(kOrthancDicomWebPlugin) +
               " is missing: install the Debian package 'orthanc-dicomweb' (deploy/install.sh does)";
    return {};
}

// A loopback TCP port that was free a moment ago (bound to port 0, then released).
inline uint16_t freeLoopbackPort() {
    const int fd = ::socket(AF_INET, SOCK_STREAM | SOCK_CLOEXEC, 0);
    sockaddr_in address{};
    address.sin_family = AF_INET;
    address.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
    socklen_t length = sizeof address;
    if (fd < 0 || ::bind(fd, reinterpret_cast<sockaddr *>(&address), sizeof address) != 0 ||
        ::getsockname(fd, reinterpret_cast<sockaddr *>(&address), &length) != 0)
        throw std::runtime_error("no free loopback port");
    ::close(fd);
    return ntohs(address.sin_port);
}

inline std::string base64(std::string_view text) {
    static constexpr char kDigits[] = "ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
    std::string out;
    size_t i = 0;
    for (; i + 2 < text.size(); i += 3) {
        const uint32_t v = uint32_t(uint8_t(text[i])) << 16 | uint32_t(uint8_t(text[i + 1])) << 8 | uint8_t(text[i + 2]);
        for (int shift : {18, 12, 6, 0}) out += kDigits[(v >> shift) & 63];
    }
    if (i + 1 == text.size()) {
        const uint32_t v = uint32_t(uint8_t(text[i])) << 16;
        out += kDigits[(v >> 18) & 63];
        out += kDigits[(v >> 12) & 63];
        out += "==";
    } else if (i + 2 == text.size()) {
        const uint32_t v = uint32_t(uint8_t(text[i])) << 16 | uint32_t(uint8_t(text[i + 1])) << 8;
        for (int shift : {18, 12, 6}) out += kDigits[(v >> shift) & 63];
        out += '=';
    }
    return out;
}

class OrthancProcess {
  public:
    static constexpr const char *kUser = "volcast";
    static constexpr const char *kPassword = "orthanc-test-password";

    // Throws std::runtime_error naming what failed (with the end of Orthanc's log).
    OrthancProcess() {
        if (const std::string missing = orthancMissing(); !missing.empty()) throw std::runtime_error(missing);
        const char *tmp = std::getenv("TMPDIR");
        std::string pattern = std::string(tmp && *tmp ? tmp : "/tmp") + "/volcast-orthanc-XXXXXX";
        if (!::mkdtemp(pattern.data())) throw std::runtime_error("mkdtemp failed for " + pattern);
        folder_ = pattern;
        port_ = freeLoopbackPort();
        const nlohmann::json config = {
            {"Name", "volcast-test"},
            {"HttpPort", port_},
            {"DicomServerEnabled", false},
            {"StorageDirectory", (folder_ / "storage").string()},
            {"IndexDirectory", (folder_ / "index").string()},
            {"RemoteAccessAllowed", false},
            {"AuthenticationEnabled", true},
            {"RegisteredUsers", {{kUser, kPassword}}},
            {"Plugins", {kOrthancDicomWebPlugin}},
            {"DicomWeb", {{"Enable", true}, {"Root", "/dicom-web/"}}},
            {"SaveJobs", false},
            {"StorageCompression", false},
        };
        std::ofstream(folder_ / "orthanc.json") << config.dump(2);

        const std::string configPath = (folder_ / "orthanc.json").string();
        const std::string logPath = (folder_ / "orthanc.log").string();
        posix_spawn_file_actions_t actions;
        posix_spawn_file_actions_init(&actions);
        posix_spawn_file_actions_addopen(&actions, 1, logPath.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0600);
        posix_spawn_file_actions_adddup2(&actions, 1, 2);
        std::vector<char *> argv{const_cast<char *>(kOrthancBinary), const_cast<char *>(configPath.c_str()), nullptr};
        const int rc = ::posix_spawn(&pid_, kOrthancBinary, &actions, nullptr, argv.data(), environ);
        posix_spawn_file_actions_destroy(&actions);
        if (rc != 0) {
            pid_ = -1;
            cleanUp();
            throw std::runtime_error(std::string("could not start ") + kOrthancBinary);
        }
        waitUntilAnswering();
    }

    ~OrthancProcess() { cleanUp(); }
    OrthancProcess(const OrthancProcess &) = delete;
    OrthancProcess &operator=(const OrthancProcess &) = delete;

    uint16_t port() const { return port_; }
    pid_t pid() const { return pid_; }
    std::string url() const { return "http://127.0.0.1:" + std::to_string(port_); }
    std::string dicomWebUrl() const { return url() + "/dicom-web"; }
    static std::string authorization() { return "Basic " + base64(std::string(kUser) + ":" + kPassword); }
    std::string log() const {
        std::ifstream in(folder_ / "orthanc.log");
        const std::string text{std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>()};
        return text.size() > 4000 ? text.substr(text.size() - 4000) : text;
    }
    void signal(int sig) const {
        if (pid_ > 0) ::kill(pid_, sig);
    }

    // Orthanc's REST API, through the library's own HTTP client.
    nlohmann::json rest(const std::string &method, const std::string &path, const std::string &body = {},
                        const std::string &contentType = "application/json") const {
        dicomweb::HttpClient http(restOptions());
        const auto response = method == "GET" ? http.get(url() + path, "application/json", 64 << 20)
                                              : http.post(url() + path, contentType, body, "application/json", 64 << 20);
        return nlohmann::json::parse(response.body);
    }
    // Stores one DICOM file; returns Orthanc's instance ID.
    std::string upload(const std::filesystem::path &file) const {
        std::ifstream in(file, std::ios::binary);
        const std::string bytes{std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>()};
        return rest("POST", "/instances", bytes, "application/dicom").at("ID").get<std::string>();
    }

  private:
    dicomweb::HttpOptions restOptions() const {
        dicomweb::HttpOptions o;
        o.sourceName = "test Orthanc";
        o.authorization = authorization();
        o.connectTimeoutSeconds = 2;
        o.requestTimeoutSeconds = 30;
        return o;
    }

    void waitUntilAnswering() {
        const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(20);
        std::string last;
        while (std::chrono::steady_clock::now() < deadline) {
            int status = 0;
            if (::waitpid(pid_, &status, WNOHANG) == pid_) {
                pid_ = -1;
                const std::string text = log();
                cleanUp();
                throw std::runtime_error("Orthanc exited at start-up; its log:\n" + text);
            }
            try {
                dicomweb::HttpOptions o = restOptions();
                o.requestTimeoutSeconds = 2;
                dicomweb::HttpClient(o).get(url() + "/system", "application/json", 1 << 20);
                return;
            } catch (const dicomweb::DicomWebError &e) {
                last = e.what();
            }
            std::this_thread::sleep_for(std::chrono::milliseconds(50));
        }
        const std::string text = log();
        cleanUp();
        throw std::runtime_error("Orthanc did not answer /system within 20 s (" + last + "); its log:\n" + text);
    }

    void cleanUp() {
        if (pid_ > 0) {
            ::kill(pid_, SIGCONT);  // a stopped process handles SIGTERM only once continued
            ::kill(pid_, SIGTERM);
            int status = 0;
            const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(5);
            bool ended = false;
            while (!ended && std::chrono::steady_clock::now() < deadline) {
                ended = ::waitpid(pid_, &status, WNOHANG) == pid_;
                if (!ended) std::this_thread::sleep_for(std::chrono::milliseconds(10));
            }
            if (!ended) {
                ::kill(pid_, SIGKILL);
                ::waitpid(pid_, &status, 0);
            }
            pid_ = -1;
        }
        if (!folder_.empty()) {
            std::error_code ec;
            std::filesystem::remove_all(folder_, ec);
            folder_.clear();
        }
    }

    std::filesystem::path folder_;
    uint16_t port_ = 0;
    pid_t pid_ = -1;
};

} // namespace volcast::test
