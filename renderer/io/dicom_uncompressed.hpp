#pragma once
// A DICOM series whose slices are stored uncompressed, little-endian, one grey frame per file
// (what CT and MR scanners and most PACS send): its headers parsed and its pixels copied
// straight from the files, in one pass over each. ITK's series scan and GDCM's slice reads
// took ~17 µs a kilobyte of such a series (2.5 s for 150 MiB), where Orthanc served it in 0.7 s.
//
// The reader takes a series only where the result is the one ITK and GDCM give for it, byte
// for byte (tests/renderer/test_volume_io_dicom.cpp compares them): anything else (another
// transfer syntax, several frames, colour, a rescale GDCM might treat otherwise, slices that
// differ where GDCM's series scan would split them, a damaged file) returns nothing, and the
// caller goes through ITK and GDCM, whose checks and messages stay the only ones a damaged
// series meets. Internal to renderer/io/; no ITK or GDCM here.

#include "renderer/io/volume_checks.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdlib>
#include <cstdint>
#include <optional>
#include <span>
#include <string>
#include <string_view>
#include <vector>

namespace volcast::io {

// What the reader needs of one slice's header, and where its pixels lie in the file.
struct UncompressedSlice {
    std::string file;               // the name within the folder
    std::string seriesUid;          // (0020,000E)
    std::string sopClass;           // (0002,0002), which (0008,0016) must repeat where present
    std::string details;            // the values GDCM's series scan also splits by, as stored
    std::string modality;           // (0008,0060), as stored
    int64_t rows = 0, columns = 0;
    int bitsAllocated = 0, bitsStored = 0;
    bool isSigned = false;          // Pixel Representation 1
    Vec3d position{0, 0, 0};                 // Image Position (Patient), mm
    std::array<double, 6> orientation{};     // Image Orientation (Patient): row, then column cosines
    std::array<double, 2> pixelSpacing{};    // between rows (y), between columns (x), mm
    double intercept = 0;                    // Rescale Intercept (the slope is 1: nothing else is taken)
    uint64_t pixelOffset = 0, pixelLength = 0;   // the Pixel Data value in the file
};

// A DICOM decimal string (DS) holding exactly N finite numbers separated by backslashes
// (spaces and NUL padding ignored), or nothing. Parsed here for GDCM's path too, rather than
// by its attribute classes, whose assertions a hostile value could reach.
template <size_t N>
std::optional<std::array<double, N>> decimalStrings(std::string_view text) {
    if (text.empty() || text.size() > 1024) return std::nullopt;
    std::array<double, N> out{};
    size_t count = 0, at = 0;
    while (at <= text.size()) {
        const size_t end = std::min(text.find('\\', at), text.size());
        std::string item;
        for (char c : text.substr(at, end - at))
            if (c != ' ' && c != '\0') item += c;
        char *stop = nullptr;
        const double x = std::strtod(item.c_str(), &stop);
        if (item.empty() || *stop != '\0' || !std::isfinite(x) || count == N) return std::nullopt;
        out[count++] = x;
        at = end + 1;
    }
    if (count != N) return std::nullopt;
    return out;
}

// The slice whose first bytes are `bytes` (the whole file or its start), or nothing when it
// is not one this reader takes; then `why` says what it met first. Reads nothing outside
// `bytes`; a header that does not end within them is not taken.
std::optional<UncompressedSlice> parseUncompressedSlice(std::span<const unsigned char> bytes, std::string &why);

// A series every file of the folder belongs to, in stack order (ascending along the normal
// of the rows and columns, as GDCM sorts), with one pixel format, orientation and rescale.
struct UncompressedSeries {
    std::vector<UncompressedSlice> slices;
    VoxelType type = VoxelType::Int16;   // the samples' type after rescaling, as GDCM names it
};

// The folder's series when this reader takes it (every entry a regular file, see
// checkDicomFolderEntries), else nothing, `why` saying what it met first. Reads only headers.
// With `only`, just those files of the folder (one stack of its series, checkSeriesIdentity).
std::optional<UncompressedSeries> scanUncompressedSeries(const fs::path &dir, std::string &why,
                                                         const std::optional<std::vector<std::string>> &only = std::nullopt);

// v placed as ITK's series reader places the series: dims, spacing, origin and direction
// (checked), the type after rescaling, modality, orientation known. No samples yet.
void placeUncompressedSeries(const fs::path &dir, const UncompressedSeries &series, Volume &v);

// The series' samples into v's narrow store (v placed, its dims checked against the memory
// budget), slice by slice with progress from `from` to `to`, packed as narrowWidth and
// packNarrow would hold them. Each file is opened anew (not following links, refused unless
// regular) and must still hold its slice's bytes at the offset given.
void readUncompressedSamples(const fs::path &dir, const UncompressedSeries &series, LoadProgress &progress,
                             double from, double to, Volume &v);

} // namespace volcast::io
