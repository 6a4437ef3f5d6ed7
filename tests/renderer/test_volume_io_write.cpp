// Tests of writing volumes (renderer/io/volume_write.cpp) against the loader.

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

// ITK's writers (saveVolume) and the loader agree on every format, oblique geometry included.
TEST_F(VolumeIoTest, SaveVolumeRoundTripsEveryFormat) {
    Volume src;
    src.dims = kDims;
    src.spacing = {0.6, 0.9, 1.75};
    src.origin = {-20, 5.5, 100};
    src.direction = rotation({0.3, -1, 0.5}, 40);
    const std::vector<double> values = testValues(VoxelType::Int16, kCount);
    src.voxels.assign(values.begin(), values.end());
    for (const char *name : {"w.nrrd", "w.nhdr", "w.mha", "w.mhd", "w.nii", "w.nii.gz"}) {
        for (bool compress : {false, true}) {
            SCOPED_TRACE(std::string(name) + (compress ? " compressed" : ""));
            fs::remove_all(dir);
            fs::create_directories(dir);
            saveVolume(src, dir / name, {VoxelType::Int16, compress});
            const Volume v = loadVolume(dir / name);
            expectVoxels(v, VoxelType::Int16, values);
            // NIfTI stores geometry as float32 (about 1e-7 relative); the others as decimal text.
            expectGeometry(v, src.spacing, src.origin, src.direction, 1e-5);
        }
    }
}

} // namespace
} // namespace volcast
