#pragma once
// Prefilter for interpolating cubic B-splines (Unser; Ruijters & Thévenaz, the paper's [18]):
// turns samples into coefficients c such that sum_k c[k]·β³(x − k) passes through every
// sample. Mirror (whole-sample symmetric) boundaries: c[−k] = c[k], c[n−1+k] = c[n−1−k].

#include "renderer/model/math.hpp"

#include <cstddef>

namespace volcast {

// Pole of the cubic B-spline's inverse filter, sqrt(3) − 2.
inline constexpr double kBSplinePole = -0.26794919243112270;

// In place along one line of n samples spaced `stride` apart. Exact on any n ≥ 1.
template <typename Real>
void bsplinePrefilterLine(Real *data, size_t n, ptrdiff_t stride);

// The simple implementation: one thread, x then y then z lines, in place.
template <typename Real>
void bsplinePrefilterSimple(Real *data, Vec3i dims);

// The same filter on several threads, computed in float: within 432·FLT_EPSILON × the largest
// sample of the exact (double) result (the bound is derived in test_bspline_prefilter.cpp),
// and the same bits on any thread count. x and y run one z slice at a time while it is in
// cache (x lines 16 side by side in a transposed block, y lines a whole slice side by side),
// then z over chunks of the xy plane: two passes over memory instead of three.
// threads = 0: std::thread::hardware_concurrency().
void bsplinePrefilterMultithreaded(float *data, Vec3i dims, int threads = 0);

// Index of coefficient k under mirror boundaries on an axis of n samples.
inline int64_t mirrorIndex(int64_t k, int64_t n) {
    if (n == 1) return 0;
    const int64_t period = 2 * n - 2;
    k %= period;
    if (k < 0) k += period;
    return k < n ? k : period - k;
}

} // namespace volcast
