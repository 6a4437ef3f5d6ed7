#pragma once
// A small DICOMweb peer on a loopback socket, one thread per connection, for the tests of
// how the server shares its sources: it serves one series (the DICOM files of a folder) as a
// PACS would (QIDO-RS series and instance records, WADO-RS multipart retrieval), answers
// study searches with no study, and can be made slow: the retrieval's body dripped over a
// chosen time, searches answered after a delay or never. It counts the requests it gets.

#include "tests/loopback_listener.hpp"

#include <arpa/inet.h>
#include <netinet/in.h>
#include <poll.h>
#include <sys/socket.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <mutex>
#include <stdexcept>
#include <string>
#include <string_view>
#include <thread>
#include <vector>

namespace volcast::test {

// The value of a UI element (group, element) in a DICOM file's bytes, explicit or implicit
// VR little endian, without its padding; "" when the file has none.
inline std::string dicomUid(const std::string &bytes, uint16_t group, uint16_t element) {
    const char tag[4] = {char(group & 0xff), char(group >> 8), char(element & 0xff), char(element >> 8)};
    for (size_t at = bytes.find(std::string(tag, 4)); at != std::string::npos && at + 8 <= bytes.size();
         at = bytes.find(std::string(tag, 4), at + 1)) {
        const bool explicitVr = bytes.compare(at + 4, 2, "UI") == 0;
        const size_t length = explicitVr ? size_t(uint8_t(bytes[at + 6])) | size_t(uint8_t(bytes[at + 7])) << 8
                                         : size_t(uint8_t(bytes[at + 4])) | size_t(uint8_t(bytes[at + 5])) << 8;
        if (length == 0 || length > 64 || at + 8 + length > bytes.size()) continue;
        std::string uid = bytes.substr(at + 8, length);
        while (!uid.empty() && (uid.back() == '\0' || uid.back() == ' ')) uid.pop_back();
        return uid;
    }
    return "";
}

class FakePacs {
  public:
    struct Behaviour {
        std::chrono::milliseconds retrievalTakes{0};   // the multipart body dripped over this long
        std::chrono::milliseconds searchDelay{0};      // before a study search is answered
        bool searchesHang = false;                     // a study search is never answered
        int rows = 64, columns = 64;                   // of the served series' images, for its records
    };

    // files: the series' instances in order, as they are to be served (damaged ones too).
    FakePacs(std::vector<std::string> files, Behaviour behaviour) : files_(std::move(files)), behaviour_(behaviour) {
        if (files_.empty()) throw std::invalid_argument("fake PACS: no instance to serve");
        studyUid_ = dicomUid(files_.front(), 0x0020, 0x000D);
        seriesUid_ = dicomUid(files_.front(), 0x0020, 0x000E);
        listener_ = loopbackListener(128, port_, "fake PACS");
        acceptor_ = std::thread([this] { acceptLoop(); });
    }
    ~FakePacs() {
        stop_ = true;
        acceptor_.join();
        std::vector<std::thread> connections;
        {
            std::lock_guard lock(mutex_);
            connections.swap(connections_);
        }
        for (auto &t : connections) t.join();
        ::close(listener_);
    }
    FakePacs(const FakePacs &) = delete;
    FakePacs &operator=(const FakePacs &) = delete;

    // The files of a folder, in name order.
    static std::vector<std::string> filesOf(const std::filesystem::path &folder) {
        std::vector<std::filesystem::path> paths;
        for (const auto &entry : std::filesystem::directory_iterator(folder)) paths.push_back(entry.path());
        std::sort(paths.begin(), paths.end());
        std::vector<std::string> out;
        for (const auto &p : paths) {
            std::ifstream in(p, std::ios::binary);
            out.emplace_back(std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>());
        }
        return out;
    }

    std::string url() const { return "http://127.0.0.1:" + std::to_string(port_); }
    const std::string &studyUid() const { return studyUid_; }
    const std::string &seriesUid() const { return seriesUid_; }
    int retrievalsBegun() const { return retrievalsBegun_; }
    int retrievalsSent() const { return retrievalsSent_; }   // bodies sent to their end
    int searchesBegun() const { return searchesBegun_; }
    int searchesAnswered() const { return searchesAnswered_; }

