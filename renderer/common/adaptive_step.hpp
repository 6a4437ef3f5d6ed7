#pragma once
// The adaptive step (quality.adaptive_step; Quatrin Campagnolo, Celes and de Figueiredo,
// SIBGRAPI 2015, in its per-brick form): each brick of the min-max grid gets a segment length
// from a bound on how fast the classified signal can change inside it, short where it may
// change fast, long where it cannot.
//
// The estimate. A segment sampled at its centre (the midpoint rule) of length h over an
// integrand f with |f'| ≤ L errs by at most L·h²/4, so by L·h/4 per unit length. Along a ray
// the integrand is the transfer function's sigma (and colour, weighted by sigma) of the
// reconstructed field, so
//     L_b = max over the brick's values of |d sigma/dv| + sigma·|d colour/dv|   (the table's)
//         × a bound on the field's gradient in the brick (world units)         (BrickGradients)
//         / the opacity unit.
// Steps equidistribute that bound: h_b = h_min · L_ref / L_b, clamped to [h_min, h_max], so
// that everywhere the error bound per unit length is at most what it is at the shortest step
// on the reference slope L_ref (a high quantile of the bricks' L_b, so that one steep brick
// does not make every other brick's step long). A brick whose values the transfer function
// maps to one constant (L_b = 0, transparent bricks among them) takes the longest step.
//
// Segments cross brick walls: a segment starting in brick b takes the smallest step of b and
// its 26 neighbours, and the longest step is at most a brick's edge on every axis, so a
// segment lies in b and its neighbours and is never longer than any of their steps.

#include "renderer/common/minmax_bricks.hpp"
#include "renderer/common/narrow_samples.hpp"
#include "renderer/common/tf_table.hpp"

#include <cstdint>
#include <vector>

namespace volcast {

// The shortest segment is the longest (quality.step) over this.
inline constexpr double kAdaptiveStepRange = 8;
// The reference slope L_ref: this quantile of the bricks' L_b > 0.
inline constexpr double kAdaptiveReferenceQuantile = 0.9;

// Per brick of a min-max grid, a bound on the reconstruction's partial derivative along each
// axis in the brick's box, in data units per level voxel: the largest difference between
// neighbouring samples (trilinear, border 1) or B-spline coefficients (cubic, border 2) that
// the box reads. Trilinear's derivative along x in a cell blends the cell's four x-edge
// differences, the cubic B-spline's blends coefficient differences with the quadratic
// B-spline's weights (≥ 0, sum 1): either is bounded by the largest difference read.
struct BrickGradients {
    int brickSize = 8, border = 1;
    Vec3i bricks{0, 0, 0};
    std::vector<float> maxDifference; // x, y, z per brick, bricks x fastest
};

// Samples b·B − border … (b+1)·B − 1 + border per axis (minmax_bricks.hpp's footprint), every
// neighbouring pair inside it. NaN differences are ignored. threads = 0: all cores.
BrickGradients buildBrickGradients(const SampleGrid &data, int brickSize, int border, int threads = 0);

// What a frame's steps depend on besides the bricks.
struct AdaptiveStepInput {
    double longest = 1, shortest = 1 / kAdaptiveStepRange; // world units
    double opacityUnit = 1;                                 // world units
    Vec3d levelVoxel{1, 1, 1};   // world length of a level voxel along each axis
    bool skipEmpty = false;      // transparent bricks get a step of −1: the march skips them
};

struct AdaptiveSteps {
    std::vector<float> step;     // per brick, world units (−1: skipped)
    double referenceSlope = 0;   // L_ref, per world unit², 0 when nothing varies
    double shortestFraction = 0; // bricks (not skipped) at the shortest step
    double meanStep = 0;         // over bricks not skipped, world units
};

// The steps of `grid`'s bricks for the transfer function tabulated in `table`; `visible`
// (classifyBricks) names the bricks skipped when input.skipEmpty.
AdaptiveSteps adaptiveBrickSteps(const MinMaxBricks &grid, const BrickGradients &gradients, const TfTable &table,
                                 const AdaptiveStepInput &input, const std::vector<uint8_t> *visible = nullptr);

} // namespace volcast
