#pragma once
// The first gate for volume names a client sends: a name must be relative and stay inside
// the server's data folders ("bonsai", "ct/head.nrrd"). The server still resolves the name
// against its folders and checks the result (symbolic links); this only refuses names that
// can never be right, each with its own message.

#include <cstddef>
#include <cstdint>
#include <optional>
#include <string>
#include <string_view>

namespace volcast::protocol {

inline constexpr size_t kMaxVolumeNameBytes = 1024;
inline constexpr size_t kMaxVolumeNameComponentBytes = 255;   // NAME_MAX of common filesystems

// One stack of a DICOM series is named by the series' name and "#stack=N" (N from 1, no
// leading zero, at most kMaxStackNumber): "dicomweb:pacs/1.2.3/1.2.3.4#stack=2", "ct/head#stack=1".
inline constexpr std::string_view kStackSuffix = "#stack=";
inline constexpr uint32_t kMaxStackNumber = 99999;
struct StackSelection {
    std::string_view series;         // the name without the suffix
    std::optional<uint32_t> stack;   // nullopt: no suffix, the whole series
};
// The name split at its stack suffix; a name without a well-formed one is all series.
StackSelection splitStackSelection(std::string_view name);
std::string stackVolumeName(std::string_view series, uint32_t stack);

// Why the name is refused ("is an absolute path; ..."), or nullopt when it is acceptable.
// Refused: empty, longer than maxBytes, NUL or other control characters, backslashes, an
// absolute path ("/x", "C:..."), a leading "~", empty components ("a//b", "a/"), "." and
// ".." components, components longer than kMaxVolumeNameComponentBytes, and a "#stack="
// that is not followed by a stack number at the end of the name.
std::optional<std::string> validateVolumeName(std::string_view name,
                                              size_t maxBytes = kMaxVolumeNameBytes);

} // namespace volcast::protocol
