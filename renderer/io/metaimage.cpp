// MetaImage's header fields and data length (metaimage.hpp).

#include "renderer/io/metaimage.hpp"

#include <spdlog/fmt/fmt.h>

#include <algorithm>
#include <fstream>

namespace volcast::io {

constexpr size_t kMetaIoLongestFieldName = 254;   // MET_FieldRecordType::name is char[255]
constexpr int64_t kMetaIoMostDimensions = 10;      // MetaImage's per-axis arrays hold 10

std::optional<MetaLayout> scanMetaHeader(const fs::path &path) {
    std::ifstream in(path, std::ios::binary);
    std::string line;
    MetaLayout layout;
    for (int count = 0; count < 10000 && std::getline(in, line); ++count) {
        // MetaIO takes ':' as well as '=' between a field's name and value, and compares
        // names as C strings (a NUL ends one): "ElementDataFile: LIST…" and
        // "ElementDataFile<NUL>…: LIST…" were its ElementDataFile but not ours, and reached
        // MetaIO's LIST reader unchecked (a segmentation fault; fuzz finding 12). A header is
        // text: a NUL in it is refused.
        if (line.find('\0') != std::string::npos)
            fail(path, fmt::format("MetaImage header line {} holds a NUL byte; the header must be text", count + 1));
        const auto eq = line.find_first_of("=:");
        // MetaIO copies each line's field name (up to the '=' or the line's end) into a
        // 255-byte buffer unchecked: a longer one overflowed it and aborted the process
        // (fortified strcpy; fuzz finding 9).
        if (const size_t name = trim(line.substr(0, eq)).size(); name > kMetaIoLongestFieldName)
            fail(path, fmt::format("MetaImage header line {} has a field name of {} bytes; at most {} are allowed",
                                   count + 1, name, kMetaIoLongestFieldName));
        if (eq == std::string::npos) continue;
        const std::string key = lower(trim(line.substr(0, eq)));
        const std::string value = trim(line.substr(eq + 1));
        // MetaIO reads NDims values into arrays of 10 and loops NDims times over the stream
        // for DimSize and the rest: a huge NDims kept the loader reading for good (fuzz
        // finding 10).
        if (key == "ndims") {
            const auto n = parseInt(value);
            if (!n || *n < 1 || *n > kMetaIoMostDimensions)
                fail(path, fmt::format("MetaImage header's NDims is '{}'; it must be a whole number from 1 to {}",
                                       value.size() > 24 ? value.substr(0, 24) + "..." : value,
                                       kMetaIoMostDimensions));
        }
        if (key == "compresseddata") layout.compressed = lower(value) == "true";
        else if (key == "binarydata") layout.binary = lower(value) != "false";
        else if (key == "headersize") layout.headerSize = parseInt(value).value_or(0);
        else if (key == "elementdatafile") {
            // ElementDataFile is the header's last field; LOCAL data starts right after it.
            layout.dataFile = value;
            layout.multiFile = value.starts_with("LIST") || value.find('%') != std::string::npos;
            const auto pos = in.tellg();
            layout.localStart = pos < 0 ? fileSize(path).value_or(0) : uint64_t(pos);
            if (value.starts_with("LIST")) {
                // The header's remaining lines are the file names.
                while (std::getline(in, line) && layout.dataFiles.size() < 100000)
                    if (const std::string name = trim(line); !name.empty()) layout.dataFiles.push_back(name);
            } else if (layout.multiFile) {
                layout.dataFiles = expandPattern(path, value);
            } else if (value != "LOCAL") {
                layout.dataFiles = {value};
            }
            return layout;
        }
    }
    return std::nullopt;
}

void checkMetaData(const fs::path &path, const MetaLayout &layout, uint64_t need, const std::string &shape) {
    if (layout.multiFile || !layout.binary) return;
    const bool local = layout.dataFile == "LOCAL";
    const fs::path file = local ? path : confinedDataFile(path, layout.dataFile);
    const std::string where = local ? "the file" : fmt::format("data file '{}'", layout.dataFile);
    const uint64_t start = local ? layout.localStart : uint64_t(std::max<int64_t>(layout.headerSize, 0));
    if (layout.compressed) {
        checkCompressedLength(path, where, inflatedSize(file, start), need, shape);
        return;
    }
    const uint64_t size = fileSize(file).value_or(0);
    const uint64_t have = size > start ? size - start : 0;
    // HeaderSize -1 means "the data is the last bytes of the file".
    checkLength(path, where, have, need, shape, /*extraAllowed=*/!local && layout.headerSize == -1);
}

} // namespace volcast::io
