#pragma once
// The first gate for volume names a client sends: a name must be relative and stay inside
// the server's data folders ("bonsai", "ct/head.nrrd"). The server still resolves the name
// against its folders and checks the result (symbolic links); this only refuses names that
// can never be right, each with its own message.

#include <cstddef>
#include <optional>
#include <string>
#include <string_view>

namespace volcast::protocol {

inline constexpr size_t kMaxVolumeNameBytes = 1024;
inline constexpr size_t kMaxVolumeNameComponentBytes = 255;   // NAME_MAX of common filesystems

// Why the name is refused ("is an absolute path; ..."), or nullopt when it is acceptable.
// Refused: empty, longer than maxBytes, NUL or other control characters, backslashes, an
// absolute path ("/x", "C:..."), a leading "~", empty components ("a//b", "a/"), "." and
// ".." components, and components longer than kMaxVolumeNameComponentBytes.
std::optional<std::string> validateVolumeName(std::string_view name,
                                              size_t maxBytes = kMaxVolumeNameBytes);

} // namespace volcast::protocol
