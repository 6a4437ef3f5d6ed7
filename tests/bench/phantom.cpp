#include "tests/bench/phantom.hpp"

#include <algorithm>
#include <cmath>
#include <random>
#include <stdexcept>
#include <thread>
#include <vector>

namespace volcast::bench {

namespace {

// Runs body(k) for k in [0, n) on all hardware threads, slices interleaved.
template <typename Body>
void parallelSlices(int64_t n, Body body) {
    const unsigned threads = std::max(1u, std::thread::hardware_concurrency());
    std::vector<std::thread> pool;
    for (unsigned t = 0; t < threads; ++t)
        pool.emplace_back([&, t] {
            for (int64_t k = t; k < n; k += threads) body(k);
        });
    for (auto &th : pool) th.join();
}

} // namespace

Volume makePeerPhantom(Vec3i dims, VoxelType sourceType, unsigned seed) {
    if (sourceType != VoxelType::UInt8 && sourceType != VoxelType::UInt16)
        throw std::invalid_argument("phantom: 8-bit or 16-bit unsigned only");
    Volume v;
    v.name = "phantom " + std::to_string(dims.x) + "x" + std::to_string(dims.y) + "x" + std::to_string(dims.z);
    v.dims = dims;
    v.sourceType = sourceType;
    v.voxels.resize(v.voxelCount());
    const double vmax = sourceType == VoxelType::UInt8 ? 255 : 4095;
    const auto coord = [](int64_t i, int64_t n) { return n > 1 ? -1.0 + 2.0 * double(i) / double(n - 1) : 0.0; };
    struct Blob { double x, y, z, r, value; };
    const Blob blobs[] = {{0.35, 0.0, 0.35, 0.16, 0.95}, {-0.35, 0.0, -0.35, 0.16, 0.85},
                          {0.0, 0.4, -0.1, 0.12, 0.75}, {0.0, -0.4, 0.15, 0.12, 0.9}};
    parallelSlices(dims.z, [&](int64_t k) {
        // One generator per slice: the same volume on any number of threads.
        std::mt19937 rng(seed * 1000003u + unsigned(k));
        std::normal_distribution<float> noise(0.0f, 0.02f);
        const double z = coord(k, dims.z);
        for (int64_t j = 0; j < dims.y; ++j) {
            const double y = coord(j, dims.y);
            for (int64_t i = 0; i < dims.x; ++i) {
                const double x = coord(i, dims.x);
                const double r2 = x * x + y * y + z * z;
                double f = 0.04;
                if (r2 < 0.78 * 0.78) f = 0.32 + 0.10 * std::sin(9 * x) * std::sin(9 * y) * std::sin(9 * z);
                else if (r2 < 0.85 * 0.85) f = 0.50;
                if (x * x + y * y < 0.07 * 0.07 && r2 < 0.78 * 0.78) f = 0.80;
                for (const Blob &b : blobs)
                    if ((x - b.x) * (x - b.x) + (y - b.y) * (y - b.y) + (z - b.z) * (z - b.z) < b.r * b.r) f = b.value;
                f = std::clamp(f + double(noise(rng)), 0.0, 1.0);
                v.voxels[v.index(i, j, k)] = float(std::rint(f * vmax));
            }
        }
    });
    computeStatistics(v);
    holdNarrow(v); // as the loader holds an 8- or 16-bit file
    return v;
}

Volume resampleTrilinear(const Volume &volume, Vec3i dims) {
    Volume out;
    out.name = volume.name + " resampled to " + std::to_string(dims.x) + "x" + std::to_string(dims.y) + "x" +
               std::to_string(dims.z);
    out.dims = dims;
    out.sourceType = volume.sourceType;
    out.origin = volume.origin;
    out.direction = volume.direction;
    for (int a = 0; a < 3; ++a)
        out.spacing[a] = dims[a] > 1 ? volume.spacing[a] * double(volume.dims[a] - 1) / double(dims[a] - 1)
                                     : volume.spacing[a];
    out.voxels.resize(out.voxelCount());
    const auto source = [&](int64_t i, int a) {
        return dims[a] > 1 ? double(i) * double(volume.dims[a] - 1) / double(dims[a] - 1) : 0.0;
    };
    parallelSlices(dims.z, [&](int64_t k) {
        const double fz = source(k, 2);
        const int64_t z0 = std::min<int64_t>(int64_t(fz), volume.dims.z - 1), z1 = std::min(z0 + 1, volume.dims.z - 1);
        const double wz = fz - double(z0);
        for (int64_t j = 0; j < dims.y; ++j) {
            const double fy = source(j, 1);
            const int64_t y0 = std::min<int64_t>(int64_t(fy), volume.dims.y - 1), y1 = std::min(y0 + 1, volume.dims.y - 1);
            const double wy = fy - double(y0);
            for (int64_t i = 0; i < dims.x; ++i) {
                const double fx = source(i, 0);
                const int64_t x0 = std::min<int64_t>(int64_t(fx), volume.dims.x - 1),
                              x1 = std::min(x0 + 1, volume.dims.x - 1);
                const double wx = fx - double(x0);
                const auto at = [&](int64_t a, int64_t b, int64_t c) { return double(volume.at(a, b, c)); };
                const double c00 = at(x0, y0, z0) * (1 - wx) + at(x1, y0, z0) * wx;
                const double c10 = at(x0, y1, z0) * (1 - wx) + at(x1, y1, z0) * wx;
                const double c01 = at(x0, y0, z1) * (1 - wx) + at(x1, y0, z1) * wx;
                const double c11 = at(x0, y1, z1) * (1 - wx) + at(x1, y1, z1) * wx;
                const double c0 = c00 * (1 - wy) + c10 * wy, c1 = c01 * (1 - wy) + c11 * wy;
                out.voxels[out.index(i, j, k)] = float(c0 * (1 - wz) + c1 * wz);
            }
        }
    });
    computeStatistics(out);
    return out;
}

} // namespace volcast::bench
