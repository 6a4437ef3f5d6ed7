#include "renderer/common/minmax_bricks.hpp"
#include "renderer/reference/reconstruction.hpp"
#include "renderer/model/synthetic.hpp"

#include "test_scenes.hpp"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <functional>
#include <limits>
#include <random>
#include <string>
#include <vector>

namespace volcast {
namespace {

using test::noiseVolume;

// The volumes the bound is checked on: dims not multiples of 8 or 4, axes of 1, 2 and 3
// samples, smooth fields and white noise (the worst case for the cubic's over- and undershoot).
std::vector<Volume> boundVolumes() {
    std::vector<Volume> out;
    out.push_back(makeGaussianBlob({19, 11, 3}, {1, 1, 1}, 3.0, 100).volume);
    out.push_back(makeSphere({13, 2, 10}, {1, 1, 1}, 4.0, 0.7, 255).volume);
    out.push_back(makeSphere({1, 17, 9}, {1, 1, 1}, 5.0, 0.5, 1).volume);
    out.push_back(noiseVolume({10, 3, 2}, 1));
    out.push_back(noiseVolume({1, 2, 3}, 2));
    out.push_back(noiseVolume({17, 9, 1}, 3));
    return out;
}

// Largest amount by which `field` leaves the [min, max] of the brick holding the point, over
// every brick's box corners and `perBrick` random points inside each box.
double worstViolation(const MinMaxBricks &grid, const std::function<double(const Vec3d &)> &field,
                      int perBrick, unsigned seed) {
    std::mt19937 rng(seed);
    std::uniform_real_distribution<double> u(0, 1);
    const double B = grid.brickSize;
    double worst = -std::numeric_limits<double>::infinity();
    for (int64_t bz = 0; bz < grid.bricks.z; ++bz)
        for (int64_t by = 0; by < grid.bricks.y; ++by)
            for (int64_t bx = 0; bx < grid.bricks.x; ++bx) {
                // The brick's box [b·B − 1/2, (b+1)·B − 1/2], clamped to the volume box.
                const Vec3i b{bx, by, bz};
                Vec3d lo, hi;
                for (int a = 0; a < 3; ++a) {
                    lo[a] = double(b[a]) * B - 0.5;
                    hi[a] = std::min((double(b[a]) + 1) * B - 0.5, double(grid.dims[a]) - 0.5);
                }
                const ValueRange r = grid.range(grid.index(bx, by, bz));
                auto check = [&](const Vec3d &p) {
                    const double v = field(p);
                    worst = std::max({worst, double(r.min) - v, v - double(r.max)});
                };
                for (int c = 0; c < 8; ++c)
                    check({c & 1 ? hi.x : lo.x, c & 2 ? hi.y : lo.y, c & 4 ? hi.z : lo.z});
                for (int s = 0; s < perBrick; ++s)
                    check({lo.x + u(rng) * (hi.x - lo.x), lo.y + u(rng) * (hi.y - lo.y),
                           lo.z + u(rng) * (hi.z - lo.z)});
            }
    return worst;
}

double maxAbs(const std::vector<float> &v) {
    double m = 0;
    for (float x : v) m = std::max(m, double(std::fabs(x)));
    return m;
}

TEST(MinMaxBricks, BoundsEveryTrilinearValueInsideEachBrick) {
    for (const Volume &v : boundVolumes())
        for (int B : {8, 4, 3}) {
            const MinMaxBricks grid = buildMinMaxBricks(v.voxels.data(), v.dims, B, kTrilinearBorder);
            const TrilinearField field(v);
            // Trilinear is a convex combination of float samples evaluated as three nested
            // double lerps; each may round ≤ 2^-53 relative past its ends, so 1e-12 of the
            // largest magnitude is a wide margin over that and far below any real violation.
            const double tol = 1e-12 * (1 + maxAbs(v.voxels));
            EXPECT_LE(worstViolation(grid, field, 200, unsigned(B)), tol) << v.name << " B=" << B;
        }
}

TEST(MinMaxBricks, BoundsEveryCubicBSplineValueInsideEachBrick) {
    for (const Volume &v : boundVolumes())
        for (int B : {8, 4, 3}) {
            const CubicBSplineField field(v);
            const std::vector<float> coeffs(field.coefficients().begin(), field.coefficients().end());
            const MinMaxBricks grid = buildMinMaxBricks(coeffs.data(), v.dims, B, kCubicBSplineBorder);
            // The grid holds the float-rounded coefficients, the field the double ones: each
            // differs by ≤ 2^-24 of its magnitude, so a convex combination moves by at most
            // 2^-24 · max|c|; 2^-23 also covers the double evaluation's own rounding.
            const double tol = std::ldexp(maxAbs(coeffs), -23) + 1e-12;
            EXPECT_LE(worstViolation(grid, field, 200, unsigned(B)), tol) << v.name << " B=" << B;
        }
}

// The negative controls: a border one sample too small is caught by the same check, so the
// checks above would notice a grid that forgot the reconstruction's reach.
TEST(MinMaxBricks, ATooSmallBorderIsCaught) {
    // A spike at x = 3, the last sample of brick 0 (B = 4): without a border, brick 1's box
    // [3.5, 7.5] reads samples 4 … 7 (all 0), yet trilinear gives 0.5 at its face x = 3.5.
    Volume spike;
    spike.dims = {12, 3, 2};
    spike.voxels.assign(spike.voxelCount(), 0.f);
    for (int64_t k = 0; k < 2; ++k)
        for (int64_t j = 0; j < 3; ++j) spike.voxels[spike.index(3, j, k)] = 1.f;
    const MinMaxBricks noBorder = buildMinMaxBricks(spike.voxels.data(), spike.dims, 4, 0);
    EXPECT_NEAR(worstViolation(noBorder, TrilinearField(spike), 50, 5), 0.5, 1e-12); // exact lerp of 0 and 1

    // Samples 1/6, 2/3, 1/6 at x = 1, 2, 3 have the coefficient delta at x = 2 (up to float
    // rounding); with border 1 brick 1 reads coefficients 3 … 8 (≈ 0), yet the spline is
    // β³(1.5) = 1/48 at its face x = 3.5.
    Volume bump = spike;
    for (int64_t k = 0; k < 2; ++k)
        for (int64_t j = 0; j < 3; ++j)
            for (int64_t i = 0; i < 12; ++i)
                bump.voxels[bump.index(i, j, k)] = i == 2 ? 2.f / 3 : (i == 1 || i == 3 ? 1.f / 6 : 0.f);
    const CubicBSplineField cubic(bump);
    const std::vector<float> coeffs(cubic.coefficients().begin(), cubic.coefficients().end());
    const MinMaxBricks border1 = buildMinMaxBricks(coeffs.data(), bump.dims, 4, 1);
    // Coefficients off the delta are float-rounding small (≪ 1e-6); 1e-6 covers them.
    EXPECT_NEAR(worstViolation(border1, cubic, 50, 6), 1.0 / 48, 1e-6);
    const MinMaxBricks border2 = buildMinMaxBricks(coeffs.data(), bump.dims, 4, kCubicBSplineBorder);
    EXPECT_LE(worstViolation(border2, cubic, 50, 6), 1e-6); // as above
}

// The separable implementation against the definition, on every split of work among threads.
TEST(MinMaxBricks, MatchesTheFootprintDefinitionExactly) {
    for (Vec3i dims : {Vec3i{1, 1, 1}, Vec3i{1, 2, 3}, Vec3i{9, 8, 7}, Vec3i{16, 5, 17}, Vec3i{33, 2, 1}})
        for (int B : {1, 2, 4, 8})
            for (int border = 0; border <= std::min(B, 2); ++border)
                for (int threads : {1, 3}) {
                    const Volume v = noiseVolume(dims, unsigned(dims.x * 100 + B));
                    const MinMaxBricks g = buildMinMaxBricks(v.voxels.data(), dims, B, border, threads);
                    ASSERT_EQ(g.bricks, (Vec3i{(dims.x + B - 1) / B, (dims.y + B - 1) / B, (dims.z + B - 1) / B}));
                    ASSERT_EQ(g.minmax.size(), 2 * g.brickCount());
                    for (int64_t bz = 0; bz < g.bricks.z; ++bz)
                        for (int64_t by = 0; by < g.bricks.y; ++by)
                            for (int64_t bx = 0; bx < g.bricks.x; ++bx) {
                                const Vec3i b{bx, by, bz};
                                Vec3i lo, hi;
                                for (int a = 0; a < 3; ++a) {
                                    lo[a] = std::max<int64_t>(b[a] * B - border, 0);
                                    hi[a] = std::min<int64_t>((b[a] + 1) * B - 1 + border, dims[a] - 1);
                                }
                                float mn = std::numeric_limits<float>::infinity(), mx = -mn;
                                for (int64_t k = lo.z; k <= hi.z; ++k)
                                    for (int64_t j = lo.y; j <= hi.y; ++j)
                                        for (int64_t i = lo.x; i <= hi.x; ++i) {
                                            mn = std::min(mn, v.at(i, j, k));
                                            mx = std::max(mx, v.at(i, j, k));
                                        }
                                // Min and max select samples, they compute nothing: exact.
                                const ValueRange r = g.range(g.index(bx, by, bz));
                                EXPECT_EQ(r.min, mn);
                                EXPECT_EQ(r.max, mx);
                            }
                }
}

TEST(MinMaxBricks, BrickOfFollowsTheBrickBoxes) {
    const MinMaxBricks g = buildMinMaxBricks(std::vector<float>(20 * 3 * 1, 0.f).data(), {20, 3, 1}, 8);
    EXPECT_EQ(g.bricks, (Vec3i{3, 1, 1}));
    EXPECT_EQ(g.brickOf({-0.5, 0, 0}), (Vec3i{0, 0, 0}));
    EXPECT_EQ(g.brickOf({7.49, 0, 0}), (Vec3i{0, 0, 0}));
    EXPECT_EQ(g.brickOf({7.5, 0, 0}), (Vec3i{1, 0, 0}));
    EXPECT_EQ(g.brickOf({19.5, 2.5, 0.5}), (Vec3i{2, 0, 0}));
    EXPECT_EQ(g.brickOf({-3, 99, -7}), (Vec3i{0, 0, 0})); // clamped to the grid
}

TEST(MinMaxBricks, RejectsBadArgumentsAndSurvivesNaN) {
    const std::vector<float> one{1.f};
    EXPECT_THROW(buildMinMaxBricks(one.data(), {0, 1, 1}), std::invalid_argument);
    EXPECT_THROW(buildMinMaxBricks(one.data(), {1, 1, 1}, 0), std::invalid_argument);
    EXPECT_THROW(buildMinMaxBricks(one.data(), {1, 1, 1}, 2, 3), std::invalid_argument);
    EXPECT_THROW(buildMinMaxBricks(one.data(), {1, 1, 1}, 2, -1), std::invalid_argument);

    // Two bricks along x: the first all NaN, the second NaN and finite values.
    const float nan = std::numeric_limits<float>::quiet_NaN();
    const std::vector<float> data{nan, nan, nan, 5.f, -2.f};
    const MinMaxBricks g = buildMinMaxBricks(data.data(), {5, 1, 1}, 3, 0);
    EXPECT_EQ(g.range(0).min, std::numeric_limits<float>::infinity());
    EXPECT_EQ(g.range(0).max, -std::numeric_limits<float>::infinity());
    EXPECT_EQ(g.range(1).min, -2.f);
    EXPECT_EQ(g.range(1).max, 5.f);
    TransferFunction opaque;
    opaque.points = {{0, 1, 1, 1, 1}};
    EXPECT_EQ(classifyBricks(g, opaque), (std::vector<uint8_t>{0, 1}));
}

TransferFunction threshold(double t) {
    TransferFunction tf;
    tf.points = {{t, 1, 1, 1, 0}, {t + 10, 1, 1, 1, 0.5}};
    return tf;
}

TEST(MinMaxBricks, ThresholdTransferFunctionEmptiesTheBricksBelowIt) {
    const Volume v = makeSphere({40, 37, 35}, {1, 1, 1}, 9.0, 1.0, 100).volume;
    const MinMaxBricks g = buildMinMaxBricks(v.voxels.data(), v.dims, 8, kTrilinearBorder);
    const double t = 50;
    const std::vector<uint8_t> visible = classifyBricks(g, threshold(t));
    size_t empty = 0;
    for (size_t b = 0; b < visible.size(); ++b) {
        // Opacity is 0 at and below t and positive above it, clamped at 0.5 past t + 10.
        EXPECT_EQ(visible[b], g.range(b).max > t ? 1 : 0) << "brick " << b;
        empty += visible[b] == 0;
    }
    EXPECT_GT(empty, 0u);                 // the corners are far outside the ball
    EXPECT_LT(empty, visible.size());     // and the centre is inside it
    EXPECT_DOUBLE_EQ(emptyBrickFraction(visible), double(empty) / double(visible.size()));
    EXPECT_EQ(emptyBrickFraction({}), 0.0);
}

TEST(MinMaxBricks, ASpikeBetweenTransparentEndsIsCaught) {
    // One brick with [min, max] = [0, 10]; the opacity is 0 at both ends.
    const std::vector<float> data{0.f, 10.f};
    const MinMaxBricks g = buildMinMaxBricks(data.data(), {2, 1, 1}, 8);
    ASSERT_EQ(g.brickCount(), 1u);
    TransferFunction spike;
    spike.points = {{-5, 0, 0, 0, 0}, {4, 1, 0, 0, 0}, {5, 1, 0, 0, 0.7}, {6, 1, 0, 0, 0}, {20, 0, 0, 0, 0}};
    ASSERT_EQ(spike.evaluate(0).a, 0);
    ASSERT_EQ(spike.evaluate(10).a, 0);
    EXPECT_EQ(classifyBricks(g, spike), std::vector<uint8_t>{1});

    // The same spike outside the brick's range leaves it empty.
    TransferFunction outside = spike;
    for (ControlPoint &p : outside.points) p.value += 10; // spike at 15
    EXPECT_EQ(classifyBricks(g, outside), std::vector<uint8_t>{0});
}

TEST(MinMaxBricks, OpacityTestIsExactOnIntervalEnds) {
    TransferFunction ramp;
    ramp.points = {{0, 1, 1, 1, 0}, {10, 1, 1, 1, 1}};
    EXPECT_FALSE(opacityPositiveOn(ramp, -5, 0));    // the clamped left end is transparent
    EXPECT_TRUE(opacityPositiveOn(ramp, -5, 1e-9));  // just past it the ramp has started
    EXPECT_TRUE(opacityPositiveOn(ramp, 3, 4));      // inside a segment: the ends decide
    EXPECT_FALSE(opacityPositiveOn(ramp, 4, 3));     // an empty interval holds no value

    TransferFunction spike;
    spike.points = {{0, 1, 1, 1, 0}, {5, 1, 1, 1, 0.3}, {10, 1, 1, 1, 0}};
    EXPECT_TRUE(opacityPositiveOn(spike, 5, 5));     // a degenerate interval on the spike
    EXPECT_TRUE(opacityPositiveOn(spike, -1, 11));   // both ends transparent, spike inside
    EXPECT_FALSE(opacityPositiveOn(spike, 10, 50));  // right of the spike

    TransferFunction none;
    EXPECT_FALSE(opacityPositiveOn(none, 0, 1));     // no points: transparent everywhere
}

// The chessboard distance to the nearest visible brick, against its definition counted
// brick by brick: on grids with one, a few and many visible bricks, flat and one-brick axes,
// and none visible (the grid's largest extent, whose cube covers the grid).
TEST(MinMaxBricks, EmptyReachIsTheChessboardDistanceToTheNearestVisibleBrick) {
    std::mt19937 rng(5);
    const std::vector<Vec3i> grids{{7, 5, 6}, {1, 9, 4}, {12, 1, 1}, {1, 1, 1}, {9, 8, 10}};
    for (const Vec3i g : grids)
        for (double density : {0.0, 0.002, 0.05, 0.5}) {
            const size_t n = size_t(g.x) * size_t(g.y) * size_t(g.z);
            std::vector<uint8_t> visible(n);
            std::bernoulli_distribution on(density);
            for (uint8_t &v : visible) v = on(rng) ? 1 : 0;
            if (density == 0.002) visible[n / 2] = 1; // exactly one, somewhere inside
            const std::vector<int32_t> reach = emptyReach(visible, g);
            ASSERT_EQ(reach.size(), n);
            const int none = int(std::max({g.x, g.y, g.z}));
            for (int z = 0; z < g.z; ++z)
                for (int y = 0; y < g.y; ++y)
                    for (int x = 0; x < g.x; ++x) {
                        int nearest = none;
                        for (int qz = 0; qz < g.z; ++qz)
                            for (int qy = 0; qy < g.y; ++qy)
                                for (int qx = 0; qx < g.x; ++qx)
                                    if (visible[size_t((qz * g.y + qy) * g.x + qx)])
                                        nearest = std::min(nearest, std::max({std::abs(qx - x), std::abs(qy - y),
                                                                              std::abs(qz - z)}));
                        ASSERT_EQ(reach[size_t((z * g.y + y) * g.x + x)], nearest)
                            << "brick (" << x << ", " << y << ", " << z << ") of " << g.x << "×" << g.y << "×" << g.z
                            << ", density " << density;
                    }
        }
    EXPECT_THROW(emptyReach(std::vector<uint8_t>(5), {2, 2, 1}), std::invalid_argument);
    EXPECT_THROW(emptyReach({}, {0, 1, 1}), std::invalid_argument);
}

} // namespace
} // namespace volcast
