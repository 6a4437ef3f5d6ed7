#pragma once
// A .zip of a DICOM series, unpacked for the loader (libzip). The archive is hostile: the
// entries' own names are never used (each regular entry becomes folder/entry_00000, …, so no
// path, link or device node can come out of it), folders are skipped, links and encrypted
// entries are refused, and the entry count, the bytes unpacked and the ratio of unpacked to
// archive bytes are bounded. The bytes written are counted as they are written, whatever the
// entries' headers declare.

#include <cstdint>
#include <filesystem>
#include <stdexcept>

namespace volcast {

struct ZipLimits {
    uint64_t maxBytes = uint64_t(8) << 30;   // unpacked bytes, all entries together
    int64_t maxEntries = 10000;
    // Unpacked bytes per archive byte. Deflate cannot exceed 1032:1; a larger ratio is a bomb
    // (entries sharing their compressed bytes, or another method's runs).
    double maxRatio = 1100;
};

// Every refusal: the message names the archive as `displayName` (not a server path) and
// what was wrong.
struct ZipError : std::runtime_error {
    using std::runtime_error::runtime_error;
};

// Unpacks `archive` into `folder` (which must exist and be empty); returns the entries written.
int64_t extractZip(const std::filesystem::path &archive, const std::filesystem::path &folder,
                   const ZipLimits &limits, const std::string &displayName);

// True when `path`'s name ends in .zip (any case).
bool isZipName(const std::filesystem::path &path);

} // namespace volcast
