#pragma once
// The socket plumbing the tests' fake peers share (tests/dicomweb/hostile_server.hpp, a PACS
// answering fixed bytes; tests/server/fake_pacs.hpp, one that serves a series): a listening
// socket on 127.0.0.1 at a free port, and a wait for bytes that ends when the peer stops.

#include <arpa/inet.h>
#include <netinet/in.h>
#include <poll.h>
#include <sys/socket.h>
#include <unistd.h>

#include <atomic>
#include <cstdint>
#include <stdexcept>
#include <string>

namespace volcast::test {

// A socket listening on 127.0.0.1 at a free port (written to `port`); throws naming `who`.
inline int loopbackListener(int backlog, uint16_t &port, const std::string &who) {
    const int listener = ::socket(AF_INET, SOCK_STREAM | SOCK_CLOEXEC, 0);
    sockaddr_in address{};
    address.sin_family = AF_INET;
    address.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
    socklen_t length = sizeof address;
    if (listener < 0 || ::bind(listener, reinterpret_cast<sockaddr *>(&address), sizeof address) != 0 ||
        ::listen(listener, backlog) != 0 ||
        ::getsockname(listener, reinterpret_cast<sockaddr *>(&address), &length) != 0) {
        if (listener >= 0) ::close(listener);
        throw std::runtime_error(who + ": no loopback socket");
    }
    port = ntohs(address.sin_port);
    return listener;
}

// True once `fd` has something to read (or is closed), false once `stop` is set: polled every
// 50 ms so that a peer stops within that.
inline bool waitReadable(int fd, const std::atomic<bool> &stop) {
    while (!stop) {
        pollfd p{fd, POLLIN, 0};
        if (::poll(&p, 1, 50) > 0) return true;
    }
    return false;
}

} // namespace volcast::test
