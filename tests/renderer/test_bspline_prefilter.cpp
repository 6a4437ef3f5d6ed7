#include "renderer/common/bspline_prefilter.hpp"
#include "renderer/common/narrow_samples.hpp"
#include "renderer/opencl/bspline_prefilter_opencl.hpp"
#include "renderer/reference/reconstruction.hpp"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
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

// Odd sizes, axes of 1, 2 and 3 samples in every position, non-cubic shapes; x lines of one
// tile, of whole tiles (32, 64) and of a partial last tile (33: one sample, whose anticausal
// start needs the tile before; 40); lines shorter than, at and past the causal horizon (13);
// row counts that leave the tiled pass's last work-group part empty.
const Vec3i kDeviceDims[] = {{5, 1, 7},  {2, 2, 2},  {33, 17, 9}, {1, 1, 1}, {3, 3, 3}, {1, 2, 17}, {3, 1, 2},
                             {2, 1, 1},  {37, 5, 3}, {40, 3, 14}, {64, 3, 2}, {32, 2, 1}, {13, 4, 3}, {14, 3, 2}};

const PrefilterXPass kXPasses[] = {PrefilterXPass::Tiled, PrefilterXPass::Lines};
const char *xPassName(PrefilterXPass p) { return p == PrefilterXPass::Tiled ? "tiled" : "lines"; }

// The mirror pad the ray caster reads, written here from mirrorIndex alone: the reference the
// device's pad is held to.
std::vector<float> padMirrorReference(const std::vector<float> &c, Vec3i n) {
    const Vec3i p{n.x + 3, n.y + 3, n.z + 3};
    std::vector<float> out(size_t(p.x * p.y * p.z));
    for (int64_t k = 0; k < p.z; ++k)
        for (int64_t j = 0; j < p.y; ++j)
            for (int64_t i = 0; i < p.x; ++i)
                out[size_t((k * p.y + j) * p.x + i)] =
                    c[size_t((mirrorIndex(k - 1, n.z) * n.y + mirrorIndex(j - 1, n.y)) * n.x + mirrorIndex(i - 1, n.x))];
    return out;
}

std::vector<float> readBack(OpenClContext &cl, const cl::Buffer &buffer, size_t count) {
    std::vector<float> out(count);
    cl.queue().enqueueReadBuffer(buffer, CL_TRUE, 0, count * sizeof(float), out.data());
    return out;
}

TEST(BSplinePrefilter, OpenClBothXPassesWithinFloatRoundingOfTheExactResult) {
    // The kernels compute in float as the multithreaded prefilter does (gain folded into the
    // causal sweep, the same initialisations), so they are held to the same derived bound.
    OpenClContext &cl = sharedContext();
    for (const Vec3i &dims : kDeviceDims)
        for (PrefilterXPass xPass : kXPasses) {
            const std::vector<float> samples = randomVolume(dims, 6);
            PrefilterLaunch launch;
            launch.xPass = xPass;
            expectWithinFloatRounding(bsplinePrefilterOpenCl(cl, samples.data(), dims, launch), samples, dims,
                                      name(dims) + " " + xPassName(xPass) + " on " + cl.deviceName());
        }
}

