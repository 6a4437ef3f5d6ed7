#pragma once
// NRRD (.nrrd, detached .nhdr): the header fields that locate the data, read by the loader
// itself (ITK reads everything else), and the data's byte count against the header's sizes.
// Internal to renderer/io/.

#include "renderer/io/volume_checks.hpp"

namespace volcast::io {

// --- NRRD: just the fields that locate the data (ITK reads everything else).
struct NrrdLayout {
    std::string encoding = "raw";
    std::optional<std::string> dataFile;  // a single detached data file, as written
    bool multiFile = false;               // LIST or a file-name pattern: lengths not checked here
    std::vector<std::string> dataFiles;   // every detached data file, in every form, as written
    int64_t lineSkip = 0;
    int64_t byteSkip = 0;
    bool attached = false;                // data follows the header's blank line
    uint64_t headerEnd = 0;
    std::vector<uint64_t> sizes;          // the "sizes:" field, each a whole number
};

// The header's layout, or nothing if the file does not start with "NRRD".
std::optional<NrrdLayout> scanNrrdHeader(const fs::path &path);

// The data holds exactly `need` bytes (raw, or gzip once decompressed); else fails.
void checkNrrdData(const fs::path &path, const NrrdLayout &layout, uint64_t need, const std::string &shape);

} // namespace volcast::io
