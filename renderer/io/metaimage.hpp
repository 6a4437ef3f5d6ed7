#pragma once
// MetaImage (.mhd, .mha): the header fields that locate the data, each refused where MetaIO
// would trust it unchecked, and the data's byte count. Internal to renderer/io/.

#include "renderer/io/volume_checks.hpp"

namespace volcast::io {

// --- MetaImage: the fields that locate the data.
struct MetaLayout {
    std::string dataFile;  // "LOCAL" or a file name
    bool multiFile = false;
    std::vector<std::string> dataFiles;  // every detached data file (LIST, pattern or one), as written
    bool compressed = false;
    bool binary = true;
    int64_t headerSize = 0;
    uint64_t localStart = 0;
};

// The header's layout up to ElementDataFile, or nothing if it names none.
std::optional<MetaLayout> scanMetaHeader(const fs::path &path);

// The data holds exactly `need` bytes (raw, or compressed once inflated); else fails.
void checkMetaData(const fs::path &path, const MetaLayout &layout, uint64_t need, const std::string &shape);

} // namespace volcast::io
