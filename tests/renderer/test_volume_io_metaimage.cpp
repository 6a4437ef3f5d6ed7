// Tests of MetaImage loading (renderer/io/metaimage.*): .mhd and .mha, and damaged headers and data.

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

TEST_F(VolumeIoTest, MetaImageDetachedMhdAndAttachedMha) {
    const std::vector<double> values = testValues(VoxelType::Int16, kCount);
    // .mhd + raw, little-endian, with an axis permutation (TransformMatrix lists the index
    // axes' world directions one after another, as ITK reads it) and an offset.
    writeFile(dir / "vol.mhd", "ObjectType = Image\nNDims = 3\nDimSize = 5 4 3\nElementType = MET_SHORT\n"
                               "ElementSpacing = 0.5 0.75 2.25\nTransformMatrix = 0 1 0 0 0 1 1 0 0\n"
                               "Offset = 1 2 3\nElementByteOrderMSB = False\nElementDataFile = vol.raw\n");
    writeFile(dir / "vol.raw", encode(VoxelType::Int16, values, false));
    const Volume mhd = loadVolume(dir / "vol.mhd");
    expectVoxels(mhd, VoxelType::Int16, values);
    Mat3d d;
    d.m = {0, 0, 1, 1, 0, 0, 0, 1, 0};
    expectGeometry(mhd, {0.5, 0.75, 2.25}, {1, 2, 3}, d);

    // .mha with the data attached, big-endian.
    writeFile(dir / "vol.mha", "ObjectType = Image\nNDims = 3\nDimSize = 5 4 3\nElementType = MET_SHORT\n"
                               "ElementSpacing = 0.5 0.75 2.25\nElementByteOrderMSB = True\nElementDataFile = LOCAL\n" +
                                   encode(VoxelType::Int16, values, true));
    const Volume mha = loadVolume(dir / "vol.mha");
    expectVoxels(mha, VoxelType::Int16, values);
    EXPECT_EQ(mha.spacing, Vec3d(0.5, 0.75, 2.25));
}

// MetaIO copies a field name into a 255-byte buffer without a check: a name of 255 bytes or
// more aborted the process in MetaIO's fortified strcpy (fuzz finding 9), with or without
// an '=' on its line. 254 is the longest it takes.
TEST_F(VolumeIoTest, MetaImageFieldNameLongerThanMetaIoTakesIsRefusedNotACrash) {
    const std::string tail = "NDims = 3\nDimSize = 2 2 2\nElementType = MET_UCHAR\nElementDataFile = LOCAL\n" +
                             std::string(8, '\1');
    writeFile(dir / "long_name.mha", "ObjectType = Image\n" + std::string(255, 'K') + " = 1\n" + tail);
    expectLoadError(dir / "long_name.mha", {"line 2", "255 bytes", "at most 254"});
    writeFile(dir / "long_line.mha", std::string(300, 'K') + "\n" + tail);
    expectLoadError(dir / "long_line.mha", {"line 1", "300 bytes"});
    // The longest name MetaIO takes loads as before (an unknown field, ignored).
    writeFile(dir / "ok_name.mha", "ObjectType = Image\n" + std::string(254, 'K') + " = 1\n" + tail);
    EXPECT_EQ(loadVolume(dir / "ok_name.mha").dims, Vec3i(2, 2, 2));
}

// MetaIO loops NDims times reading the header's per-axis values into arrays of 10: a huge
// NDims kept the loader reading for good (fuzz finding 10).
TEST_F(VolumeIoTest, MetaImageNDimsOutsideOneToTenIsRefusedBeforeMetaIoLoopsOnIt) {
    const std::string rest = "DimSize = 2 2 2\nElementType = MET_UCHAR\nElementDataFile = LOCAL\n" + std::string(8, '\1');
    writeFile(dir / "huge_ndims.mha", "ObjectType = Image\nNDims = " + std::string(120, '9') + "\n" + rest);
    expectLoadError(dir / "huge_ndims.mha", {"ndims", "1 to 10"});
    writeFile(dir / "eleven.mha", "ObjectType = Image\nNDims = 11\n" + rest);
    expectLoadError(dir / "eleven.mha", {"ndims is '11'"});
    writeFile(dir / "zero.mha", "ObjectType = Image\nNDims = 0\n" + rest);
    expectLoadError(dir / "zero.mha", {"ndims is '0'"});
}

// MetaIO reads "Name: value" as "Name = value", and a NUL ends a name: both spellings of
// ElementDataFile reached its LIST reader without the loader's data-file checks (a crash;
// fuzz finding 12). The colon form is now checked like the other; a NUL is refused.
TEST_F(VolumeIoTest, MetaImageColonSeparatorIsCheckedAndANulIsRefused) {
    const std::string head = "ObjectType = Image\nNDims = 3\nDimSize = 2 2 2\nElementType = MET_UCHAR\n";
    writeFile(dir / "colon.mha", head + "ElementDataFile: LIST\nmissing_a.raw\nmissing_b.raw\n");
    expectLoadError(dir / "colon.mha", {"missing_a.raw"});
    writeFile(dir / "nul.mha", head + std::string("ElementDataFile\0x: LIST\n", 24) + "a.raw\n");
    expectLoadError(dir / "nul.mha", {"line 5", "nul"});
    // The colon form of a sound header loads as the '=' form does.
    writeFile(dir / "colon_ok.mha", head + "ElementDataFile: LOCAL\n" + std::string(8, '\1'));
    EXPECT_EQ(loadVolume(dir / "colon_ok.mha").dims, Vec3i(2, 2, 2));
}

TEST_F(VolumeIoTest, TruncatedMetaImage) {
    // MetaIO prints "data not read completely" and ITK returns garbage; the loader refuses.
    writeFile(dir / "short.mha", "ObjectType = Image\nNDims = 3\nDimSize = 2 2 2\nElementType = MET_UCHAR\n"
                                 "ElementDataFile = LOCAL\n" + std::string(5, '\1'));
    expectLoadError(dir / "short.mha", {"truncated"});
    writeFile(dir / "short.mhd", "ObjectType = Image\nNDims = 3\nDimSize = 2 2 2\nElementType = MET_UCHAR\n"
                                 "ElementDataFile = short.raw\n");
    writeFile(dir / "short.raw", std::string(7, '\1'));
    expectLoadError(dir / "short.mhd", {"truncated"});
    // Compressed: ITK prints "Uncompress failed" and carries on.
    const std::string z = gzipBytes(std::string(8, '\1'));
    writeFile(dir / "short_z.mha", "ObjectType = Image\nNDims = 3\nDimSize = 2 2 2\nElementType = MET_UCHAR\n"
                                   "CompressedData = True\nElementDataFile = LOCAL\n" + z.substr(0, z.size() / 2));
    expectLoadError(dir / "short_z.mha", {"truncated"});
}

} // namespace
} // namespace volcast
