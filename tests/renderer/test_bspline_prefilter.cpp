#include "renderer/common/bspline_prefilter.hpp"
#include "renderer/opencl/bspline_prefilter_opencl.hpp"
#include "renderer/reference/reconstruction.hpp"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <random>
#include <string>
#include <vector>

namespace volcast {
namespace {

// Independent solution: the interpolation condition (c[k−1] + 4c[k] + c[k+1]) / 6 = s[k]
// with mirrored coefficients, solved as a dense linear system by Gaussian elimination.
std::vector<double> solveDirect(const std::vector<double> &s) {
    const int n = int(s.size());
    if (n == 1) return s;
    std::vector<double> a(size_t(n * n), 0.0), b = s;
    for (int k = 0; k < n; ++k)
        for (int o = -1; o <= 1; ++o)
            a[size_t(k * n + mirrorIndex(k + o, n))] += (o == 0 ? 4.0 : 1.0) / 6.0;
    for (int c = 0; c < n; ++c) {
        int p = c;
        for (int r = c + 1; r < n; ++r)
            if (std::fabs(a[size_t(r * n + c)]) > std::fabs(a[size_t(p * n + c)])) p = r;
        for (int k = 0; k < n; ++k) std::swap(a[size_t(c * n + k)], a[size_t(p * n + k)]);
        std::swap(b[size_t(c)], b[size_t(p)]);
        for (int r = c + 1; r < n; ++r) {
            const double f = a[size_t(r * n + c)] / a[size_t(c * n + c)];
            for (int k = c; k < n; ++k) a[size_t(r * n + k)] -= f * a[size_t(c * n + k)];
            b[size_t(r)] -= f * b[size_t(c)];
        }
    }
    std::vector<double> x(static_cast<size_t>(n));
    for (int r = n - 1; r >= 0; --r) {
        double sum = b[size_t(r)];
        for (int k = r + 1; k < n; ++k) sum -= a[size_t(r * n + k)] * x[size_t(k)];
        x[size_t(r)] = sum / a[size_t(r * n + r)];
    }
    return x;
}

TEST(BSplinePrefilter, MatchesDirectSolveOnEveryShortAndLongAxis) {
    std::mt19937 rng(11);
    std::uniform_real_distribution<double> u(-100, 100);
    for (int n : {1, 2, 3, 4, 5, 7, 16, 31, 64}) {
        std::vector<double> s(static_cast<size_t>(n));
        for (double &x : s) x = u(rng);
        std::vector<double> c = s;
        bsplinePrefilterLine(c.data(), c.size(), 1);
        const std::vector<double> expected = solveDirect(s);
        // Double precision and a well-conditioned system (diagonal dominance 4:1+1): the
        // truncated causal sum stops at |z|^k < 2.2e-16, so 1e-11 on values ~100 holds.
        for (int k = 0; k < n; ++k) EXPECT_NEAR(c[size_t(k)], expected[size_t(k)], 1e-11) << "n=" << n << " k=" << k;
    }
}

TEST(BSplinePrefilter, CoefficientsInterpolateTheSamplesIn3D) {
    const Vec3i dims{5, 3, 9}; // includes an axis shorter than the filter's 4 taps
    Volume v;
    v.dims = dims;
    v.voxels.resize(v.voxelCount());
    std::mt19937 rng(5);
    std::uniform_real_distribution<float> u(0, 1000);
    for (float &x : v.voxels) x = u(rng);
    const CubicBSplineField f(v);
    for (int64_t k = 0; k < dims.z; ++k)
        for (int64_t j = 0; j < dims.y; ++j)
            for (int64_t i = 0; i < dims.x; ++i)
                // At the samples the spline passes through them: only double rounding (~1e-13).
                EXPECT_NEAR(f(Vec3d(Vec3i{i, j, k})), v.at(i, j, k), 1e-9);
}

TEST(BSplinePrefilter, FloatAgreesWithDoubleToFloatPrecision) {
    std::vector<double> d(40);
    std::mt19937 rng(2);
    std::uniform_real_distribution<double> u(0, 1);
    for (double &x : d) x = u(rng);
    std::vector<float> f(d.begin(), d.end());
    bsplinePrefilterLine(d.data(), d.size(), 1);
    bsplinePrefilterLine(f.data(), f.size(), 1);
    // Float keeps ~1.2e-7 relative per operation; the recursion's gain is bounded by
    // 1 / (1 − |z|)² ≈ 1.9, so a few 1e-7 on unit-size values; 1e-5 relative is the required bound.
    for (size_t k = 0; k < d.size(); ++k) EXPECT_NEAR(f[k], d[k], 1e-5 * std::max(1.0, std::fabs(d[k])));
}

OpenClContext &sharedContext() {
    static OpenClContext cl;
    return cl;
}

// Axes shorter than the filter's 4 taps included, and one-sample axes in every position.
const Vec3i kAgreementDims[] = {{37, 5, 3}, {1, 2, 17}, {3, 1, 2}, {16, 9, 11}};

std::vector<float> randomVolume(Vec3i dims, unsigned seed) {
    std::vector<float> v(size_t(dims.x * dims.y * dims.z));
    std::mt19937 rng(seed);
    std::uniform_real_distribution<float> u(-100, 100);
    for (float &x : v) x = u(rng);
    return v;
}

// Every coefficient of `got` within 1e-5 (the required bound) relative to the volume's largest
// coefficient, of the simple float result and of the double one. Relative to the volume, not
// to each coefficient: a coefficient near 0 is a difference of values ~100, so float rounding
// of those values (~1e-5 absolute) is all it can be held to.
void expectAgreesWithSimple(const std::vector<float> &got, const std::vector<float> &samples, Vec3i dims,
                            const std::string &what) {
    std::vector<float> single = samples;
    bsplinePrefilterSimple(single.data(), dims);
    std::vector<double> reference(samples.begin(), samples.end());
    bsplinePrefilterSimple(reference.data(), dims);
    double scale = 1;
    for (double c : reference) scale = std::max(scale, std::fabs(c));
    const double tolerance = 1e-5 * scale;
    ASSERT_EQ(got.size(), samples.size()) << what;
    for (size_t k = 0; k < got.size(); ++k) {
        EXPECT_NEAR(got[k], single[k], tolerance) << what << " k=" << k;
        EXPECT_NEAR(got[k], reference[k], tolerance) << what << " k=" << k;
    }
}

std::string name(Vec3i d) {
    return std::to_string(d.x) + "x" + std::to_string(d.y) + "x" + std::to_string(d.z);
}

// The multithreaded prefilter computes in float (simple in double, then rounds), so it is held
// to float rounding of the recursion, relative to the largest sample M. Per axis: the causal
// values reach 6/(1 − |z|)·m ≈ 8.2·m (m the axis's largest input), each step rounds twice
// (½ε each) and an error decays by |z| per step, so ≤ 8.2·ε/(1 − |z|) ≈ 11ε·m; the anticausal
// sweep passes on |z|/(1 − |z|) of that and adds ≈ 2ε·m: ≤ 12ε·m per axis, rounded up to 16ε.
// Each axis's filter has ∞-norm √3·(1 + |z|)/(1 − |z|) = 3, so the inputs of the three axes
// are ≤ M, 3M, 9M, and the first axis's error is multiplied by 9, the second's by 3:
// 16ε·(9M + 3·3M + 9M) = 432ε·M ≈ 5.2e-5·M. A wrong initialisation or a missing pass is off
// by a sizeable fraction of M (a causal sum truncated after 6 terms: |z|^6·8.2M ≈ 3e-3·M).
constexpr double kFloatRecursionBound = 432 * 1.1920928955078125e-7; // × M; FLT_EPSILON

void expectWithinFloatRounding(const std::vector<float> &got, const std::vector<float> &samples, Vec3i dims,
                               const std::string &what) {
    std::vector<double> exact(samples.begin(), samples.end());
    bsplinePrefilterSimple(exact.data(), dims);
    double largestSample = 0, worst = 0;
    size_t worstAt = 0;
    for (float x : samples) largestSample = std::max(largestSample, double(std::fabs(x)));
    ASSERT_EQ(got.size(), samples.size()) << what;
    for (size_t k = 0; k < got.size(); ++k)
        if (const double e = std::fabs(double(got[k]) - exact[k]); e > worst) worst = e, worstAt = k;
    EXPECT_LE(worst, kFloatRecursionBound * largestSample)
        << what << ": largest error " << worst << " at voxel " << worstAt << " (" << got[worstAt] << " against "
        << exact[worstAt] << "), " << worst / largestSample / 1.1920928955078125e-7
        << " FLT_EPSILON × the largest sample; the bound is 432";
}

// Odd sizes; full and partial groups of 16 x lines; axes of 1, 2 and 3 samples in every
// position; axes shorter than, equal to and longer than the float initialisation's horizon
// (13: there the causal sum switches from the whole mirrored period to a truncated sum).
const Vec3i kMultithreadedDims[] = {{37, 5, 3},  {70, 21, 9},  {9, 40, 23}, {1, 2, 17}, {3, 1, 2},
                                     {16, 9, 11}, {12, 13, 14}, {2, 2, 2},   {1, 1, 1},  {33, 1, 1}};

TEST(BSplinePrefilter, MultithreadedWithinFloatRoundingOfTheExactResult) {
    for (const Vec3i &dims : kMultithreadedDims)
        for (int threads : {1, 2, 3, 0}) {
            const std::vector<float> samples = randomVolume(dims, 3);
            std::vector<float> got = samples;
            bsplinePrefilterMultithreaded(got.data(), dims, threads);
            expectWithinFloatRounding(got, samples, dims, name(dims) + " threads=" + std::to_string(threads));
        }
}

TEST(BSplinePrefilter, MultithreadedWithinFloatRoundingOnTheWorstCaseCheckerboard) {
    // ±M alternating along every axis meets each axis's gain of 3 in full: coefficients ±27M.
    for (const Vec3i &dims : {Vec3i{40, 17, 33}, Vec3i{5, 64, 7}}) {
        std::vector<float> samples(size_t(dims.x * dims.y * dims.z));
        for (int64_t k = 0; k < dims.z; ++k)
            for (int64_t j = 0; j < dims.y; ++j)
                for (int64_t i = 0; i < dims.x; ++i)
                    samples[size_t((k * dims.y + j) * dims.x + i)] = (i + j + k) % 2 ? -1000.0f : 1000.0f;
        std::vector<float> got = samples;
        bsplinePrefilterMultithreaded(got.data(), dims, 2);
        expectWithinFloatRounding(got, samples, dims, "checkerboard " + name(dims));
    }
}

TEST(BSplinePrefilter, MultithreadedGivesTheSameBitsOnAnyThreadCount) {
    // Lines are grouped by slice (x, y) and by fixed chunks of the xy plane (z), never by a
    // thread's share, so the arithmetic of every voxel is the same on 1, 2 or 3 threads.
    for (const Vec3i &dims : {Vec3i{70, 21, 9}, Vec3i{9, 40, 23}, Vec3i{130, 67, 5}}) {
        const std::vector<float> samples = randomVolume(dims, 4);
        std::vector<float> one = samples;
        bsplinePrefilterMultithreaded(one.data(), dims, 1);
        for (int threads : {2, 3}) {
            std::vector<float> many = samples;
            bsplinePrefilterMultithreaded(many.data(), dims, threads);
            EXPECT_EQ(one, many) << name(dims) << " threads=" << threads;
        }
    }
}

TEST(BSplinePrefilter, OpenClAgreesWithSimple) {
    OpenClContext &cl = sharedContext();
    for (const Vec3i &dims : kAgreementDims) {
        const std::vector<float> samples = randomVolume(dims, 5);
        expectAgreesWithSimple(bsplinePrefilterOpenCl(cl, samples.data(), dims), samples, dims,
                               name(dims) + " on " + cl.deviceName());
    }
}

TEST(BSplinePrefilter, MirrorIndexFoldsAtBothEnds) {
    EXPECT_EQ(mirrorIndex(-1, 5), 1);
    EXPECT_EQ(mirrorIndex(-2, 5), 2);
    EXPECT_EQ(mirrorIndex(5, 5), 3);
    EXPECT_EQ(mirrorIndex(6, 5), 2);
    EXPECT_EQ(mirrorIndex(9, 5), 1);
    EXPECT_EQ(mirrorIndex(-7, 1), 0);
    EXPECT_EQ(mirrorIndex(2, 2), 0);
}

} // namespace
} // namespace volcast
