#pragma once
// The loader's checks that need no ITK (volume_io.hpp says what is accepted): each step's
// progress, time limit and stop request; the sizes and memory budget a header gives, its
// geometry; the data files a header names (inside its folder, regular files) and their byte
// counts; the non-finite voxel policy. Internal to renderer/io/.

#include "renderer/io/volume_io.hpp"

#include <chrono>
#include <cstdint>
#include <filesystem>
#include <functional>
#include <limits>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

namespace volcast::io {

namespace fs = std::filesystem;

// LoadOptions::progress, kept from going backwards; every step is also where the time
// limit and a stop request end the load.
class LoadProgress {
  public:
    LoadProgress(const LoadOptions &options, const std::filesystem::path &path)
        : fn_(options.progress), stopRequested_(options.stopRequested), limit_(options.timeLimitSeconds),
          path_(path.string()) {}
    void operator()(double fraction, std::string_view task);

  private:
    std::function<void(double, std::string_view)> fn_;
    std::function<bool()> stopRequested_;
    double limit_ = 0;
    std::string path_;
    std::chrono::steady_clock::time_point start_ = std::chrono::steady_clock::now();
    double last_ = 0;
};

// Throws VolumeLoadError("<path>: <problem>"): every refusal starts with the path given.
[[noreturn]] void fail(const fs::path &path, const std::string &problem);

// A load that ran out of memory (std::bad_alloc): the DICOM checker tells it apart from
// every other refusal, since its memory limit, not the file's header, may be the cause.
struct LoadOutOfMemory : VolumeLoadError {
    using VolumeLoadError::VolumeLoadError;
};

// ---------------------------------------------------------------------------------------
// Small helpers

std::string lower(std::string s);
std::string trim(const std::string &s);
std::optional<int64_t> parseInt(const std::string &s);
std::string withThousands(uint64_t n);
// Header text fit for a sentence and the checker's hand-back (a modality statement):
// printable ASCII only, at most 64 bytes, no trailing spaces.
std::string statedText(const std::string &text);
std::string humanBytes(uint64_t n);

// Multiplication that reports overflow instead of wrapping (sizes come from untrusted headers).
inline std::optional<uint64_t> checkedMul(uint64_t a, uint64_t b) {
    if (a != 0 && b > std::numeric_limits<uint64_t>::max() / a) return std::nullopt;
    return a * b;
}

std::optional<uint64_t> fileSize(const fs::path &p);
bool isInside(const fs::path &p, const fs::path &folder);

// ---------------------------------------------------------------------------------------
// Data files a header names

// Resolved inside the header's folder, a regular file, checked with stat() only; else fails.
fs::path confinedDataFile(const fs::path &header, const std::string &name);
// The names a teem/MetaIO pattern ("slice%03d.raw min max step") stands for.
std::vector<std::string> expandPattern(const fs::path &header, const std::string &spec);
bool startsWithGzipMagic(const fs::path &file, uint64_t offset);

// Byte counts on disk: what the data holds against what the header promises.
struct Decoded {
    uint64_t bytes = 0;
    bool complete = false;  // the stream ended properly (false: truncated or corrupt)
};
// Decompressed length of the gzip or zlib stream starting at `offset`.
Decoded inflatedSize(const fs::path &file, uint64_t offset);
// The same, reading a single gzip member's recorded length first when it is `expected`.
Decoded compressedSize(const fs::path &file, uint64_t offset, uint64_t expected);
// `where` names the bytes ("data file 'x.raw'"); `need` is what the header promises.
void checkLength(const fs::path &path, const std::string &where, uint64_t have, uint64_t need,
                 const std::string &shape, bool extraAllowed = false);
void checkCompressedLength(const fs::path &path, const std::string &where, const Decoded &d, uint64_t need,
                           const std::string &shape);
// Offset after skipping `lines` text lines from `offset`, or nothing if the file ends first.
std::optional<uint64_t> skipLines(const fs::path &file, uint64_t offset, int64_t lines);

// ---------------------------------------------------------------------------------------
// The volume a header describes

// Every axis at least 1 and at most LoadOptions::maxDimension; float32 bytes within
// LoadOptions::maxBytes (else VolumeTooLarge).
void checkShape(const fs::path &path, const Vec3i &dims, const LoadOptions &options);
// Spacing positive and finite, direction orthonormal; the direction re-orthonormalized.
Mat3d checkedGeometry(const fs::path &path, const Vec3d &spacing, const Vec3d &origin, const Mat3d &direction);
// The non-finite policy of volume_io.hpp; returns how many voxels it replaced.
size_t replaceNonFinite(const fs::path &path, std::vector<float> &voxels);
// The file's or folder's own name, the volume's name.
std::string displayName(const fs::path &path);

} // namespace volcast::io
