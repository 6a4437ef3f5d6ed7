// Tests of the loader's checks that hold in every format (renderer/io/volume_checks.*,
// itk_reading.*): progress, sizes and the memory budget, voxel types and components, geometry,
// the time limit and stop request, and the NaN/Inf policy.

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

TEST_F(VolumeIoTest, ProgressOfAFileRunsFromZeroToOneThroughItsSteps) {
    Volume src;
    src.dims = {40, 30, 20};
    src.voxels.assign(src.voxelCount(), 7.0f);
    saveVolume(src, dir / "p.nrrd", {VoxelType::Int32, true});
    ProgressLog log;
    loadVolume(dir / "p.nrrd", log.options());
    log.expectWellFormed();
    for (const char *task : {"reading header", "checking data", "reading voxels", "statistics"})
        EXPECT_GE(log.count(task), 1u) << task;
    // int32 to float in 16 chunks or more (8- and 16-bit files are read straight into the
    // narrow store and say "converting" once).
    EXPECT_GE(log.count("converting"), 16u);
}

// ---------------------------------------------------------------------------------------
// Files the loader refuses whatever their format

TEST_F(VolumeIoTest, UnknownTypeInHeader) {
    SKIP_WITHOUT_SCANS();
    expectLoadError(copyScan("headsq", "badtype.nhdr", {{"type", "complex"}}), {"type"});
}

TEST_F(VolumeIoTest, UnsupportedInt64Type) {
    SKIP_WITHOUT_SCANS();
    expectLoadError(copyScan("headsq", "int64.nhdr", {{"type", "int64"}}), {"type", "not supported"});
}

TEST_F(VolumeIoTest, ZeroSize) {
    SKIP_WITHOUT_SCANS();
    expectLoadError(copyScan("headsq", "zero.nhdr", {{"sizes", "0 64 93"}}), {"size"});
}

TEST_F(VolumeIoTest, AbsurdSize) {
    SKIP_WITHOUT_SCANS();
    expectLoadError(copyScan("headsq", "huge.nhdr", {{"sizes", "1000000 1000000 1000000"}}), {"size", "absurd"});
}

TEST_F(VolumeIoTest, MoreVoxelsThanMemoryBudget) {
    SKIP_WITHOUT_SCANS();
    LoadOptions small;
    small.maxBytes = 100000;  // head_mr_volume needs 124,992 x 4 bytes as float32
    expectLoadError(kDataDir / "head_mr_volume.nhdr", {"budget"}, small);
}

TEST_F(VolumeIoTest, MissingHeaderFile) { expectLoadError(dir / "nothere.nhdr", {"not found"}); }

TEST_F(VolumeIoTest, TextFileNamedNrrd) {
    writeFile(dir / "text.nrrd", "hello, I am not a volume\n");
    expectLoadError(dir / "text.nrrd", {"format"});
}

TEST_F(VolumeIoTest, FourComponentImage) {
    writeFile(dir / "rgba.nrrd", "NRRD0004\ntype: uint8\ndimension: 4\nsizes: 4 2 2 2\n"
                                 "kinds: RGBA-color domain domain domain\nencoding: raw\n\n" + std::string(32, '\0'));
    expectLoadError(dir / "rgba.nrrd", {"4 components", "scalar"});
}

TEST_F(VolumeIoTest, TimeSeriesIsNotAVolume) {
    writeFile(dir / "4d.nrrd",
              "NRRD0004\ntype: uint8\ndimension: 4\nsizes: 2 2 2 3\nencoding: raw\n\n" + std::string(24, '\0'));
    expectLoadError(dir / "4d.nrrd", {"4-d", "3-d"});
}

TEST_F(VolumeIoTest, NonOrthonormalDirections) {
    const fs::path p = writeNrrd("skew.nrrd", "uint8", {2, 2, 2}, std::string(8, '\0'), false, false, "",
                                 "space: left-posterior-superior\nspace directions: (1,0,0) (1,1,0) (0,0,1)\n");
    expectLoadError(p, {"direction", "orthonormal"});
}

TEST_F(VolumeIoTest, ZeroOrNegativeSpacing) {
    // A zero space direction gives ITK spacing 0 and a NaN direction; "spacings: -2" passes ITK.
    const fs::path zero = writeNrrd("zero_dir.nrrd", "uint8", {2, 2, 2}, std::string(8, '\0'), false, false, "",
                                    "space: left-posterior-superior\nspace directions: (1,0,0) (0,0,0) (0,0,1)\n");
    expectLoadError(zero, {"spacing"});
    const fs::path negative =
        writeNrrd("neg.nrrd", "uint8", {2, 2, 2}, std::string(8, '\0'), false, false, "", "spacings: -2 1 1\n");
    expectLoadError(negative, {"spacing"});
}

// ---------------------------------------------------------------------------------------
// Time limit and stop request, checked at every progress step

TEST_F(VolumeIoTest, LoadPastItsTimeLimitFailsNamingTheLimit) {
    Volume src;
    src.dims = {8, 8, 12};
    src.voxels.assign(src.voxelCount(), 100.0f);
    saveDicomSeries(src, dir / "slow", VoxelType::Int16);
    LoadOptions slow;
    slow.timeLimitSeconds = 0.2;
    // Each step takes 50 ms: the 12 slices alone take 0.6 s, three times the limit.
    slow.progress = [](double, std::string_view) { std::this_thread::sleep_for(std::chrono::milliseconds(50)); };
    EXPECT_THROW(loadVolume(dir / "slow", slow), VolumeLoadTimeout);
    expectLoadError(dir / "slow", {"time limit", "0.2 s"}, slow);
    // Without the limit the same load completes.
    slow.timeLimitSeconds = 0;
    EXPECT_EQ(loadVolume(dir / "slow", slow).dims, src.dims);
}

TEST_F(VolumeIoTest, StopRequestEndsTheLoad) {
    Volume src;
    src.dims = {8, 8, 4};
    src.voxels.assign(src.voxelCount(), 1.0f);
    saveVolume(src, dir / "s.nrrd");
    LoadOptions stopping;
    stopping.stopRequested = [] { return true; };
    expectLoadError(dir / "s.nrrd", {"stopped"}, stopping);
}

// ---------------------------------------------------------------------------------------
// NaN / Inf policy

TEST_F(VolumeIoTest, NonFiniteVoxelsAreReplaced) {
    const float nan = std::numeric_limits<float>::quiet_NaN(), inf = std::numeric_limits<float>::infinity();
    const std::vector<double> values = {nan, inf, -inf, 1, 2, 3, -5, 7};
    const fs::path p =
        writeNrrd("nan.nrrd", "float", {2, 2, 2}, encode(VoxelType::Float32, values, false), false, false);
    const Volume v = loadVolume(p);
    // NaN and -Inf take the smallest finite value (-5), +Inf the largest (7).
    EXPECT_EQ(v.samples().toFloats(), std::vector<float>({-5, 7, -5, 1, 2, 3, -5, 7}));
    EXPECT_EQ(v.nonFiniteReplaced, 3u);
    EXPECT_EQ(v.range.min, -5.0f);
    EXPECT_EQ(v.range.max, 7.0f);
}

TEST_F(VolumeIoTest, AllNanVolumeIsRejected) {
    const std::vector<double> values(8, std::numeric_limits<double>::quiet_NaN());
    // Big-endian gzip double, so the NaN bit patterns go through the whole decoding path.
    const fs::path p =
        writeNrrd("allnan.nrrd", "double", {2, 2, 2}, encode(VoxelType::Float64, values, true), true, true);
    expectLoadError(p, {"finite"});
}

} // namespace
} // namespace volcast
