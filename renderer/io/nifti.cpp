// NIfTI's header checks, data length and read path (nifti.hpp).

#include "renderer/io/nifti.hpp"

#include <spdlog/fmt/fmt.h>
#include <spdlog/spdlog.h>
#include <zlib.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <random>
#include <utility>

namespace volcast::io {
namespace {

// --- NIfTI-1/2: the header's fields, read by the loader itself.
template <typename T>
T readScalar(const unsigned char *p, bool swap) {
    std::array<unsigned char, sizeof(T)> b;
    std::memcpy(b.data(), p, sizeof(T));
    if (swap) std::reverse(b.begin(), b.end());
    T v;
    std::memcpy(&v, b.data(), sizeof(T));
    return v;
}

// The NIfTI-1 data types and the bits per voxel the specification ties to each.
std::optional<int> niftiBitsOf(int datatype) {
    switch (datatype) {
    case 1: return 1;                                  // binary
    case 2: case 256: return 8;                        // uint8, int8
    case 4: case 512: return 16;                       // int16, uint16
    case 8: case 16: case 768: return 32;              // int32, float32, uint32
    case 128: return 24;                               // rgb24
    case 2304: return 32;                              // rgba32
    case 32: case 64: case 1024: case 1280: return 64; // complex64, float64, int64, uint64
    case 1536: case 1792: return 128;                  // float128, complex128
    case 2048: return 256;                             // complex256
    default: return std::nullopt;
    }
}

} // namespace

// Reads and checks the header fields niftilib would trust: ITK reads a header that breaks
// the specification (sizeof_hdr, dim, bitpix against datatype, vox_offset inside the
// header, pixdim 0, negative or NaN) into a zero-filled or shifted volume without a word.
// Each refusal names the field.
constexpr double kNiftiLargestCoordinate = 1e9;   // mm; squares stay far below float overflow (3.4e38)

NiftiHeader readNiftiHeader(const fs::path &path) {
    std::array<unsigned char, 540> h{};
    int got = 0;
    if (gzFile g = gzopen(path.string().c_str(), "rb")) {  // gzread also reads plain files
        got = gzread(g, h.data(), unsigned(h.size()));
        gzclose(g);
    }
    if (got < 348) fail(path, "NIfTI header is truncated");
    const int32_t sizeofHdr = readScalar<int32_t>(h.data(), false);
    const int32_t swappedSize = readScalar<int32_t>(h.data(), true);
    const bool swap = sizeofHdr != 348 && sizeofHdr != 540;
    const int32_t hdrSize = swap ? swappedSize : sizeofHdr;
    if (hdrSize != 348 && hdrSize != 540)
        fail(path, fmt::format("NIfTI header's sizeof_hdr is {}; the specification requires 348 (NIfTI-1) or 540 "
                               "(NIfTI-2)",
                               sizeofHdr));
    if (hdrSize == 540 && got < 540) fail(path, "NIfTI-2 header is truncated");
    NiftiHeader n;
    int datatype = 0;
    std::array<double, 8> pixdim{};
    int64_t rawOffset = 0;
    std::string offsetAsWritten;   // vox_offset as the header holds it, for the messages
    std::string offsetProblem;     // why it cannot be a byte offset at all, if it cannot
    uint64_t headerBytes = 352;
    int qformCode = 0, sformCode = 0;
    std::array<double, 6> quatern{};  // quatern_b, _c, _d, qoffset_x, _y, _z
    std::array<double, 12> srow{};    // srow_x, srow_y, srow_z
    if (hdrSize == 348) {
        for (size_t i = 0; i < 8; ++i) n.dim[i] = readScalar<int16_t>(h.data() + 40 + 2 * i, swap);
        datatype = readScalar<int16_t>(h.data() + 70, swap);
        n.bitpix = readScalar<int16_t>(h.data() + 72, swap);
        for (size_t i = 0; i < 8; ++i) pixdim[i] = readScalar<float>(h.data() + 76 + 4 * i, swap);
        const float off = readScalar<float>(h.data() + 108, swap);
        offsetAsWritten = fmt::format("{}", off);
        if (!std::isfinite(off)) offsetProblem = "it must be a finite number of bytes";
        else if (off < 0) offsetProblem = "a byte offset cannot be negative";
        else if (off >= 9e18f) offsetProblem = "no file is that large";
        rawOffset = offsetProblem.empty() ? int64_t(off) : -1;
        n.singleFile = std::memcmp(h.data() + 344, "n+1", 4) == 0;
        qformCode = readScalar<int16_t>(h.data() + 252, swap);
        sformCode = readScalar<int16_t>(h.data() + 254, swap);
        for (size_t i = 0; i < 6; ++i) quatern[i] = readScalar<float>(h.data() + 256 + 4 * i, swap);
        for (size_t i = 0; i < 12; ++i) srow[i] = readScalar<float>(h.data() + 280 + 4 * i, swap);
    } else {
        for (size_t i = 0; i < 8; ++i) n.dim[i] = readScalar<int64_t>(h.data() + 16 + 8 * i, swap);
        datatype = readScalar<int16_t>(h.data() + 12, swap);
        n.bitpix = readScalar<int16_t>(h.data() + 14, swap);
        for (size_t i = 0; i < 8; ++i) pixdim[i] = readScalar<double>(h.data() + 104 + 8 * i, swap);
        rawOffset = readScalar<int64_t>(h.data() + 168, swap);
        offsetAsWritten = std::to_string(rawOffset);
        if (rawOffset < 0) offsetProblem = "a byte offset cannot be negative";
        n.singleFile = std::memcmp(h.data() + 4, "n+2", 4) == 0;
        headerBytes = 544;
        qformCode = readScalar<int32_t>(h.data() + 344, swap);
        sformCode = readScalar<int32_t>(h.data() + 348, swap);
        for (size_t i = 0; i < 6; ++i) quatern[i] = readScalar<double>(h.data() + 352 + 8 * i, swap);
        for (size_t i = 0; i < 12; ++i) srow[i] = readScalar<double>(h.data() + 400 + 8 * i, swap);
    }
    if (n.dim[0] < 1 || n.dim[0] > 7)
        fail(path, fmt::format("NIfTI header's dim[0] (the number of dimensions) is {}; the specification allows "
                               "1 to 7",
                               n.dim[0]));
    for (int64_t i = 1; i <= n.dim[0]; ++i)
        if (n.dim[size_t(i)] < 1)
            fail(path, fmt::format("NIfTI header's dim[{}] (size of axis {}) is {}; every size must be at least 1",
                                   i, i - 1, n.dim[size_t(i)]));
    const auto bits = niftiBitsOf(datatype);
    if (!bits) fail(path, fmt::format("NIfTI header's datatype {} is not a NIfTI data type", datatype));
    if (n.bitpix != *bits)
        fail(path, fmt::format("NIfTI header's bitpix is {}, but its datatype {} has {} bits per voxel", n.bitpix,
                               datatype, *bits));
    if (n.bitpix % 8 != 0)
        fail(path, fmt::format("NIfTI header's datatype {} ({} bits per voxel) is not supported", datatype,
                               n.bitpix));
    for (int64_t i = 1; i <= std::min<int64_t>(n.dim[0], 3); ++i)
        if (!std::isfinite(pixdim[size_t(i)]) || pixdim[size_t(i)] <= 0)
            fail(path, fmt::format("NIfTI header's pixdim[{}] (spacing of axis {}) is {}; it must be finite and "
                                   "greater than 0",
                                   i, i - 1, pixdim[size_t(i)]));
    // niftilib builds the orientation from the quaternion (qform_code > 0) or the affine rows
    // (sform_code > 0), and ITK takes a single-precision SVD of it: on a NaN, an infinity or
    // values whose products overflow a float (-1.7e38 beside 1.5e26) that SVD never ends (fuzz
    // findings 8 and 11: the one loader spun for good). Nothing physical comes near 1e9 mm.
    // The codes are the specification's NIFTI_XFORM_* values, 0 to 5.
    for (const auto &[name, code] : {std::pair{"qform_code", qformCode}, std::pair{"sform_code", sformCode}})
        if (code < 0 || code > 5)
            fail(path, fmt::format("NIfTI header's {} is {}; the specification's codes are 0 to 5", name, code));
    const auto checkFinite = [&](const std::string &field, double v) {
        if (!std::isfinite(v) || std::abs(v) > kNiftiLargestCoordinate)
            fail(path, fmt::format("NIfTI header's {} is {}; it must be finite and at most {:g} in size", field, v,
                                   kNiftiLargestCoordinate));
    };
    for (int64_t i = 1; i <= std::min<int64_t>(n.dim[0], 3); ++i)
        checkFinite(fmt::format("pixdim[{}]", i), pixdim[size_t(i)]);
    if (qformCode > 0) {
        static constexpr const char *kNames[] = {"quatern_b", "quatern_c", "quatern_d",
                                                 "qoffset_x", "qoffset_y", "qoffset_z"};
        for (size_t i = 0; i < 6; ++i) checkFinite(kNames[i], quatern[i]);
    }
    if (sformCode > 0)
        for (size_t i = 0; i < 12; ++i)
            checkFinite(fmt::format("srow_{}[{}]", "xyz"[i / 4], i % 4), srow[i]);
    if (!offsetProblem.empty())
        fail(path, fmt::format("NIfTI header's vox_offset (where the voxels start) is {}; {}", offsetAsWritten,
                               offsetProblem));
    if (n.singleFile && uint64_t(rawOffset) < headerBytes)
        fail(path, fmt::format("NIfTI header's vox_offset is {}; in a single-file NIfTI the voxels start after "
                               "the {}-byte header",
                               offsetAsWritten, headerBytes));
    n.voxOffset = uint64_t(std::max<int64_t>(rawOffset, 0));
    std::optional<uint64_t> bytes = uint64_t(n.bitpix / 8);
    for (int64_t i = 1; i <= n.dim[0]; ++i) {
        bytes = bytes ? checkedMul(*bytes, uint64_t(n.dim[size_t(i)])) : std::nullopt;
        n.shape += (n.shape.empty() ? "" : " x ") + std::to_string(n.dim[size_t(i)]);
    }
    if (!bytes) fail(path, "header sizes are absurd (the voxel count overflows)");
    n.bytes = *bytes;
    n.shape += fmt::format(", {} bits per voxel, data at byte {}", n.bitpix, n.voxOffset);
    return n;
}

// NiftiImageIO reports a size of 0 as 1 and reads short data without complaint, so the
// data's length is checked against the header's own fields.
void checkNiftiData(const fs::path &path, const NiftiHeader &n) {
    fs::path dataFile = path;
    std::string where = "the file";
    if (!n.singleFile) {
        // A .hdr/.img pair (NIfTI "ni1"/"ni2" or Analyze): the voxels are in the .img file.
        std::string stem = path.string();
        const bool gz = stem.ends_with(".gz");
        if (gz) stem.resize(stem.size() - 3);
        if (!lower(stem).ends_with(".hdr")) return;
        stem.resize(stem.size() - 4);
        dataFile = fs::path(stem + (gz ? ".img.gz" : ".img"));
        if (!fs::exists(dataFile)) dataFile = fs::path(stem + (gz ? ".img" : ".img.gz"));
        if (!fs::exists(dataFile))
            fail(path, fmt::format("data file '{}' named by the header was not found",
                                   fs::path(stem + ".img").filename().string()));
        const std::string name = dataFile.filename().string();
        dataFile = confinedDataFile(path, name);
        where = fmt::format("data file '{}'", name);
    }
    const uint64_t need = n.voxOffset + n.bytes;
    if (startsWithGzipMagic(dataFile, 0)) {
        checkCompressedLength(path, where, compressedSize(dataFile, 0, need), need, n.shape);
    } else {
        checkLength(path, where, fileSize(dataFile).value_or(0), need, n.shape);
    }
}

// niftilib looks for a single-file image's voxels in "x.nii" before "x.nii.gz", whatever
// name it was given: with both side by side, loading x.nii.gz would pair its header with
// x.nii's bytes. Such a file is read through a link in a folder of its own.
fs::path niftiReadPath(const fs::path &path, TemporaryLink &alias) {
    const std::string name = path.string();
    if (!lower(name).ends_with(".nii.gz")) return path;
    const fs::path sibling(name.substr(0, name.size() - 3));
    if (!fs::exists(sibling)) return path;
    std::random_device random;
    alias.folder = fs::temp_directory_path() / fmt::format("volcast_nifti_{:08x}{:08x}", random(), random());
    std::error_code ec;
    fs::create_directories(alias.folder, ec);
    if (!ec) fs::create_symlink(fs::absolute(path), alias.folder / path.filename(), ec);
    if (ec)
        fail(path, fmt::format("'{}' lies beside it and the NIfTI library would read that file's voxels instead; "
                               "move one of the two away",
                               sibling.filename().string()));
    alias.link = alias.folder / path.filename();
    spdlog::info("{}: '{}' lies beside it; reading through a link so that the NIfTI library takes the right voxels",
                 path.string(), sibling.filename().string());
    return alias.link;
}

} // namespace volcast::io
