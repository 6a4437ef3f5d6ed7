// Tests of the volume loader (renderer/io/) on the real scans of MANIFEST.md.

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

namespace volume_io_test {
const fs::path kDataDir = VOLCAST_DATA_DIR;  // declared in volume_io_test_helpers.hpp
} // namespace volume_io_test

namespace {

using namespace volume_io_test;

// ---------------------------------------------------------------------------------------
// The real scans of MANIFEST.md

// SHA-256 through coreutils' sha256sum (no home-made hash).
std::string sha256(const std::string &bytes) {
    const fs::path file = fs::temp_directory_path() / ("volcast_io_sha_" + std::to_string(getpid()));
    writeFile(file, bytes);
    std::string out;
    if (FILE *pipe = popen(("sha256sum '" + file.string() + "'").c_str(), "r")) {
        char buf[128] = {};
        if (std::fgets(buf, sizeof buf, pipe)) out = buf;
        pclose(pipe);
    }
    fs::remove(file);
    return out.substr(0, std::min<size_t>(64, out.size()));
}

// Loaded float voxels converted back to their native type, in the given byte order.
std::string nativeBytes(const Volume &v, bool bigEndian) {
    const std::vector<float> samples = v.samples().toFloats();
    return encode(v.sourceType, {samples.begin(), samples.end()}, bigEndian);
}

struct ScanExpectation {
    const char *header;
    Vec3i dims;
    VoxelType type;
    Vec3d spacing;
    float min, max;
    const char *littleEndianSha256;  // sha256 of the voxels as native little-endian bytes
};

// Dims, type and spacing are MANIFEST.md's table. min/max came from an independent reader
// (a python3 script with gzip + struct that decodes each data file by its header, run once
// when these tests were written) and agree with MANIFEST.md's "Stats" where it gives them
// (iguana_microct and head_mr_volume have no stats there). Values are integers or exact
// float32 values, so they are compared exactly.
Volume checkScan(const ScanExpectation &e) {
    const Volume v = loadVolume(kDataDir / e.header);
    EXPECT_EQ(v.name, e.header);
    EXPECT_EQ(v.dims, e.dims);
    EXPECT_EQ(v.sourceType, e.type) << voxelTypeName(v.sourceType);
    // The headers' decimal spacings parse to the same doubles here and in ITK/teem; 4 ULPs
    // (EXPECT_DOUBLE_EQ) only allows for a differently rounding parser.
    EXPECT_DOUBLE_EQ(v.spacing.x, e.spacing.x);
    EXPECT_DOUBLE_EQ(v.spacing.y, e.spacing.y);
    EXPECT_DOUBLE_EQ(v.spacing.z, e.spacing.z);
    // The headers carry no space origin or directions.
    EXPECT_EQ(v.origin, Vec3d(0, 0, 0));
    EXPECT_EQ(v.direction, Mat3d::identity());
    EXPECT_EQ(v.range.min, e.min);
    EXPECT_EQ(v.range.max, e.max);
    EXPECT_EQ(v.nonFiniteReplaced, 0u);
    EXPECT_TRUE(v.hasSamples());
    EXPECT_EQ(v.voxelCount(), size_t(e.dims.x * e.dims.y * e.dims.z));
    // Voxels back in their native type, little-endian: the exact decoded bytes.
    EXPECT_EQ(sha256(nativeBytes(v, false)), e.littleEndianSha256);
    return v;
}

// "voxel sha256" of MANIFEST.md (decoded little-endian or 1-byte voxel bytes).
TEST(VolumeIoRealScans, CraniumCt) {
    SKIP_WITHOUT_SCANS();
    checkScan({"cranium_ct.nhdr", {256, 256, 108}, VoxelType::Int16, {0.9570312, 0.9570312, 1.5}, -1024, 2986,
               "d87fd5e6aaf2c4fdf4f3fe28ee3335192fc2464ed8e9682fc78530cb837938da"});
}

TEST(VolumeIoRealScans, Headsq) {
    SKIP_WITHOUT_SCANS();
    checkScan({"headsq.nhdr", {64, 64, 93}, VoxelType::Int16, {3.2, 3.2, 1.5}, 0, 3926,
               "35b0a0101e612dc83ff56295b09e1ac95c8462198def11a8db1297f8aed3e5f6"});
}

TEST(VolumeIoRealScans, Lidc2ChestCt) {
    SKIP_WITHOUT_SCANS();
    checkScan({"lidc2_chest_ct.nhdr", {256, 256, 133}, VoxelType::UInt8, {1.40625, 1.40625, 2.5}, 0, 255,
               "d697a46dadafc1b2e08b9c088e7e78b905c3ddfa602f397992f54cd593ec8b25"});
}

TEST(VolumeIoRealScans, Aneurism) {
    SKIP_WITHOUT_SCANS();
    checkScan({"aneurism.nhdr", {256, 256, 256}, VoxelType::UInt8, {1, 1, 1}, 0, 255,
               "2826a66db406f19bdd9e38cfe42a80b861fbce34a947c24ce511f07f1c160b83"});
}

TEST(VolumeIoRealScans, AvmCta) {
    SKIP_WITHOUT_SCANS();
    checkScan({"avm_cta.nhdr", {337, 319, 154}, VoxelType::UInt8, {0.5469, 0.5469, 1}, 0, 255,
               "11a92b60abc4cc56e1a4e994d49bbf986607860ac4bb835efb2d83d82d70516c"});
}

TEST(VolumeIoRealScans, StentCt) {
    SKIP_WITHOUT_SCANS();
    checkScan({"stent_ct.nhdr", {128, 128, 256}, VoxelType::Int16, {1, 1, 1}, 0, 2000,
               "8431cfdc59600c1a6e2b68adeac61a8535d01cfdba236150b92101f984454da1"});
}

TEST(VolumeIoRealScans, Bonsai) {
    SKIP_WITHOUT_SCANS();
    checkScan({"bonsai.nhdr", {256, 256, 256}, VoxelType::UInt8, {1, 1, 1}, 0, 255,
               "d5c346c6c7507e88ba2bb93700d1223188f0566a93956ede73ea2df9559c2e4e"});
}

TEST(VolumeIoRealScans, Engine) {
    SKIP_WITHOUT_SCANS();
    checkScan({"engine.nhdr", {256, 256, 128}, VoxelType::UInt8, {1, 1, 1}, 0, 255,
               "0824611d5656143ee2d6fb4ad5cec3b6f64e1736b34e66217f5375da9fb63575"});
}

TEST(VolumeIoRealScans, IguanaMicroCt) {
    SKIP_WITHOUT_SCANS();
    checkScan({"iguana_microct.nhdr", {210, 256, 179}, VoxelType::UInt8, {0.1018, 0.1018, 0.1018}, 0, 229,
               "eeaf934b88e1032fb85c4e6b1d309d933fb215d23ba8fe7e682abe01435826c7"});
}

TEST(VolumeIoRealScans, Colin27MrT1) {
    SKIP_WITHOUT_SCANS();
    checkScan({"colin27_mr_t1.nhdr", {181, 217, 181}, VoxelType::UInt8, {1, 1, 1}, 0, 254,
               "38e1383cfd10824abc62dd61c9597f83ff899c82e2a84eb37737bdc83bfc9d7d"});
}

// A 1-byte raw file: MANIFEST.md's "data sha256 (= source sha256)" is of the voxel bytes.
TEST(VolumeIoRealScans, HeadMrVolume) {
    SKIP_WITHOUT_SCANS();
    checkScan({"head_mr_volume.nhdr", {48, 62, 42}, VoxelType::UInt8, {4, 4, 4}, 0, 255,
               "714ff5b2db59d3867675d0f2419c24a71ed234985b39dc1ea83ee7d72110de4b"});
}

// Big-endian raw scans. The little-endian sha256 was computed by the same python reader
// (struct '>H' / '>f', re-packed '<'); on top of it the test decodes the raw file itself
// with explicit byte swapping and compares voxel by voxel, and re-encodes the loaded
// voxels big-endian, which must reproduce MANIFEST.md's "data sha256" of the file.
template <typename T>
void checkBigEndianScan(const Volume &v, const char *dataFile, const char *fileSha256) {
    const std::string raw = readFile(kDataDir / dataFile);
    const std::vector<float> samples = v.samples().toFloats();
    ASSERT_EQ(raw.size(), samples.size() * sizeof(T));
    size_t mismatches = 0;
    for (size_t i = 0; i < samples.size(); ++i) {
        char b[sizeof(T)];
        std::memcpy(b, raw.data() + i * sizeof(T), sizeof(T));
        std::reverse(b, b + sizeof(T));
        T value;
        std::memcpy(&value, b, sizeof(T));
        if (float(value) != samples[i]) ++mismatches;
    }
    EXPECT_EQ(mismatches, 0u);
    EXPECT_EQ(sha256(nativeBytes(v, true)), fileSha256);
}

TEST(VolumeIoRealScans, ToothBigEndian) {
    SKIP_WITHOUT_SCANS();
    const Volume v = checkScan({"tooth.nhdr", {103, 94, 161}, VoxelType::UInt16, {1, 1, 1}, 0, 1300,
                                "0149b5fa6dc38d5314bae74f2644b4f76b6da98129b0156a967960b450735a74"});
    checkBigEndianScan<uint16_t>(v, "tooth.raw", "a0bbab299083a4a11155bd5142397b2c9a7910ecb6e04c43f1a315f9494ad688");
}

TEST(VolumeIoRealScans, CarotidFloatBigEndian) {
    SKIP_WITHOUT_SCANS();
    const Volume v = checkScan({"carotid_float.nhdr", {76, 49, 45}, VoxelType::Float32, {1, 1, 1}, 0, 580,
                                "9a675d4040f6ce60e8b37deda7d615912c1567c9a2d9d82e9ea5c5fcb03d8d54"});
    checkBigEndianScan<float>(v, "carotid_float.raw",
                              "a34434396659c45f3e7449d91f625b42b2aae5803cf7a65a1e960be105e51c20");
}

} // namespace
} // namespace volcast
