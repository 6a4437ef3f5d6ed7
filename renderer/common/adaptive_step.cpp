#include "renderer/common/adaptive_step.hpp"

#include "renderer/common/parallel_for.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <stdexcept>

namespace volcast {

namespace {

// Samples brick b reads on an axis of n samples (minmax_bricks.cpp's footprint).
struct Footprint {
    int64_t brickSize, border;
    int64_t first(int64_t b) const { return std::max<int64_t>(b * brickSize - border, 0); }
    int64_t last(int64_t b, int64_t n) const { return std::min<int64_t>((b + 1) * brickSize - 1 + border, n - 1); }
};

// `a > m` is false for NaN: NaN differences never enter.
inline float larger(float m, float a) { return a > m ? a : m; }

// Range maxima over a fixed array in O(1) per query (a sparse table).
class RangeMax {
  public:
    explicit RangeMax(std::vector<float> values) {
        levels_.push_back(std::move(values));
        const size_t n = levels_[0].size();
        for (size_t width = 2; width <= n; width *= 2) {
            const std::vector<float> &below = levels_.back();
            std::vector<float> level(n - width + 1);
            for (size_t i = 0; i < level.size(); ++i) level[i] = std::max(below[i], below[i + width / 2]);
            levels_.push_back(std::move(level));
        }
    }
    // max of values[first..last], first ≤ last < size.
    float max(size_t first, size_t last) const {
        size_t level = 0;
        while ((size_t(2) << level) <= last - first + 1) ++level;
        return std::max(levels_[level][first], levels_[level][last + 1 - (size_t(1) << level)]);
    }

