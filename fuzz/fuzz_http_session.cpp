// HTTP requests into the server's HttpSession, over beast::test::stream (no socket): the
// input is what a client sends on one connection, then it closes its end. The first byte
// sets how many bytes each read returns (1..256), so requests also arrive in pieces.
// One SharedState (on the native CPU back end: no OpenCL device is opened) and one
// io_context for the process, with a small web root and a file beside it that must never
// be served. The server's log lines go to a null sink: they are still formatted (that code
// runs, the debug lines included) but not written: at the default level a refused
// WebSocket origin alone wrote a warning to stderr.
// Invariants: the session ends by itself once the input is consumed (a hang is a libFuzzer
// timeout); whatever it writes is HTTP/1.x responses, never a 500; the file outside the
// web root never appears in the output.

#include "fuzz/fuzz_check.hpp"
#include "server/http_session.hpp"
#include "server/shared_state.hpp"

#include <boost/asio/io_context.hpp>
#include <boost/asio/write.hpp>
#include <boost/beast/_experimental/test/stream.hpp>
#include <spdlog/sinks/null_sink.h>
#include <spdlog/spdlog.h>

#include <cstddef>
#include <cstdint>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <memory>
#include <string>
#include <string_view>

namespace beast = boost::beast;
namespace net = boost::asio;
namespace fs = std::filesystem;
using namespace volcast;

namespace {
constexpr std::string_view kSecret = "SECRET-OUTSIDE-THE-WEB-ROOT";

struct Fixture {
    fs::path top;
    std::shared_ptr<server::SharedState> state;
    std::shared_ptr<const server::HttpEndpoint> endpoint;
    net::io_context ioc;   // reused: restart() before each input

    Fixture() {
        spdlog::set_default_logger(spdlog::null_logger_mt("fuzz-null"));
        spdlog::set_level(spdlog::level::debug);   // the session's debug lines are formatted too
        char pattern[] = "/tmp/volcast-fuzz-http-XXXXXX";
        if (!mkdtemp(pattern)) fuzz::fail("cannot create the temporary web root");
        top = fs::canonical(pattern);
        const fs::path root = top / "web";
        fs::create_directories(root / "app");
        std::ofstream(root / "index.html") << "<!doctype html><title>fuzz</title>";
        std::ofstream(root / "app" / "main.js") << "export {};";
        std::ofstream(top / "secret.txt") << kSecret;
        fs::create_symlink(top / "secret.txt", root / "escape.txt");
        server::ServerConfig config;
        config.webRoot = root;
        config.port = 8080;
        config.device = "cpu";
        state = std::make_shared<server::SharedState>(config);
        endpoint = std::make_shared<const server::HttpEndpoint>(server::httpEndpointFor(config, "127.0.0.1", false));
    }
    ~Fixture() {
        state->stopWorkers();
        std::error_code ec;
        fs::remove_all(top, ec);
    }
};
Fixture &fixture() {
    static Fixture f;
    return f;
}
} // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size) {
    if (size < 1) return 0;
    Fixture &f = fixture();
    const std::string_view input(reinterpret_cast<const char *>(data + 1), size - 1);

    net::io_context &ioc = f.ioc;
    ioc.restart();
    beast::test::stream client(ioc);
    beast::test::stream serverSide(ioc);
    client.connect(serverSide);
    serverSide.read_size(size_t(data[0]) + 1);
    beast::error_code ec;
    net::write(client, net::buffer(input.data(), input.size()), ec);
    fuzz::check(!ec, "writing the request into the test stream failed");
    client.close();   // the session reads end-of-stream once the input is consumed

    std::make_shared<server::BasicHttpSession<beast::test::stream>>(std::move(serverSide), f.state, f.endpoint)->run();
    ioc.run();

    const std::string_view out = client.str();
    if (out.empty()) return 0;
    fuzz::check(out.starts_with("HTTP/1.1 ") || out.starts_with("HTTP/1.0 "), "the session wrote something other than an HTTP response",
                out.substr(0, 200));
    fuzz::check(out.find("\r\n\r\n") != std::string_view::npos, "a response head is not terminated", out.substr(0, 200));
    fuzz::check(out.substr(9, 3) != "500", "the session answered 500", out.substr(0, 200));
    // Refusals quote the request (the Origin, the path): only a secret the input lacks counts.
    fuzz::check(out.find(kSecret) == std::string_view::npos || input.find(kSecret) != std::string_view::npos,
                "the file outside the web root was served");
    return 0;
}
