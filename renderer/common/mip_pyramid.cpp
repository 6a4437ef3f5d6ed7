#include "renderer/common/mip_pyramid.hpp"

#include "renderer/common/parallel_for.hpp"

#include <algorithm>
#include <cstdint>
#include <stdexcept>
#include <string>

namespace volcast {

Vec3i mipLevelDims(Vec3i dims0, int level) {
    Vec3i d = dims0;
    for (int L = 0; L < level; ++L)
        for (int a = 0; a < 3; ++a) d[a] = std::max<int64_t>((d[a] + 1) / 2, 1);
    return d;
}

namespace {

// The first level of a narrow store (an 8- or 16-bit scan), from its codes: the eight codes of
// a block summed as integers, then the offset added eight times, in double. Each sample is
// the integer float(code) + offset, so this sum is the float path's sum exactly, and so is
// every average; it only skips widening each sample to float and then to double (0.18 s of a
// 512x512x300 scan's first frame, against 0.03 s).
template <class Code>
void downsampleNarrow(const SampleGrid &fine, Vec3i m, MipSamples &coarse) {
    using Aliased [[gnu::may_alias]] = Code;   // the store's bytes, little-endian as the host
    const Vec3i n = fine.dims;
    const auto *codes = reinterpret_cast<const Aliased *>(fine.narrow);
    const double offsets = 8.0 * double(fine.width.offset);
    const auto row = [&](int64_t j, int64_t k) { return codes + (size_t(k) * size_t(n.y) + size_t(j)) * size_t(n.x); };
    auto slices = [&](int64_t kBegin, int64_t kEnd) {
        for (int64_t K = kBegin; K < kEnd; ++K) {
            const int64_t k0 = 2 * K, k1 = std::min(2 * K + 1, n.z - 1);
            for (int64_t J = 0; J < m.y; ++J) {
                const int64_t j0 = 2 * J, j1 = std::min(2 * J + 1, n.y - 1);
                const Aliased *r00 = row(j0, k0), *r10 = row(j1, k0), *r01 = row(j0, k1), *r11 = row(j1, k1);
                float *out = &coarse[size_t((K * m.y + J) * m.x)];
                const auto block = [&](int64_t i0, int64_t i1) {
                    const uint32_t sum = uint32_t(r00[i0]) + r00[i1] + r10[i0] + r10[i1] + r01[i0] + r01[i1] +
                                         r11[i0] + r11[i1];
                    return float((double(sum) + offsets) * 0.125);
                };
                const int64_t whole = n.x / 2;   // blocks with both samples inside the row
                for (int64_t I = 0; I < whole; ++I) out[I] = block(2 * I, 2 * I + 1);
                if (whole < m.x) out[whole] = block(n.x - 1, n.x - 1);   // an odd row repeats its edge
            }
        }
    };
    const bool share = m.z >= 2 && size_t(m.x * m.y * m.z) >= (size_t(1) << 16) && resolveThreadCount(0) > 1;
    parallelFor(m.z, share ? 2 : 1, slices);
}

} // namespace

MipSamples downsampleMip(const SampleGrid &fine) {
    const Vec3i n = fine.dims;
    const Vec3i m = mipLevelDims(n, 1);
    MipSamples coarse(size_t(m.x) * size_t(m.y) * size_t(m.z));
    if (fine.width.bytes == 1) {
        downsampleNarrow<uint8_t>(fine, m, coarse);
        return coarse;
    }
    if (fine.width.bytes == 2) {
        downsampleNarrow<uint16_t>(fine, m, coarse);
        return coarse;
    }
    // Average the 2×2×2 block of each coarse sample; an odd axis repeats its edge sample.
    auto slices = [&](int64_t kBegin, int64_t kEnd) {
        std::vector<float> s00, s10, s01, s11; // a narrow level's rows, widened
        for (int64_t K = kBegin; K < kEnd; ++K) {
            const int64_t k0 = 2 * K, k1 = std::min(2 * K + 1, n.z - 1);
            for (int64_t J = 0; J < m.y; ++J) {
                const int64_t j0 = 2 * J, j1 = std::min(2 * J + 1, n.y - 1);
                const float *r00 = fine.row(j0, k0, s00), *r10 = fine.row(j1, k0, s10);
                const float *r01 = fine.row(j0, k1, s01), *r11 = fine.row(j1, k1, s11);
                float *out = &coarse[size_t((K * m.y + J) * m.x)];
                for (int64_t I = 0; I < m.x; ++I) {
                    const int64_t i0 = 2 * I, i1 = std::min(2 * I + 1, n.x - 1);
                    // Sum in double, pairwise: exact for a constant block, so constants stay constant.
                    const double sum = ((double(r00[i0]) + double(r00[i1])) + (double(r10[i0]) + double(r10[i1]))) +
                                       ((double(r01[i0]) + double(r01[i1])) + (double(r11[i0]) + double(r11[i1])));
                    out[I] = float(sum * 0.125);
                }
            }
        }
    };
    // Two halves of the coarse slices on two threads when there is enough work to share.
    const bool share = m.z >= 2 && size_t(m.x * m.y * m.z) >= (size_t(1) << 16) && resolveThreadCount(0) > 1;
    parallelFor(m.z, share ? 2 : 1, slices);
    return coarse;
}

MipPyramid::MipPyramid(const Volume &level0) : volume_(level0) {
    if (level0.dims.x < 1 || level0.dims.y < 1 || level0.dims.z < 1 || !level0.hasSamples())
        throw std::invalid_argument("mip pyramid: volume '" + level0.name + "' has no samples or mismatched dims");
    for (Vec3i d = level0.dims; d.x > 1 || d.y > 1 || d.z > 1; d = mipLevelDims(d, 1)) ++maxLevel_;
    levels_.resize(size_t(maxLevel_) + 1);
}

void MipPyramid::check(int L) const {
    if (L < 0 || L > maxLevel_)
        throw std::out_of_range("mip level " + std::to_string(L) + " is outside [0, " + std::to_string(maxLevel_) +
                                 "] for volume '" + volume_.name + "'");
}

SampleGrid MipPyramid::level(int L) {
    check(L);
    if (L == 0) return volume_.samples();
    std::lock_guard lock(mutex_);
    // Build the missing levels in order, each from the one below; levels_ never reallocates.
    for (int l = built_ + 1; l <= L; ++l) {
        levels_[size_t(l)] = downsampleMip(l == 1 ? volume_.samples()
                                                  : SampleGrid::ofFloats(dims(l - 1), levels_[size_t(l) - 1].data()));
        built_ = l;
    }
    return SampleGrid::ofFloats(dims(L), levels_[size_t(L)].data());
}

Vec3i MipPyramid::dims(int L) const {
    check(L);
    return mipLevelDims(volume_.dims, L);
}

int MipPyramid::levelsBuilt() const {
    std::lock_guard lock(mutex_);
    return built_;
}

Volume MipPyramid::levelVolume(int L) {
    const SampleGrid samples = level(L);
    Volume v;
    v.name = volume_.name + " (mip level " + std::to_string(L) + ")";
    v.dims = dims(L);
    const double scale = std::ldexp(1.0, L);
    v.spacing = volume_.spacing * scale;
    const double first = (scale - 1) / 2; // level-0 index of level-L voxel 0 on every axis
    v.origin = volume_.worldFromIndex({first, first, first});
    v.direction = volume_.direction;
    v.sourceType = volume_.sourceType;
    v.voxels = samples.toFloats();
    computeStatistics(v);
    return v;
}

} // namespace volcast
