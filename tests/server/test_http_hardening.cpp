// The HTTP layer against hostile or broken clients (docs/hardening.md, "HTTP"): refused
// WebSocket upgrades, malformed and oversized requests, slow headers, Host names, dotfiles,
// /metrics behind the token or on a port of its own, the per-address connection cap, and
// the server executable out of file descriptors. Each request is written byte for byte, as
// an attacker would, and each test then checks that the server still answers.

#include "client/cpp/ws_client.hpp"
#include "server/http_session.hpp"
#include "server/server.hpp"
#include "tests/server/server_fixture.hpp"

#include <boost/beast/_experimental/test/stream.hpp>
#include <gtest/gtest.h>

#include <csignal>
#include <fcntl.h>
#include <filesystem>
#include <fstream>
#include <sys/resource.h>
#include <sys/socket.h>
#include <sys/wait.h>
#include <thread>
#include <unistd.h>

namespace {

namespace fs = std::filesystem;
namespace http = boost::beast::http;
using namespace std::chrono_literals;
using volcast::test::httpGet;
using volcast::test::rawExchange;

constexpr auto kStartTimeout = 20s;   // a cold PoCL cache builds programs for seconds
constexpr const char *kToken = "s3cret-token";

std::string upgradeRequest(const std::string &target, const std::string &origin) {
    std::string r = "GET " + target +
                    " HTTP/1.1\r\nHost: 127.0.0.1\r\nUpgrade: websocket\r\nConnection: Upgrade\r\n"
                    "Sec-WebSocket-Key: dGhlIHNhbXBsZSBub25jZQ==\r\nSec-WebSocket-Version: 13\r\n";
    if (!origin.empty()) r += "Origin: " + origin + "\r\n";
    return r + "\r\n";
}

std::string get(const std::string &target, const std::string &host = "127.0.0.1") {
    return "GET " + target + " HTTP/1.1\r\nHost: " + host + "\r\n\r\n";
}

// Status of the response, 0 when there was none (with why, for the failure message).
int statusOf(const volcast::test::RawExchange &x) { return x.response ? int(x.response->result_int()) : 0; }
std::string describe(const volcast::test::RawExchange &x) {
    if (!x.response) return "no response: " + x.error;
    return std::to_string(x.response->result_int()) + " " + x.response->body();
}

// A refusal: `status`, a body naming `why`, Connection: close, and the connection closed.
void expectRefusal(const volcast::test::RawExchange &x, int status, const std::string &why) {
    ASSERT_EQ(statusOf(x), status) << describe(x);
    EXPECT_NE(x.response->body().find(why), std::string::npos) << x.response->body();
    EXPECT_FALSE(x.response->keep_alive());
    EXPECT_TRUE(x.closedAfter) << "the connection stayed open after the refusal";
}

void startAndWaitReady(volcast::server::Server &server) { volcast::test::startAndWaitReady(server, kStartTimeout); }

// ---- a server with the default HTTP settings on loopback (and a token) -----------------

class HttpHardening : public ::testing::Test {
  protected:
    static inline std::unique_ptr<volcast::server::Server> server;
    static inline fs::path tmp;
    static constexpr int kHeaderTimeoutMs = 500;   // short, so that the slowloris test is quick

    static void SetUpTestSuite() {
        tmp = fs::temp_directory_path() / ("volcast_http_hardening_" + std::to_string(::getpid()));
        fs::remove_all(tmp);
        fs::create_directories(tmp / "web" / "app");
        fs::create_directories(tmp / "web" / ".git");
        std::ofstream(tmp / "web" / "index.html") << "<!doctype html><title>volcast</title>";
        std::ofstream(tmp / "web" / "app" / "main.js") << "export const x = 1;";
        std::ofstream(tmp / "web" / ".git" / "config") << "[remote \"origin\"]\n";
        std::ofstream(tmp / "web" / ".env") << "SECRET=1\n";
        std::ofstream(tmp / "web" / "app" / ".hidden.js") << "secret";
        // A link with an ordinary name to a dotfile inside the root.
        fs::create_symlink(tmp / "web" / ".env", tmp / "web" / "env.txt");

        volcast::server::ServerConfig config;
        config.port = 0;
        config.webRoot = tmp / "web";
        config.defaultVolume = "";
        config.token = kToken;
        config.headerTimeoutMs = kHeaderTimeoutMs;
        server = std::make_unique<volcast::server::Server>(config);
        startAndWaitReady(*server);
    }
    static void TearDownTestSuite() {
        server.reset();
        fs::remove_all(tmp);
    }

