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

void bsplinePrefilterMultithreaded(float *data, Vec3i dims, int threads) {
    const auto nx = size_t(dims.x), ny = size_t(dims.y), nz = size_t(dims.z);
    if (nx == 0 || ny == 0 || nz == 0) return;
    const size_t wanted = threads > 0 ? size_t(threads) : size_t(std::max(1u, std::thread::hardware_concurrency()));

    // Line l of an axis starts at (l / inner)·outerStride + (l % inner)·innerStride.
    struct Axis {
        size_t n;
        ptrdiff_t stride;
        size_t lines, inner, innerStride, outerStride;
    };
    const Axis axes[3] = {
        {nx, 1, ny * nz, ny, nx, nx * ny},
        {ny, ptrdiff_t(nx), nx * nz, nx, 1, nx * ny},
        {nz, ptrdiff_t(nx * ny), nx * ny, nx, 1, nx},
    };
    for (const Axis &a : axes) {
        if (a.n < 2) continue; // a one-sample axis is its own coefficient
        // Contiguous ranges of lines, so neighbouring threads rarely share cache lines.
        const size_t count = std::min(wanted, a.lines);
        auto work = [&a, data, count](size_t t) {
            const size_t begin = a.lines * t / count, end = a.lines * (t + 1) / count;
            for (size_t l = begin; l < end; ++l)
                bsplinePrefilterLine(data + (l / a.inner) * a.outerStride + (l % a.inner) * a.innerStride, a.n, a.stride);
        };
        std::vector<std::thread> pool;
        pool.reserve(count - 1);
        for (size_t t = 1; t < count; ++t) pool.emplace_back(work, t);
        work(0); // the calling thread takes the first share
        for (std::thread &th : pool) th.join();
    }
}

template void bsplinePrefilterLine<float>(float *, size_t, ptrdiff_t);
template void bsplinePrefilterLine<double>(double *, size_t, ptrdiff_t);
template void bsplinePrefilterSimple<float>(float *, Vec3i);
template void bsplinePrefilterSimple<double>(double *, Vec3i);

} // namespace volcast
