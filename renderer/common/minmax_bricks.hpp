#pragma once
// Min-max brick grid for empty-space skipping (docs/design.md `empty_space_skipping`; Open VKL's
// value ranges). The grid is built once per data array; classifying it against a transfer
// function is the cheap step redone on every transfer-function change.
//
// Guarantee. Brick b along an axis of n samples covers the continuous index-space interval
// [b·B − 1/2, (b+1)·B − 1/2] (clamped to the volume box [−1/2, n − 1/2]); its [min, max]
// bounds every value the reconstruction produces at any point of that box, because
//   - trilinear on voxels (border 1): a point p reads samples floor(p) and floor(p) + 1,
//     clamped to [0, n − 1], so the box reads samples b·B − 1 … (b+1)·B;
//   - cubic B-spline on prefiltered coefficients (border 2): the value is a convex
//     combination (weights ≥ 0, sum 1) of the 4³ coefficients floor(p) − 1 … floor(p) + 2
//     under mirror boundaries, so the box reads b·B − 2 … (b+1)·B + 1, and for border ≤ B
//     the mirrored indices of those stay inside the clamped range used here (as do clamped
//     ones, should a kernel clamp coefficient indices instead of mirroring them);
// and the min and max of the samples a convex combination reads bound the combination (also
// with hardware-filtered fetches, whose quantised weights are still ≥ 0 and sum to 1).
// The stored values are the exact float min/max of those samples; a float-precision
// reconstruction (GPU lerp) may round up to an ulp past them.

#include "renderer/model/math.hpp"
#include "renderer/model/transfer_function.hpp"
#include "renderer/model/volume.hpp"

#include <cstddef>
#include <cstdint>
#include <vector>

namespace volcast {

// Samples each side of a brick that a reconstruction reads (see the guarantee above).
inline constexpr int kTrilinearBorder = 1;
inline constexpr int kCubicBSplineBorder = 2;

struct MinMaxBricks {
    int brickSize = 8;          // samples per brick along each axis (B)
    int border = 1;             // samples read beyond the brick on each side
    Vec3i dims{0, 0, 0};        // samples of the data the grid was built from
    Vec3i bricks{0, 0, 0};      // ceil(dims / brickSize) per axis
    std::vector<float> minmax;  // min, max per brick, bricks x fastest

    size_t brickCount() const { return size_t(bricks.x) * size_t(bricks.y) * size_t(bricks.z); }
    size_t index(int64_t bx, int64_t by, int64_t bz) const {
        return size_t((bz * bricks.y + by) * bricks.x + bx);
    }
    ValueRange range(size_t brick) const { return {minmax[2 * brick], minmax[2 * brick + 1]}; }
    // Brick whose box holds index-space point p, clamped to the grid: floor((p + 1/2) / B).
    Vec3i brickOf(const Vec3d &indexPos) const;
};

// Builds the grid over `data` (dims.x fastest). Samples b·B − border … (b+1)·B − 1 + border,
// clamped to [0, n − 1], count for brick b. Needs dims ≥ 1, brickSize ≥ 1 and
// 0 ≤ border ≤ brickSize (std::invalid_argument otherwise). NaN samples are ignored; a brick
// of NaN only gets min = +inf, max = −inf and classifies as empty. threads = 0: all cores.
MinMaxBricks buildMinMaxBricks(const SampleGrid &data, int brickSize = 8, int border = kTrilinearBorder,
                               int threads = 0);
inline MinMaxBricks buildMinMaxBricks(const float *data, Vec3i dims, int brickSize = 8,
                                      int border = kTrilinearBorder, int threads = 0) {
    return buildMinMaxBricks(SampleGrid::ofFloats(dims, data), brickSize, border, threads);
}

// True where the transfer function's opacity is > 0 somewhere in [lo, hi]: exact for a
// piecewise-linear function, whose maximum on an interval lies at an end or a control point.
bool opacityPositiveOn(const TransferFunction &tf, double lo, double hi);

// 1 for each brick whose [min, max] the transfer function makes visible, 0 for empty ones.
std::vector<uint8_t> classifyBricks(const MinMaxBricks &grid, const TransferFunction &tf);

// Per brick, its chessboard (L∞) distance in bricks to the nearest visible brick: 0 for a
// visible one; r ≥ 1 for an empty one, every brick within r − 1 of which on each axis is empty
// too, so that a ray may cross the whole (2r − 1)³ cube of bricks around it in one step
// (Sramek and Kaufman's distance-transform skipping, on the brick grid). Bricks outside the
// grid count as empty: no ray samples there. Where no brick is visible every brick gets the
// grid's largest extent, whose cube covers the grid. `visible` is classifyBricks' list for a
// grid of `bricks` (x fastest); std::invalid_argument if its size is not their product.
std::vector<int32_t> emptyReach(const std::vector<uint8_t> &visible, Vec3i bricks);

// Fraction of bricks classified empty (0 for an empty list).
double emptyBrickFraction(const std::vector<uint8_t> &visible);

} // namespace volcast
