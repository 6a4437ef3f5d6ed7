#include "renderer/bspline_prefilter.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <thread>
#include <vector>

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

// bsplinePrefilterLine on `width` adjacent lines at once: line i is data[i + k·stride], k < n.
// The same operations in the same order per element, so the same bits; but each step walks
// a contiguous row, which on the y and z axes turns one cache miss per sample into a stream.
template <typename Real>
void bsplinePrefilterRows(Real *data, size_t n, ptrdiff_t stride, size_t width) {
    if (n < 2) return;
    const double z = kBSplinePole;
    const double gain = (1 - z) * (1 - 1 / z);
    auto row = [&](size_t k) { return data + ptrdiff_t(k) * stride; };
    for (size_t k = 0; k < n; ++k) {
        Real *r = row(k);
        for (size_t i = 0; i < width; ++i) r[i] = Real(double(r[i]) * gain);
    }
    const size_t horizon = size_t(std::ceil(std::log(std::numeric_limits<Real>::epsilon()) /
                                            std::log(std::fabs(z))));
    std::vector<double> sum(row(0), row(0) + width);
    if (horizon < n) {
        double zk = z;
        for (size_t k = 1; k < horizon; ++k, zk *= z) {
            const Real *r = row(k);
            for (size_t i = 0; i < width; ++i) sum[i] += zk * double(r[i]);
        }
    } else {
        const size_t period = 2 * n - 2;
        double zk = z;
        for (size_t k = 1; k < period; ++k, zk *= z) {
            const Real *r = row(size_t(mirrorIndex(int64_t(k), int64_t(n))));
            for (size_t i = 0; i < width; ++i) sum[i] += zk * double(r[i]);
        }
        const double norm = 1 - std::pow(z, double(period));
        for (double &v : sum) v /= norm;
    }
    for (size_t i = 0; i < width; ++i) row(0)[i] = Real(sum[i]);
    for (size_t k = 1; k < n; ++k) {
        Real *r = row(k);
        const Real *p = row(k - 1);
        for (size_t i = 0; i < width; ++i) r[i] = Real(double(r[i]) + z * double(p[i]));
    }
    {
        Real *last = row(n - 1);
        const Real *before = row(n - 2);
        for (size_t i = 0; i < width; ++i) last[i] = Real(z / (z * z - 1) * (double(last[i]) + z * double(before[i])));
    }
    for (size_t k = n - 1; k-- > 0;) {
        Real *r = row(k);
        const Real *next = row(k + 1);
        for (size_t i = 0; i < width; ++i) r[i] = Real(z * (double(next[i]) - double(r[i])));
    }
}

// bsplinePrefilterLine on the contiguous lines [first, end) of length n (the x axis), kLines
// at a time: they are copied transposed into a block (element k of every line in row k),
// filtered there as rows, and copied back. Same operations per element, so the same bits; but
// the recursions of kLines lines run side by side instead of one long chain of dependent
// multiply-adds per line (a line's recursion is latency-bound: each element waits for the
// one before).
template <typename Real>
void bsplinePrefilterContiguousLines(Real *data, size_t n, size_t first, size_t end) {
    constexpr size_t kLines = 16;
    std::vector<Real> block(n * kLines);
    for (size_t l = first; l < end; l += kLines) {
        const size_t width = std::min(kLines, end - l);
        Real *lines = data + l * n;
        for (size_t i = 0; i < width; ++i)
            for (size_t k = 0; k < n; ++k) block[k * width + i] = lines[i * n + k];
        bsplinePrefilterRows(block.data(), n, ptrdiff_t(width), width);
        for (size_t i = 0; i < width; ++i)
            for (size_t k = 0; k < n; ++k) lines[i * n + k] = block[k * width + i];
    }
}

// Runs work(begin, end) over [0, count) split in contiguous shares, the caller taking the first.
template <typename Work>
void splitAmong(size_t threads, size_t count, Work work) {
    threads = std::max<size_t>(1, std::min(threads, count));
    std::vector<std::thread> pool;
    pool.reserve(threads - 1);
    for (size_t t = 1; t < threads; ++t) pool.emplace_back(work, count * t / threads, count * (t + 1) / threads);
    work(0, count / threads);
    for (std::thread &th : pool) th.join();
}

} // namespace

void bsplinePrefilterMultithreaded(float *data, Vec3i dims, int threads) {
    const auto nx = size_t(dims.x), ny = size_t(dims.y), nz = size_t(dims.z);
    if (nx == 0 || ny == 0 || nz == 0) return;
    const size_t wanted = threads > 0 ? size_t(threads) : size_t(std::max(1u, std::thread::hardware_concurrency()));
    // x: each thread takes a range of the contiguous lines, 16 filtered side by side.
    if (nx > 1)
        splitAmong(wanted, ny * nz,
                   [&](size_t begin, size_t end) { bsplinePrefilterContiguousLines(data, nx, begin, end); });
    // y: per z slice, all nx lines at once, row by row.
    if (ny > 1)
        splitAmong(wanted, nz, [&](size_t begin, size_t end) {
            for (size_t k = begin; k < end; ++k) bsplinePrefilterRows(data + k * nx * ny, ny, ptrdiff_t(nx), nx);
        });
    // z: per y, the nx lines of that row at once, slice by slice.
    if (nz > 1)
        splitAmong(wanted, ny, [&](size_t begin, size_t end) {
            for (size_t j = begin; j < end; ++j) bsplinePrefilterRows(data + j * nx, nz, ptrdiff_t(nx * ny), nx);
        });
}

template void bsplinePrefilterLine<float>(float *, size_t, ptrdiff_t);
template void bsplinePrefilterLine<double>(double *, size_t, ptrdiff_t);
template void bsplinePrefilterSimple<float>(float *, Vec3i);
template void bsplinePrefilterSimple<double>(double *, Vec3i);

} // namespace volcast
