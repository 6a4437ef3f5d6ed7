#include "server/static_files.hpp"

#include <algorithm>

namespace volcast::server {

namespace fs = std::filesystem;

namespace {
std::optional<std::string> percentDecode(std::string_view s) {
    std::string out;
    for (size_t i = 0; i < s.size(); ++i) {
        if (s[i] != '%') {
            out += s[i];
            continue;
        }
        if (i + 2 >= s.size() || !std::isxdigit((unsigned char)s[i + 1]) || !std::isxdigit((unsigned char)s[i + 2]))
            return std::nullopt;
        out += char(std::stoi(std::string(s.substr(i + 1, 2)), nullptr, 16));
        i += 2;
    }
    return out;
}
} // namespace

std::optional<fs::path> resolveStaticFile(const fs::path &root, std::string_view target) {
    target = target.substr(0, target.find_first_of("?#"));
    if (target.empty() || target[0] != '/') return std::nullopt;
    const auto decoded = percentDecode(target);
    if (!decoded || decoded->find('\0') != std::string::npos || decoded->find('\\') != std::string::npos)
        return std::nullopt;
    // Refuse every component starting with a dot: ".." (the canonical check below would
    // catch it too, but a request that tries it is an attack, not a typo), "." (browsers
    // never send it) and dotfiles (.git/, .env, .htpasswd: never meant for the web).
    fs::path rel;
    size_t start = 1;
    while (start <= decoded->size()) {
        const size_t end = std::min(decoded->find('/', start), decoded->size());
        const std::string part = decoded->substr(start, end - start);
        if (part.starts_with('.')) return std::nullopt;
        if (!part.empty()) rel /= part;
        start = end + 1;
    }
    std::error_code ec;
    const fs::path base = fs::canonical(root, ec);
    if (ec) return std::nullopt;
    fs::path p = fs::weakly_canonical(base / rel, ec);
    if (ec) return std::nullopt;
    if (fs::is_directory(p, ec)) p /= "index.html";
    p = fs::weakly_canonical(p, ec);
    if (ec) return std::nullopt;
    // Inside the root once every link is followed.
    const auto [inBase, inP] = std::mismatch(base.begin(), base.end(), p.begin(), p.end());
    if (inBase != base.end()) return std::nullopt;
    // Nor a dotfile reached through a link.
    for (auto it = inP; it != p.end(); ++it)
        if (it->string().starts_with('.')) return std::nullopt;
    if (!fs::is_regular_file(p, ec)) return std::nullopt;
    return p;
}

std::string_view mimeType(const fs::path &path) {
    std::string ext = path.extension().string();
    std::transform(ext.begin(), ext.end(), ext.begin(), [](unsigned char c) { return char(std::tolower(c)); });
    if (ext == ".html" || ext == ".htm") return "text/html; charset=utf-8";
    if (ext == ".js" || ext == ".mjs") return "text/javascript; charset=utf-8";
    if (ext == ".css") return "text/css; charset=utf-8";
    if (ext == ".json" || ext == ".map") return "application/json";
    if (ext == ".txt" || ext == ".md") return "text/plain; charset=utf-8";
    if (ext == ".svg") return "image/svg+xml";
    if (ext == ".png") return "image/png";
    if (ext == ".jpg" || ext == ".jpeg") return "image/jpeg";
    if (ext == ".webp") return "image/webp";
    if (ext == ".ico") return "image/vnd.microsoft.icon";
    if (ext == ".wasm") return "application/wasm";
    if (ext == ".woff2") return "font/woff2";
    return "application/octet-stream";
}

} // namespace volcast::server
