// A request target for a static file (resolveStaticFile) on a small web root this target
// creates once: a page, a folder with an index, a file outside the root and links pointing
// out of it. Invariants: a resolved path is a regular file inside the canonical root, and
// never the file outside it.

#include "fuzz/fuzz_check.hpp"
#include "server/static_files.hpp"

#include <algorithm>
#include <cstddef>
#include <cstdint>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <string_view>

namespace fs = std::filesystem;
using namespace volcast;

namespace {
struct WebRoot {
    fs::path top;       // holds the root and the secret beside it
    fs::path root;      // canonical
    fs::path secret;    // canonical; outside the root

    WebRoot() {
        char pattern[] = "/tmp/volcast-fuzz-static-XXXXXX";
        if (!mkdtemp(pattern)) fuzz::fail("cannot create the temporary web root");
        top = fs::canonical(pattern);
        root = top / "web";
        fs::create_directories(root / "app" / "sub");
        fs::create_directories(root / "empty");
        std::ofstream(root / "index.html") << "<!doctype html>";
        std::ofstream(root / "app" / "main.js") << "export {};";
        std::ofstream(root / "app" / "sub" / "index.html") << "sub";
        std::ofstream(root / "a b%.css") << "body{}";
        secret = top / "secret.txt";
        std::ofstream(secret) << "outside the root";
        fs::create_symlink(secret, root / "escape.txt");
        fs::create_directory_symlink(top, root / "up");
        fs::create_symlink(root / "app" / "main.js", root / "inside.js");
    }
    ~WebRoot() {
        std::error_code ec;
        fs::remove_all(top, ec);
    }
};
const WebRoot &webRoot() {
    static const WebRoot r;
    return r;
}
} // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size) {
    const WebRoot &w = webRoot();
    const std::string_view target(reinterpret_cast<const char *>(data), size);
    const auto file = server::resolveStaticFile(w.root, target);
    if (!file) return 0;
    const fs::path p = fs::canonical(*file);
    fuzz::check(std::mismatch(w.root.begin(), w.root.end(), p.begin(), p.end()).first == w.root.end(),
                "a resolved static file lies outside the root", p.string());
    fuzz::check(p != w.secret, "the file outside the root was served");
    fuzz::check(fs::is_regular_file(p), "a resolved static file is not a regular file", p.string());
    return 0;
}
