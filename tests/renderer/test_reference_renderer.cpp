// Closed-form checks of the reference integrator. Each tolerance says where it comes from.

#include "renderer/reference/reconstruction.hpp"
#include "renderer/reference/reference_renderer.hpp"
#include "renderer/model/synthetic.hpp"
#include "test_scenes.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <limits>
#include <random>

namespace volcast {
namespace {

using test::chordLength;
using test::constantTf;
Camera obliqueCamera(const Volume &v) { return test::obliqueCamera(v, 28); }

TEST(ReferenceRenderer, ConstantBoxObliqueMatchesClosedForm) {
    const SyntheticVolume box = makeConstantBox({12, 9, 15}, {1.0, 1.5, 0.8}, 100);
    const double a = 0.07, unit = 0.9;
    const ReferenceRenderer ref(box.volume, constantTf(0.9, 0.5, 0.2, a, unit), Reconstruction::Linear);
    const RayGenerator rays(obliqueCamera(box.volume), 24, 20);
    int hits = 0;
    for (int y = 0; y < 20; ++y)
        for (int x = 0; x < 24; ++x) {
            const Ray ray = rays.pixelRay(x, y);
            const double L = chordLength(box.volume, ray);
            const RayIntegral r = ref.integrate(ray, {}, 1e-10);
            // Opacity 1 − (1 − a)^(L/u) and colour c·A. The integrand is constant on the
            // chord, which 5-point Gauss integrates exactly: only rounding remains (~1e-15
            // per interval), so 1e-12 is a generous bound.
            const double A = -std::expm1(L / unit * std::log1p(-a));
            EXPECT_NEAR(r.color.a, A, 1e-12) << x << "," << y;
            EXPECT_NEAR(r.color.r, 0.9 * A, 1e-12);
            EXPECT_NEAR(r.color.g, 0.5 * A, 1e-12);
            EXPECT_NEAR(r.color.b, 0.2 * A, 1e-12);
            hits += L > 0;
        }
    EXPECT_GT(hits, 60); // the camera really sees the box
}

TEST(ReferenceRenderer, OpaqueBoxIsExactlyOpaqueAndMissesAreExactlyZero) {
    const SyntheticVolume box = makeConstantBox({10, 10, 10}, {1, 1, 1}, 50);
    const ReferenceRenderer ref(box.volume, constantTf(0.25, 0.5, 0.75, 1.0, 1.0), Reconstruction::Linear);
    const RayGenerator rays(obliqueCamera(box.volume), 32, 32);
    int hits = 0, misses = 0;
    for (int y = 0; y < 32; ++y)
        for (int x = 0; x < 32; ++x) {
            const Ray ray = rays.pixelRay(x, y);
            const RayIntegral r = ref.integrate(ray, {}, 1e-9);
            if (chordLength(box.volume, ray) > 0) {
                // a = 1: the first point of material stops the ray, exactly.
                EXPECT_EQ(r.color.a, 1.0);
                EXPECT_EQ(r.color.r, 0.25);
                EXPECT_EQ(r.color.g, 0.5);
                EXPECT_EQ(r.color.b, 0.75);
                ++hits;
            } else {
                EXPECT_EQ(r.color.a, 0.0);
                EXPECT_EQ(r.color.r, 0.0);
                ++misses;
            }
        }
    EXPECT_GT(hits, 50);
    EXPECT_GT(misses, 50);
}

// dC/dx = c τ exp(−OD), dOD/dx = τ integrated by classical RK4 on pieces between known
// kinks, an independent 1-D quadrature of the same integral.
struct Rk4Result {
    double color, od;
};
template <typename Tau, typename Col>
Rk4Result rk4(const Tau &tau, const Col &col, std::vector<double> knots, int stepsPerPiece) {
    double C = 0, od = 0;
    for (size_t p = 0; p + 1 < knots.size(); ++p) {
        const double h = (knots[p + 1] - knots[p]) / stepsPerPiece;
        for (int s = 0; s < stepsPerPiece; ++s) {
            const double x = knots[p] + s * h;
            auto f = [&](double xx, double odd) { return std::make_pair(col(xx) * tau(xx) * std::exp(-odd), tau(xx)); };
            const auto k1 = f(x, od);
            const auto k2 = f(x + h / 2, od + h / 2 * k1.second);
            const auto k3 = f(x + h / 2, od + h / 2 * k2.second);
            const auto k4 = f(x + h, od + h * k3.second);
            C += h / 6 * (k1.first + 2 * k2.first + 2 * k3.first + k4.first);
            od += h / 6 * (k1.second + 2 * k2.second + 2 * k3.second + k4.second);
        }
    }
    return {C, od};
}

TEST(ReferenceRenderer, LinearRampMatchesOneDimensionalQuadrature) {
    // Ramp 0..252 along x over 64 samples (slope 4: every sample exact in float32, so the
    // quadrature below integrates the very field the volume holds); the ray runs along x
    // through the middle, where trilinear reconstruction is the ramp, clamped in the outer
    // half-voxels.
    const int n = 64;
    const SyntheticVolume ramp = makeLinearRamp({n, 8, 8}, {1, 1, 1}, 0, 4.0 * (n - 1));
    TransferFunction tf;
    // A smooth rise, then a spike one data unit wide: the kinks must all be found.
    tf.points = {{0, 0.2, 0.2, 0.2, 0}, {100, 1, 0.5, 0, 0.02}, {150, 1, 0.5, 0, 0.02},
                 {150.5, 0, 1, 0, 0.6}, {151, 1, 0.5, 0, 0.02}, {255, 1, 1, 1, 0.05}};
    tf.opacityUnit = 1.0;
    const ReferenceRenderer ref(ramp.volume, tf, Reconstruction::Linear);
    const Ray ray{{-5, 3.5, 3.5}, {1, 0, 0}};
    const RayIntegral r = ref.integrate(ray, {}, 1e-10);

    const double slope = 4.0;
    auto value = [&](double x) { return std::clamp(x, 0.0, double(n - 1)) * slope; }; // world x = index x
    auto tau = [&](double x) { return extinction(tf.evaluate(value(x)).a, 1.0); };
    std::vector<double> knots{-0.5, 0.0};
    for (const auto &p : tf.points)
        if (p.value / slope < n - 1) knots.push_back(p.value / slope); // kinks inside the chord
    knots.push_back(double(n - 1));
    knots.push_back(n - 0.5);
    std::sort(knots.begin(), knots.end());
    for (int c = 0; c < 3; ++c) {
        auto col = [&](double x) {
            const Rgba q = tf.evaluate(value(x));
            return c == 0 ? q.r : (c == 1 ? q.g : q.b);
        };
        // RK4 with 2000 steps per smooth piece: its error is O(h⁴) ≈ 1e-13 here, so the
        // two integrals must agree to the reference's requested 1e-10 (plus rounding).
        const Rk4Result q = rk4(tau, col, knots, 2000);
        const double got = c == 0 ? r.color.r : (c == 1 ? r.color.g : r.color.b);
        EXPECT_NEAR(got, q.color, 2e-10) << "channel " << c;
        EXPECT_NEAR(r.color.a, -std::expm1(-q.od), 2e-10);
    }
    EXPECT_LE(r.errorEstimate, 1e-10);
    EXPECT_GT(r.color.a, 0.5); // the spike and the rise really matter in this test
}

TEST(ReferenceRenderer, CubicPathMatchesDirectQuadratureOfTheSpline) {
    // The integrator represents the B-spline along a ray by a degree-9 polynomial per cell;
    // here the same integral is taken by RK4 evaluating the spline itself at every step.
    const SyntheticVolume blob = makeGaussianBlob({20, 12, 12}, {1, 1, 1}, 2.5, 200);
    TransferFunction tf;
    tf.points = {{-100, 0.3, 0.6, 0.9, 0.0}, {300, 0.9, 0.6, 0.3, 0.4}}; // one linear segment
    tf.opacityUnit = 1.0;
    const ReferenceRenderer ref(blob.volume, tf, Reconstruction::Cubic);
    const CubicBSplineField spline(blob.volume);
    const double y = 5.3, z = 6.1; // off the grid lines, through the blob
    const RayIntegral r = ref.integrate(Ray{{-3, y, z}, {1, 0, 0}}, {}, 1e-11);
    auto tau = [&](double x) { return extinction(tf.evaluate(spline({x, y, z})).a, 1.0); };
    auto red = [&](double x) { return tf.evaluate(spline({x, y, z})).r; };
    std::vector<double> knots{-0.5};
    for (int k = 0; k <= 19; ++k) knots.push_back(k); // the spline's knots along x
    knots.push_back(19.5);
    // Between knots the integrand is smooth, so RK4 at 400 steps per voxel is accurate to
    // ~1e-12; the spline is C² at the knots, where the pieces meet.
    const Rk4Result q = rk4(tau, red, knots, 400);
    EXPECT_NEAR(r.color.a, -std::expm1(-q.od), 1e-9);
    EXPECT_NEAR(r.color.r, q.color, 1e-9);
    EXPECT_GT(r.color.a, 0.2);
}

TEST(ReferenceRenderer, MirroringVolumeAndCameraTogetherMirrorsTheImage) {
    // An asymmetric volume: random values, so no accidental symmetry hides an error.
    const Vec3i dims{9, 7, 8};
    std::mt19937 rng(7);
    std::uniform_real_distribution<double> u(0, 255);
    Volume v;
    v.dims = dims;
    v.spacing = {1, 1.2, 0.9};
    v.voxels.resize(v.voxelCount());
    for (float &x : v.voxels) x = float(u(rng));
    computeStatistics(v);
    Volume m = v;
    for (int64_t k = 0; k < dims.z; ++k)
        for (int64_t j = 0; j < dims.y; ++j)
            for (int64_t i = 0; i < dims.x; ++i) m.voxels[m.index(i, j, k)] = v.at(dims.x - 1 - i, j, k);
    TransferFunction tf;
    tf.points = {{0, 0, 0, 1, 0}, {120, 1, 0, 0, 0.1}, {200, 0, 1, 0, 0.4}, {255, 1, 1, 1, 0.2}};
    // Mirror x about the volume's centre plane.
    const double cx = v.center().x;
    auto mirror = [cx](Vec3d p) { return Vec3d{2 * cx - p.x, p.y, p.z}; };
    Camera cam = obliqueCamera(v);
    Camera camM = cam;
    camM.eye = mirror(cam.eye);
    camM.target = mirror(cam.target);
    camM.up = {-cam.up.x, cam.up.y, cam.up.z};
    for (Reconstruction rec : {Reconstruction::Linear, Reconstruction::Cubic}) {
        const ReferenceRenderer a(v, tf, rec), b(m, tf, rec);
        ReferenceOptions opt;
        opt.tolerance = 1e-8;
        const Image ia = a.render(cam, 20, 16, {}, opt), ib = b.render(camM, 20, 16, {}, opt);
        // Mirroring flips handedness, so image x runs the other way. Both integrals are
        // within 1e-8 of the truth and stored as float32 (~6e-8 relative): 2e-7 bounds it.
        for (int y = 0; y < 16; ++y)
            for (int x = 0; x < 20; ++x)
                for (int c = 0; c < 4; ++c)
                    EXPECT_NEAR(ia.pixel(x, y)[c], ib.pixel(19 - x, y)[c], 2e-7) << x << "," << y << "," << c;
    }
}

TEST(ReferenceRenderer, ClipPlaneShortensTheChordExactly) {
    const SyntheticVolume box = makeConstantBox({16, 16, 16}, {1, 1, 1}, 10);
    const ReferenceRenderer ref(box.volume, constantTf(1, 1, 1, 0.2, 1.0), Reconstruction::Linear);
    // Ray along +z through the box; the plane keeps z ≥ 4.25 (normal +z), so L = 15.5 − 4.25.
    const Ray ray{{7.5, 7.5, -10}, {0, 0, 1}};
    const ClipPlane keepAbove{{0, 0, 4.25}, {0, 0, 1}};
    const RayIntegral r = ref.integrate(ray, std::span<const ClipPlane>(&keepAbove, 1), 1e-12);
    EXPECT_NEAR(r.color.a, -std::expm1((15.5 - 4.25) * std::log1p(-0.2)), 1e-13); // constant integrand: exact
    const ClipPlane removeAll{{0, 0, 100}, {0, 0, 1}};
    EXPECT_EQ(ref.integrate(ray, std::span<const ClipPlane>(&removeAll, 1), 1e-9).color.a, 0.0);
}

TEST(ReferenceRenderer, CubicReconstructionOfALinearFieldIsExactAwayFromTheBoundary) {
    const Vec3i dims{48, 48, 48};
    auto field = [](const Vec3d &p) { return 3.0 + 1.5 * p.x - 0.75 * p.y + 0.5 * p.z; };
    const SyntheticVolume lin = sampleField("linear", dims, {1, 1, 1}, {}, field);
    const CubicBSplineField cubic(lin.volume);
    std::mt19937 rng(3);
    std::uniform_real_distribution<double> u(20, 27);
    for (int i = 0; i < 200; ++i) {
        const Vec3d p{u(rng), u(rng), u(rng)};
        // B-splines reproduce linear functions; the mirror boundary's disturbance decays as
        // |z|^d with z = √3 − 2: at d ≥ 20 voxels, 0.268^20 ≈ 4e-12 times the boundary's
        // kink (~slope · n ≈ 100): ~4e-10. The samples are multiples of 1/4, exact in
        // float32, so nothing else enters: 1e-8 bounds it with room.
        EXPECT_NEAR(cubic(p), field(p), 1e-8);
    }
}

TEST(ReferenceRenderer, ReportsAToleranceAtLeastAsGoodAsRequested) {
    const SyntheticVolume blob = makeGaussianBlob({24, 24, 24}, {1, 1, 1}, 5, 200);
    TransferFunction tf;
    tf.points = {{0, 0, 0, 0, 0}, {50, 1, 0.3, 0.1, 0.05}, {120, 0.2, 0.8, 1, 0.3}, {200, 1, 1, 1, 0.9}};
    const ReferenceRenderer ref(blob.volume, tf, Reconstruction::Linear);
    Camera cam = obliqueCamera(blob.volume);
    ReferenceOptions loose, tight;
    loose.tolerance = 1e-3;
    tight.tolerance = 1e-9;
    ReferenceStats sl, st;
    const Image il = ref.render(cam, 16, 16, {}, loose, &sl);
    const Image it = ref.render(cam, 16, 16, {}, tight, &st);
    EXPECT_LE(sl.toleranceReached, 1e-3);
    EXPECT_LE(st.toleranceReached, 1e-9);
    // The loose image is within its own tolerance of the tight one (which is ~exact).
    for (size_t i = 0; i < il.rgba.size(); ++i) EXPECT_NEAR(il.rgba[i], it.rgba[i], 1e-3 + 1e-7);
}

TEST(ReferenceRenderer, AnalyticFieldConvergesToTheSampledOneOnAFineGrid) {
    // A smooth blob sampled finely: trilinear reconstruction error is O(h²·f''), small here,
    // so the analytic and sampled integrals must be close but not identical.
    const SyntheticVolume blob = makeGaussianBlob({32, 32, 32}, {1, 1, 1}, 8, 200);
    TransferFunction tf;
    tf.points = {{0, 0, 0, 0, 0}, {60, 1, 0.5, 0.2, 0.05}, {200, 1, 1, 1, 0.3}};
    const ReferenceRenderer sampled(blob.volume, tf, Reconstruction::Linear);
    const ReferenceRenderer analytic(blob.volume, tf, blob.field);
    const Ray ray{{-20, 15.2, 16.1}, normalize(Vec3d{1, 0.05, -0.02})};
    ReferenceStats stats;
    const RayIntegral a = analytic.integrate(ray, {}, 1e-9, &stats);
    const RayIntegral s = sampled.integrate(ray, {}, 1e-9);
    EXPECT_GT(a.color.a, 0.3);
    // Trilinear error of a Gaussian with σ = 8 voxels: h²/8·max|f''| ≈ 200/64/8 ≈ 0.4 data
    // units, which moves opacity by well under 1 %.
    EXPECT_NEAR(a.color.a, s.color.a, 1e-2);
    EXPECT_LT(stats.analyticFitError, 1e-6); // the degree-9 fit on quarter voxels is tight
}

// Picking on a constant box: the optical depth grows linearly along the chord, so the opacity
// 1 − (1 − a)^(L/u) reaches one half after L* = u·ln ½ / ln(1 − a). τ is constant, so the
// crossing's placement inside its interval is exact: only rounding remains (1e-9 mm). Rays
// whose chord is shorter than L* never get there: no hit, their final opacity as the closed form.
TEST(ReferencePick, ConstantBoxReachesOneHalfWhereTheClosedFormSays) {
    const SyntheticVolume box = makeConstantBox({12, 9, 15}, {1.0, 1.5, 0.8}, 100);
    const double a = 0.2, unit = 0.9;
    const ReferenceRenderer ref(box.volume, constantTf(0.9, 0.5, 0.2, a, unit), Reconstruction::Linear);
    const RayGenerator rays(obliqueCamera(box.volume), 24, 20);
    const double lStar = unit * std::log(0.5) / std::log1p(-a);
    int hits = 0, misses = 0;
    for (int y = 0; y < 20; ++y)
        for (int x = 0; x < 24; ++x) {
            const Ray ray = rays.pixelRay(x, y);
            const double L = chordLength(box.volume, ray);
            const RayPick pick = ref.pick(ray, {}, 0.5, 1e-9);
            EXPECT_NEAR(pick.opacity, -std::expm1(L / unit * std::log1p(-a)), 1e-12);
            // A ray grazing the box by less than 1e-9 of L* could go either way.
            if (std::fabs(L - lStar) < 1e-9) continue;
            ASSERT_EQ(pick.hit, L > lStar) << x << "," << y << " chord " << L;
            if (!pick.hit) {
                misses += L > 0;
                continue;
            }
            ++hits;
            // The entry point: where the chord starts, from the exit side's length.
            double t0 = 0, t1 = std::numeric_limits<double>::infinity();
            for (int k = 0; k < 3; ++k) {
                const double lo = box.volume.origin[k] - 0.5 * box.volume.spacing[k];
                const double hi = box.volume.origin[k] + (double(box.volume.dims[k]) - 0.5) * box.volume.spacing[k];
                double ta = (lo - ray.origin[k]) / ray.dir[k], tb = (hi - ray.origin[k]) / ray.dir[k];
                if (ta > tb) std::swap(ta, tb);
                t0 = std::max(t0, ta);
                t1 = std::min(t1, tb);
            }
            EXPECT_NEAR(pick.t, t0 + lStar, 1e-9);
            EXPECT_NEAR(length(pick.point - (ray.origin + ray.dir * (t0 + lStar))), 0, 1e-9);
        }
    EXPECT_GT(hits, 40);
    EXPECT_GT(misses, 0) << "some corner rays are too short to reach one half";
}

// An opaque box (a = 1) is half opaque at its surface; a clip plane moves that surface.
TEST(ReferencePick, OpaqueSurfaceAndClipPlane) {
    const SyntheticVolume box = makeConstantBox({10, 10, 10}, {1, 1, 1}, 50);
    const ReferenceRenderer ref(box.volume, constantTf(1, 1, 1, 1.0, 1.0), Reconstruction::Linear);
    // Straight down −z through the middle: the top face is at z = 9.5.
    const Ray ray{{4.5, 4.5, 50}, {0, 0, -1}};
    RayPick pick = ref.pick(ray, {}, 0.5, 1e-7);
    ASSERT_TRUE(pick.hit);
    EXPECT_NEAR(pick.point.z, 9.5, 1e-12);
    EXPECT_EQ(pick.opacity, 1.0);
    const ClipPlane cut{{0, 0, 3}, {0, 0, -1}};   // keeps z <= 3
    pick = ref.pick(ray, std::span<const ClipPlane>(&cut, 1), 0.5, 1e-7);
    ASSERT_TRUE(pick.hit);
    EXPECT_NEAR(pick.point.z, 3, 1e-12);
    // A ray beside the box: no hit, opacity 0.
    pick = ref.pick({{40, 4.5, 50}, {0, 0, -1}}, {}, 0.5, 1e-7);
    EXPECT_FALSE(pick.hit);
    EXPECT_EQ(pick.opacity, 0.0);
    EXPECT_THROW(ref.pick(ray, {}, 1.0, 1e-7), std::invalid_argument);
}

// Under MIP the pick is where the ray's maximum lies: for a ray through a Gaussian blob's
// centre that is the centre, within the trilinear field's flat top (a voxel's tenth here:
// the samples around the peak are symmetric, so the reconstruction peaks at the centre).
TEST(ReferencePick, MipPicksTheMaximum) {
    const SyntheticVolume blob = makeGaussianBlob({25, 25, 25}, {1, 1, 1}, 4, 900);
    TransferFunction tf;
    tf.points = {{0, 0, 0, 0, 1}, {900, 1, 1, 1, 1}};
    ReferenceRenderer ref(blob.volume, tf, Reconstruction::Linear);
    ref.setCompositing(Compositing::Maximum);
    const Vec3d c = blob.volume.center();
    const Ray ray{c + Vec3d{0, 0, 60}, {0, 0, -1}};
    const RayPick pick = ref.pick(ray, {}, 0.5, 1e-7);
    ASSERT_TRUE(pick.hit);
    EXPECT_EQ(pick.opacity, 1.0);
    EXPECT_NEAR(length(pick.point - c), 0, 0.1);
}
} // namespace
} // namespace volcast