  private:
    std::vector<std::vector<float>> levels_;
};

} // namespace

BrickGradients buildBrickGradients(const SampleGrid &data, int brickSize, int border, int threads) {
    const Vec3i dims = data.dims;
    if (dims.x < 1 || dims.y < 1 || dims.z < 1)
        throw std::invalid_argument("brick gradients: dims must be at least 1 on every axis");
    if (brickSize < 1 || border < 0 || border > brickSize)
        throw std::invalid_argument("brick gradients: needs brickSize ≥ 1 and border in [0, brickSize]");
    BrickGradients g;
    g.brickSize = brickSize;
    g.border = border;
    const int64_t B = brickSize;
    g.bricks = {(dims.x + B - 1) / B, (dims.y + B - 1) / B, (dims.z + B - 1) / B};
    const Footprint fp{B, border};
    const auto nx = size_t(dims.x), ny = size_t(dims.y), nz = size_t(dims.z);
    const auto nbx = size_t(g.bricks.x), nby = size_t(g.bricks.y), nbz = size_t(g.bricks.z);
    const size_t layer = nbx * nby;

    // Per slice k and brick column (bx, by): the largest x and y differences within slice k,
    // and the largest z difference between slices k and k + 1, over the column's footprint.
    std::vector<float> sliceX(nz * layer, 0.0f), sliceY(nz * layer, 0.0f), sliceZ(nz * layer, 0.0f);
    parallelFor(nz, threads, [&](size_t kBegin, size_t kEnd) {
        std::vector<float> scratch, nextScratch, dx(nx * ny), dy(nx * ny), dz(nx * ny);
        for (size_t k = kBegin; k < kEnd; ++k) {
            const float *s = data.slice(int64_t(k), scratch);
            const float *next = k + 1 < nz ? data.slice(int64_t(k + 1), nextScratch) : nullptr;
            // dx(i, j) = |s(i+1, j) − s(i, j)|, dy(i, j) = |s(i, j+1) − s(i, j)|, dz likewise
            // towards the next slice; 0 past the last sample (no pair there).
            for (size_t j = 0; j < ny; ++j)
                for (size_t i = 0; i < nx; ++i) {
                    const size_t at = j * nx + i;
                    dx[at] = i + 1 < nx ? std::fabs(s[at + 1] - s[at]) : 0.0f;
                    dy[at] = j + 1 < ny ? std::fabs(s[at + nx] - s[at]) : 0.0f;
                    dz[at] = next ? std::fabs(next[at] - s[at]) : 0.0f;
                }
            for (size_t by = 0; by < nby; ++by)
                for (size_t bx = 0; bx < nbx; ++bx) {
                    const int64_t x0 = fp.first(int64_t(bx)), x1 = fp.last(int64_t(bx), dims.x);
                    const int64_t y0 = fp.first(int64_t(by)), y1 = fp.last(int64_t(by), dims.y);
                    float mx = 0, my = 0, mz = 0;
                    for (int64_t j = y0; j <= y1; ++j)
                        for (int64_t i = x0; i <= x1; ++i) {
                            const size_t at = size_t(j) * nx + size_t(i);
                            if (i < x1) mx = larger(mx, dx[at]); // the pair (i, i+1) inside the footprint
                            if (j < y1) my = larger(my, dy[at]);
                            mz = larger(mz, dz[at]);
                        }
                    const size_t c = k * layer + by * nbx + bx;
                    sliceX[c] = mx;
                    sliceY[c] = my;
                    sliceZ[c] = mz;
                }
        }
    });
    g.maxDifference.assign(3 * layer * nbz, 0.0f);
    parallelFor(nbz, threads, [&](size_t bzBegin, size_t bzEnd) {
        for (size_t bz = bzBegin; bz < bzEnd; ++bz) {
            const int64_t k0 = fp.first(int64_t(bz)), k1 = fp.last(int64_t(bz), dims.z);
            for (size_t b = 0; b < layer; ++b) {
                float mx = 0, my = 0, mz = 0;
                for (int64_t k = k0; k <= k1; ++k) {
                    const size_t c = size_t(k) * layer + b;
                    mx = larger(mx, sliceX[c]);
                    my = larger(my, sliceY[c]);
                    if (k < k1) mz = larger(mz, sliceZ[c]); // the pair (k, k+1) inside the footprint
                }
                float *out = &g.maxDifference[3 * (bz * layer + b)];
                out[0] = mx;
                out[1] = my;
                out[2] = mz;
            }
        }
    });
    return g;
}

AdaptiveSteps adaptiveBrickSteps(const MinMaxBricks &grid, const BrickGradients &gradients, const TfTable &table,
                                 const AdaptiveStepInput &in, const std::vector<uint8_t> *visible) {
    if (gradients.bricks != grid.bricks) throw std::invalid_argument("adaptive steps: brick grids differ");
    const size_t count = grid.brickCount();
    if (in.skipEmpty && (!visible || visible->size() != count))
        throw std::invalid_argument("adaptive steps: skipping needs the bricks' classification");
    const double inf = std::numeric_limits<double>::infinity();

    // The classified signal's rate of change per data unit on each table interval: sigma's
    // slope plus sigma (the larger end) times the steepest colour channel's slope.
    const int entries = table.entries();
    std::vector<float> rate(size_t(std::max(entries - 1, 1)), 0.0f);
    for (int i = 0; i + 1 < entries; ++i) {
        const float *a = &table.rgba[4 * size_t(i)], *b = a + 4;
        double colour = 0;
        for (int c = 0; c < 3; ++c) colour = std::max(colour, std::fabs(double(b[c]) - double(a[c])));
        const double sigma = std::max(double(a[3]), double(b[3]));
        rate[size_t(i)] = float((std::fabs(double(b[3]) - double(a[3])) + sigma * colour) * table.scale);
    }
    const RangeMax rateOn(std::move(rate));
    const double lastInterval = double(std::max(entries - 2, 0));

    // L_b per brick, per world unit², and which bricks are skipped.
    std::vector<double> slope(count, 0.0);
    std::vector<double> positive;
    for (size_t b = 0; b < count; ++b) {
        if (in.skipEmpty && !(*visible)[b]) continue;
        const float lo = grid.minmax[2 * b], hi = grid.minmax[2 * b + 1];
        if (!(lo <= hi)) continue; // a brick of NaN: no values
        const double xlo = std::clamp((double(lo) - table.minValue) * table.scale, 0.0, lastInterval);
        const double xhi = std::clamp((double(hi) - table.minValue) * table.scale, 0.0, lastInterval);
        const double perValue = rateOn.max(size_t(xlo), size_t(xhi));
        const float *d = &gradients.maxDifference[3 * b];
        double gradient = 0;
        for (int a = 0; a < 3; ++a) gradient += std::pow(double(d[a]) / in.levelVoxel[a], 2);
        const double L = perValue == 0 ? 0 : perValue * std::sqrt(gradient) / in.opacityUnit;
        slope[b] = std::isnan(L) ? inf : L;
        if (slope[b] > 0) positive.push_back(slope[b]);
    }
    AdaptiveSteps out;
    if (!positive.empty()) {
        const auto at = positive.begin() + ptrdiff_t(kAdaptiveReferenceQuantile * double(positive.size() - 1));
        std::nth_element(positive.begin(), at, positive.end());
        out.referenceSlope = *at;
    }

    // h_b, then the smallest over each brick's 3×3×3 neighbourhood (separable: x, y, z).
    const auto nbx = size_t(grid.bricks.x), nby = size_t(grid.bricks.y), nbz = size_t(grid.bricks.z);
    std::vector<float> h(count), pass(count);
    for (size_t b = 0; b < count; ++b) {
        const double L = slope[b];
        double step = in.longest;
        if (L > 0) {
            const double ratio = out.referenceSlope / L; // inf / inf (NaN) and x / inf: shortest
            step = ratio >= 1 ? in.shortest * std::min(ratio, in.longest / in.shortest) : in.shortest;
            step = std::clamp(step, in.shortest, in.longest);
        }
        h[b] = float(step);
    }
    const auto dilate = [&](size_t stride, size_t n) {
        pass = h;
        for (size_t b = 0; b < count; ++b) {
            const size_t i = (b / stride) % n;
            if (i > 0) h[b] = std::min(h[b], pass[b - stride]);
            if (i + 1 < n) h[b] = std::min(h[b], pass[b + stride]);
        }
    };
    dilate(1, nbx);
    dilate(nbx, nby);
    dilate(nbx * nby, nbz);

    double sum = 0;
    size_t kept = 0, shortest = 0;
    for (size_t b = 0; b < count; ++b) {
        if (in.skipEmpty && !(*visible)[b]) {
            h[b] = -1.0f;
            continue;
        }
        sum += h[b];
        ++kept;
        if (h[b] <= float(in.shortest)) ++shortest;
    }
    out.meanStep = kept ? sum / double(kept) : 0;
    out.shortestFraction = kept ? double(shortest) / double(kept) : 0;
    out.step = std::move(h);
    return out;
}

} // namespace volcast
