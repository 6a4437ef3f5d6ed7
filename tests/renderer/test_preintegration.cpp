#include "renderer/common/preintegration.hpp"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <random>

namespace volcast {
namespace {

// A spike one data unit wide at 300 on a CT range (Hounsfield units −1024..3071).
TransferFunction spikeTf() {
    TransferFunction tf;
    tf.points = {{-1024, 0, 0, 0, 0},
                 {299.5, 1, 0.2, 0.1, 0},
                 {300, 1, 0.8, 0.3, 0.9},
                 {300.5, 0.2, 0.4, 1, 0},
                 {3071, 0, 0, 0, 0}};
    return tf;
}

TransferFunction ctTf() { return presetTransferFunction("ct_soft_tissue", {-1024, 3071}); }

// Brute-force reference: RK4 on dD/dt = τ, dC/dt = c·τ·exp(−D) along the segment, with
// `steps` steps spread over the stretches between control-point crossings (so each stretch
// is smooth and RK4 keeps its fourth order), over [0, length·end].
SegmentIntegral rk4(const TransferFunction &tf, double sf, double sb, double length, double unit, int steps,
                    double end = 1) {
    auto deriv = [&](double t, double od, double out[4]) {
        const Rgba q = tf.evaluate(sf + (sb - sf) * t / length);
        const double tau = extinction(q.a, unit), w = tau * std::exp(-od);
        out[0] = q.r * w;
        out[1] = q.g * w;
        out[2] = q.b * w;
        out[3] = tau;
    };
    std::vector<double> breaks = {0, length * end};
    for (const auto &p : tf.points) {
        const double t = (p.value - sf) / (sb - sf) * length;
        if (sf != sb && t > 0 && t < length * end) breaks.push_back(t);
    }
    std::sort(breaks.begin(), breaks.end());
    double y[4] = {0, 0, 0, 0};
    for (size_t b = 0; b + 1 < breaks.size(); ++b) {
        const double t0 = breaks[b], t1 = breaks[b + 1];
        const int n = std::max(4096, int(steps * (t1 - t0) / (length * end)));
        const double h = (t1 - t0) / n;
        for (int i = 0; i < n; ++i) {
            const double t = t0 + i * h;
            double k1[4], k2[4], k3[4], k4[4];
            deriv(t, y[3], k1);
            deriv(t + h / 2, y[3] + h / 2 * k1[3], k2);
            deriv(t + h / 2, y[3] + h / 2 * k2[3], k3);
            deriv(t + h, y[3] + h * k3[3], k4);
            for (int k = 0; k < 4; ++k) y[k] += h / 6 * (k1[k] + 2 * k2[k] + 2 * k3[k] + k4[k]);
        }
    }
    SegmentIntegral s;
    s.r = y[0];
    s.g = y[1];
    s.b = y[2];
    s.opticalDepth = y[3];
    return s;
}

void expectNear(const SegmentIntegral &got, const SegmentIntegral &want, double tol, const char *what) {
    EXPECT_NEAR(got.r, want.r, tol) << what;
    EXPECT_NEAR(got.g, want.g, tol) << what;
    EXPECT_NEAR(got.b, want.b, tol) << what;
    EXPECT_NEAR(got.alpha(), want.alpha(), tol) << what;
}

// ---- The exact segment integral ----------------------------------------------------------

TEST(PreintegrationSegment, ConstantValueIsOpacityCorrection) {
    TransferFunction tf;
    tf.points = {{0, 0.2, 0.5, 0.9, 0.3}, {10, 1, 1, 1, 0.95}};
    for (double v : {0.0, 2.5, 7.0, 10.0, 50.0})
        for (double d : {1e-6, 0.3, 1.0, 4.0}) {
            const double unit = 0.7;
            const Rgba q = tf.evaluate(v);
            const SegmentIntegral s = integrateSegment(tf, v, v, d, unit);
            // 1 − (1 − a)^(d/u), written with expm1/log1p so that the reference itself keeps
            // relative precision at d = 1e-6 (the naive form loses ~1e-10 there).
            const double alpha = -std::expm1(d / unit * std::log1p(-q.a));
            // Both sides are a few roundings of the same closed form: relative 1e-12.
            EXPECT_NEAR(s.alpha() / alpha, 1.0, 1e-12) << v << " " << d;
            EXPECT_NEAR(s.r / (q.r * alpha), 1.0, 1e-12);
            EXPECT_NEAR(s.g / (q.g * alpha), 1.0, 1e-12);
            EXPECT_NEAR(s.b / (q.b * alpha), 1.0, 1e-12);
        }
}

TEST(PreintegrationSegment, OpacityRampMatchesClosedForm) {
    // a linear in t from a0 to a1, constant colour: D = (d/u)·(H(a1) − H(a0))/(a1 − a0) with
    // H(a) = a + (1 − a)·ln(1 − a) the antiderivative of −ln(1 − a); and C = c·alpha.
    const double a0 = 0.1, a1 = 0.7;
    TransferFunction tf;
    tf.points = {{0, 0.3, 0.6, 0.9, a0}, {100, 0.3, 0.6, 0.9, a1}};
    auto H = [](double a) { return a + (1 - a) * std::log(1 - a); };
    for (double d : {0.05, 1.0, 20.0}) {
        const double unit = 0.5;
        const double od = d / unit * (H(a1) - H(a0)) / (a1 - a0);
        for (auto [sf, sb] : {std::pair{0.0, 100.0}, std::pair{100.0, 0.0}}) {
            const SegmentIntegral s = integrateSegment(tf, sf, sb, d, unit);
            // Closed forms on both sides, differently arranged: 1e-12 relative.
            EXPECT_NEAR(s.opticalDepth / od, 1.0, 1e-12) << d;
            const double alpha = -std::expm1(-od);
            EXPECT_NEAR(s.r, 0.3 * alpha, 1e-12 * alpha);
            EXPECT_NEAR(s.b, 0.9 * alpha, 1e-12 * alpha);
        }
    }
}

TEST(PreintegrationSegment, ColourRampWithConstantExtinctionMatchesClosedForm) {
    // τ constant, c = c0 + c'·t: C = c0(1 − e^−τd) + c'(1 − e^−τd(1 + τd))/τ.
    const double a = 0.4, unit = 2.0, tau = -std::log1p(-a) / unit;
    TransferFunction tf;
    tf.points = {{0, 0.1, 0.9, 0.0, a}, {1, 0.8, 0.2, 1.0, a}};
    for (double d : {1e-3, 0.5, 3.0, 1e4 / tau}) { // the last has τ·d = 1e4
        const double x = tau * d, e = std::exp(-x);
        // 1 − e^−x(1 + x) = Σₙ≥₂ (−1)ⁿ (n − 1) xⁿ / n!, summed where the closed form cancels.
        double bracket = 1 - e * (1 + x);
        if (x < 0.1) {
            bracket = 0;
            double power = 1, factorial = 1;
            for (int n = 1; n <= 20; ++n) {
                power *= -x;
                factorial *= n;
                if (n >= 2) bracket += (n - 1) * power / factorial;
            }
        }
        auto closed = [&](double c0, double c1) {
            const double slope = (c1 - c0) / d;
            return c0 * -std::expm1(-x) + slope * bracket / tau;
        };
        const SegmentIntegral s = integrateSegment(tf, 0, 1, d, unit);
        // The series / expm1 forms against the textbook expression: 1e-12 relative.
        EXPECT_NEAR(s.r, closed(0.1, 0.8), 1e-12 * closed(0.1, 0.8)) << d;
        EXPECT_NEAR(s.g, closed(0.9, 0.2), 1e-12 * closed(0.9, 0.2)) << d;
        EXPECT_NEAR(s.b, closed(0.0, 1.0), 1e-12 * closed(0.0, 1.0)) << d;
        EXPECT_NEAR(s.alpha(), 1 - e, 1e-12);
    }
}

TEST(PreintegrationSegment, SpikeCrossingMatchesBruteForceRk4) {
    const TransferFunction tf = spikeTf();
    struct Case {
        double sf, sb, length, unit;
    };
    for (const Case &c : {Case{299, 301, 2.0, 0.5}, Case{301, 299, 2.0, 0.5}, Case{299.8, 300.2, 0.5, 1.0},
                          Case{299.7, 305, 1.0, 0.25}, Case{-1024, 3071, 3.0, 0.01}, Case{300.4, 299.3, 0.7, 0.3}}) {
        const SegmentIntegral s = integrateSegment(tf, c.sf, c.sb, c.length, c.unit);
        const SegmentIntegral ref = rk4(tf, c.sf, c.sb, c.length, c.unit, 1 << 16);
        // RK4 on smooth stretches with ≥ 4096 steps each: Simpson-like error ~(h/L)⁴·f⁗ ≲ 1e-11,
        // so a 1e-9 agreement checks the promised accuracy of the exact integral.
        expectNear(s, ref, 1e-9, "spike");
        EXPECT_NEAR(s.opticalDepth, ref.opticalDepth, 1e-9);
    }
}

TEST(PreintegrationSegment, HugeOpticalDepthOnARampMatchesRk4) {
    // a from 0.5 to 0.9 and colour varying: the segment's optical depth is about 1e4 and all
    // its light comes from its first ~1/τ, a boundary layer the quadrature must resolve.
    TransferFunction tf;
    tf.points = {{0, 0.0, 1.0, 0.5, 0.5}, {100, 1.0, 0.0, 0.5, 0.9}};
    const double length = 7000, unit = 1;
    for (auto [sf, sb] : {std::pair{0.0, 100.0}, std::pair{100.0, 0.0}}) {
        const SegmentIntegral s = integrateSegment(tf, sf, sb, length, unit);
        ASSERT_GT(s.opticalDepth, 5e3);
        EXPECT_EQ(s.alpha(), 1.0);
        // RK4 with τ·h ≤ 0.016: relative error per step ~(τh)⁵/120 ≈ 1e-11 over the ~100
        // steps that carry light: 1e-8 leaves a margin.
        const SegmentIntegral ref = rk4(tf, sf, sb, length, unit, 1 << 20);
        expectNear(s, ref, 1e-8, "ramp");
        EXPECT_NEAR(s.opticalDepth / ref.opticalDepth, 1.0, 1e-10);
    }
}

TEST(PreintegrationSegment, NearlyEqualValuesAreContinuous) {
    const TransferFunction tf = spikeTf();
    const double delta = 1e-7, length = 0.5, unit = 1;
    // The integral is Lipschitz in (sf, sb): |∂/∂v| ≤ (d/u)·|a'|/(1 − a) + |c'| ≈ 0.5·1.8/0.1 + 2
    // ≈ 11 per unit here, so moving an end by δ moves the result by < 1e-6 — also across a
    // kink, and also when the two ends become equal (the constant-value branch).
    for (double v : {299.5, 299.6, 299.75, 300.0, 300.2, 300.5}) {
        const SegmentIntegral same = integrateSegment(tf, v, v, length, unit);
        expectNear(integrateSegment(tf, v, v + delta, length, unit), same, 1e-6, "sb = sf + δ");
        expectNear(integrateSegment(tf, v - delta, v, length, unit), same, 1e-6, "sf = sb − δ");
    }
    // Inside a linear piece it is smooth, and the mean of a segment and its reverse is
    // symmetric in (sf, sb): it equals the constant value at the midpoint to O(δ²·curvature)
    // ≈ 1e-14·100 (the difference of the two is first order: the front is seen less occluded).
    for (double v : {299.6, 299.75, 300.2}) {
        const SegmentIntegral fwd = integrateSegment(tf, v, v + delta, length, unit);
        const SegmentIntegral rev = integrateSegment(tf, v + delta, v, length, unit);
        const SegmentIntegral mid = integrateSegment(tf, v + delta / 2, v + delta / 2, length, unit);
        SegmentIntegral mean;
        mean.r = (fwd.r + rev.r) / 2;
        mean.g = (fwd.g + rev.g) / 2;
        mean.b = (fwd.b + rev.b) / 2;
        mean.opticalDepth = (fwd.opticalDepth + rev.opticalDepth) / 2;
        expectNear(mean, mid, 1e-11, "inside a piece");
    }
}

TEST(PreintegrationSegment, OpaquePlateauGivesAlphaOneWithoutNaN) {
    // a rises to 1 at 10 and stays 1 up to 20.
    TransferFunction tf;
    tf.points = {{0, 1, 0, 0, 0}, {10, 0, 1, 0, 1}, {20, 0, 0, 1, 1}};
    const SegmentIntegral s = integrateSegment(tf, 5, 15, 1.0, 1.0);
    EXPECT_TRUE(std::isinf(s.opticalDepth));
    EXPECT_EQ(s.alpha(), 1.0);
    // The light is the part in front (5 → 10, half the length) plus the entry colour of the
    // plateau seen through it. Same code path twice, but it pins the composition.
    const SegmentIntegral front = integrateSegment(tf, 5, 10, 0.5, 1.0);
    ASSERT_TRUE(std::isfinite(front.opticalDepth)); // −ln(1 − a) is integrable at a = 1
    const double t = std::exp(-front.opticalDepth);
    EXPECT_NEAR(s.r, front.r, 1e-15);
    EXPECT_NEAR(s.g, front.g + t * 1.0, 1e-15);
    EXPECT_NEAR(s.b, front.b, 1e-15);
    // The part in front against RK4 stopped 1e-9 short of a = 1 (τ = ∞ there): the tail left
    // out holds ≤ 1e-9·(1 + ln 1e9) ≈ 2e-8 of optical depth, and the log singularity slows
    // RK4 to ~h·ln h near it: 1e-6 with 2^20 steps.
    expectNear(front, rk4(tf, 5, 10, 0.5, 1.0, 1 << 20, 1 - 1e-9), 1e-6, "front of the plateau");
    // Starting inside the plateau: its own colour, opaque.
    for (auto [sf, sb] : {std::pair{15.0, 15.0}, std::pair{15.0, 5.0}, std::pair{12.0, 30.0}}) {
        const SegmentIntegral in = integrateSegment(tf, sf, sb, 0.25, 1.0);
        const Rgba c = tf.evaluate(sf);
        EXPECT_EQ(in.alpha(), 1.0);
        EXPECT_NEAR(in.r, c.r, 1e-15);
        EXPECT_NEAR(in.g, c.g, 1e-15);
        EXPECT_NEAR(in.b, c.b, 1e-15);
    }
    // A single value with a = 1 crossed by a sloped segment absorbs a finite amount.
    TransferFunction peak;
    peak.points = {{0, 1, 1, 1, 0}, {1, 1, 1, 1, 1}, {2, 1, 1, 1, 0}};
    const SegmentIntegral p = integrateSegment(peak, 0, 2, 0.5, 1.0);
    // D = (d/u)·mean(−ln(1 − a)) over a ∈ [0, 1] = 0.5·1.
    EXPECT_NEAR(p.opticalDepth, 0.5, 1e-12);
    EXPECT_FALSE(std::isnan(p.r));
    EXPECT_EQ(integrateSegment(peak, 1, 1, 0.5, 1.0).alpha(), 1.0);
}

TEST(PreintegrationSegment, TinyOpacityKeepsRelativeAccuracy) {
    const double a = 1e-9;
    TransferFunction flat;
    flat.points = {{0, 0.5, 0.5, 0.5, a}};
    const SegmentIntegral s = integrateSegment(flat, 3, 3, 0.5, 1.0);
    // 1 − (1 − a)^0.5 = a/2 + a²/8 + …; relative accuracy to rounding, 1e-12.
    const double alpha = 0.5 * a + a * a / 8;
    EXPECT_NEAR(s.alpha() / alpha, 1.0, 1e-12);
    EXPECT_NEAR(s.r / (0.5 * alpha), 1.0, 1e-12);
    // A ramp 0 → a with colour 0 → 1 over a unit segment: to first order in a,
    // C = ∫₀¹ s·(a·s) ds = a/3 and D = a/2; the neglected terms are O(a) relative = 1e-9.
    TransferFunction ramp;
    ramp.points = {{0, 0, 0, 0, 0}, {10, 1, 1, 1, a}};
    const SegmentIntegral r = integrateSegment(ramp, 0, 10, 1.0, 1.0);
    EXPECT_NEAR(r.opticalDepth / (a / 2), 1.0, 1e-8);
    EXPECT_NEAR(r.r / (a / 3), 1.0, 1e-8);
    EXPECT_NEAR(r.alpha() / (a / 2), 1.0, 1e-8);
}

TEST(PreintegrationSegment, OpticalDepthIsSymmetricAndZeroLengthIsEmpty) {
    const TransferFunction tf = ctTf();
    // D = d·mean τ over [sf, sb] does not depend on the direction.
    for (auto [sf, sb] : {std::pair{-900.0, 2500.0}, std::pair{0.0, 70.0}, std::pair{-1024.0, 3071.0}})
        EXPECT_NEAR(integrateSegment(tf, sf, sb, 0.5, 1).opticalDepth,
                    integrateSegment(tf, sb, sf, 0.5, 1).opticalDepth, 1e-14);
    const SegmentIntegral none = integrateSegment(tf, 0, 100, 0, 1);
    EXPECT_EQ(none.alpha(), 0.0);
    EXPECT_EQ(none.r, 0.0);
    EXPECT_EQ(integrateSegment(tf, NAN, 100, 1, 1).alpha(), 0.0); // NaN data is transparent
}

// ---- The table ---------------------------------------------------------------------------

// The two tables several tests read, built once (step 0.5, opacity unit 1, CT range, 2 threads).
const PreintegrationTable &spikeTable() {
    static const PreintegrationTable t = buildPreintegrationTable(spikeTf(), 0.5, 1.0, -1024, 3071, 1e-3, 1024, 2);
    return t;
}
const PreintegrationTable &ctTable() {
    static const PreintegrationTable t = buildPreintegrationTable(ctTf(), 0.5, 1.0, -1024, 3071, 1e-3, 1024, 2);
    return t;
}

void expectAllFinite(const PreintegrationTable &t) {
    size_t bad = 0;
    for (size_t k = 0; k < t.rgba.size(); ++k) {
        const float v = t.rgba[k];
        if (!std::isfinite(v) || v < 0 || v > 1.0f + 1e-6f) ++bad;
    }
    EXPECT_EQ(bad, 0u) << "entries that are NaN, Inf or outside [0, 1]";
}

void printRecord(const char *name, const PreintegrationTable &t) {
    std::printf("[ table    ] %s: %d nodes, max error %.3g, %lld segments, %.3f s, locator %d buckets (scan <= %d)\n",
                name, t.nodeCount(), t.maxError, t.segmentsIntegrated, t.buildSeconds, t.locatorBuckets,
                t.locatorMaxScan);
}

// Largest |lookup − exact| over channels at random (sf, sb) pairs drawn from families that
// stress the table: anywhere, one end near the spike, both near it, and near the diagonal.
double randomPairError(const PreintegrationTable &t, const TransferFunction &tf, double centre, int perFamily) {
    std::mt19937 rng(12345);
    std::uniform_real_distribution<double> any(t.valueMin, t.valueMax), near(centre - 3, centre + 3);
    std::normal_distribution<double> tiny(0, 0.05);
    double worst = 0;
    for (int family = 0; family < 4; ++family)
        for (int k = 0; k < perFamily; ++k) {
            double sf = 0, sb = 0;
            switch (family) {
            case 0: sf = any(rng); sb = any(rng); break;
            case 1: sf = any(rng); sb = near(rng); if (k % 2) std::swap(sf, sb); break;
            case 2: sf = near(rng); sb = near(rng); break;
            default: sf = near(rng); sb = sf + tiny(rng); break;
            }
            // The table clamps values to its range by design; compare inside it.
            const float fsf = float(std::clamp(sf, t.valueMin, t.valueMax));
            const float fsb = float(std::clamp(sb, t.valueMin, t.valueMax));
            const Rgba got = t.lookup(fsf, fsb);
            const SegmentIntegral want = integrateSegment(tf, fsf, fsb, t.step, t.opacityUnit);
            worst = std::max({worst, std::fabs(got.r - want.r), std::fabs(got.g - want.g),
                              std::fabs(got.b - want.b), std::fabs(got.a - want.alpha())});
        }
    return worst;
}

TEST(PreintegrationTable, SpikeOnCtRangeStaysWithinTolerance) {
    const TransferFunction tf = spikeTf();
    const PreintegrationTable &t = spikeTable();
    printRecord("spike", t);
    EXPECT_TRUE(t.converged);
    EXPECT_FALSE(t.hitNodeLimit);
    EXPECT_LE(t.maxError, 1e-3);
    // The point of the non-uniform nodes: far fewer than the 4096 a uniform table would need
    // to resolve a one-unit spike on a 4096-unit range.
    EXPECT_LT(t.nodeCount(), 512);
    expectAllFinite(t);
    // Independent check between the build's own check points, against the exact integral.
    EXPECT_LE(randomPairError(t, tf, 300, 5000), 1e-3);
}

TEST(PreintegrationTable, CtPresetStaysWithinTolerance) {
    const TransferFunction tf = ctTf();
    const PreintegrationTable &t = ctTable();
    printRecord("ct_soft_tissue", t);
    EXPECT_TRUE(t.converged);
    EXPECT_LT(t.nodeCount(), 512);
    expectAllFinite(t);
    EXPECT_LE(randomPairError(t, tf, 60, 3000), 1e-3);
}

TEST(PreintegrationTable, ControlPointsAreNodesAndNodesAreExact) {
    const TransferFunction tf = spikeTf();
    const PreintegrationTable &t = spikeTable();
    ASSERT_GE(t.nodeCount(), 2);
    EXPECT_EQ(t.nodes.front(), -1024.0f);
    EXPECT_EQ(t.nodes.back(), 3071.0f);
    EXPECT_TRUE(std::is_sorted(t.nodes.begin(), t.nodes.end()));
    EXPECT_EQ(std::adjacent_find(t.nodes.begin(), t.nodes.end()), t.nodes.end());
    for (float v : {299.5f, 300.0f, 300.5f})
        EXPECT_TRUE(std::binary_search(t.nodes.begin(), t.nodes.end(), v)) << v;
    // At nodes the lookup returns the stored exact value: float rounding, 1e-6.
    for (int i = 0; i < t.nodeCount(); i += 7)
        for (int j = 0; j < t.nodeCount(); j += 5) {
            const Rgba got = t.lookup(t.nodes[size_t(i)], t.nodes[size_t(j)]);
            const SegmentIntegral want = integrateSegment(tf, t.nodes[size_t(i)], t.nodes[size_t(j)], 0.5, 1.0);
            EXPECT_NEAR(got.r, want.r, 1e-6);
            EXPECT_NEAR(got.a, want.alpha(), 1e-6);
        }
}

TEST(PreintegrationTable, LocatorFindsTheInterval) {
    const PreintegrationTable &t = spikeTable();
    ASSERT_EQ(int(t.locator.size()), t.locatorBuckets + 1);
    std::mt19937 rng(7);
    std::uniform_real_distribution<float> any(-1024, 3071), near(298, 302);
    std::vector<float> values(t.nodes.begin(), t.nodes.end());
    for (int k = 0; k < 20000; ++k) values.push_back(k % 2 ? any(rng) : near(rng));
    for (float v : values) {
        const auto c = t.locate(v);
        ASSERT_GE(c.i, 0);
        ASSERT_LE(c.i, t.nodeCount() - 2);
        const float lo = t.nodes[size_t(c.i)], hi = t.nodes[size_t(c.i) + 1];
        ASSERT_TRUE(v >= lo && v <= hi) << v << " not in [" << lo << ", " << hi << "]";
        // The position is the value's, to float rounding of (v − lo)/(hi − lo).
        EXPECT_NEAR(lo + c.f * (hi - lo), v, 1e-6 * std::max(1.0f, std::fabs(v)) + 1e-6 * (hi - lo));
    }
}

TEST(PreintegrationTable, ValuesOutsideTheRangeClampToTheEndNodes) {
    const PreintegrationTable &t = ctTable();
    for (float other : {-1024.0f, 0.0f, 200.0f, 3071.0f}) {
        const Rgba inLo = t.lookup(-1024, other), outLo = t.lookup(-5000, other);
        const Rgba inHi = t.lookup(other, 3071), outHi = t.lookup(other, 1e6f);
        EXPECT_EQ(inLo.r, outLo.r);
        EXPECT_EQ(inLo.a, outLo.a);
        EXPECT_EQ(inHi.g, outHi.g);
        EXPECT_EQ(inHi.a, outHi.a);
    }
}

TEST(PreintegrationTable, OpaqueTransferFunctionGivesAFiniteTable) {
    // a = 1 on a plateau: D = inf there, the table must still hold alpha = 1 and finite colour.
    TransferFunction tf;
    tf.points = {{0, 1, 0, 0, 0}, {10, 0, 1, 0, 1}, {20, 0, 0, 1, 1}, {30, 1, 1, 1, 0.2}};
    const PreintegrationTable t = buildPreintegrationTable(tf, 1.0, 1.0, 0, 30, 1e-3, 1024, 2);
    printRecord("opaque plateau", t);
    expectAllFinite(t);
    // The jump into the plateau sits between two adjacent floats, so the table converges.
    EXPECT_TRUE(t.converged);
    EXPECT_LE(randomPairError(t, tf, 10, 3000), 1e-3);
    EXPECT_EQ(t.lookup(15, 15).a, 1.0);
    EXPECT_NEAR(t.lookup(15, 5).b, 0.5, 1e-6); // the entry colour of the plateau at 15
    // Plateau edges that are not floats (0.1, 0.3): the jump still falls between two nodes.
    TransferFunction odd;
    odd.points = {{0, 1, 0, 0, 0}, {0.1, 0, 1, 0, 1}, {0.3, 0, 0, 1, 1}, {1, 1, 1, 1, 0.5}};
    const PreintegrationTable u = buildPreintegrationTable(odd, 0.01, 0.01, 0, 1, 1e-3, 1024, 2);
    printRecord("plateau 0.1..0.3", u);
    expectAllFinite(u);
    EXPECT_TRUE(u.converged);
    EXPECT_LE(randomPairError(u, odd, 0.2, 3000), 1e-3);
}

TEST(PreintegrationTable, OpacityReachingOneAtASingleValueConverges) {
    // a → 1 linearly at 1500 (the last control point, clamped beyond: a = 1 plateau above).
    // Near 1500 the optical depth of a short segment grows like −ln(1 − a): alpha approaches 1
    // like a power of the distance, which only nodes down to adjacent floats can follow.
    TransferFunction tf;
    tf.points = {{-1024, 0, 0, 0, 0}, {100, 0.8, 0.3, 0.2, 0}, {400, 0.9, 0.7, 0.5, 0.5}, {1500, 1, 1, 1, 1}};
    const PreintegrationTable t = buildPreintegrationTable(tf, 0.25, 1.0, -1024, 3071, 1e-3, 1024, 2);
    printRecord("a = 1 at 1500", t);
    EXPECT_TRUE(t.converged);
    EXPECT_LT(t.nodeCount(), 512);
    expectAllFinite(t);
    EXPECT_LE(randomPairError(t, tf, 1500, 3000), 1e-3);
}

TEST(PreintegrationTable, NodeLimitIsReportedNotLoopedOn) {
    const PreintegrationTable t = buildPreintegrationTable(spikeTf(), 0.5, 1.0, -1024, 3071, 1e-6, 40, 2);
    EXPECT_TRUE(t.hitNodeLimit);
    EXPECT_FALSE(t.converged);
    EXPECT_LE(t.nodeCount(), 40);
    EXPECT_GT(t.maxError, 1e-6);
    expectAllFinite(t);
}

TEST(PreintegrationTable, RejectsBadArguments) {
    EXPECT_THROW(buildPreintegrationTable(TransferFunction{}, 0.5, 1, 0, 1), std::invalid_argument);
    EXPECT_THROW(buildPreintegrationTable(ctTf(), 0, 1, 0, 1), std::invalid_argument);
    EXPECT_THROW(buildPreintegrationTable(ctTf(), 0.5, 1, 1, 1), std::invalid_argument);
}

// ---- Partial segments --------------------------------------------------------------------

TEST(PreintegrationPartialSegment, ConstantValueMatchesExact) {
    const TransferFunction tf = ctTf();
    const PreintegrationTable &t = ctTable();
    // At a node pair (v, v) the table holds the exact full step, so the partial helper must
    // reproduce the exact partial segment to float rounding (relative 1e-5 through log1p/expm1).
    for (int i = 0; i < t.nodeCount(); i += 3) {
        const float v = t.nodes[size_t(i)];
        for (float len : {0.5f, 0.25f, 0.05f, 1e-4f}) {
            const Rgba got = t.partialSegment(v, v, len);
            const SegmentIntegral want = integrateSegment(tf, v, v, len, 1.0);
            EXPECT_NEAR(got.a, want.alpha(), 1e-5 * want.alpha() + 1e-12) << v << " " << len;
            EXPECT_NEAR(got.r, want.r, 1e-5 * want.r + 1e-12) << v << " " << len;
            EXPECT_NEAR(got.g, want.g, 1e-5 * want.g + 1e-12);
        }
    }
    // Zero length adds nothing; the full step is the table itself.
    EXPECT_EQ(t.partialSegment(100, 200, 0).a, 0.0);
    EXPECT_EQ(t.partialSegment(100, 200, 0.5f).a, t.lookup(100, 200).a);
}

TEST(PreintegrationPartialSegment, ThinSegmentsScaleWithLength) {
    // Where alpha → 0 the colour ratio alpha'/alpha tends to len/step.
    TransferFunction tf;
    tf.points = {{0, 1, 0.5, 0.25, 1e-7}};
    const PreintegrationTable t = buildPreintegrationTable(tf, 1.0, 1.0, 0, 10, 1e-3, 64, 2);
    const Rgba full = t.lookup(3, 3), part = t.partialSegment(3, 3, 0.25f);
    // Relative 1e-6: float rounding of log1p/expm1 at alpha ≈ 1e-7.
    EXPECT_NEAR(part.a / full.a, 0.25, 1e-6);
    EXPECT_NEAR(part.r / full.r, 0.25, 1e-6);
}

} // namespace
} // namespace volcast
