// The adaptive step's per-brick pieces (renderer/common/adaptive_step.hpp): the gradient bound
// holds for the reconstruction's derivative everywhere in a brick's box, and the steps follow
// the classified signal's variation (longest where it is constant, shortest where it is
// steepest, never longer than a neighbour's).

#include "renderer/common/adaptive_step.hpp"
#include "renderer/common/minmax_bricks.hpp"
#include "renderer/model/synthetic.hpp"
#include "renderer/reference/reconstruction.hpp"

#include "test_scenes.hpp"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <functional>
#include <random>
#include <vector>

namespace volcast {
namespace {

using test::noiseVolume;

// Largest amount by which |∂f/∂axis| (central differences in double) passes the brick's bound,
// over random points in every brick's box.
double worstGradientExcess(const BrickGradients &g, Vec3i dims, const std::function<double(const Vec3d &)> &field,
                           unsigned seed) {
    std::mt19937 rng(seed);
    std::uniform_real_distribution<double> u(0, 1);
    const double B = g.brickSize, h = 1e-5;
    double worst = -1e300;
    for (int64_t bz = 0; bz < g.bricks.z; ++bz)
        for (int64_t by = 0; by < g.bricks.y; ++by)
            for (int64_t bx = 0; bx < g.bricks.x; ++bx) {
                const Vec3i b{bx, by, bz};
                const float *bound = &g.maxDifference[3 * size_t((bz * g.bricks.y + by) * g.bricks.x + bx)];
                for (int s = 0; s < 60; ++s) {
                    Vec3d p;
                    for (int a = 0; a < 3; ++a) {
                        const double lo = double(b[a]) * B - 0.5 + h;
                        const double hi = std::min((double(b[a]) + 1) * B - 0.5, double(dims[a]) - 0.5) - h;
                        p[a] = lo + u(rng) * std::max(hi - lo, 0.0);
                    }
                    for (int a = 0; a < 3; ++a) {
                        Vec3d plus = p, minus = p;
                        plus[a] += h;
                        minus[a] -= h;
                        const double d = std::fabs(field(plus) - field(minus)) / (2 * h);
                        worst = std::max(worst, d - double(bound[a]));
                    }
                }
            }
    return worst;
}

std::vector<Volume> volumes() {
    return {makeGaussianBlob({19, 11, 5}, {1, 1, 1}, 3.0, 100).volume, noiseVolume({10, 9, 6}, 1),
            noiseVolume({17, 4, 3}, 2)};
}

TEST(BrickGradients, BoundEveryTrilinearDerivativeInsideEachBrick) {
    for (const Volume &v : volumes())
        for (int B : {8, 4}) {
            const BrickGradients g = buildBrickGradients(SampleGrid::ofFloats(v.dims, v.voxels.data()), B, kTrilinearBorder);
            // Central differences of a piecewise-trilinear field over 2e-5 voxels are exact up
            // to double rounding of values ~100: ~1e-14 / 1e-5 = 1e-9; 1e-6 is a wide margin
            // far below a real violation (whole sample differences, ~1–200).
            EXPECT_LE(worstGradientExcess(g, v.dims, TrilinearField(v), unsigned(B)), 1e-6) << v.name << " B=" << B;
        }
}

TEST(BrickGradients, BoundEveryCubicBSplineDerivativeInsideEachBrick) {
    for (const Volume &v : volumes())
        for (int B : {8, 4}) {
            const CubicBSplineField field(v);
            const std::vector<float> c(field.coefficients().begin(), field.coefficients().end());
            const BrickGradients g = buildBrickGradients(SampleGrid::ofFloats(v.dims, c.data()), B, kCubicBSplineBorder);
            // The bound holds float-rounded coefficients (each within 2^-24 of its magnitude,
            // a difference within 2^-23 of the largest), and central differences of a cubic
            // err by h²/6·|f'''| ≤ 1e-10·(8·max|c|): 2^-22·max|c| covers both.
            double maxC = 0;
            for (float x : c) maxC = std::max(maxC, double(std::fabs(x)));
            EXPECT_LE(worstGradientExcess(g, v.dims, field, unsigned(B)), std::ldexp(maxC, -22)) << v.name << " B=" << B;
        }
}

TEST(BrickGradients, ATooSmallBorderIsCaught) {
    // A ramp step between samples 3 and 4 (B = 4): without a border brick 1 reads samples 4 … 7
    // only (no difference), yet its box starts at 3.5, inside the cell whose slope is 1.
    Volume v;
    v.dims = {12, 3, 2};
    v.voxels.assign(v.voxelCount(), 0.f);
    for (int64_t k = 0; k < 2; ++k)
        for (int64_t j = 0; j < 3; ++j)
            for (int64_t i = 4; i < 12; ++i) v.voxels[v.index(i, j, k)] = 1.f;
    const BrickGradients g = buildBrickGradients(SampleGrid::ofFloats(v.dims, v.voxels.data()), 4, 0);
    EXPECT_NEAR(worstGradientExcess(g, v.dims, TrilinearField(v), 3), 1.0, 1e-6);
}

// A 64³ volume, 0 everywhere but a sharp step (0 → 200 over one voxel) across x = 40.5: the
// bricks touching it see a gradient of 200 per voxel, the others none.
struct StepEdge {
    Volume volume;
    MinMaxBricks grid;
    BrickGradients gradients;
    StepEdge() {
        volume.dims = {64, 64, 64};
        volume.voxels.assign(volume.voxelCount(), 0.f);
        for (int64_t k = 0; k < 64; ++k)
            for (int64_t j = 0; j < 64; ++j)
                for (int64_t i = 41; i < 64; ++i) volume.voxels[volume.index(i, j, k)] = 200.f;
        computeStatistics(volume);
        const SampleGrid s = SampleGrid::ofFloats(volume.dims, volume.voxels.data());
        grid = buildMinMaxBricks(s, 8, kTrilinearBorder);
        gradients = buildBrickGradients(s, 8, kTrilinearBorder);
    }
    float stepAtX(const AdaptiveSteps &a, int bx) const { return a.step[grid.index(bx, 3, 3)]; }
};

TransferFunction ramp() {
    TransferFunction tf;
    tf.points = {{0, 0, 0, 0, 0}, {200, 1, 1, 1, 0.5}};
    return tf;
}

AdaptiveStepInput input(bool skip = false) {
    AdaptiveStepInput in;
    in.longest = 4;
    in.shortest = 0.5;
    in.opacityUnit = 1;
    in.skipEmpty = skip;
    return in;
}

TEST(AdaptiveBrickSteps, AConstantClassificationTakesTheLongestStepEverywhere) {
    const StepEdge e;
    TransferFunction flat;
    flat.points = {{0, 0.2, 0.4, 0.6, 0.3}, {200, 0.2, 0.4, 0.6, 0.3}};
    const AdaptiveSteps a = adaptiveBrickSteps(e.grid, e.gradients, buildTfTable(flat), input());
    for (float h : a.step) ASSERT_EQ(h, 4.0f);
    EXPECT_EQ(a.referenceSlope, 0);
}

TEST(AdaptiveBrickSteps, TheEdgeTakesTheShortestStepItsNeighboursFollowAndFarBricksTheLongest) {
    const StepEdge e;
    const AdaptiveSteps a = adaptiveBrickSteps(e.grid, e.gradients, buildTfTable(ramp()), input());
    // The edge at x = 40.5 lies in brick 5 (x in [39.5, 47.5]); brick 4's footprint reaches
    // sample 40, not 41, so bricks 5 (and, by its border, nothing else) see the gradient.
    EXPECT_EQ(e.stepAtX(a, 5), 0.5f);
    // Its neighbours take its step (a segment from them may reach into it).
    EXPECT_EQ(e.stepAtX(a, 4), 0.5f);
    EXPECT_EQ(e.stepAtX(a, 6), 0.5f);
    // Farther bricks see no variation: the longest step.
    EXPECT_EQ(e.stepAtX(a, 2), 4.0f);
    EXPECT_EQ(e.stepAtX(a, 7), 4.0f);
    EXPECT_GT(a.referenceSlope, 0);
    EXPECT_GT(a.shortestFraction, 0);
    EXPECT_LT(a.shortestFraction, 0.5);
}

TEST(AdaptiveBrickSteps, SkippedBricksAreMarkedAndOnlyThey) {
    const StepEdge e;
    TransferFunction high; // only values near 200 visible
    high.points = {{0, 0, 0, 0, 0}, {150, 0, 0, 0, 0}, {200, 1, 1, 1, 0.5}};
    const std::vector<uint8_t> visible = classifyBricks(e.grid, high);
    const AdaptiveSteps a = adaptiveBrickSteps(e.grid, e.gradients, buildTfTable(high), input(true), &visible);
    for (size_t b = 0; b < visible.size(); ++b) {
        if (visible[b]) EXPECT_GT(a.step[b], 0.0f) << b;
        else EXPECT_EQ(a.step[b], -1.0f) << b;
    }
    EXPECT_EQ(e.stepAtX(a, 0), -1.0f); // all 0: transparent
    EXPECT_EQ(e.stepAtX(a, 5), 0.5f);  // the edge
    EXPECT_EQ(e.stepAtX(a, 7), 4.0f);  // 200 throughout: visible, constant
}

TEST(AdaptiveBrickSteps, StepsScaleInverselyWithTheVariation) {
    // Two edges of the same height, at x = 20.5 (0 → 100) and x = 68.5 (100 → 200).
    Volume v;
    v.dims = {96, 16, 16};
    v.voxels.assign(v.voxelCount(), 0.f);
    for (int64_t k = 0; k < 16; ++k)
        for (int64_t j = 0; j < 16; ++j)
            for (int64_t i = 0; i < 96; ++i) v.voxels[v.index(i, j, k)] = i > 20 ? (i > 68 ? 200.f : 100.f) : 0.f;
    computeStatistics(v);
    const SampleGrid s = SampleGrid::ofFloats(v.dims, v.voxels.data());
    const MinMaxBricks grid = buildMinMaxBricks(s, 8, kTrilinearBorder);
    const BrickGradients g = buildBrickGradients(s, 8, kTrilinearBorder);
    AdaptiveStepInput in = input();
    in.shortest = 0.25;
    // Both edges have a gradient of 100 per voxel; a transfer function four times as steep
    // in opacity above 100 (and with more colour there) makes the upper edge's bricks the
    // reference and the lower edge's slower: a longer step there, within the bounds.
    TransferFunction kink;
    kink.points = {{0, 0, 0, 0, 0}, {100, 0.25, 0.25, 0.25, 0.1}, {200, 1, 1, 1, 0.5}};
    const AdaptiveSteps b = adaptiveBrickSteps(grid, g, buildTfTable(kink), in);
    const float lower = b.step[grid.index(2, 1, 1)], upper = b.step[grid.index(8, 1, 1)];
    EXPECT_EQ(upper, 0.25f);
    EXPECT_GT(lower, 0.25f * 1.5f);
    EXPECT_LE(lower, 4.0f);
}

} // namespace
} // namespace volcast
