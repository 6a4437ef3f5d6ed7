#include "renderer/model/synthetic.hpp"

#include <gtest/gtest.h>

#include <stdexcept>

namespace volcast {
namespace {

TEST(Synthetic, SamplesAreTheFieldAtVoxelCentres) {
    for (const std::string &name : builtinVolumeNames()) {
        const SyntheticVolume s = makeBuiltinVolume(name);
        const Volume &v = s.volume;
        for (Vec3i p : {Vec3i{0, 0, 0}, Vec3i{v.dims.x - 1, v.dims.y / 2, 3}, v.dims - Vec3i{1, 1, 1}})
            // Stored as float32: relative rounding 6e-8 of values up to 255.
            EXPECT_NEAR(v.at(p.x, p.y, p.z), s.field(v.worldFromIndex(Vec3d(p))), 255 * 6e-8) << name;
        if (name != "constant_box") {
            EXPECT_LT(v.range.min, v.range.max) << name;
        }
    }
}

TEST(Synthetic, RampIsLinearAndBoxIsConstant) {
    const SyntheticVolume r = makeLinearRamp({5, 2, 2}, {2, 1, 1}, 10, 50);
    EXPECT_FLOAT_EQ(r.volume.at(0, 1, 1), 10);
    EXPECT_FLOAT_EQ(r.volume.at(4, 0, 0), 50);
    EXPECT_DOUBLE_EQ(r.field({3, 0, 0}), 25); // x = 3 world = index 1.5
    const SyntheticVolume b = makeConstantBox({3, 3, 3}, {1, 1, 1}, 7);
    EXPECT_EQ(b.volume.range.min, 7);
    EXPECT_EQ(b.volume.range.max, 7);
}

TEST(Synthetic, DemoPhantomLooksLikeAn8BitScan) {
    const SyntheticVolume d = makeDemoPhantom(48);
    EXPECT_GE(d.volume.range.min, 0);
    EXPECT_LE(d.volume.range.max, 255);
    EXPECT_GT(d.volume.range.max, 150); // bone and vessels are bright
}

TEST(Synthetic, UnknownBuiltinNamesTheKnownOnes) {
    try {
        makeBuiltinVolume("teapot");
        FAIL();
    } catch (const std::invalid_argument &e) {
        EXPECT_NE(std::string(e.what()).find("builtin:teapot"), std::string::npos);
        EXPECT_NE(std::string(e.what()).find("thin_tube"), std::string::npos);
    }
}

} // namespace
} // namespace volcast
