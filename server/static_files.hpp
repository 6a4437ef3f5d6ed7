#pragma once
// Static files under the web root: which file a request target names (never one outside
// the root) and its MIME type.

#include <filesystem>
#include <optional>
#include <string>
#include <string_view>

namespace volcast::server {

// The file for `target` ("/app/main.js?x=1"), or nullopt when it names nothing servable:
// bad percent-encoding, NUL or backslash, a component starting with '.' (".." or a dotfile,
// also once links are resolved), a path that leaves the root once symbolic links are
// resolved, or no such regular file. A folder means its index.html.
std::optional<std::filesystem::path> resolveStaticFile(const std::filesystem::path &root, std::string_view target);

// By extension; application/octet-stream for unknown ones.
std::string_view mimeType(const std::filesystem::path &path);

} // namespace volcast::server