  private:
    bool waitReadable(int fd) const { return volcast::test::waitReadable(fd, stop_); }
    bool sendAll(int fd, std::string_view bytes) const {
        while (!bytes.empty() && !stop_) {
            const ssize_t n = ::send(fd, bytes.data(), bytes.size(), MSG_NOSIGNAL);
            if (n <= 0) return false;
            bytes.remove_prefix(size_t(n));
        }
        return bytes.empty();
    }
    // Sleeps `d` unless the peer stops first; false then.
    bool pause(std::chrono::milliseconds d) const {
        const auto until = std::chrono::steady_clock::now() + d;
        while (!stop_ && std::chrono::steady_clock::now() < until) std::this_thread::sleep_for(std::chrono::milliseconds(10));
        return !stop_;
    }
    static std::string json(int status, const std::string &body) {
        return "HTTP/1.1 " + std::to_string(status) + " X\r\nConnection: close\r\nContent-Type: application/dicom+json\r\n"
               "Content-Length: " + std::to_string(body.size()) + "\r\n\r\n" + body;
    }

    void acceptLoop() {
        while (waitReadable(listener_)) {
            const int fd = ::accept4(listener_, nullptr, nullptr, SOCK_CLOEXEC);
            if (fd < 0) continue;
            std::lock_guard lock(mutex_);
            connections_.emplace_back([this, fd] {
                serve(fd);
                ::shutdown(fd, SHUT_WR);
                ::close(fd);
            });
        }
    }

    void serve(int fd) {
        std::string request;
        char buffer[4096];
        while (request.find("\r\n\r\n") == std::string::npos && waitReadable(fd)) {
            const ssize_t n = ::recv(fd, buffer, sizeof buffer, 0);
            if (n <= 0) return;
            request.append(buffer, size_t(n));
        }
        const size_t pathStart = request.find(' ') + 1;
        const std::string target = request.substr(pathStart, request.find(' ', pathStart) - pathStart);
        const std::string seriesPath = "/studies/" + studyUid_ + "/series/" + seriesUid_;
        if (target.starts_with("/studies?")) {
            ++searchesBegun_;
            if (behaviour_.searchesHang) {
                pause(std::chrono::hours(1));
                return;
            }
            if (!pause(behaviour_.searchDelay)) return;
            // Counted before the answer goes: the server may pass it on, and a test count it,
            // before this thread runs again.
            ++searchesAnswered_;
            sendAll(fd, json(200, "[]"));
        } else if (target.starts_with("/studies/" + studyUid_ + "/series?")) {
            sendAll(fd, json(200, "[{\"0020000E\":{\"vr\":\"UI\",\"Value\":[\"" + seriesUid_ +
                                      "\"]},\"00201209\":{\"vr\":\"IS\",\"Value\":[" + std::to_string(files_.size()) +
                                      "]}}]"));
        } else if (target.starts_with(seriesPath + "/instances?")) {
            sendAll(fd, json(200, "[{\"00280010\":{\"vr\":\"US\",\"Value\":[" + std::to_string(behaviour_.rows) +
                                      "]},\"00280011\":{\"vr\":\"US\",\"Value\":[" +
                                      std::to_string(behaviour_.columns) + "]}}]"));
        } else if (target == seriesPath) {
            ++retrievalsBegun_;
            std::string body;
            for (const std::string &file : files_)
                body += "--fakepacs\r\nContent-Type: application/dicom\r\n\r\n" + file + "\r\n";
            body += "--fakepacs--\r\n";
            const std::string head = "HTTP/1.1 200 OK\r\nConnection: close\r\nContent-Type: multipart/related; "
                                     "type=\"application/dicom\"; boundary=fakepacs\r\nContent-Length: " +
                                     std::to_string(body.size()) + "\r\n\r\n";
            if (!sendAll(fd, head)) return;
            // 50 drips over retrievalTakes: a series of tens of KiB dripped over 10 s stays above
            // the client's low-speed limit (1 KiB/s), so only a stop ends it early.
            constexpr size_t kDrips = 50;
            const size_t chunk = (body.size() + kDrips - 1) / kDrips;
            for (size_t at = 0; at < body.size(); at += chunk) {
                if (at > 0 && !pause(behaviour_.retrievalTakes / kDrips)) return;
                if (!sendAll(fd, std::string_view(body).substr(at, chunk))) return;
            }
            ++retrievalsSent_;
        } else {
            sendAll(fd, json(404, ""));
        }
    }

    std::vector<std::string> files_;
    Behaviour behaviour_;
    std::string studyUid_, seriesUid_;
    int listener_ = -1;
    uint16_t port_ = 0;
    std::atomic<bool> stop_{false};
    std::atomic<int> retrievalsBegun_{0}, retrievalsSent_{0}, searchesBegun_{0}, searchesAnswered_{0};
    std::mutex mutex_;
    std::vector<std::thread> connections_;
    std::thread acceptor_;
};

} // namespace volcast::test
