// The paper's remedies in the OpenCL ray caster, each switched on alone and measured against
// the double-precision reference integrator or a closed form; then every pair of switches
// together. Also: preprocessing happens only when a switch first needs it.

#include "renderer/error_metrics.hpp"
#include "renderer/opencl/opencl_renderer.hpp"
#include "renderer/reference_renderer.hpp"
#include "renderer/synthetic.hpp"
#include "opencl_test_context.hpp"
#include "test_scenes.hpp"

#include <gtest/gtest.h>

#include <array>
#include <cmath>

namespace volcast {
namespace {

OpenClContext &cl() { return test::sharedOpenClContext(); }

Quality plain(double step) { return test::plainQuality(step); }

TransferFunction blobTf() {
    TransferFunction tf;
    tf.points = {{0, 0, 0, 0, 0}, {40, 0, 0, 0, 0}, {90, 1, 0.4, 0.1, 0.15}, {150, 0.3, 0.7, 1, 0.4},
                 {220, 1, 1, 1, 0.7}};
    return tf;
}

const SyntheticVolume &blob() {
    static const SyntheticVolume v = makeGaussianBlob({24, 24, 24}, {1, 1, 1}, 4, 220);
    return v;
}

Image reference(const Volume &v, const TransferFunction &tf, Reconstruction rec, const Camera &cam, int w, int h,
                bool shading = false, double tolerance = 1e-6) {
    ReferenceRenderer ref(v, tf, rec);
    ref.setShading(shading);
    ReferenceOptions o;
    o.tolerance = tolerance;
    return ref.render(cam, w, h, {}, o);
}

// Every pixel finite, premultiplied (colour ≤ alpha up to float rounding), alpha in [0, 1].
void expectValidImage(const Image &img, const std::string &what) {
    int bad = 0;
    for (size_t i = 0; i < img.rgba.size(); i += 4) {
        const float a = img.rgba[i + 3];
        bool ok = std::isfinite(a) && a >= 0 && a <= 1;
        for (int k = 0; k < 3; ++k)
            ok = ok && std::isfinite(img.rgba[i + k]) && img.rgba[i + k] >= 0 && img.rgba[i + k] <= a + 1e-5f;
        bad += !ok;
    }
    EXPECT_EQ(bad, 0) << what;
}

TEST(OpenClRemedies, PreprocessingHappensOnlyWhenASwitchFirstNeedsIt) {
    OpenClRenderer r(cl(), blob().volume);
    const Camera cam = test::obliqueCamera(blob().volume, 30);
    TransferFunction tf = blobTf();
    auto counts = [&] { return r.preprocessCounts(); };

    r.render(tf, cam, 8, 8, plain(1), {});
    EXPECT_EQ(counts().tfTables, 1);
    EXPECT_EQ(counts().coefficientVolumes, 0); // no cubic asked for: no B-spline coefficients
    EXPECT_EQ(counts().preintegrationTables, 0);
    EXPECT_EQ(counts().brickGrids, 0);
    EXPECT_EQ(counts().mipLevels, 0);

    r.render(tf, cam, 8, 8, plain(0.5), {}); // a new step needs no new 1-D table
    EXPECT_EQ(counts().tfTables, 1);

    Quality q = plain(1);
    q.emptySpaceSkipping = true;
    r.render(tf, cam, 8, 8, q, {});
    EXPECT_EQ(counts().brickGrids, 1);
    EXPECT_EQ(counts().brickClassifications, 1);
    tf.points[2].a = 0.3; // a new transfer function re-classifies the same grid
    r.render(tf, cam, 8, 8, q, {});
    EXPECT_EQ(counts().brickGrids, 1);
    EXPECT_EQ(counts().brickClassifications, 2);
    EXPECT_EQ(counts().tfTables, 2);

    q.preintegrated = true;
    r.render(tf, cam, 8, 8, q, {});
    r.render(tf, cam, 8, 8, q, {});
    EXPECT_EQ(counts().preintegrationTables, 1); // same transfer function and step: reused
    q.step = 0.7;
    r.render(tf, cam, 8, 8, q, {});
    EXPECT_EQ(counts().preintegrationTables, 2); // the table depends on the step
    EXPECT_EQ(counts().coefficientVolumes, 0);

    q.interpolation = Interpolation::Cubic;
    r.render(tf, cam, 8, 8, q, {});
    r.render(tf, cam, 8, 8, q, {});
    EXPECT_EQ(counts().coefficientVolumes, 1);
    EXPECT_EQ(counts().brickGrids, 2); // the spline's bricks bound its coefficients
    EXPECT_EQ(counts().mipLevels, 0);

    q.mipLevel = 2;
    r.render(tf, cam, 8, 8, q, {});
    EXPECT_EQ(counts().mipLevels, 2); // levels 1 and 2, once
    q.mipLevel = 1;
    r.render(tf, cam, 8, 8, q, {});
    EXPECT_EQ(counts().mipLevels, 2);
}

TEST(OpenClRemedies, CubicBSplineMatchesTheReferenceSpline) {
    const Camera cam = test::obliqueCamera(blob().volume, 30);
    const Image exactCubic = reference(blob().volume, blobTf(), Reconstruction::Cubic, cam, 32, 32);
    OpenClRenderer r(cl(), blob().volume);
    Quality q = plain(0.125);
    const double linearError = compareImages(r.render(blobTf(), cam, 32, 32, q, {}), exactCubic).rmse;
    q.interpolation = Interpolation::Cubic;
    RenderStats st;
    const double cubicError = compareImages(r.render(blobTf(), cam, 32, 32, q, {}, &st), exactCubic).rmse;
    // Step 0.125 leaves a midpoint-rule error below 1e-3 (the trilinear convergence test);
    // the same spline on both sides leaves nothing else but float rounding.
    EXPECT_LT(cubicError, 1e-3);
    // And the kernel really reconstructs the spline: trilinear is far from it on a σ = 4 blob.
    EXPECT_GT(linearError, 5 * cubicError);
    EXPECT_GT(st.coefficientSeconds, 0);
}

TEST(OpenClRemedies, CubicFromEightTrilinearFetchesEqualsSixtyFourTaps) {
    OpenClRendererOptions taps, fetches;
    taps.cubicFetch = CubicFetch::Taps64;
    fetches.cubicFetch = CubicFetch::Trilinear8;
    OpenClRenderer a(cl(), blob().volume, taps), b(cl(), blob().volume, fetches);
    Quality q = plain(0.5);
    q.interpolation = Interpolation::Cubic;
    const Camera cam = test::obliqueCamera(blob().volume, 30);
    const Image ia = a.render(blobTf(), cam, 24, 24, q, {}), ib = b.render(blobTf(), cam, 24, 24, q, {});
    EXPECT_NE(a.buildOptions(q, false), b.buildOptions(q, false));
    // PoCL filters 3-D images in float (docs/platform.md: 1.2e-7 of a trilinear); GPUs use ~8-bit
    // weights, 1/256 of a coefficient step, which an opacity of 0.7 turns into ~1e-2.
    EXPECT_LT(compareImages(ia, ib).maxAbs, cl().isGpu() ? 2e-2 : 1e-4);
}

TEST(OpenClRemedies, EmptySpaceSkippingChangesTheWorkNotTheImage) {
    const SyntheticVolume sphere = makeSphere({48, 40, 44}, {1, 1, 1.2}, 9, 2, 200);
    TransferFunction tf;
    tf.points = {{0, 0, 0, 0, 0}, {60, 0, 0, 0, 0}, {120, 1, 0.6, 0.3, 0.3}, {200, 1, 1, 1, 0.5}};
    OpenClRenderer r(cl(), sphere.volume);
    const Camera cam = test::obliqueCamera(sphere.volume, 40);
    for (auto interpolation : {Interpolation::Linear, Interpolation::Cubic})
        for (bool preintegrated : {false, true}) {
            Quality q = plain(0.5);
            q.interpolation = interpolation;
            q.preintegrated = preintegrated;
            RenderStats without, with;
            const Image full = r.render(tf, cam, 32, 32, q, {}, &without);
            q.emptySpaceSkipping = true;
            const Image skipped = r.render(tf, cam, 32, 32, q, {}, &with);
            const std::string what = std::string(interpolation == Interpolation::Cubic ? "cubic" : "linear") +
                                     (preintegrated ? " pre-integrated" : "");
            // Only segments wholly inside bricks where the transfer function is 0 are skipped;
            // they add exactly 0 (pre-integration's table cells there are all zero too, since
            // the control point at 60 is a node). What remains is float rounding of t.
            EXPECT_LT(compareImages(full, skipped).maxAbs, 1e-5) << what;
            EXPECT_GT(with.skippedSegmentsPerRay, 10) << what;
            EXPECT_LT(with.meanSamplesPerRay, 0.7 * without.meanSamplesPerRay) << what;
            EXPECT_GT(with.emptyBrickFraction, 0.3) << what;
        }
}

// A linear ramp crossed by a transfer-function spike one data unit wide: the thin slab the
// paper's onion rings come from. Trilinear reconstruction of a linear field is exact, so the
// value along each segment is linear and pre-integration has only its table's error.
TEST(OpenClRemedies, PreintegrationCatchesASpikeThatSamplingMisses) {
    const SyntheticVolume ramp = makeLinearRamp({32, 24, 24}, {1, 1, 1}, 0, 248); // 8 units per voxel
    TransferFunction tf;
    tf.points = {{0, 0, 0, 0, 0}, {99.5, 0, 0, 0, 0}, {100, 1, 0.8, 0.3, 0.9}, {100.5, 0, 0, 0, 0}};
    const Camera cam = test::obliqueCamera(ramp.volume, 30);
    const Image exact = reference(ramp.volume, tf, Reconstruction::Linear, cam, 32, 32, false, 1e-7);
    OpenClRenderer r(cl(), ramp.volume);
    Quality q = plain(2);
    const double sampledError = compareImages(r.render(tf, cam, 32, 32, q, {}), exact).rmse;
    q.preintegrated = true;
    RenderStats st;
    const double preError = compareImages(r.render(tf, cam, 32, 32, q, {}, &st), exact).rmse;
    // Each ray crosses the slab once: one or two table lookups at ≤ 1e-3 each, plus float.
    EXPECT_LT(preError, 2e-3);
    EXPECT_LE(st.preintegrationError, 1e-3);
    EXPECT_GT(sampledError, 10 * preError); // step 2 (16 data units) mostly misses the spike
}

TEST(OpenClRemedies, PreintegrationConvergesOnASmoothVolume) {
    const Camera cam = test::obliqueCamera(blob().volume, 30);
    const Image exact = reference(blob().volume, blobTf(), Reconstruction::Linear, cam, 32, 32);
    OpenClRenderer r(cl(), blob().volume);
    Quality q = plain(2);
    q.preintegrated = true;
    const double coarse = compareImages(r.render(blobTf(), cam, 32, 32, q, {}), exact).rmse;
    q.step = 0.5;
    RenderStats st;
    const double fine = compareImages(r.render(blobTf(), cam, 32, 32, q, {}, &st), exact).rmse;
    // The value is not linear along a segment here: that error is second order in the step
    // (measured 3.5e-3 at step 2, 1.5e-4 at 0.5). Below that the table's own error (≤ 1e-3
    // per segment, absolute) adds up over more, fainter segments and sets the floor.
    EXPECT_LT(fine, coarse / 8);
    EXPECT_LT(fine, 1e-3);
    EXPECT_LE(st.preintegrationError, 1e-3);
}

TEST(OpenClRemedies, ShadingMatchesTheReferenceLighting) {
    const Camera cam = test::obliqueCamera(blob().volume, 30);
    const Image exactLit = reference(blob().volume, blobTf(), Reconstruction::Linear, cam, 24, 24, true, 1e-5);
    const Image exactUnlit = reference(blob().volume, blobTf(), Reconstruction::Linear, cam, 24, 24);
    OpenClRenderer r(cl(), blob().volume);
    Quality q = plain(0.125);
    q.shading = true;
    const Image lit = r.render(blobTf(), cam, 24, 24, q, {});
    expectValidImage(lit, "shaded");
    // The same lighting on the same field: the step's midpoint error (< 1e-3 at 0.125, as
    // unlit) and the reference's 1e-5 tolerance, with a margin for the |n·l| kinks.
    EXPECT_LT(compareImages(lit, exactLit).rmse, 2e-3);
    EXPECT_GT(compareImages(exactLit, exactUnlit).rmse, 10 * compareImages(lit, exactLit).rmse);
}

TEST(OpenClRemedies, MipLevelsKeepAConstantBoxExact) {
    const SyntheticVolume box = makeConstantBox({20, 13, 9}, {1, 1.5, 2}, 70);
    const TransferFunction tf = test::constantTf(0.9, 0.5, 0.2, 0.08, 1.0);
    OpenClRenderer r(cl(), box.volume);
    const Camera cam = test::obliqueCamera(box.volume, 30);
    const ReferenceRenderer ref(box.volume, tf, Reconstruction::Linear);
    const RayGenerator rays(cam, 24, 24);
    for (int level : {1, 2, 4}) {
        Quality q = plain(0.8);
        q.mipLevel = level;
        const Image img = r.render(tf, cam, 24, 24, q, {});
        // Rays are clipped to the level-0 box at every level, so a constant box keeps its
        // exact chord lengths: the tolerance of the level-0 constant-box test.
        double worst = 0;
        for (int y = 0; y < 24; ++y)
            for (int x = 0; x < 24; ++x) {
                double t0, t1;
                const double L = ref.clipRay(rays.pixelRay(x, y), {}, t0, t1) ? t1 - t0 : 0;
                worst = std::max(worst, std::fabs(img.pixel(x, y)[3] - -std::expm1(L * std::log1p(-0.08))));
            }
        EXPECT_LT(worst, 1e-5) << "mip level " << level;
    }
    Quality q = plain(1);
    q.mipLevel = 6; // 20 → 10 → 5 → 3 → 2 → 1: level 5 is the last
    try {
        r.render(tf, cam, 8, 8, q, {});
        FAIL();
    } catch (const std::invalid_argument &e) {
        EXPECT_NE(std::string(e.what()).find("mip_level"), std::string::npos) << e.what();
    }
}

TEST(OpenClRemedies, MipLevelErrorGrowsWithTheLevel) {
    const Camera cam = test::obliqueCamera(blob().volume, 30);
    const Image exact = reference(blob().volume, blobTf(), Reconstruction::Linear, cam, 24, 24);
    OpenClRenderer r(cl(), blob().volume);
    double previous = 0;
    for (int level : {0, 1, 2}) {
        Quality q = plain(0.25);
        q.mipLevel = level;
        const double e = compareImages(r.render(blobTf(), cam, 24, 24, q, {}), exact).rmse;
        EXPECT_GT(e, previous) << "level " << level; // coarser data, further from the exact picture
        previous = e;
    }
}

TEST(OpenClRemedies, ImageScaleCastsFewerRaysAndUpsamplesThem) {
    OpenClRenderer r(cl(), blob().volume);
    const Camera cam = test::obliqueCamera(blob().volume, 30);
    Quality q = plain(0.5);
    const Image small = r.render(blobTf(), cam, 15, 10, q, {});
    q.imageScale = 0.5;
    RenderStats st;
    const Image scaled = r.render(blobTf(), cam, 30, 20, q, {}, &st);
    EXPECT_EQ(st.raysWide, 15);
    EXPECT_EQ(st.raysHigh, 10);
    ASSERT_EQ(scaled.width, 30);
    ASSERT_EQ(scaled.height, 20);
    // The same rays (same image plane, same aspect) then bilinear upsampling: identical.
    EXPECT_EQ(compareImages(scaled, resizeBilinear(small, 30, 20)).maxAbs, 0);
}

TEST(OpenClRemedies, JitteredPassesAveragedBeatOnionRings) {
    const SyntheticVolume ramp = makeLinearRamp({32, 24, 24}, {1, 1, 1}, 0, 248);
    TransferFunction tf;
    // A shell one voxel (8 data units) thick: a 3-voxel step hits or misses it by ray.
    tf.points = {{0, 0, 0, 0, 0}, {96, 0, 0, 0, 0}, {100, 1, 0.7, 0.3, 0.5}, {104, 0, 0, 0, 0}};
    const Camera cam = test::obliqueCamera(ramp.volume, 30);
    const Image exact = reference(ramp.volume, tf, Reconstruction::Linear, cam, 32, 32);
    OpenClRenderer r(cl(), ramp.volume);
    Quality q = plain(3);
    const double rings = compareImages(r.render(tf, cam, 32, 32, q, {}), exact).rmse;
    q.jitter = true;
    Image mean(32, 32);
    const int passes = 16;
    for (int pass = 0; pass < passes; ++pass) {
        q.seed = uint64_t(pass);
        const Image img = r.render(tf, cam, 32, 32, q, {});
        for (size_t i = 0; i < mean.rgba.size(); ++i) mean.rgba[i] += img.rgba[i] / passes;
    }
    // Jitter turns the rings' structured error into noise that averaging shrinks by √16
    // (measured: 0.11 for the rings, 0.042 for the mean of 16 passes).
    EXPECT_LT(compareImages(mean, exact).rmse, 0.5 * rings);
}

// Every pair of switches on together at least once: ten binary factors in six runs. Column
// c is on in the rows of one 3-subset of {0..5} containing row 0 (ten such subsets): any two
// share row 0 (both on), together leave a row out (both off) and differ somewhere.
TEST(OpenClRemedies, EveryPairOfSwitchesWorksTogether) {
    std::vector<std::array<int, 3>> subsets;
    for (int a = 1; a < 6; ++a)
        for (int b = a + 1; b < 6; ++b) subsets.push_back({0, a, b});
    ASSERT_EQ(subsets.size(), 10u);
    const Camera cam = test::obliqueCamera(blob().volume, 30);
    const std::vector<ClipPlane> clip{{blob().volume.center(), normalize(Vec3d{0.2, 1, -0.3})}};
    OpenClRenderer r(cl(), blob().volume);
    for (int row = 0; row < 6; ++row) {
        bool on[10];
        for (int c = 0; c < 10; ++c) {
            const auto &s = subsets[size_t(c)];
            on[c] = s[0] == row || s[1] == row || s[2] == row;
        }
        Quality q = plain(0.5);
        q.jitter = on[0];
        q.preintegrated = on[1];
        q.interpolation = on[2] ? Interpolation::Cubic : Interpolation::Linear;
        q.boundarySegment = on[3];
        q.earlyTermination = on[4] ? 0.98 : 1;
        q.emptySpaceSkipping = on[5];
        q.shading = on[6];
        q.mipLevel = on[8] ? 1 : 0;
        q.imageScale = on[9] ? 0.5 : 1;
        const std::vector<ClipPlane> planes = on[7] ? clip : std::vector<ClipPlane>{};
        const std::string what = "row " + std::to_string(row) + ": " + r.buildOptions(q, !planes.empty());
        const Image img = r.render(blobTf(), cam, 24, 24, q, planes);
        expectValidImage(img, what);
        ReferenceRenderer ref(blob().volume, blobTf(), on[2] ? Reconstruction::Cubic : Reconstruction::Linear);
        ref.setShading(q.shading);
        ReferenceOptions o;
        o.tolerance = 1e-5;
        const Image exact = ref.render(cam, 24, 24, planes, o);
        // A loose bound that still catches a broken combination (a wrong image is off by
        // ~0.1–0.5): mip level 1 and half-resolution rays cost up to a few hundredths here.
        EXPECT_LT(compareImages(img, exact).rmse, 0.05) << what;
    }
}

} // namespace
} // namespace volcast
