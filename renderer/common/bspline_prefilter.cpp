#include "renderer/common/bspline_prefilter.hpp"

#include "renderer/common/parallel_for.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <vector>

#if defined(__SSE2__)
#include <immintrin.h>
#endif

namespace volcast {

template <typename Real>
void bsplinePrefilterLine(Real *data, size_t n, ptrdiff_t stride) {
    if (n < 2) return; // one sample: the coefficient is the sample
    const double z = kBSplinePole;
    const double gain = (1 - z) * (1 - 1 / z); // = 6: the filter's DC gain
    auto at = [&](size_t k) -> Real & { return data[ptrdiff_t(k) * stride]; };

    for (size_t k = 0; k < n; ++k) at(k) = Real(double(at(k)) * gain);

    // Causal initialisation: sum over the mirrored signal (period 2n − 2), truncated where
    // z^k falls below the type's epsilon, exact otherwise.
    const size_t horizon = size_t(std::ceil(std::log(std::numeric_limits<Real>::epsilon()) /
                                            std::log(std::fabs(z))));
    double sum = double(at(0));
    if (horizon < n) {
        double zk = z;
        for (size_t k = 1; k < horizon; ++k, zk *= z) sum += zk * double(at(k));
    } else {
        const size_t period = 2 * n - 2;
        double zk = z;
        for (size_t k = 1; k < period; ++k, zk *= z)
            sum += zk * double(at(size_t(mirrorIndex(int64_t(k), int64_t(n)))));
        sum /= 1 - std::pow(z, double(period));
    }
    at(0) = Real(sum);

    // Causal recursion c+[k] = s[k] + z·c+[k−1].
    for (size_t k = 1; k < n; ++k) at(k) = Real(double(at(k)) + z * double(at(k - 1)));

    // Anticausal initialisation for mirror boundaries, then c[k] = z·(c[k+1] − c+[k]).
    at(n - 1) = Real(z / (z * z - 1) * (double(at(n - 1)) + z * double(at(n - 2))));
    for (size_t k = n - 1; k-- > 0;) at(k) = Real(z * (double(at(k + 1)) - double(at(k))));
}

template <typename Real>
void bsplinePrefilterSimple(Real *data, Vec3i dims) {
    const auto nx = size_t(dims.x), ny = size_t(dims.y), nz = size_t(dims.z);
    for (size_t k = 0; k < nz; ++k)
        for (size_t j = 0; j < ny; ++j) bsplinePrefilterLine(data + (k * ny + j) * nx, nx, 1);
    for (size_t k = 0; k < nz; ++k)
        for (size_t i = 0; i < nx; ++i) bsplinePrefilterLine(data + k * ny * nx + i, ny, ptrdiff_t(nx));
    for (size_t j = 0; j < ny; ++j)
        for (size_t i = 0; i < nx; ++i) bsplinePrefilterLine(data + j * nx + i, nz, ptrdiff_t(nx * ny));
}

namespace {

constexpr float kPoleFloat = float(kBSplinePole);
constexpr float kGainFloat = 6; // (1 − z)(1 − 1/z), exactly 6

// Causal initialisation's truncation for float: |z|^k < FLT_EPSILON from k = 13 on.
size_t floatHorizon() {
    return size_t(std::ceil(std::log(std::numeric_limits<float>::epsilon()) / std::log(std::fabs(kBSplinePole))));
}

// The line filter on `width` lines side by side, in float: line i is data[i + k·stride], k < n.
// Every step is a loop over contiguous i (vectorised by the compiler), the recursion runs along
// k, carried in `carry` (`width` floats).
// The gain of 6 is folded into the causal sweep (c+[k] = 6·s[k] + z·c+[k−1]), so each line is
// read and written twice, and the rows the initialisation reads are still in cache when the
// causal sweep reaches them. With `prefetch`, the causal sweep asks for the rows
// kPrefetchRows ahead: on the z axis each row is a short run of a different page, which the
// hardware prefetcher does not foresee.
constexpr size_t kPrefetchRows = 8;
void filterRows(float *data, size_t n, ptrdiff_t stride, size_t width, float *carry, bool prefetch) {
    if (n < 2) return; // one sample: the coefficient is the sample
    const float z = kPoleFloat, gain = kGainFloat;
    const auto row = [&](size_t k) { return data + ptrdiff_t(k) * stride; };
    const auto ask = [&](size_t k) {
        if (!prefetch || k >= n) return;
        const float *r = row(k);
        for (size_t i = 0; i < width; i += 64 / sizeof(float)) __builtin_prefetch(r + i, 1);
    };
    const size_t horizon = floatHorizon();
    {
        const float *r0 = row(0);
        for (size_t i = 0; i < width; ++i) carry[i] = r0[i];
    }
    double norm = 1;
    if (horizon < n) {
        for (size_t k = 1; k <= kPrefetchRows; ++k) ask(k);
        double zk = kBSplinePole;
        for (size_t k = 1; k < horizon; ++k, zk *= kBSplinePole) {
            ask(k + kPrefetchRows);
            const float *r = row(k), w = float(zk);
            for (size_t i = 0; i < width; ++i) carry[i] += w * r[i];
        }
    } else { // the whole mirrored period, exactly (Simple's formula)
        const size_t period = 2 * n - 2;
        double zk = kBSplinePole;
        for (size_t k = 1; k < period; ++k, zk *= kBSplinePole) {
            const float *r = row(size_t(mirrorIndex(int64_t(k), int64_t(n)))), w = float(zk);
            for (size_t i = 0; i < width; ++i) carry[i] += w * r[i];
        }
        norm = 1 - std::pow(kBSplinePole, double(period));
    }
    {
        float *r0 = row(0);
        const float scale = float(double(gain) / norm);
        for (size_t i = 0; i < width; ++i) r0[i] = carry[i] = scale * carry[i];
    }
    for (size_t k = 1; k < n; ++k) {
        ask(std::max(k, horizon) + kPrefetchRows - 1);
        float *r = row(k);
        for (size_t i = 0; i < width; ++i) r[i] = carry[i] = gain * r[i] + z * carry[i];
    }
    {
        float *last = row(n - 1);
        const float *before = row(n - 2);
        const float lastScale = float(kBSplinePole / (kBSplinePole * kBSplinePole - 1));
        for (size_t i = 0; i < width; ++i) last[i] = carry[i] = lastScale * (carry[i] + z * before[i]);
    }
    for (size_t k = n - 1; k-- > 0;) {
        float *r = row(k);
        for (size_t i = 0; i < width; ++i) r[i] = carry[i] = z * (carry[i] - r[i]);
    }
}

// The x pass on `count` contiguous lines of length n starting at `lines`, kLines at a time:
// copied transposed into `block` (element k of every line in row k, n × kLines floats, in L1),
// filtered there as rows (kLines independent recursions per step instead of one chain of
// dependent operations per line), copied back. A last group of fewer lines leaves the
// block's other lanes as they were: they are filtered and never copied back.
constexpr size_t kLines = 16;
// Copies 4 lines × 4 elements (line i at from[i·fromStride]) to 4 rows × 4 lanes (row k at
// to[k·toStride]), or back: the same transpose both ways.
void transpose4x4(const float *from, size_t fromStride, float *to, size_t toStride) {
#if defined(__SSE2__)
    __m128 r0 = _mm_loadu_ps(from), r1 = _mm_loadu_ps(from + fromStride), r2 = _mm_loadu_ps(from + 2 * fromStride),
           r3 = _mm_loadu_ps(from + 3 * fromStride);
    _MM_TRANSPOSE4_PS(r0, r1, r2, r3);
    _mm_storeu_ps(to, r0);
    _mm_storeu_ps(to + toStride, r1);
    _mm_storeu_ps(to + 2 * toStride, r2);
    _mm_storeu_ps(to + 3 * toStride, r3);
#else
    for (size_t i = 0; i < 4; ++i)
        for (size_t k = 0; k < 4; ++k) to[k * toStride + i] = from[i * fromStride + k];
#endif
}

// Line i of the group (lines[i·n + k]) to lane i of the block (block[k·kLines + i]), or back
// (toBlock false), for lines i < width; 4 × 4 tiles where whole.
void transposeGroup(float *lines, size_t n, size_t width, float *block, bool toBlock) {
    const size_t tiledLines = width / 4 * 4, tiledK = n / 4 * 4;
    for (size_t i = 0; i < tiledLines; i += 4)
        for (size_t k = 0; k < tiledK; k += 4) {
            if (toBlock) transpose4x4(lines + i * n + k, n, block + k * kLines + i, kLines);
            else transpose4x4(block + k * kLines + i, kLines, lines + i * n + k, n);
        }
    for (size_t i = 0; i < width; ++i)
        for (size_t k = i < tiledLines ? tiledK : 0; k < n; ++k) {
            if (toBlock) block[k * kLines + i] = lines[i * n + k];
            else lines[i * n + k] = block[k * kLines + i];
        }
}

void filterContiguousLines(float *lines, size_t n, size_t count, float *block) {
    alignas(64) float carry[kLines];
    for (size_t l = 0; l < count; l += kLines) {
        const size_t width = std::min(kLines, count - l);
        float *group = lines + l * n;
        transposeGroup(group, n, width, block, true);
        filterRows(block, n, ptrdiff_t(kLines), kLines, carry, false);
        transposeGroup(group, n, width, block, false);
    }
}

#ifndef VOLCAST_PREFILTER_Z_BLOCK_BYTES
#define VOLCAST_PREFILTER_Z_BLOCK_BYTES (256 * 1024)
#endif
// How many z lines are filtered side by side: their block (nz × width floats) stays in the
// 1 MiB L2 between the causal and the anticausal sweep (256 KiB measured no slower than
// 512 KiB or 1 MiB here); at least a few cache lines per row.
size_t zChunkWidth(size_t nz, size_t plane) {
    const size_t width = size_t(VOLCAST_PREFILTER_Z_BLOCK_BYTES) / sizeof(float) / nz / 16 * 16;
    return std::min(plane, std::max<size_t>(width, 64));
}

} // namespace

void bsplinePrefilterMultithreaded(float *data, Vec3i dims, int threads) {
    const auto nx = size_t(dims.x), ny = size_t(dims.y), nz = size_t(dims.z);
    if (nx == 0 || ny == 0 || nz == 0) return;
    const size_t plane = nx * ny;
    // x then y, one z slice at a time: the slice is still in cache when its y lines (all nx
    // of a slice side by side, row by row) follow its x lines.
    if (nx > 1 || ny > 1)
        parallelFor(nz, threads, [&](size_t begin, size_t end) {
            std::vector<float> block(nx * kLines), carry(nx);
            for (size_t k = begin; k < end; ++k) {
                float *slice = data + k * plane;
                if (nx > 1) filterContiguousLines(slice, nx, ny, block.data());
                filterRows(slice, ny, ptrdiff_t(nx), nx, carry.data(), false);
            }
        });
    // z: the plane's nx·ny lines side by side, a chunk of them at a time.
    if (nz > 1) {
        const size_t chunk = zChunkWidth(nz, plane);
        parallelFor((plane + chunk - 1) / chunk, threads, [&](size_t begin, size_t end) {
            std::vector<float> carry(chunk);
            for (size_t c = begin; c < end; ++c) {
                const size_t first = c * chunk, width = std::min(chunk, plane - first);
                filterRows(data + first, nz, ptrdiff_t(plane), width, carry.data(), true);
            }
        });
    }
}

template void bsplinePrefilterLine<float>(float *, size_t, ptrdiff_t);
template void bsplinePrefilterLine<double>(double *, size_t, ptrdiff_t);
template void bsplinePrefilterSimple<float>(float *, Vec3i);
template void bsplinePrefilterSimple<double>(double *, Vec3i);

} // namespace volcast
