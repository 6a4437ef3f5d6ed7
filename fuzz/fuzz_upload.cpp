// Uploads (POST /api/volumes) into the server's HttpSession over beast::test::stream, as
// fuzz_http_session.cpp drives it: the input is what one client sends on one connection,
// then it closes its end; the first byte sets how many bytes each read returns (1..256).
// What is fuzzed is the request handling up to the parse: the token, the file name (header
// and ?filename=), its extension, Content-Length and chunked bodies against the upload limit,
// the body streamed into the upload folder, keep-alive after an answer. The parse itself is
// not: $VOLCAST_DICOM_CHECK names a checker that does not exist, so every complete upload is
// refused (422) at once by the loader, before any parser sees its bytes (the parsers have
// fuzz_volume_header and fuzz_volume_checks; a child process per input would be ~100x slower).
// The session's answer to a complete upload comes back from the store's worker thread, so each
// input runs until the session is gone, not only until the io_context runs dry.
// Invariants: the session ends by itself; its output is HTTP/1.x responses, never a 500, never
// a 201; no answer names the upload folder; after each input no upload is kept and the upload
// folder is empty (every refused, cut or abandoned upload deleted its file).

#include "fuzz/fuzz_check.hpp"
#include "server/http_session.hpp"
#include "server/shared_state.hpp"

#include <boost/asio/io_context.hpp>
#include <boost/asio/write.hpp>
#include <boost/beast/_experimental/test/stream.hpp>
#include <spdlog/sinks/null_sink.h>
#include <spdlog/spdlog.h>

#include <chrono>
#include <cstddef>
#include <cstdint>
#include <cstdlib>
#include <filesystem>
#include <memory>
#include <string>
#include <string_view>

namespace beast = boost::beast;
namespace net = boost::asio;
namespace fs = std::filesystem;
using namespace volcast;

namespace {

struct Fixture {
    fs::path top;
    std::shared_ptr<server::SharedState> state;
    std::shared_ptr<const server::HttpEndpoint> endpoint;
    net::io_context ioc;

    Fixture() {
        spdlog::set_default_logger(spdlog::null_logger_mt("fuzz-null"));
        spdlog::set_level(spdlog::level::debug);
        char pattern[] = "/tmp/volcast-fuzz-upload-XXXXXX";
        if (!mkdtemp(pattern)) fuzz::fail("cannot create the temporary folder");
        top = fs::canonical(pattern);
        fs::create_directories(top / "web");
        // A checker that is not there: a complete upload is refused before any parse.
        ::setenv("VOLCAST_DICOM_CHECK", (top / "no-checker").c_str(), 1);
        server::ServerConfig config;
        config.webRoot = top / "web";
        config.device = "cpu";
        config.token = "fuzz-token";
        config.maxUploadBytes = 64 * 1024;   // small, so that chunked bodies reach the limit
        config.maxUploadsPerAddress = 1;
        config.uploadDir = top / "uploads";
        state = std::make_shared<server::SharedState>(config);
        endpoint = std::make_shared<const server::HttpEndpoint>(server::httpEndpointFor(config, "127.0.0.1", false));
    }
    ~Fixture() {
        state->stopWorkers();
        state.reset();
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
    client.close();

    std::weak_ptr<server::BasicHttpSession<beast::test::stream>> session;
    {
        auto s = std::make_shared<server::BasicHttpSession<beast::test::stream>>(std::move(serverSide), f.state,
                                                                                 f.endpoint);
        session = s;
        s->run();
    }
    // The store's worker answers a complete upload after the io_context ran dry; libFuzzer's
    // timeout catches a session that never ends.
    while (!session.expired()) {
        ioc.restart();
        ioc.run_for(std::chrono::milliseconds(1));
    }

    const std::string_view out = client.str();
    auto &store = f.state->uploads();
    fuzz::check(store.count() == 0, "an upload was kept");
    std::error_code dirError;
    fuzz::check(fs::is_empty(store.folder(), dirError), "a file was left in the upload folder");
    if (out.empty()) return 0;
    fuzz::check(out.starts_with("HTTP/1.1 ") || out.starts_with("HTTP/1.0 "),
                "the session wrote something other than an HTTP response", out.substr(0, 200));
    fuzz::check(out.find("\r\n\r\n") != std::string_view::npos, "a response head is not terminated", out.substr(0, 200));
    // Refusals quote the file name: only a status line the input lacks counts.
    const auto answered = [&](std::string_view statusLine) {
        return out.find(statusLine) != std::string_view::npos && input.find(statusLine) == std::string_view::npos;
    };
    fuzz::check(!answered("HTTP/1.1 500") && !answered("HTTP/1.0 500"), "the session answered 500", out.substr(0, 400));
    fuzz::check(!answered("HTTP/1.1 201") && !answered("HTTP/1.0 201"), "an upload was accepted without a parse",
                out.substr(0, 400));
    // A refusal quotes the request (a Host header, say): the folder counts only where the
    // input did not hold it (libFuzzer learns the string from this very comparison).
    fuzz::check(!answered(store.folder().string()), "an answer names the upload folder", out.substr(0, 400));
    return 0;
}
