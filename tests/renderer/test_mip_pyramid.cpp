#include "renderer/common/mip_pyramid.hpp"
#include "renderer/reference/reconstruction.hpp"
#include "renderer/model/synthetic.hpp"

#include <gtest/gtest.h>

#include <tuple>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <random>
#include <stdexcept>
#include <string>
#include <thread>
#include <vector>

namespace volcast {
namespace {

Volume makeVolume(Vec3i dims, std::vector<float> voxels) {
    Volume v;
    v.name = "tiny";
    v.dims = dims;
    v.voxels = std::move(voxels);
    computeStatistics(v);
    return v;
}

double mean(const std::vector<float> &v) {
    double s = 0;
    for (float x : v) s += x;
    return s / double(v.size());
}

TEST(MipPyramid, LevelDimsHalveRoundingUpAndStopAtOne) {
    EXPECT_EQ(mipLevelDims({5, 1, 2}, 0), (Vec3i{5, 1, 2}));
    EXPECT_EQ(mipLevelDims({5, 1, 2}, 1), (Vec3i{3, 1, 1}));
    EXPECT_EQ(mipLevelDims({5, 1, 2}, 2), (Vec3i{2, 1, 1}));
    EXPECT_EQ(mipLevelDims({5, 1, 2}, 3), (Vec3i{1, 1, 1}));
    EXPECT_EQ(mipLevelDims({5, 1, 2}, 9), (Vec3i{1, 1, 1}));
    const Volume v = makeVolume({5, 1, 2}, std::vector<float>(10, 1.f));
    const MipPyramid pyramid(v);
    EXPECT_EQ(pyramid.maxLevel(), 3);
    EXPECT_EQ(pyramid.dims(3), (Vec3i{1, 1, 1}));
    EXPECT_EQ(MipPyramid(makeVolume({1, 1, 1}, {4.f})).maxLevel(), 0);
    EXPECT_EQ(MipPyramid(makeVolume({256, 1, 1}, std::vector<float>(256, 0.f))).maxLevel(), 8);
}

TEST(MipPyramid, AveragesBlocksAndRepeatsTheEdgeOnOddAxes) {
    // dims 3×2×1, x fastest: row y = 0 is 1 2 3, row y = 1 is 4 5 6.
    const Volume v = makeVolume({3, 2, 1}, {1, 2, 3, 4, 5, 6});
    MipPyramid pyramid(v);
    ASSERT_EQ(pyramid.dims(1), (Vec3i{2, 1, 1}));
    // Voxel 0: x {0, 1}, y {0, 1}, z {0, 0 (repeated)}: (1 + 2 + 4 + 5)·2 / 8 = 3.
    // Voxel 1: x {2, 2 (repeated)}, y {0, 1}, z repeated: (3 + 3 + 6 + 6)·2 / 8 = 4.5.
    // Quarters and halves of small integers: exact in float, hence EXPECT_EQ.
    EXPECT_EQ(pyramid.level(1).toFloats(), (std::vector<float>{3, 4.5f}));
    // Level 2 averages the two (every other axis repeats its one sample): 3.75.
    EXPECT_EQ(pyramid.level(2).toFloats(), (std::vector<float>{3.75f}));
    EXPECT_EQ(pyramid.maxLevel(), 2);
}

TEST(MipPyramid, AOneSampleAxisRepeatsItsSample) {
    const Volume v = makeVolume({1, 1, 5}, {1, 2, 3, 10, 7});
    MipPyramid pyramid(v);
    ASSERT_EQ(pyramid.dims(1), (Vec3i{1, 1, 3}));
    // Along z: (1 + 2) / 2, (3 + 10) / 2, (7 + 7) / 2; x and y repeat their one sample.
    EXPECT_EQ(pyramid.level(1).toFloats(), (std::vector<float>{1.5f, 6.5f, 7}));
    EXPECT_EQ(pyramid.level(2).toFloats(), (std::vector<float>{4, 7}));
    EXPECT_EQ(pyramid.level(3).toFloats(), (std::vector<float>{5.5f}));
}

TEST(MipPyramid, MatchesTheBlockAverageDefinitionOnALargeOddVolume) {
    // Large enough (65·64·18 coarse samples) that the downsampling splits its slices among
    // threads; odd x and z, so the clamped edge blocks are checked in 3-D too.
    const Vec3i n{129, 128, 35};
    Volume v = makeVolume(n, std::vector<float>(size_t(n.x * n.y * n.z)));
    std::mt19937 rng(8);
    std::uniform_real_distribution<float> u(-50, 50);
    for (float &x : v.voxels) x = u(rng);
    MipPyramid pyramid(v);
    const Vec3i m = pyramid.dims(1);
    ASSERT_EQ(m, (Vec3i{65, 64, 18}));
    const std::vector<float> level1 = pyramid.level(1).toFloats();
    for (int64_t K = 0; K < m.z; ++K)
        for (int64_t J = 0; J < m.y; ++J)
            for (int64_t I = 0; I < m.x; ++I) {
                double sum = 0;
                for (int c = 0; c < 8; ++c)
                    sum += v.at(std::min(2 * I + (c & 1), n.x - 1), std::min(2 * J + (c >> 1 & 1), n.y - 1),
                                std::min(2 * K + (c >> 2), n.z - 1));
                // The level is a double sum (~1e-16 relative) rounded once to float: half an
                // ulp of values < 64, 2^-19; 2^-18 ≈ 3.8e-6 leaves margin.
                ASSERT_NEAR(level1[size_t((K * m.y + J) * m.x + I)], sum / 8, std::ldexp(1.0, -18))
                    << I << " " << J << " " << K;
            }
}

TEST(MipPyramid, EvenDimsPreserveTheMean) {
    // Powers of two: every level is an exact 2×2×2 partition (a 1-sample axis repeats its
    // sample, which averages to itself), so the mean is preserved down to the last level.
    Volume v = makeVolume({16, 4, 8}, std::vector<float>(16 * 4 * 8));
    std::mt19937 rng(3);
    std::uniform_real_distribution<float> u(0, 1000);
    for (float &x : v.voxels) x = u(rng);
    MipPyramid pyramid(v);
    const double m0 = mean(v.voxels);
    for (int L = 1; L <= pyramid.maxLevel(); ++L)
        // Each level rounds each average to float (≤ 2^-24 relative, values ≤ 1000), so after
        // L ≤ 4 levels the mean moves by < 4·1000·2^-24 ≈ 2.4e-4; 1e-3 leaves margin.
        EXPECT_NEAR(mean(pyramid.level(L).toFloats()), m0, 1e-3) << "level " << L;
}

TEST(MipPyramid, AConstantVolumeStaysConstantAtEveryLevel) {
    const float c = 0.1f; // not a dyadic fraction: a sequential float sum of eight would round
    const Volume v = makeVolume({7, 5, 3}, std::vector<float>(7 * 5 * 3, c));
    MipPyramid pyramid(v);
    for (int L = 0; L <= pyramid.maxLevel(); ++L) {
        const std::vector<float> level = pyramid.level(L).toFloats();
        ASSERT_EQ(level.size(), size_t(pyramid.dims(L).x * pyramid.dims(L).y * pyramid.dims(L).z));
        // The pairwise double sum of eight equal floats is 8c exactly, and /8 is exact.
        for (float x : level) ASSERT_EQ(x, c) << "level " << L;
    }
}

TEST(MipPyramid, BuildsLevelsOnFirstRequestOnly) {
    const Volume v = makeLinearRamp({20, 12, 9}, {1, 1, 1}, 0, 1).volume;
    MipPyramid pyramid(v);
    EXPECT_EQ(pyramid.maxLevel(), 5);
    EXPECT_EQ(pyramid.levelsBuilt(), 0);
    EXPECT_EQ(pyramid.level(0).floats, v.voxels.data()); // level 0 is the volume's own samples, not a copy
    EXPECT_EQ(pyramid.dims(4), (Vec3i{2, 1, 1}));
    EXPECT_EQ(pyramid.levelsBuilt(), 0);     // neither level 0 nor dims builds anything
    const float *level3 = pyramid.level(3).floats;
    EXPECT_EQ(pyramid.levelsBuilt(), 3);     // 1, 2 and 3, once
    const float *level1 = pyramid.level(1).floats;
    EXPECT_EQ(pyramid.level(3).floats, level3); // cached: the same storage again
    EXPECT_EQ(pyramid.level(1).floats, level1);
    EXPECT_EQ(pyramid.levelsBuilt(), 3);
    pyramid.level(5);
    EXPECT_EQ(pyramid.levelsBuilt(), 5);
    EXPECT_EQ(pyramid.level(3).floats, level3); // building further levels moves none
}

// A volume held narrow (an 8- or 16-bit scan) is level 0 as it is, and its coarser levels
// are the float averages the same samples held as float give, to the bit.
TEST(MipPyramid, ANarrowLevelZeroBuildsTheLevelsItsFloatCopyBuilds) {
    // 16 and 8 bits, odd and even axes (an odd axis repeats its edge sample).
    for (const auto &[lo, hi, bytes, dims] : {std::tuple{-1024, 3071, 2, Vec3i{21, 14, 9}},
                                              std::tuple{-3000, 60000, 2, Vec3i{16, 7, 10}},
                                              std::tuple{0, 255, 1, Vec3i{13, 12, 5}}}) {
        Volume v = makeVolume(dims, std::vector<float>(size_t(dims.x * dims.y * dims.z)));
        std::mt19937 rng(5);
        std::uniform_int_distribution<int> u(lo, hi);
        for (float &x : v.voxels) x = float(u(rng));
        Volume held = v;
        ASSERT_TRUE(holdNarrow(held));
        ASSERT_EQ(held.narrow.bytes, bytes);
        MipPyramid narrow(held), wide(v);
        EXPECT_EQ(narrow.level(0).narrow, held.narrowVoxels.data()); // not a copy
        EXPECT_EQ(narrow.level(0).toFloats(), v.voxels);
        for (int L = 1; L <= narrow.maxLevel(); ++L) {
            EXPECT_FALSE(narrow.level(L).isNarrow()) << "level " << L << ": averages are held as float";
            EXPECT_EQ(narrow.level(L).toFloats(), wide.level(L).toFloats()) << "level " << L << ", " << bytes << " bytes";
        }
    }
}

TEST(MipPyramid, ConcurrentRequestsBuildOnce) {
    const Volume v = makeGaussianBlob({33, 30, 31}, {1, 1, 1}, 6, 100).volume;
    MipPyramid pyramid(v);
    std::vector<const float *> got(4);
    std::vector<std::thread> threads;
    for (size_t t = 0; t < got.size(); ++t)
        threads.emplace_back([&, t] { got[t] = pyramid.level(pyramid.maxLevel() - int(t % 2)).floats; });
    for (std::thread &th : threads) th.join();
    EXPECT_EQ(pyramid.levelsBuilt(), pyramid.maxLevel());
    EXPECT_EQ(got[0], got[2]);
    EXPECT_EQ(got[1], got[3]);
    EXPECT_EQ(got[0], pyramid.level(pyramid.maxLevel()).floats);
}

TEST(MipPyramid, LevelsOutOfRangeThrowNamingTheRange) {
    const Volume v = makeVolume({4, 4, 4}, std::vector<float>(64, 1.f));
    MipPyramid pyramid(v);
    EXPECT_THROW(pyramid.level(-1), std::out_of_range);
    EXPECT_THROW(pyramid.dims(3), std::out_of_range);
    try {
        pyramid.level(3);
        FAIL();
    } catch (const std::out_of_range &e) {
        EXPECT_NE(std::string(e.what()).find("mip level 3 is outside [0, 2]"), std::string::npos) << e.what();
    }
    EXPECT_EQ(pyramid.levelsBuilt(), 0);
}

TEST(MipPyramid, CoarseIndexMapReproducesALinearRamp) {
    // A ramp along x, 0 at the first sample and 10 at the last; level 0 index p holds 10·p/31.
    const Volume v0 = makeLinearRamp({32, 4, 6}, {0.5, 2, 1.5}, 0, 10).volume;
    auto ramp = [](double p) { return 10 * p / 31; };
    MipPyramid pyramid(v0);

    // Level 1 sampled at the centre of the level-0 pair (2j, 2j + 1) is the pair's average.
    const Volume v1 = pyramid.levelVolume(1);
    const TrilinearField level1(v1);
    for (int64_t j = 0; j < 16; ++j) {
        const Vec3d p{2 * double(j) + 0.5, 1.5, 2.5};
        const Vec3d q = mipIndexFromIndex(p, 1);
        EXPECT_DOUBLE_EQ(q.x, double(j));
        // Float samples of values ≤ 10 (rounding ≤ 6e-7 each) averaged and rounded once more:
        // 2e-6 bounds both.
        EXPECT_NEAR(level1(q), 0.5 * (double(v0.at(2 * j, 1, 2)) + double(v0.at(2 * j + 1, 1, 2))), 2e-6);
    }

    // Anywhere between the first and last coarse samples (level-0 x in [(2^L − 1)/2,
    // n − (2^L + 1)/2]) linear interpolation of the averaged ramp is the ramp itself.
    std::mt19937 rng(9);
    for (int L = 1; L <= 3; ++L) {
        const Volume vL = pyramid.levelVolume(L);
        const TrilinearField field(vL);
        const double s = std::ldexp(1.0, L);
        std::uniform_real_distribution<double> px((s - 1) / 2, 32 - (s + 1) / 2), pyz(-0.5, 3.5);
        for (int n = 0; n < 200; ++n) {
            const Vec3d p{px(rng), pyz(rng), pyz(rng)};
            const Vec3d q = mipIndexFromIndex(p, L);
            // The same world point through levelVolume's spacing and origin lands on q.
            const Vec3d qWorld = vL.indexFromWorld(v0.worldFromIndex(p));
            for (int a = 0; a < 3; ++a) EXPECT_NEAR(qWorld[a], q[a], 1e-12); // double round trip
            // Level-0 rounding (≤ 6e-7 on values ≤ 10) plus one float rounding per level
            // (L ≤ 3): below 4·6e-7 = 2.4e-6; 3e-6 leaves margin.
            EXPECT_NEAR(field(q), ramp(p.x), 3e-6) << "level " << L << " p.x " << p.x;
        }
    }
}

// A narrow store of 2 MiB or more starts on a 2 MiB boundary, so that the kernel can back it
// with huge pages (renderer/model/huge_pages.hpp: rays crossing slices otherwise miss the TLB); a
// smaller one is an ordinary block. Either holds exactly the samples.
TEST(NarrowStore, LargeStoresAreAlignedForHugePages) {
    for (const Vec3i dims : {Vec3i{256, 256, 40}, Vec3i{7, 5, 3}}) {
        Volume v = makeVolume(dims, std::vector<float>(size_t(dims.x) * size_t(dims.y) * size_t(dims.z)));
        for (size_t i = 0; i < v.voxels.size(); ++i) v.voxels[i] = float(i % 251);
        const std::vector<float> samples = v.voxels;
        ASSERT_TRUE(holdNarrow(v));
        const auto address = reinterpret_cast<uintptr_t>(v.narrowVoxels.data());
        if (v.narrowVoxels.size() >= kHugePageBytes) {
            EXPECT_EQ(address % kHugePageBytes, 0u) << v.narrowVoxels.size() << " bytes";
        }
        EXPECT_EQ(MipPyramid(v).level(0).toFloats(), samples);
    }
}

} // namespace
} // namespace volcast