TEST(BSplinePrefilter, OpenClSmallSlabsGiveTheBitsOfOneLaunchPerAxis) {
    // A slab holds whole lines and every line's arithmetic is its own, so how the passes are
    // cut into launches cannot change a bit.
    OpenClContext &cl = sharedContext();
    PrefilterLaunch whole;
    whole.firstSlabSamples = SIZE_MAX; // every axis in one launch, one wait at the end
    PrefilterLaunch small;
    small.firstSlabSamples = 1;     // one unit (a z slice, a y row, or 32 x lines) per launch
    small.slabTargetSeconds = 0;    // never grows
    for (const Vec3i &dims : {Vec3i{33, 17, 9}, Vec3i{40, 3, 14}, Vec3i{5, 1, 7}})
        for (PrefilterXPass xPass : kXPasses) {
            const std::vector<float> samples = randomVolume(dims, 7);
            whole.xPass = small.xPass = xPass;
            const std::string what = name(dims) + " " + xPassName(xPass);
            const size_t count = samples.size();
            cl::Buffer a(cl.context(), CL_MEM_READ_WRITE | CL_MEM_COPY_HOST_PTR, count * sizeof(float),
                         const_cast<float *>(samples.data()));
            cl::Buffer b(cl.context(), CL_MEM_READ_WRITE | CL_MEM_COPY_HOST_PTR, count * sizeof(float),
                         const_cast<float *>(samples.data()));
            const PrefilterLaunchCounts one = bsplinePrefilterOpenCl(cl, a, dims, whole);
            const PrefilterLaunchCounts many = bsplinePrefilterOpenCl(cl, b, dims, small);
            const int axes = (dims.x > 1) + (dims.y > 1) + (dims.z > 1);
            EXPECT_EQ(one.launches, axes) << what;
            EXPECT_EQ(one.waits, 1) << what;
            // One unit per launch: x in groups of 32 lines (tiled) or z slices, y in z slices, z in y rows.
            const int64_t units = (dims.x > 1 ? (xPass == PrefilterXPass::Tiled ? (dims.y * dims.z + 31) / 32 : dims.z) : 0) +
                                  (dims.y > 1 ? dims.z : 0) + (dims.z > 1 ? dims.y : 0);
            EXPECT_EQ(many.launches, units) << what;
            EXPECT_EQ(many.waits, many.launches) << what;
            EXPECT_EQ(readBack(cl, a, count), readBack(cl, b, count)) << what;
        }
}

TEST(BSplinePrefilter, OpenClPaddedCoefficientsArePadMirrorOfTheDevicePrefilter) {
    // The renderer's path (upload as held, widen, filter, pad, nothing read back) gives the
    // bits of padMirror applied to the device's coefficients: the pad is a copy and the
    // widening exact (integers within 2^24). Float, 8-bit and 16-bit samples.
    OpenClContext &cl = sharedContext();
    int sixteenBit = 0;
    for (const Vec3i &dims : kDeviceDims) {
        std::vector<float> floats = randomVolume(dims, 8);
        // Integers in [−100, 100] (+0, not −0: narrowWidth keeps −0 in float): ≤ 201 values fit 8 bits.
        for (float &x : floats) x = std::round(x) + 0.0f;
        std::vector<float> wide(floats.size());
        for (size_t i = 0; i < wide.size(); ++i) wide[i] = floats[i] * 300; // 60,001 apart: 16 bits
        for (const std::vector<float> *samples : {&floats, &wide})
            for (bool narrow : {false, true})
                for (PrefilterXPass xPass : kXPasses) {
                    const NarrowWidth width = narrow ? narrowWidth(*samples) : NarrowWidth{};
                    const std::string what = name(dims) + " " + std::to_string(width.bytes) + " bytes " +
                                             xPassName(xPass) + " on " + cl.deviceName();
                    ASSERT_EQ(width.bytes < 4, narrow) << what;
                    sixteenBit += width.bytes == 2;
                    std::vector<unsigned char> store(samples->size() * size_t(width.bytes) + kNarrowSlack);
                    SampleGrid grid = SampleGrid::ofFloats(dims, samples->data());
                    if (narrow) {
                        packNarrow(samples->data(), samples->size(), width, store.data());
                        grid = SampleGrid{dims, nullptr, store.data(), width};
                    }
                    PrefilterLaunch launch;
                    launch.xPass = xPass;
                    const cl::Buffer padded = bsplinePaddedCoefficientsOpenCl(cl, grid, launch);
                    const std::vector<float> coefficients = bsplinePrefilterOpenCl(cl, samples->data(), dims, launch);
                    const size_t paddedCount = size_t((dims.x + 3) * (dims.y + 3) * (dims.z + 3));
                    EXPECT_EQ(readBack(cl, padded, paddedCount), padMirrorReference(coefficients, dims)) << what;
                    expectWithinFloatRounding(coefficients, *samples, dims, what);
                }
    }
    EXPECT_GT(sixteenBit, 0); // the larger volumes' ×300 samples span more than 256 values
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
