#pragma once
// A hostile HTTP peer on a loopback socket: not a PACS, a server that answers every request
// with bytes the test chose (malformed multipart, redirects elsewhere, endless or oversized
// bodies, silence). One thread; one request per connection, then the connection is closed.

#include "tests/loopback_listener.hpp"

#include <arpa/inet.h>
#include <netinet/in.h>
#include <poll.h>
#include <sys/socket.h>
#include <unistd.h>

#include <atomic>
#include <cstdint>
#include <functional>
#include <mutex>
#include <stdexcept>
#include <string>
#include <thread>
#include <vector>

namespace volcast::test {

class HostileServer {
  public:
    // respond(index, request head) → the bytes to send (a whole HTTP response, or not).
    // An empty answer means: say nothing and keep the connection open until the server stops.
    using Responder = std::function<std::string(int index, const std::string &request)>;

    explicit HostileServer(Responder respond) : respond_(std::move(respond)) {
        listener_ = loopbackListener(16, port_, "hostile server");
        thread_ = std::thread([this] { serve(); });
    }
    ~HostileServer() {
        stop_ = true;
        thread_.join();
        ::close(listener_);
    }
    HostileServer(const HostileServer &) = delete;
    HostileServer &operator=(const HostileServer &) = delete;

    uint16_t port() const { return port_; }
    std::string url() const { return "http://127.0.0.1:" + std::to_string(port_); }
    std::vector<std::string> requests() const {
        std::lock_guard lock(mutex_);
        return requests_;
    }

  private:
    bool waitReadable(int fd) const { return volcast::test::waitReadable(fd, stop_); }

    void serve() {
        int index = 0;
        while (waitReadable(listener_)) {
            const int fd = ::accept4(listener_, nullptr, nullptr, SOCK_CLOEXEC);
            if (fd < 0) continue;
            std::string request;
            char buffer[4096];
            while (request.find("\r\n\r\n") == std::string::npos && waitReadable(fd)) {
                const ssize_t n = ::recv(fd, buffer, sizeof buffer, 0);
                if (n <= 0) break;
                request.append(buffer, size_t(n));
            }
            {
                std::lock_guard lock(mutex_);
                requests_.push_back(request);
            }
            const std::string answer = respond_(index++, request);
            if (answer.empty()) {
                while (!stop_) std::this_thread::sleep_for(std::chrono::milliseconds(20));
            } else {
                size_t sent = 0;
                while (sent < answer.size()) {
                    const ssize_t n = ::send(fd, answer.data() + sent, answer.size() - sent, MSG_NOSIGNAL);
                    if (n <= 0) break;
                    sent += size_t(n);
                }
            }
            ::shutdown(fd, SHUT_WR);
            ::close(fd);
        }
    }

    Responder respond_;
    int listener_ = -1;
    uint16_t port_ = 0;
    std::atomic<bool> stop_{false};
    mutable std::mutex mutex_;
    std::vector<std::string> requests_;
    std::thread thread_;
};

// An HTTP/1.1 response with a Content-Length and Connection: close.
inline std::string httpResponse(int status, const std::string &contentType, const std::string &body,
                                const std::string &extraHeaders = {}) {
    std::string head = "HTTP/1.1 " + std::to_string(status) + " X\r\nConnection: close\r\n";
    if (!contentType.empty()) head += "Content-Type: " + contentType + "\r\n";
    return head + extraHeaders + "Content-Length: " + std::to_string(body.size()) + "\r\n\r\n" + body;
}

// The Authorization value of a request head ("" if none).
inline std::string authorizationIn(const std::string &request) {
    const std::string name = "\r\nAuthorization: ";
    const size_t at = request.find(name);
    if (at == std::string::npos) return {};
    const size_t from = at + name.size();
    return request.substr(from, request.find("\r\n", from) - from);
}

// Every form in which a server could echo an Authorization value back: as sent, its
// credentials alone, for Basic the decoded "user:password" and the password alone, and each
// of these percent-encoded with upper- and with lower-case hex; the value with '+' for its
// space (form encoding). What a hostile PACS in these tests sends back, and what no message
// may hold.
inline std::vector<std::string> credentialEchoes(const std::string &authorization) {
    const auto percentEncoded = [](const std::string &text, bool upper) {
        const char *hex = upper ? "0123456789ABCDEF" : "0123456789abcdef";
        std::string out;
        for (const char c : text) {
            const auto u = static_cast<unsigned char>(c);
            if ((u >= 'A' && u <= 'Z') || (u >= 'a' && u <= 'z') || (u >= '0' && u <= '9') || c == '-' || c == '.' ||
                c == '_' || c == '~') {
                out += c;
            } else {
                out += '%';
                out += hex[u >> 4];
                out += hex[u & 15];
            }
        }
        return out;
    };
    const auto base64Decoded = [](const std::string &text) {
        static const std::string alphabet = "ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
        std::string out;
        uint32_t bits = 0;
        int count = 0;
        for (const char c : text) {
            const size_t v = alphabet.find(c);
            if (v == std::string::npos) break;   // '=' padding
            bits = (bits << 6) | uint32_t(v);
            count += 6;
            if (count >= 8) {
                count -= 8;
                out += char((bits >> count) & 0xFF);
            }
        }
        return out;
    };
    std::vector<std::string> plain{authorization};
    const size_t space = authorization.find(' ');
    const std::string credentials = authorization.substr(space + 1);
    plain.push_back(credentials);
    if (authorization.rfind("Basic ", 0) == 0) {
        const std::string userAndPassword = base64Decoded(credentials);
        plain.push_back(userAndPassword);
        plain.push_back(userAndPassword.substr(userAndPassword.find(':') + 1));
    }
    std::vector<std::string> out = plain;
    for (const std::string &p : plain)
        for (const bool upper : {true, false}) out.push_back(percentEncoded(p, upper));
    std::string formEncoded = authorization;
    formEncoded[space] = '+';
    out.push_back(formEncoded);
    return out;
}

// The first of `echoes` that `text` holds, whole or its first 16 characters (a quote cut
// short), or "" when it holds none.
inline std::string echoIn(const std::string &text, const std::vector<std::string> &echoes) {
    for (const std::string &echo : echoes)
        if (text.find(echo.substr(0, 16)) != std::string::npos) return echo;
    return {};
}

} // namespace volcast::test
