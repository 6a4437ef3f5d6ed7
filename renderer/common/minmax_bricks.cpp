#include "renderer/common/minmax_bricks.hpp"

#include "renderer/common/parallel_for.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <stdexcept>
#include <string>

namespace volcast {

namespace {

constexpr float kInf = std::numeric_limits<float>::infinity();

// Samples brick b reads on an axis of n samples: [b·B − border, (b+1)·B − 1 + border] ∩ [0, n − 1].
struct Footprint {
    int64_t brickSize, border;
    int64_t first(int64_t b) const { return std::max<int64_t>(b * brickSize - border, 0); }
    int64_t last(int64_t b, int64_t n) const { return std::min<int64_t>((b + 1) * brickSize - 1 + border, n - 1); }
};

// Elementwise running min and max; `v < m` is false for NaN, so NaN samples never enter.
inline void runningMin(float *mn, const float *v, size_t count) {
    for (size_t i = 0; i < count; ++i) mn[i] = v[i] < mn[i] ? v[i] : mn[i];
}
inline void runningMax(float *mx, const float *v, size_t count) {
    for (size_t i = 0; i < count; ++i) mx[i] = v[i] > mx[i] ? v[i] : mx[i];
}

} // namespace

Vec3i MinMaxBricks::brickOf(const Vec3d &p) const {
    Vec3i b;
    for (int a = 0; a < 3; ++a) {
        const double f = std::floor((p[a] + 0.5) / double(brickSize));
        b[a] = int64_t(std::clamp(f, 0.0, double(bricks[a] - 1)));
    }
    return b;
}

MinMaxBricks buildMinMaxBricks(const SampleGrid &data, int brickSize, int border, int threads) {
    const Vec3i dims = data.dims;
    if (dims.x < 1 || dims.y < 1 || dims.z < 1)
        throw std::invalid_argument("min-max bricks: dims must be at least 1 on every axis");
    if (brickSize < 1) throw std::invalid_argument("min-max bricks: brickSize must be at least 1");
    if (border < 0 || border > brickSize)
        throw std::invalid_argument("min-max bricks: border must be in [0, brickSize], got " + std::to_string(border));

    MinMaxBricks grid;
    grid.brickSize = brickSize;
    grid.border = border;
    grid.dims = dims;
    const int64_t B = brickSize;
    grid.bricks = {(dims.x + B - 1) / B, (dims.y + B - 1) / B, (dims.z + B - 1) / B};
    const Footprint fp{B, border};
    const auto nx = size_t(dims.x), nz = size_t(dims.z);
    const auto nbx = size_t(grid.bricks.x), nby = size_t(grid.bricks.y), nbz = size_t(grid.bricks.z);

    // Min and max are separable: reduce over y, then x, within each slice, then over z.
    // Each sample is read from memory once; the overlapping footprints re-read cached rows.
    std::vector<float> sliceMin(nz * nby * nbx), sliceMax(nz * nby * nbx);
    parallelFor(nz, threads, [&](size_t kBegin, size_t kEnd) {
        std::vector<float> rowMin(nby * nx), rowMax(nby * nx), scratch;
        for (size_t k = kBegin; k < kEnd; ++k) {
            const float *slice = data.slice(int64_t(k), scratch);
            // Reduce rows over each brick row's y footprint (elementwise, vectorizable).
            std::fill(rowMin.begin(), rowMin.end(), kInf);
            std::fill(rowMax.begin(), rowMax.end(), -kInf);
            for (size_t by = 0; by < nby; ++by)
                for (int64_t j = fp.first(int64_t(by)); j <= fp.last(int64_t(by), dims.y); ++j) {
                    runningMin(&rowMin[by * nx], slice + size_t(j) * nx, nx);
                    runningMax(&rowMax[by * nx], slice + size_t(j) * nx, nx);
                }
            // Reduce each brick's x footprint of the reduced rows.
            for (size_t by = 0; by < nby; ++by) {
                const float *rmn = &rowMin[by * nx], *rmx = &rowMax[by * nx];
                for (size_t bx = 0; bx < nbx; ++bx) {
                    float mn = kInf, mx = -kInf;
                    for (int64_t i = fp.first(int64_t(bx)); i <= fp.last(int64_t(bx), dims.x); ++i) {
                        mn = rmn[i] < mn ? rmn[i] : mn;
                        mx = rmx[i] > mx ? rmx[i] : mx;
                    }
                    sliceMin[(k * nby + by) * nbx + bx] = mn;
                    sliceMax[(k * nby + by) * nbx + bx] = mx;
                }
            }
        }
    });

    // Reduce the per-slice results over each brick layer's z footprint, then interleave.
    grid.minmax.resize(2 * grid.brickCount());
    const size_t layer = nby * nbx;
    parallelFor(nbz, threads, [&](size_t bzBegin, size_t bzEnd) {
        std::vector<float> mn(layer), mx(layer);
        for (size_t bz = bzBegin; bz < bzEnd; ++bz) {
            std::fill(mn.begin(), mn.end(), kInf);
            std::fill(mx.begin(), mx.end(), -kInf);
            for (int64_t k = fp.first(int64_t(bz)); k <= fp.last(int64_t(bz), dims.z); ++k) {
                runningMin(mn.data(), &sliceMin[size_t(k) * layer], layer);
                runningMax(mx.data(), &sliceMax[size_t(k) * layer], layer);
            }
            for (size_t b = 0; b < layer; ++b) {
                grid.minmax[2 * (bz * layer + b)] = mn[b];
                grid.minmax[2 * (bz * layer + b) + 1] = mx[b];
            }
        }
    });
    return grid;
}

bool opacityPositiveOn(const TransferFunction &tf, double lo, double hi) {
    if (!(lo <= hi) || tf.points.empty()) return false; // an empty range (or NaN) has no values
    // The maximum of a piecewise-linear function on [lo, hi] is at an end or a control point.
    if (tf.evaluate(lo).a > 0 || tf.evaluate(hi).a > 0) return true;
    auto it = std::lower_bound(tf.points.begin(), tf.points.end(), lo,
                               [](const ControlPoint &p, double v) { return p.value < v; });
    for (; it != tf.points.end() && it->value <= hi; ++it)
        if (it->a > 0) return true;
    return false;
}

std::vector<uint8_t> classifyBricks(const MinMaxBricks &grid, const TransferFunction &tf) {
    std::vector<uint8_t> visible(grid.brickCount());
    for (size_t b = 0; b < visible.size(); ++b)
        visible[b] = opacityPositiveOn(tf, grid.minmax[2 * b], grid.minmax[2 * b + 1]) ? 1 : 0;
    return visible;
}

std::vector<int32_t> emptyReach(const std::vector<uint8_t> &visible, Vec3i bricks) {
    const int64_t nx = bricks.x, ny = bricks.y, nz = bricks.z;
    if (nx < 1 || ny < 1 || nz < 1 || uint64_t(nx) * uint64_t(ny) * uint64_t(nz) != visible.size())
        throw std::invalid_argument("emptyReach: " + std::to_string(visible.size()) + " flags for a grid of " +
                                    std::to_string(nx) + "×" + std::to_string(ny) + "×" + std::to_string(nz) + " bricks");
    const int32_t none = int32_t(std::max({nx, ny, nz}));
    std::vector<int32_t> reach(visible.size());
    for (size_t b = 0; b < visible.size(); ++b) reach[b] = visible[b] ? 0 : none;
    // Two raster passes of the 26-neighbour mask, each brick taking 1 + the least of the
    // neighbours already passed: exact for the chessboard distance, whose every shortest path
    // to a visible brick can be taken in steps that all go one way along each axis.
    const auto pass = [&](int dir) {
        const int64_t zs = dir > 0 ? 0 : nz - 1, ys = dir > 0 ? 0 : ny - 1, xs = dir > 0 ? 0 : nx - 1;
        for (int64_t z = zs; z >= 0 && z < nz; z += dir)
            for (int64_t y = ys; y >= 0 && y < ny; y += dir)
                for (int64_t x = xs; x >= 0 && x < nx; x += dir) {
                    int32_t &here = reach[size_t((z * ny + y) * nx + x)];
                    if (here == 0) continue;
                    // The neighbours before this brick in the pass's order: the layer behind
                    // (9), the row behind in this layer (3), the brick behind in this row (1).
                    for (int64_t dz = -1; dz <= 0; ++dz)
                        for (int64_t dy = -1; dy <= 1; ++dy)
                            for (int64_t dx = -1; dx <= 1; ++dx) {
                                if (dz == 0 && (dy > 0 || (dy == 0 && dx >= 0))) continue;
                                const int64_t qx = x + dir * dx, qy = y + dir * dy, qz = z + dir * dz;
                                if (qx < 0 || qy < 0 || qz < 0 || qx >= nx || qy >= ny || qz >= nz) continue;
                                here = std::min(here, reach[size_t((qz * ny + qy) * nx + qx)] + 1);
                            }
                }
    };
    pass(1);
    pass(-1);
    return reach;
}

double emptyBrickFraction(const std::vector<uint8_t> &visible) {
    if (visible.empty()) return 0;
    const auto empty = std::count(visible.begin(), visible.end(), uint8_t(0));
    return double(empty) / double(visible.size());
}

} // namespace volcast
