// The loader's checks that need no ITK (volume_checks.hpp).

#include "renderer/io/volume_checks.hpp"

#include <spdlog/fmt/fmt.h>
#include <spdlog/spdlog.h>
#include <zlib.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstring>
#include <exception>
#include <fstream>
#include <limits>
#include <regex>
#include <sstream>

namespace volcast::io {

void LoadProgress::operator()(double fraction, std::string_view task) {
    if (stopRequested_ && stopRequested_()) throw VolumeLoadError(path_ + ": loading was stopped");
    const double elapsed = std::chrono::duration<double>(std::chrono::steady_clock::now() - start_).count();
    if (limit_ > 0 && elapsed > limit_)
        throw VolumeLoadTimeout(fmt::format("{}: loading took longer than the time limit of {:g} s (stopped "
                                            "while {})",
                                            path_, limit_, task.empty() ? "starting" : std::string(task)),
                                limit_);
    if (!fn_) return;
    last_ = std::clamp(fraction, last_, 1.0);
    fn_(last_, task);
}

[[noreturn]] void fail(const fs::path &path, const std::string &problem) {
    throw VolumeLoadError(path.string() + ": " + problem);
}

// ---------------------------------------------------------------------------------------
// Small helpers

std::string lower(std::string s) {
    std::transform(s.begin(), s.end(), s.begin(), [](unsigned char c) { return char(std::tolower(c)); });
    return s;
}

std::string trim(const std::string &s) {
    const auto b = s.find_first_not_of(" \t\r\n");
    if (b == std::string::npos) return {};
    const auto e = s.find_last_not_of(" \t\r\n");
    return s.substr(b, e - b + 1);
}

std::string statedText(const std::string &text) {
    constexpr size_t kMaxStatedBytes = 64;
    std::string said;
    for (char c : text)
        if (c >= 0x20 && c < 0x7f && said.size() < kMaxStatedBytes) said += c;
    while (!said.empty() && said.back() == ' ') said.pop_back();
    return said;
}

std::optional<int64_t> parseInt(const std::string &s) {
    try {
        size_t used = 0;
        const long long v = std::stoll(s, &used);
        if (trim(s.substr(used)).empty()) return int64_t(v);
    } catch (const std::exception &) {
    }
    return std::nullopt;
}

std::string withThousands(uint64_t n) {
    const std::string digits = std::to_string(n);
    std::string out;
    for (size_t i = 0; i < digits.size(); ++i) {
        if (i > 0 && (digits.size() - i) % 3 == 0) out.push_back(',');
        out.push_back(digits[i]);
    }
    return out;
}

std::string humanBytes(uint64_t n) {
    if (n < 1024) return fmt::format("{} bytes", n);
    if (n < (uint64_t(1) << 20)) return fmt::format("{:.1f} KiB", double(n) / 1024.0);
    if (n < (uint64_t(1) << 30)) return fmt::format("{:.1f} MiB", double(n) / double(1 << 20));
    return fmt::format("{:.2f} GiB", double(n) / double(1 << 30));
}

std::optional<uint64_t> fileSize(const fs::path &p) {
    std::error_code ec;
    const auto size = fs::file_size(p, ec);
    if (ec) return std::nullopt;
    return uint64_t(size);
}

bool isInside(const fs::path &p, const fs::path &folder) {
    auto [f, pIt] = std::mismatch(folder.begin(), folder.end(), p.begin(), p.end());
    return f == folder.end();
}

// A data file a header names: relative to the header's folder and inside it once symbolic
// links are resolved (no absolute name, no "..", no link out), and a regular file. Only
// stat() is used, never open(): a FIFO named as data would block the loader. The messages
// name the data file as the header wrote it, never the server's absolute paths.
fs::path confinedDataFile(const fs::path &header, const std::string &name) {
    const auto refuse = [&](const std::string &why) {
        fail(header, fmt::format("data file '{}' named by the header {}", name, why));
    };
    const fs::path given(name);
    if (name.empty()) refuse("is empty");
    if (given.is_absolute() || given.has_root_name() || given.has_root_directory())
        refuse("is an absolute path; data files must lie in the header's folder (give a relative name)");
    std::error_code ec;
    const fs::path folder = fs::canonical(fs::absolute(header, ec).parent_path(), ec);
    if (ec) refuse("cannot be checked: the header's folder cannot be resolved");
    const fs::path candidate = folder / given;
    if (!fs::exists(fs::symlink_status(candidate, ec))) refuse("was not found");
    const fs::path resolved = fs::weakly_canonical(candidate, ec);
    if (ec || !fs::exists(resolved, ec)) refuse("was not found (a broken symbolic link?)");
    if (!isInside(resolved, folder))
        refuse("lies outside the header's folder (through '..' or a symbolic link); data files must lie in the "
               "header's folder");
    const auto status = fs::status(resolved, ec);
    if (ec) refuse("cannot be checked: " + ec.message());
    if (fs::is_directory(status)) refuse("is a folder, not a data file");
    if (!fs::is_regular_file(status)) refuse("is not a regular file (a FIFO, socket or device)");
    // The header read again as its own voxels: never what was meant (a file holding both says
    // so otherwise: NRRD's attached data, MetaImage's LOCAL).
    if (fs::equivalent(resolved, header, ec)) refuse("is the header's own file; the data cannot be the header itself");
    return resolved;
}

// Expands a teem/MetaIO file-name pattern ("slice%03d.raw" with min, max, step) into names.
// Only one %d conversion, with an optional 0 flag and width, is accepted: the format
// comes from an untrusted header and is never handed to printf.
std::vector<std::string> expandPattern(const fs::path &header, const std::string &spec) {
    std::istringstream in(spec);
    std::string format;
    int64_t first = 0, last = 0, step = 0;
    if (!(in >> format >> first >> last >> step))
        fail(header, fmt::format("data file pattern '{}' is not 'format min max step'", spec));
    static const std::regex conversion(R"(^([^%]*)%(0?)([0-9]{0,2})d([^%]*)$)");
    std::smatch m;
    if (!std::regex_match(format, m, conversion))
        fail(header, fmt::format("data file pattern '{}' must hold exactly one %d conversion", format));
    if (step == 0 || (step > 0 ? first > last : first < last))
        fail(header, fmt::format("data file pattern '{}' has an empty or endless range {} {} {}", format, first,
                                 last, step));
    constexpr int64_t kMaxFiles = 100000;
    const int64_t count = (last - first) / step + 1;
    if (count > kMaxFiles)
        fail(header, fmt::format("data file pattern '{}' names {} files, more than the {} allowed", format, count,
                                 kMaxFiles));
    const bool zeros = m[2].length() > 0;
    const int width = m[3].length() > 0 ? std::stoi(m[3].str()) : 0;
    std::vector<std::string> names;
    for (int64_t i = 0; i < count; ++i) {
        const int64_t n = first + i * step;
        std::string digits = std::to_string(n < 0 ? -n : n);
        const size_t signWidth = n < 0 ? 1 : 0;
        if (digits.size() + signWidth < size_t(width))
            digits.insert(0, size_t(width) - digits.size() - signWidth, zeros ? '0' : ' ');
        // One character, not a C string: GCC 12 at -O3 sees a bogus overlap (-Wrestrict) in
        // insert(pos, "-") once this function is inlined.
        if (n < 0) digits.insert(zeros ? 0 : digits.find_first_not_of(' '), 1, '-');
        names.push_back(m[1].str() + digits + m[4].str());
    }
    return names;
}

bool startsWithGzipMagic(const fs::path &file, uint64_t offset) {
    std::ifstream in(file, std::ios::binary);
    in.seekg(std::streamoff(offset));
    unsigned char magic[2] = {0, 0};
    in.read(reinterpret_cast<char *>(magic), 2);
    return in.gcount() == 2 && magic[0] == 0x1f && magic[1] == 0x8b;
}

// ---------------------------------------------------------------------------------------
// Byte counts on disk. ITK accepts raw and gzip NRRD data longer than the header says, and
// MetaImageIO and NiftiImageIO "read" truncated data into garbage (MetaIO only prints a line
// on stderr), so the loader compares what the data holds with what the header promises.

// Decompressed length of the gzip or zlib stream starting at `offset` (concatenated gzip
// members count together, trailing non-gzip bytes are ignored as teem and zlib do).
Decoded inflatedSize(const fs::path &file, uint64_t offset) {
    std::ifstream in(file, std::ios::binary);
    in.seekg(std::streamoff(offset));
    z_stream zs{};
    if (inflateInit2(&zs, 15 + 32) != Z_OK) return {};  // 15 + 32: gzip or zlib header
    std::vector<unsigned char> inBuf(size_t(1) << 16);
    std::vector<unsigned char> outBuf(size_t(1) << 18);
    // Keep the unread input and append more from the file.
    auto refill = [&] {
        const size_t keep = zs.avail_in;
        if (keep > 0) std::memmove(inBuf.data(), zs.next_in, keep);
        in.read(reinterpret_cast<char *>(inBuf.data() + keep), std::streamsize(inBuf.size() - keep));
        zs.next_in = inBuf.data();
        zs.avail_in = uInt(keep + size_t(in.gcount()));
    };
    Decoded result;
    for (;;) {
        if (zs.avail_in == 0) {
            refill();
            if (zs.avail_in == 0) break;  // the file ended inside the stream
        }
        zs.next_out = outBuf.data();
        zs.avail_out = uInt(outBuf.size());
        const int ret = inflate(&zs, Z_NO_FLUSH);
        result.bytes += outBuf.size() - zs.avail_out;
        if (ret == Z_STREAM_END) {
            result.complete = true;
            if (zs.avail_in < 2) refill();
            if (zs.avail_in >= 2 && zs.next_in[0] == 0x1f && zs.next_in[1] == 0x8b) {
                inflateReset(&zs);  // another gzip member follows
                result.complete = false;
                continue;
            }
            break;
        }
        if (ret != Z_OK && ret != Z_BUF_ERROR) break;  // corrupt stream
    }
    inflateEnd(&zs);
    return result;
}

// Fast path: a single gzip member records its length (mod 2^32) in its last 4 bytes; only
// when that disagrees is the whole stream inflated to count.
Decoded compressedSize(const fs::path &file, uint64_t offset, uint64_t expected) {
    const auto size = fileSize(file);
    if (size && *size >= offset + 18 && startsWithGzipMagic(file, offset)) {
        std::ifstream in(file, std::ios::binary);
        in.seekg(std::streamoff(*size - 4));
        unsigned char t[4] = {0, 0, 0, 0};
        in.read(reinterpret_cast<char *>(t), 4);
        const uint32_t isize = uint32_t(t[0]) | uint32_t(t[1]) << 8 | uint32_t(t[2]) << 16 | uint32_t(t[3]) << 24;
        if (in.gcount() == 4 && isize == uint32_t(expected)) return {expected, true};
    }
    return inflatedSize(file, offset);
}

// `where` names the bytes ("data file 'x.raw'"); `need` is what the header promises.
void checkLength(const fs::path &path, const std::string &where, uint64_t have, uint64_t need,
                 const std::string &shape, bool extraAllowed) {
    if (have < need)
        fail(path, fmt::format("data is truncated: {} holds {} bytes, but the header's sizes and type "
                               "({}) need {} bytes",
                               where, withThousands(have), shape, withThousands(need)));
    if (have > need && !extraAllowed)
        fail(path, fmt::format("header sizes disagree with the data: {} holds {} bytes, more than the {} "
                               "bytes the header's sizes and type ({}) need",
                               where, withThousands(have), withThousands(need), shape));
}

void checkCompressedLength(const fs::path &path, const std::string &where, const Decoded &d, uint64_t need,
                           const std::string &shape) {
    if (!d.complete)
        fail(path, fmt::format("data is truncated or corrupt: the compressed stream in {} breaks off "
                               "after {} decompressed bytes (the header's sizes and type ({}) need {} bytes)",
                               where, withThousands(d.bytes), shape, withThousands(need)));
    checkLength(path, where + " (decompressed)", d.bytes, need, shape);
}

// Offset after skipping `lines` text lines from `offset`, or nothing if the file ends first.
std::optional<uint64_t> skipLines(const fs::path &file, uint64_t offset, int64_t lines) {
    std::ifstream in(file, std::ios::binary);
    in.seekg(std::streamoff(offset));
    std::string line;
    for (int64_t i = 0; i < lines; ++i)
        if (!std::getline(in, line)) return std::nullopt;
    const auto pos = in.tellg();
    if (pos < 0) return fileSize(file);
    return uint64_t(pos);
}

// ---------------------------------------------------------------------------------------
// The volume a header describes

void checkShape(const fs::path &path, const Vec3i &dims, const LoadOptions &options) {
    const std::string sizes = fmt::format("{} x {} x {}", dims.x, dims.y, dims.z);
    for (int a = 0; a < 3; ++a) {
        if (dims[a] < 1)
            fail(path, fmt::format("size of axis {} is {} ({}); every size must be at least 1", a, dims[a], sizes));
        if (dims[a] > options.maxDimension)
            fail(path, fmt::format("size {} is absurd: axis {} has {} samples, more than the {} allowed per axis",
                                   sizes, a, dims[a], options.maxDimension));
    }
    std::optional<uint64_t> bytes = sizeof(float);
    for (int a = 0; a < 3; ++a) bytes = bytes ? checkedMul(*bytes, uint64_t(dims[a])) : std::nullopt;
    if (!bytes || *bytes > options.maxBytes)
        throw VolumeTooLarge(path.string() + ": " +
                                 fmt::format("volume of {} voxels needs {} as float32, more than the memory budget "
                                             "of {}",
                                             sizes, bytes ? humanBytes(*bytes) : std::string("more than 16 EiB"),
                                             humanBytes(options.maxBytes)),
                             bytes.value_or(std::numeric_limits<uint64_t>::max()));
}

// Spacing must be positive and finite, the direction matrix orthonormal; returns the
// direction re-orthonormalized exactly (same handedness), since Volume inverts it by transposing.
Mat3d checkedGeometry(const fs::path &path, const Vec3d &spacing, const Vec3d &origin, const Mat3d &direction) {
    for (int a = 0; a < 3; ++a) {
        if (!std::isfinite(spacing[a]) || spacing[a] <= 0)
            fail(path, fmt::format("spacing of axis {} is {}; spacings must be finite and greater than 0", a,
                                   spacing[a]));
        if (!std::isfinite(origin[a])) fail(path, fmt::format("origin of axis {} is {}", a, origin[a]));
    }
    std::array<Vec3d, 3> c;
    for (int a = 0; a < 3; ++a) c[size_t(a)] = {direction(0, a), direction(1, a), direction(2, a)};
    constexpr double kTolerance = 1e-3;
    const auto describe = [&] {
        std::string s;
        for (const auto &v : c) s += fmt::format(" ({:.6g}, {:.6g}, {:.6g})", v.x, v.y, v.z);
        return s;
    };
    for (int a = 0; a < 3; ++a) {
        const double len = length(c[size_t(a)]);
        if (!std::isfinite(len) || std::abs(len - 1) > kTolerance)
            fail(path, fmt::format("direction matrix is singular or not orthonormal: axis {} has length {:.6g} "
                                   "(axes:{})",
                                   a, len, describe()));
    }
    for (int a = 0; a < 3; ++a) {
        const int b = (a + 1) % 3;
        const double d = dot(c[size_t(a)], c[size_t(b)]);
        if (std::abs(d) > kTolerance)
            fail(path, fmt::format("direction matrix is not orthonormal: axes {} and {} are {:.3f} degrees apart, "
                                   "not 90 (axes:{})",
                                   a, b, std::acos(std::clamp(d, -1.0, 1.0)) * 180 / 3.14159265358979323846,
                                   describe()));
    }
    // Gram-Schmidt on the first two axes; the third follows from the handedness.
    const double det = dot(c[0], cross(c[1], c[2]));
    const Vec3d x = normalize(c[0]);
    const Vec3d y = normalize(c[1] - x * dot(c[1], x));
    const Vec3d z = cross(x, y) * (det < 0 ? -1.0 : 1.0);
    Mat3d out;
    for (int r = 0; r < 3; ++r) {
        out(r, 0) = x[r];
        out(r, 1) = y[r];
        out(r, 2) = z[r];
    }
    return out;
}

// NaN -> smallest finite, +Inf -> largest finite, -Inf -> smallest finite (see volume_io.hpp).
size_t replaceNonFinite(const fs::path &path, std::vector<float> &voxels) {
    float lo = std::numeric_limits<float>::max();
    float hi = std::numeric_limits<float>::lowest();
    size_t bad = 0;
    for (float x : voxels) {
        if (std::isfinite(x)) {
            lo = std::min(lo, x);
            hi = std::max(hi, x);
        } else {
            ++bad;
        }
    }
    if (bad == voxels.size())
        fail(path, fmt::format("has no finite voxel (all {} voxels are NaN or infinite)", voxels.size()));
    if (bad == 0) return 0;
    for (float &x : voxels)
        if (!std::isfinite(x)) x = (x > 0) ? hi : lo;  // NaN compares false, so it takes lo
    spdlog::warn("{}: replaced {} non-finite voxels (NaN and -Inf by the smallest finite value {}, +Inf by the "
                 "largest {})",
                 path.string(), bad, lo, hi);
    return bad;
}

std::string displayName(const fs::path &path) {
    const fs::path p = path.has_filename() ? path : path.parent_path();
    return p.filename().string();
}

} // namespace volcast::io
