// Tests of NIfTI loading (renderer/io/nifti.*): .nii and .nii.gz, the scale slope, damaged data,
// and each header field the specification constrains.

#include "volume_io_test_helpers.hpp"

#include "renderer/io/volume_io.hpp"

#include <gtest/gtest.h>
#include <zlib.h>

#include <algorithm>
#include <bit>
#include <cctype>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstring>
#include <chrono>
#include <filesystem>
#include <future>
#include <thread>
#include <fstream>
#include <initializer_list>
#include <limits>
#include <numbers>
#include <sstream>
#include <string>
#include <vector>

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

namespace volcast {
namespace {

using namespace volume_io_test;

// A NIfTI-1 single-file header (348 bytes + 4 bytes of empty extension flag).
std::string niftiHeader(const Vec3i &dims, int16_t datatype, int16_t bitpix, const float sform[3][4],
                        float slope = 1, float intercept = 0) {
    std::string h(352, '\0');
    auto put = [&](size_t offset, auto value) { std::memcpy(h.data() + offset, &value, sizeof value); };
    put(0, int32_t(348));
    const int16_t dim[8] = {3, int16_t(dims.x), int16_t(dims.y), int16_t(dims.z), 1, 1, 1, 1};
    for (size_t i = 0; i < 8; ++i) put(40 + 2 * i, dim[i]);
    put(70, datatype);
    put(72, bitpix);
    const float pixdim[8] = {1, std::hypot(sform[0][0], sform[1][0], sform[2][0]),
                             std::hypot(sform[0][1], sform[1][1], sform[2][1]),
                             std::hypot(sform[0][2], sform[1][2], sform[2][2]), 1, 1, 1, 1};
    for (size_t i = 0; i < 8; ++i) put(76 + 4 * i, pixdim[i]);
    put(108, 352.0f);  // vox_offset
    put(112, slope);
    put(116, intercept);
    put(252, int16_t(0));  // qform_code: unused
    put(254, int16_t(2));  // sform_code: aligned
    for (size_t r = 0; r < 3; ++r)
        for (size_t c = 0; c < 4; ++c) put(280 + 16 * r + 4 * c, sform[r][c]);
    std::memcpy(h.data() + 344, "n+1", 4);
    return h;
}

// sform columns: index x along world y (spacing 2), y along z (3), z along x (4); origin
// (10, 20, 30) in RAS, which ITK turns into LPS.
constexpr float kSform[3][4] = {{0, 0, 4, 10}, {2, 0, 0, 20}, {0, 3, 0, 30}};
const Mat3d kSformLps = [] {
    Mat3d d;
    d.m = {0, 0, -1, -1, 0, 0, 0, 1, 0};
    return d;
}();

// vol.nii and vol.nii.gz side by side on purpose: niftilib, asked for vol.nii.gz, takes its
// header but looks for the voxels in vol.nii first; the loader must not mix the two.
TEST_F(VolumeIoTest, NiftiNiAndNiiGz) {
    const std::vector<double> shorts = testValues(VoxelType::Int16, kCount);
    writeFile(dir / "vol.nii", niftiHeader(kDims, 4, 16, kSform) + encode(VoxelType::Int16, shorts, false));
    const Volume nii = loadVolume(dir / "vol.nii");
    expectVoxels(nii, VoxelType::Int16, shorts);
    expectGeometry(nii, {2, 3, 4}, {-10, -20, 30}, kSformLps, 1e-6);  // float32 header fields

    const std::vector<double> floats = testValues(VoxelType::Float32, kCount);
    writeFile(dir / "vol.nii.gz",
              gzipBytes(niftiHeader(kDims, 16, 32, kSform) + encode(VoxelType::Float32, floats, false)));
    const Volume gz = loadVolume(dir / "vol.nii.gz");
    expectVoxels(gz, VoxelType::Float32, floats);
    expectGeometry(gz, {2, 3, 4}, {-10, -20, 30}, kSformLps, 1e-6);
}

TEST_F(VolumeIoTest, NiftiScaleSlopeIsApplied) {
    // uint8 stored values 0..59 with scl_slope 2.5, scl_inter -1: ITK hands back float32
    // physical values (exact here: multiples of 0.5).
    std::vector<double> stored(kCount);
    for (size_t i = 0; i < kCount; ++i) stored[i] = double(i);
    writeFile(dir / "scaled.nii",
              niftiHeader(kDims, 2, 8, kSform, 2.5f, -1.0f) + encode(VoxelType::UInt8, stored, false));
    const Volume v = loadVolume(dir / "scaled.nii");
    std::vector<double> physical(kCount);
    for (size_t i = 0; i < kCount; ++i) physical[i] = 2.5 * stored[i] - 1;
    expectVoxels(v, VoxelType::Float32, physical);
}

TEST_F(VolumeIoTest, TruncatedNifti) {
    // NiftiImageIO reads a short .nii or a cut .nii.gz without any error.
    const std::string full =
        niftiHeader(kDims, 4, 16, kSform) + encode(VoxelType::Int16, testValues(VoxelType::Int16, kCount), false);
    writeFile(dir / "short.nii", full.substr(0, full.size() - 10));
    expectLoadError(dir / "short.nii", {"truncated"});
    const std::string gz = gzipBytes(full);
    writeFile(dir / "cut.nii.gz", gz.substr(0, gz.size() - 30));
    expectLoadError(dir / "cut.nii.gz", {"truncated"});
    writeFile(dir / "long.nii", full + "extra bytes");
    expectLoadError(dir / "long.nii", {"size", "disagree"});
}

TEST_F(VolumeIoTest, NiftiZeroSize) {
    // NiftiImageIO reports a size of 0 as 1; the loader reads the header's own dims.
    writeFile(dir / "zero.nii", niftiHeader({5, 0, 3}, 2, 8, kSform) + std::string(15, '\0'));
    expectLoadError(dir / "zero.nii", {"size"});
}

// ---------------------------------------------------------------------------------------
// Damaged NIfTI headers: each breaks one rule of the NIfTI-1 specification, which ITK
// would read into a zero-filled or shifted volume. The refusal names the field.

template <typename T>
std::string patched(std::string bytes, size_t offset, T value) {
    std::memcpy(bytes.data() + offset, &value, sizeof value);
    return bytes;
}

class VolumeIoNiftiHeader : public VolumeIoTest {
  protected:
    // A valid int16 .nii of kDims with one header field replaced.
    template <typename T>
    fs::path writeWith(const std::string &name, size_t offset, T value) {
        const std::string good =
            niftiHeader(kDims, 4, 16, kSform) + encode(VoxelType::Int16, testValues(VoxelType::Int16, kCount), false);
        writeFile(dir / name, patched(good, offset, value));
        return dir / name;
    }
};

TEST_F(VolumeIoNiftiHeader, ValidHeaderLoads) {  // the baseline the others break
    EXPECT_EQ(loadVolume(writeWith("ok.nii", 70, int16_t(4))).dims, kDims);
}
TEST_F(VolumeIoNiftiHeader, SizeofHdrNot348) {
    expectLoadError(writeWith("header_size.nii", 0, int32_t(350)), {"sizeof_hdr", "348"});
}
TEST_F(VolumeIoNiftiHeader, DimZeroOutsideOneToSeven) {
    expectLoadError(writeWith("rank_zero.nii", 40, int16_t(0)), {"dim[0]"});
    expectLoadError(writeWith("rank_eight.nii", 40, int16_t(8)), {"dim[0]"});
}
TEST_F(VolumeIoNiftiHeader, NegativeDim) {
    expectLoadError(writeWith("negative_size.nii", 44, int16_t(-4)), {"dim[2]", "-4"});
}
TEST_F(VolumeIoNiftiHeader, BitpixNotMatchingDatatype) {
    // int16 data (datatype 4) declared with 8 bits per voxel.
    expectLoadError(writeWith("bits.nii", 72, int16_t(8)), {"bitpix", "datatype 4"});
}
TEST_F(VolumeIoNiftiHeader, UnknownDatatype) {
    expectLoadError(writeWith("type3.nii", 70, int16_t(3)), {"datatype 3"});
}
TEST_F(VolumeIoNiftiHeader, VoxOffsetInsideTheHeader) {
    expectLoadError(writeWith("early_data.nii", 108, 100.0f), {"vox_offset", "100"});
}
// Each named as written, with why it cannot be where the voxels start (not as one made-up -1).
TEST_F(VolumeIoNiftiHeader, VoxOffsetNotAByteOffsetIsNamedAsWritten) {
    expectLoadError(writeWith("huge_offset.nii", 108, 1e30f), {"vox_offset", "1e+30", "no file is that large"});
    expectLoadError(writeWith("nan_offset.nii", 108, std::numeric_limits<float>::quiet_NaN()),
                    {"vox_offset", "nan", "finite"});
    expectLoadError(writeWith("negative_offset.nii", 108, -4096.0f), {"vox_offset", "-4096", "negative"});
}
TEST_F(VolumeIoNiftiHeader, ZeroPixdim) {
    expectLoadError(writeWith("zero_spacing.nii", 80, 0.0f), {"pixdim[1]"});
}
TEST_F(VolumeIoNiftiHeader, NegativePixdim) {
    expectLoadError(writeWith("negative_spacing.nii", 84, -3.0f), {"pixdim[2]"});
}
TEST_F(VolumeIoNiftiHeader, NanPixdim) {
    expectLoadError(writeWith("nan_spacing.nii", 88, std::numeric_limits<float>::quiet_NaN()), {"pixdim[3]"});
}
// ITK's orientation SVD never ended on a NaN in the affine rows (fuzz finding 8): the load
// must fail at once, naming the field, not spin the loader (ctest's timeout caught it before).
TEST_F(VolumeIoNiftiHeader, NanInTheSformRowsIsRefusedBeforeItkLoopsOnIt) {
    expectLoadError(writeWith("nan_srow.nii", 280 + 16 * 1 + 4 * 2, std::numeric_limits<float>::quiet_NaN()),
                    {"srow_y[2]", "finite"});
    expectLoadError(writeWith("inf_srow.nii", 280, std::numeric_limits<float>::infinity()), {"srow_x[0]"});
}
// Finite but huge affine rows overflowed inside the single-precision SVD, which then never
// ended either (fuzz finding 11: -1.7e38 beside 1.5e26).
TEST_F(VolumeIoNiftiHeader, HugeAffineRowsAndSpacingsAreRefused) {
    expectLoadError(writeWith("huge_srow.nii", 280 + 16 * 1 + 4 * 1, -1.7e38f), {"srow_y[1]", "at most 1e+09"});
    expectLoadError(writeWith("huge_offset.nii", 280 + 16 * 2 + 4 * 3, 2e9f), {"srow_z[3]"});
    expectLoadError(writeWith("huge_spacing.nii", 80, 1e12f), {"pixdim[1]", "at most 1e+09"});
}
TEST_F(VolumeIoNiftiHeader, NanInTheQuaternionIsRefused) {
    const std::string good =
        niftiHeader(kDims, 4, 16, kSform) + encode(VoxelType::Int16, testValues(VoxelType::Int16, kCount), false);
    std::string bad = patched(good, 252, int16_t(1));  // qform_code: scanner
    const float nan = std::numeric_limits<float>::quiet_NaN();
    bad.replace(260, sizeof nan, reinterpret_cast<const char *>(&nan), sizeof nan);  // quatern_c
    writeFile(dir / "nan_quatern.nii", bad);
    expectLoadError(dir / "nan_quatern.nii", {"quatern_c", "finite"});
}
TEST_F(VolumeIoNiftiHeader, TransformCodesOutsideTheSpecificationAreRefused) {
    expectLoadError(writeWith("sform_code.nii", 254, int16_t(18789)), {"sform_code", "18789"});
    expectLoadError(writeWith("qform_code.nii", 252, int16_t(-1)), {"qform_code", "-1"});
}

} // namespace
} // namespace volcast