    uint16_t port() const { return server->port(); }

    void expectAlive() {
        const auto reply = httpGet(port(), "/healthz");
        EXPECT_EQ(reply.status, 200) << reply.body;
    }
};

TEST_F(HttpHardening, RefusedUpgradeForeignOriginKeepsServerUp) {
    // Each refusal used to be written from a response already destroyed: a crash at once.
    for (int i = 0; i < 3; ++i) {
        expectRefusal(rawExchange(port(), upgradeRequest("/ws", "http://evil.example")), 403, "evil.example");
        expectAlive();
    }
}

TEST_F(HttpHardening, RefusedUpgradeNullOriginKeepsServerUp) {
    for (int i = 0; i < 3; ++i) {
        expectRefusal(rawExchange(port(), upgradeRequest("/ws", "null")), 403, "origin null is not allowed");
        expectAlive();
    }
}

TEST_F(HttpHardening, UpgradeOnAnotherPathIs404AndKeepsServerUp) {
    for (int i = 0; i < 3; ++i) {
        expectRefusal(rawExchange(port(), upgradeRequest("/elsewhere", "")), 404, "/ws");
        expectAlive();
    }
}

TEST_F(HttpHardening, MalformedRequestsAre400) {
    expectRefusal(rawExchange(port(), "GARBAGE\r\n\r\n"), 400, "malformed request");
    expectRefusal(rawExchange(port(), "GET / HTTP/1.1\r\nHost: 127.0.0.1\r\nBad Header: x\r\n\r\n"), 400,
                  "malformed request");
    expectRefusal(rawExchange(port(), "GET / HTTP/9.9\r\nHost: 127.0.0.1\r\n\r\n"), 400, "malformed request");
    expectRefusal(rawExchange(port(), "GET / HTTP/1.1\r\nHost: 127.0.0.1\r\nContent-Length: x\r\n\r\n"), 400,
                  "malformed request");
    expectAlive();
}

TEST_F(HttpHardening, BodyOverTheLimitIs413) {
    // The header alone announces it: refused before any of the body is read.
    const std::string head = "POST /x HTTP/1.1\r\nHost: 127.0.0.1\r\nContent-Length: " +
                             std::to_string(volcast::server::kMaxRequestBodyBytes + 1) + "\r\n\r\n";
    expectRefusal(rawExchange(port(), head), 413, "request body over");
    // Sent in full, the answer still arrives (the server drains what it does not read).
    expectRefusal(rawExchange(port(), head + std::string(volcast::server::kMaxRequestBodyBytes + 1, 'b')), 413,
                  "request body over");
    expectAlive();
}

TEST_F(HttpHardening, TargetOverTheLimitIs414) {
    // Within the header block's limit, and past it: both a URI too long, not a header problem.
    expectRefusal(rawExchange(port(), get("/" + std::string(volcast::server::kMaxTargetBytes, 'a'))), 414,
                  "request target over");
    expectRefusal(rawExchange(port(), get("/" + std::string(2 * volcast::server::kMaxHeaderBytes, 'a'))), 414,
                  "request target over");
    expectAlive();
}

TEST_F(HttpHardening, HeaderBlockOverTheLimitIs431) {
    std::string r = "GET / HTTP/1.1\r\nHost: 127.0.0.1\r\n";
    for (size_t i = 0; i * 1000 < volcast::server::kMaxHeaderBytes + 1000; ++i)
        r += "X-Filler-" + std::to_string(i) + ": " + std::string(990, 'f') + "\r\n";
    expectRefusal(rawExchange(port(), r + "\r\n"), 431, "request headers over");
    // Just under it (Beast's default of 8 KiB is no longer the limit): served.
    std::string ok = "GET /healthz HTTP/1.1\r\nHost: 127.0.0.1\r\nX-Filler: " +
                     std::string(volcast::server::kMaxHeaderBytes - 200, 'f') + "\r\n\r\n";
    EXPECT_EQ(statusOf(rawExchange(port(), ok)), 200);
}

TEST_F(HttpHardening, SlowHeadersAreCutOffAtTheHeaderTimeout) {
    boost::asio::io_context ioc;
    boost::asio::ip::tcp::socket socket(ioc);
    socket.connect({boost::asio::ip::make_address("127.0.0.1"), port()});
    const auto start = std::chrono::steady_clock::now();
    boost::system::error_code ec;
    boost::asio::write(socket, boost::asio::buffer(std::string("GET / HTTP/1.1\r\nHost: 127.0.0.1\r\n")), ec);
    // A slowloris client: one more header line every 100 ms, never the blank line.
    bool closed = false;
    for (int i = 0; i < 40 && !closed; ++i) {
        std::this_thread::sleep_for(100ms);
        boost::asio::write(socket, boost::asio::buffer("X-Slow-" + std::to_string(i) + ": 1\r\n"), ec);
        char byte = 0;
        const ssize_t n = ::recv(socket.native_handle(), &byte, 1, MSG_DONTWAIT);
        closed = ec || n == 0 || (n < 0 && errno != EAGAIN && errno != EWOULDBLOCK);
    }
    const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    ASSERT_TRUE(closed) << "still open after " << seconds << " s of trickled headers";
    // The header timeout plus the 100 ms trickle period plus scheduling slack on 2 cores.
    EXPECT_LT(seconds, kHeaderTimeoutMs / 1000.0 + 1.0);
    expectAlive();
}

TEST_F(HttpHardening, HostMustBeALoopbackNameOnALoopbackBind) {
    // DNS rebinding: a page of evil.example whose name now resolves to 127.0.0.1.
    expectRefusal(rawExchange(port(), get("/healthz", "evil.example")), 421, "host evil.example");
    expectRefusal(rawExchange(port(), get("/healthz", "evil.example:" + std::to_string(port()))), 421,
                  "--allowed-host");
    for (const std::string host : {"localhost", "LOCALHOST:8080", "127.0.0.1:1", "[::1]:8080", "localhost."})
        EXPECT_EQ(statusOf(rawExchange(port(), get("/healthz", host))), 200) << host;
    // HTTP/1.1 must name a host, once; HTTP/1.0 may not know the header.
    expectRefusal(rawExchange(port(), "GET /healthz HTTP/1.1\r\n\r\n"), 400, "no Host header");
    expectRefusal(rawExchange(port(), "GET /healthz HTTP/1.1\r\nHost: localhost\r\nHost: evil.example\r\n\r\n"), 400,
                  "more than one Host");
    expectRefusal(rawExchange(port(), get("/healthz", "local host")), 400, "malformed Host");
    expectRefusal(rawExchange(port(), get("/healthz", "::1")), 400, "malformed Host");
    EXPECT_EQ(statusOf(rawExchange(port(), "GET /healthz HTTP/1.0\r\n\r\n")), 200);
    // WebSocket upgrades are checked too.
    expectRefusal(rawExchange(port(), "GET /ws HTTP/1.1\r\nHost: evil.example\r\nUpgrade: websocket\r\n"
                                      "Connection: Upgrade\r\nSec-WebSocket-Key: dGhlIHNhbXBsZSBub25jZQ==\r\n"
                                      "Sec-WebSocket-Version: 13\r\n\r\n"),
                  421, "host evil.example");
}

TEST_F(HttpHardening, DotfilesAreNotServed) {
    EXPECT_EQ(httpGet(port(), "/app/main.js").status, 200);
    for (const std::string target : {"/.git/config", "/.env", "/app/.hidden.js", "/%2egit/config", "/%2Eenv",
                                     "/app/%2ehidden.js", "/app/./main.js", "/env.txt"}) {
        const auto reply = httpGet(port(), target);
        EXPECT_EQ(reply.status, 404) << target << ": " << reply.body;
        EXPECT_EQ(reply.body.find("SECRET"), std::string::npos) << target;
    }
}

TEST_F(HttpHardening, MetricsNeedTheTokenWhenOneIsSet) {
    const auto bare = rawExchange(port(), get("/metrics"));
    ASSERT_EQ(statusOf(bare), 401) << describe(bare);
    EXPECT_EQ(std::string((*bare.response)[http::field::www_authenticate]).rfind("Bearer", 0), 0u);
    const auto wrong = rawExchange(port(), "GET /metrics HTTP/1.1\r\nHost: 127.0.0.1\r\nAuthorization: Bearer "
                                           "s3cret-tokeX\r\n\r\n");
    EXPECT_EQ(statusOf(wrong), 401) << describe(wrong);
    const auto right = rawExchange(port(), "GET /metrics HTTP/1.1\r\nHost: 127.0.0.1\r\nAuthorization: bearer " +
                                               std::string(kToken) + "\r\n\r\n");
    ASSERT_EQ(statusOf(right), 200) << describe(right);
    EXPECT_NE(right.response->body().find("volcast_"), std::string::npos);
    // Health stays open: probes carry no token.
    expectAlive();
    EXPECT_EQ(httpGet(port(), "/readyz").status, 200);
}

// ---- a server with every HTTP flag set --------------------------------------------------

class HttpHardeningConfigured : public ::testing::Test {
  protected:
    static inline std::unique_ptr<volcast::server::Server> server;
    static constexpr int kCap = 4;

