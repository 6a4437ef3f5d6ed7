// Tests of DICOM series loading (renderer/io/dicom_series.*): a series written by saveDicomSeries,
// a single slice, progress slice by slice, two series in one folder, and damaged series.

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

TEST_F(VolumeIoTest, DicomSeriesFolder) {
    Volume src;
    src.dims = {6, 5, 4};
    src.spacing = {0.7, 0.8, 2.5};
    src.origin = {-100, -120.5, 50};
    src.voxels.resize(src.voxelCount());
    for (size_t i = 0; i < src.voxels.size(); ++i) src.voxels[i] = float(int(i) * 37 - 1024);  // CT-like int16
    saveDicomSeries(src, dir / "series", VoxelType::Int16);
    size_t files = 0;
    for (const auto &entry : fs::directory_iterator(dir / "series")) files += entry.path().extension() == ".dcm";
    EXPECT_EQ(files, 4u);

    const Volume v = loadVolume(dir / "series");
    EXPECT_EQ(v.name, "series");
    EXPECT_EQ(v.dims, src.dims);
    EXPECT_EQ(v.sourceType, VoxelType::Int16);
    EXPECT_EQ(v.samples().toFloats(), src.voxels);  // int16 values, exact
    EXPECT_EQ(v.narrow.bytes, 2) << "held in 16 bits";
    // DICOM stores decimal strings (10 significant digits here), the z spacing is the
    // distance between slice positions: 1e-6 covers both.
    expectGeometry(v, src.spacing, src.origin, Mat3d::identity(), 1e-6);

    // One file of the series on its own is a one-slice volume at that slice's position.
    const Volume slice = loadVolume(dir / "series" / "slice_0002.dcm");
    EXPECT_EQ(slice.dims, Vec3i(6, 5, 1));
    EXPECT_EQ(slice.samples().toFloats(),
              std::vector<float>(src.voxels.begin() + 60, src.voxels.begin() + 90));
    EXPECT_NEAR(slice.origin.z, 50 + 2 * 2.5, 1e-6);  // decimal string in the file, as above
}

TEST_F(VolumeIoTest, ProgressOfADicomSeriesAdvancesSliceBySlice) {
    Volume src;
    src.dims = {8, 8, 12};
    src.voxels.assign(src.voxelCount(), 100.0f);
    saveDicomSeries(src, dir / "slices", VoxelType::Int16);
    ProgressLog log;
    loadVolume(dir / "slices", log.options());
    log.expectWellFormed();
    std::vector<double> slices;
    for (const auto &[f, task] : log.steps)
        if (task == "reading slices" && (slices.empty() || f > slices.back())) slices.push_back(f);
    EXPECT_GE(slices.size(), 6u) << "12 slices should advance the bar in several steps";
}

TEST_F(VolumeIoTest, DicomFolderWithTwoSeriesLoadsOne) {
    // Two series of different sizes in one folder: the loader takes one of them whole (the
    // first GDCM lists, logged) rather than mixing slices of both.
    Volume a, b;
    a.dims = {6, 5, 4};
    b.dims = {3, 3, 2};
    for (Volume *v : {&a, &b}) {
        v->spacing = {1, 1, 2};
        v->voxels.resize(v->voxelCount());
        for (size_t i = 0; i < v->voxels.size(); ++i) v->voxels[i] = float(i) + (v == &a ? 0.0f : 1000.0f);
    }
    saveDicomSeries(a, dir / "both", VoxelType::Int16);
    saveDicomSeries(b, dir / "b", VoxelType::Int16);
    for (const auto &entry : fs::directory_iterator(dir / "b"))
        fs::rename(entry.path(), dir / "both" / ("b_" + entry.path().filename().string()));
    const Volume v = loadVolume(dir / "both");
    const Volume &expected = v.dims == a.dims ? a : b;
    EXPECT_EQ(v.dims, expected.dims);
    EXPECT_EQ(v.samples().toFloats(), expected.voxels);
}

TEST_F(VolumeIoTest, FolderWithoutDicom) {
    fs::create_directories(dir / "empty_series");
    writeFile(dir / "empty_series" / "readme.txt", "no images here\n");
    expectLoadError(dir / "empty_series", {"no dicom"});
}

// ---------------------------------------------------------------------------------------
// Damaged DICOM series

// A slice cut short: GDCM would read the missing pixels as zeros.
TEST_F(VolumeIoTest, DicomSeriesWithATruncatedSlice) {
    Volume src;
    src.dims = {6, 5, 4};
    src.voxels.resize(src.voxelCount());
    for (size_t i = 0; i < src.voxels.size(); ++i) src.voxels[i] = float(int(i) * 37 - 1024);
    saveDicomSeries(src, dir / "series", VoxelType::Int16);
    const fs::path slice = dir / "series" / "slice_0002.dcm";
    fs::resize_file(slice, fs::file_size(slice) - 10);
    expectLoadError(dir / "series", {"slice_0002.dcm", "truncated"});
    // The same file on its own, as a one-slice volume.
    expectLoadError(slice, {"truncated"});
}

// A series whose slices do not form one regular stack would load as a picture with the wrong
// geometry and no word of it; the loader refuses it, naming the slices.
Volume obliqueSeriesVolume() {
    Volume src;
    src.dims = {6, 5, 7};
    src.spacing = {0.7, 0.7, 2.5};
    src.origin = {10, -20, 30};
    const double c = std::cos(0.4), s = std::sin(0.4);
    src.direction.m = {c, 0, s, 0, 1, 0, -s, 0, c};
    src.voxels.resize(src.voxelCount());
    for (size_t i = 0; i < src.voxels.size(); ++i) src.voxels[i] = float(int(i) * 37 - 1024);
    return src;
}

TEST_F(VolumeIoTest, DicomSeriesWithAMissingSliceIsRefusedNamingTheGap) {
    saveDicomSeries(obliqueSeriesVolume(), dir / "series", VoxelType::Int16);
    EXPECT_EQ(loadVolume(dir / "series").dims.z, 7) << "the whole oblique stack loads";
    fs::remove(dir / "series" / "slice_0003.dcm");
    expectLoadError(dir / "series", {"slice_0002.dcm", "slice_0004.dcm", "5 mm", "2.5 mm", "missing"});
}

TEST_F(VolumeIoTest, DicomSeriesWithASliceTwiceIsRefused) {
    saveDicomSeries(obliqueSeriesVolume(), dir / "series", VoxelType::Int16);
    fs::copy_file(dir / "series" / "slice_0004.dcm", dir / "series" / "slice_0004_again.dcm");
    expectLoadError(dir / "series", {"same position"});
}

} // namespace
} // namespace volcast