    static void SetUpTestSuite() {
        volcast::server::ServerConfig config;
        config.port = 0;
        config.defaultVolume = "";
        config.token = kToken;
        config.allowedHosts = {"Volcast.Example:443", "127.0.0.1"};
        config.metricsBind = "127.0.0.1:0";
        config.maxConnectionsPerAddress = kCap;
        server = std::make_unique<volcast::server::Server>(config);
        startAndWaitReady(*server);
    }
    static void TearDownTestSuite() { server.reset(); }

    uint16_t port() const { return server->port(); }
};

TEST_F(HttpHardeningConfigured, AllowedHostFlagReplacesTheLoopbackNames) {
    EXPECT_EQ(statusOf(rawExchange(port(), get("/healthz", "volcast.example"))), 200);
    EXPECT_EQ(statusOf(rawExchange(port(), get("/healthz", "volcast.example:8080"))), 200);
    expectRefusal(rawExchange(port(), get("/healthz", "localhost")), 421, "host localhost");
}

TEST_F(HttpHardeningConfigured, MetricsBindServesMetricsThereAndNotOnTheMainPort) {
    const uint16_t metricsPort = server->metricsPort();
    ASSERT_NE(metricsPort, 0);
    ASSERT_NE(metricsPort, port());
    // The metrics port is the private alternative to the token: no Authorization needed.
    const auto metrics = httpGet(metricsPort, "/metrics");
    EXPECT_EQ(metrics.status, 200);
    EXPECT_NE(metrics.body.find("volcast_"), std::string::npos);
    EXPECT_EQ(httpGet(metricsPort, "/healthz").status, 200);
    EXPECT_EQ(httpGet(metricsPort, "/readyz").status, 200);
    EXPECT_EQ(httpGet(metricsPort, "/index.html").status, 404);
    EXPECT_EQ(statusOf(rawExchange(metricsPort, upgradeRequest("/ws", ""))), 404);
    const auto main = rawExchange(port(), "GET /metrics HTTP/1.1\r\nHost: 127.0.0.1\r\nAuthorization: Bearer " +
                                              std::string(kToken) + "\r\n\r\n");
    EXPECT_EQ(statusOf(main), 404) << describe(main);
    EXPECT_EQ(httpGet(port(), "/healthz").status, 200);
}

TEST_F(HttpHardeningConfigured, ConnectionsPerAddressAreCappedWebSocketsIncluded) {
    boost::asio::io_context ioc;
    std::vector<boost::asio::ip::tcp::socket> idle;
    for (int i = 0; i < kCap - 1; ++i) {
        idle.emplace_back(ioc);
        idle.back().connect({boost::asio::ip::make_address("127.0.0.1"), port()});
    }
    // The earlier tests' connections are torn down asynchronously and count until then: the
    // WebSocket is refused while any of them is left, so try again until they are gone.
    std::unique_ptr<volcast::client::Client> ws;
    std::string lastRefusal;
    for (const auto until = std::chrono::steady_clock::now() + 5s; !ws && std::chrono::steady_clock::now() < until;) {
        try {
            ws = std::make_unique<volcast::client::Client>("127.0.0.1", port());
        } catch (const std::exception &e) {
            lastRefusal = e.what();
            std::this_thread::sleep_for(50ms);
        }
    }
    ASSERT_TRUE(ws) << "the WebSocket was refused for 5 s with " << kCap - 1 << " idle connections open: " << lastRefusal;
    // kCap open: the next one is refused at once, with a hint when to come back.
    const auto refused = rawExchange(port(), get("/healthz"));
    ASSERT_EQ(statusOf(refused), 503) << describe(refused);
    EXPECT_FALSE(std::string((*refused.response)[http::field::retry_after]).empty());
    EXPECT_NE(refused.response->body().find("--max-connections-per-address"), std::string::npos);
    // The other listener counts against the same cap.
    EXPECT_EQ(statusOf(rawExchange(server->metricsPort(), get("/healthz"))), 503);

    // Closing the WebSocket session frees its place (its teardown is asynchronous: poll).
    ws.reset();
    auto deadline = std::chrono::steady_clock::now() + 5s;
    int status = 0;
    while (status != 200 && std::chrono::steady_clock::now() < deadline) {
        status = statusOf(rawExchange(port(), get("/healthz")));
        if (status != 200) std::this_thread::sleep_for(50ms);
    }
    EXPECT_EQ(status, 200) << "the WebSocket session's place was not freed";
    idle.clear();
}

// ---- small parts ------------------------------------------------------------------------

TEST(HttpHardeningParts, HostNameParsing) {
    using volcast::server::hostName;
    EXPECT_EQ(hostName("LocalHost:8080"), "localhost");
    EXPECT_EQ(hostName("example.org."), "example.org");
    EXPECT_EQ(hostName("[::1]:80"), "[::1]");
    EXPECT_EQ(hostName("[::1]"), "[::1]");
    EXPECT_EQ(hostName("127.0.0.1:"), "127.0.0.1");
    EXPECT_EQ(hostName(" 10.0.0.7:8080 "), "10.0.0.7");
    for (const std::string bad : {"", ":80", "::1", "[::1", "[zz]:80", "[::1]x", "a b", "host:80:80", "host:123456",
                                  "host:8o", "ho/st", "ho@st"})
        EXPECT_FALSE(hostName(bad).has_value()) << bad;
}

TEST(HttpHardeningParts, AllowedHostsDefaultToLoopbackNamesOnlyOnALoopbackBind) {
    using volcast::server::httpEndpointFor;
    volcast::server::ServerConfig config;
    const std::vector<std::string> loopback{"localhost", "127.0.0.1", "[::1]"};
    EXPECT_EQ(httpEndpointFor(config, "127.0.0.1", false).allowedHosts, loopback);
    EXPECT_EQ(httpEndpointFor(config, "::1", false).allowedHosts, loopback);
    // The container and k8s bind all addresses: probes and ingresses send any name.
    EXPECT_TRUE(httpEndpointFor(config, "0.0.0.0", false).allowedHosts.empty());
    EXPECT_TRUE(httpEndpointFor(config, "::", false).allowedHosts.empty());
    config.allowedHosts = {"Example.org:8080"};
    EXPECT_EQ(httpEndpointFor(config, "0.0.0.0", false).allowedHosts, std::vector<std::string>{"example.org"});
    config.allowedHosts = {"example.org", "*"};
    EXPECT_TRUE(httpEndpointFor(config, "127.0.0.1", false).allowedHosts.empty());
    // /metrics leaves the main port only when a metrics listener exists.
    EXPECT_TRUE(httpEndpointFor(config, "127.0.0.1", false).serveMetrics);
    config.metricsBind = "127.0.0.1:9090";
    EXPECT_FALSE(httpEndpointFor(config, "127.0.0.1", false).serveMetrics);
    EXPECT_TRUE(httpEndpointFor(config, "127.0.0.1", true).serveMetrics);
}

// What the fuzz target relies on: the session over beast::test::stream, without a socket.
TEST(HttpHardeningParts, SessionRunsOverABeastTestStream) {
    volcast::server::ServerConfig config;
    config.defaultVolume = "";
    auto state = std::make_shared<volcast::server::SharedState>(config);
    auto endpoint =
        std::make_shared<volcast::server::HttpEndpoint>(volcast::server::httpEndpointFor(config, "127.0.0.1", false));
    boost::asio::io_context ioc;
    boost::beast::test::stream client(ioc), serverSide(ioc);
    client.connect(serverSide);
    std::make_shared<volcast::server::BasicHttpSession<boost::beast::test::stream>>(std::move(serverSide), state,
                                                                                    endpoint)
        ->run();
    // Two pipelined requests: a health check, then an upgrade that passes every check; only
    // a socket can become a WebSocket session, so this one is answered 501.
    const std::string requests = get("/healthz", "localhost") + upgradeRequest("/ws", "");
    boost::asio::write(client, boost::asio::buffer(requests));
    ioc.run_for(2s);
    const std::string answer(client.str());
    EXPECT_EQ(answer.rfind("HTTP/1.1 200 OK\r\n", 0), 0u) << answer;
    EXPECT_NE(answer.find("HTTP/1.1 501 Not Implemented\r\n"), std::string::npos) << answer;
    EXPECT_NE(answer.find("no WebSocket over this stream"), std::string::npos) << answer;
}

// ---- the executable out of file descriptors ---------------------------------------------

// CPU time (user + system) of a process so far, seconds.
double cpuSeconds(pid_t pid) {
    std::ifstream in("/proc/" + std::to_string(pid) + "/stat");
    std::string stat((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
    // Fields after the command name (which may hold spaces) start past its ')'.
    std::istringstream rest(stat.substr(stat.rfind(')') + 2));
    std::string field;
    unsigned long long utime = 0, stime = 0;
    for (int i = 3; i <= 15 && rest >> field; ++i) {
        if (i == 14) utime = std::stoull(field);
        if (i == 15) stime = std::stoull(field);
    }
    return double(utime + stime) / double(::sysconf(_SC_CLK_TCK));
}

// The log's lines about accept errors. Other lines may come meanwhile (the warm-up render that
// readiness waits for builds its kernel in these seconds when PoCL's cache is cold, as on a
// fresh machine), and say nothing about the accept loop.
std::vector<std::string> acceptLines(const fs::path &file) {
    std::ifstream in(file);
    std::vector<std::string> lines;
    std::string line;
    while (std::getline(in, line))
        if (line.find("accept on port") != std::string::npos) lines.push_back(line);
    return lines;
}

TEST(HttpHardeningProcess, OutOfFileDescriptorsBacksOffLogsLittleAndRecovers) {
    // Low enough that a few dozen connections exhaust it, high enough for the server's own
    // files (OpenCL/PoCL, the log, the listener: about 20 here).
    constexpr rlim_t kOpenFileLimit = 64;
    const std::string tag = std::to_string(::getpid());
    const fs::path portFile = fs::temp_directory_path() / ("volcast_fd_port_" + tag);
    const fs::path logFile = fs::temp_directory_path() / ("volcast_fd_log_" + tag);
    fs::remove(portFile);
    const pid_t pid = ::fork();
    ASSERT_GE(pid, 0);
    if (pid == 0) {
        const rlimit limit{kOpenFileLimit, kOpenFileLimit};
        ::setrlimit(RLIMIT_NOFILE, &limit);
        const int log = ::open(logFile.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
        ::dup2(log, 1);
        ::dup2(log, 2);
        ::close(log);
        // No per-address cap and a long header timeout: only the file limit stops connections.
        ::execl(VOLCAST_SERVER_EXE, VOLCAST_SERVER_EXE, "--port", "0", "--port-file", portFile.c_str(),
                "--default-volume", "", "--max-connections-per-address", "0", "--header-timeout-ms", "60000",
                "--log-level", "info", static_cast<char *>(nullptr));
        ::_exit(127);
    }
    struct Stop {
        pid_t pid;
        ~Stop() {
            ::kill(pid, SIGKILL);
            ::waitpid(pid, nullptr, 0);
        }
    } stopAtEnd{pid};
    uint16_t port = 0;
    const auto deadline = std::chrono::steady_clock::now() + kStartTimeout;
    while (port == 0 && std::chrono::steady_clock::now() < deadline) {
        std::ifstream in(portFile);
        int p = 0;
        if (in >> p) {
            port = uint16_t(p);
        } else {
            std::this_thread::sleep_for(20ms);
        }
    }
    ASSERT_NE(port, 0) << "the server did not start; its log: " << logFile;

    // More connections than the server has descriptors left: the rest wait in its backlog.
    boost::asio::io_context ioc;
    std::vector<boost::asio::ip::tcp::socket> connections;
    for (rlim_t i = 0; i < kOpenFileLimit + 16; ++i) {
        connections.emplace_back(ioc);
        connections.back().connect({boost::asio::ip::make_address("127.0.0.1"), port});
    }
    // Wait until the server reports the limit.
    auto until = std::chrono::steady_clock::now() + 5s;
    auto logged = [&] {
        std::ifstream in(logFile);
        std::string text((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
        return text.find("accept") != std::string::npos;
    };
    while (!logged() && std::chrono::steady_clock::now() < until) std::this_thread::sleep_for(50ms);
    ASSERT_TRUE(logged()) << "the server never reported an accept error; its log: " << logFile;

    // Out of descriptors for a while: the log grows by at most one line a second, and the
    // server does not spin (a retry loop would burn a whole core: ~kWindow of CPU).
    constexpr auto kWindow = 3s;
    const size_t linesBefore = acceptLines(logFile).size();
    const double cpuBefore = cpuSeconds(pid);
    std::this_thread::sleep_for(kWindow);
    const std::vector<std::string> after = acceptLines(logFile);
    const double cpu = cpuSeconds(pid) - cpuBefore;
    std::string newLines;
    for (size_t i = linesBefore; i < after.size(); ++i) newLines += after[i] + "\n";
    EXPECT_LE(after.size() - linesBefore, 3u + 1u) << "accept-error log lines in 3 s (at most one a second):\n"
                                                   << newLines;
    // Retries every second at most cost microseconds; 0.3 s leaves room for PoCL's idle
    // threads and the clock tick granularity (10 ms).
    EXPECT_LT(cpu, 0.3) << "CPU seconds used in 3 s while out of descriptors";

    // Descriptors freed: the server answers again, within the longest back-off (1 s) and the
    // time to accept and drop the closed connections in its backlog.
    connections.clear();
    until = std::chrono::steady_clock::now() + 10s;
    int status = 0;
    std::string last;
    while (status != 200 && std::chrono::steady_clock::now() < until) {
        try {
            const auto x = rawExchange(port, get("/healthz"), 2s);
            status = statusOf(x);
            last = describe(x);
        } catch (const std::exception &e) {
            last = e.what();
        }
        if (status != 200) std::this_thread::sleep_for(100ms);
    }
    EXPECT_EQ(status, 200) << last;
    if (!HasFailure()) {
        fs::remove(logFile);
        fs::remove(portFile);
    }
}

} // namespace
