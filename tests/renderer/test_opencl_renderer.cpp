// The OpenCL ray caster against closed forms and the reference integrator, on whatever
// device OpenCL offers (PoCL's CPU device in CI). Each new feature set costs PoCL about a
// second to build, so the tests share one context and few combinations.

#include "renderer/error_metrics.hpp"
#include "renderer/opencl/opencl_renderer.hpp"
#include "renderer/reference_renderer.hpp"
#include "renderer/synthetic.hpp"
#include "opencl_test_context.hpp"
#include "test_scenes.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <limits>

namespace volcast {
namespace {

OpenClContext &sharedContext() { return test::sharedOpenClContext(); }

TransferFunction constantTf(double a) { return test::constantTf(0.9, 0.5, 0.2, a, 1.0); }
Camera obliqueCamera(const Volume &v) { return test::obliqueCamera(v, 30); }

Quality plain(double step) { return test::plainQuality(step); }

// Largest per-pixel |A − closed form| over the image, and the count of pixels that hit.
double constantBoxAlphaError(const Image &img, const Volume &v, const Camera &cam, double a, int *hits = nullptr) {
    const RayGenerator rays(cam, img.width, img.height);
    const ReferenceRenderer ref(v, constantTf(a), Reconstruction::Linear);
    double worst = 0;
    for (int y = 0; y < img.height; ++y)
        for (int x = 0; x < img.width; ++x) {
            double t0, t1;
            const double L = ref.clipRay(rays.pixelRay(x, y), {}, t0, t1) ? t1 - t0 : 0;
            if (hits && L > 0) ++*hits;
            worst = std::max(worst, std::fabs(img.pixel(x, y)[3] - -std::expm1(L * std::log1p(-a))));
        }
    return worst;
}

TEST(OpenClRenderer, ReportsItsDevice) { EXPECT_FALSE(sharedContext().deviceName().empty()); }

TEST(OpenClRenderer, ConstantBoxIsExactWithPartialSegmentsAtAnyStep) {
    const SyntheticVolume box = makeConstantBox({12, 9, 15}, {1.0, 1.5, 0.8}, 100);
    OpenClRenderer r(sharedContext(), box.volume);
    const Camera cam = obliqueCamera(box.volume);
    for (double step : {0.3, 1.0, 2.7, 40.0}) { // 40: one segment longer than the volume
        const Image img = r.render(constantTf(0.07), cam, 32, 24, plain(step), {});
        int hits = 0;
        // Float32 ray parameters ~100 world units from the eye carry ~1e-5 absolute error,
        // which moves A by at most τ·1e-5 ≈ 1e-6; summing ≤ 60 segment depths adds ~1e-6.
        EXPECT_LT(constantBoxAlphaError(img, box.volume, cam, 0.07, &hits), 1e-5) << "step " << step;
        EXPECT_GT(hits, 60); // the box really is in view
    }
}

TEST(OpenClRenderer, ConstantBoxIsMeasurablyWrongWithoutPartialSegments) {
    const SyntheticVolume box = makeConstantBox({12, 9, 15}, {1.0, 1.5, 0.8}, 100);
    OpenClRenderer r(sharedContext(), box.volume);
    const Camera cam = obliqueCamera(box.volume);
    Quality q = plain(2.7);
    q.boundarySegment = false;
    const Image img = r.render(constantTf(0.07), cam, 32, 24, q, {});
    // Dropping up to one 2.7-voxel segment per ray loses up to 1 − 0.93^2.7 ≈ 0.18 of
    // opacity: the jerky edges of the paper's Figure 4.
    EXPECT_GT(constantBoxAlphaError(img, box.volume, cam, 0.07), 0.05);
}

TEST(OpenClRenderer, ClipPlaneWithPartialSegmentsIsExactOnAConstantBox) {
    const SyntheticVolume box = makeConstantBox({16, 16, 16}, {1, 1, 1}, 10);
    OpenClRenderer r(sharedContext(), box.volume);
    const Camera cam = obliqueCamera(box.volume);
    const std::vector<ClipPlane> clip{{{7.5, 7.5, 7.5}, normalize(Vec3d{0.3, -1, 0.5})}};
    const Image img = r.render(constantTf(0.1), cam, 32, 32, plain(1.7), clip);
    const ReferenceRenderer ref(box.volume, constantTf(0.1), Reconstruction::Linear);
    const RayGenerator rays(cam, 32, 32);
    double worst = 0;
    for (int y = 0; y < 32; ++y)
        for (int x = 0; x < 32; ++x) {
            double t0, t1;
            const double L = ref.clipRay(rays.pixelRay(x, y), clip, t0, t1) ? t1 - t0 : 0;
            worst = std::max(worst, std::fabs(img.pixel(x, y)[3] - -std::expm1(L * std::log1p(-0.1))));
        }
    EXPECT_LT(worst, 1e-5); // as for the box without planes
}

TEST(OpenClRenderer, ConvergesToTheReferenceAsTheStepShrinks) {
    const SyntheticVolume blob = makeGaussianBlob({32, 32, 32}, {1, 1, 1}, 7, 220);
    TransferFunction tf;
    tf.points = {{0, 0, 0, 0, 0}, {60, 1, 0.4, 0.1, 0.05}, {140, 0.3, 0.7, 1, 0.3}, {220, 1, 1, 1, 0.6}};
    const Camera cam = obliqueCamera(blob.volume);
    const ReferenceRenderer ref(blob.volume, tf, Reconstruction::Linear);
    ReferenceOptions ro;
    ro.tolerance = 1e-6;
    const Image exact = ref.render(cam, 40, 40, {}, ro);
    OpenClRenderer r(sharedContext(), blob.volume);
    double previous = 1;
    for (double step : {2.0, 0.5, 0.125}) {
        const double rmse = compareImages(r.render(tf, cam, 40, 40, plain(step), {}), exact).rmse;
        // Midpoint sampling is second order: a 4× smaller step cuts the error ≥ 4× until
        // float rounding (~1e-6) is reached.
        EXPECT_LT(rmse, std::max(previous / 4, 2e-6)) << "step " << step;
        previous = rmse;
    }
    EXPECT_LT(previous, 1e-3);
}

TEST(OpenClRenderer, ProgramsHoldOnlyTheFeaturesInUseAndAreBuiltOnce) {
    const SyntheticVolume box = makeConstantBox({4, 4, 4}, {1, 1, 1}, 1);
    OpenClRenderer r(sharedContext(), box.volume);
    Quality q = plain(1);
    q.boundarySegment = false;
    EXPECT_EQ(r.buildOptions(q, false), "");
    q.jitter = true;
    q.earlyTermination = 0.95;
    q.boundarySegment = true;
    EXPECT_EQ(r.buildOptions(q, true), "-DJITTER -DBOUNDARY_SEGMENT -DEARLY_TERMINATION -DCLIP_PLANES");
    q.interpolation = Interpolation::Cubic;
    q.preintegrated = true;
    q.emptySpaceSkipping = true;
    q.shading = true;
    EXPECT_EQ(r.buildOptions(q, false), std::string("-DJITTER -DBOUNDARY_SEGMENT -DEARLY_TERMINATION ") +
                                            (sharedContext().isGpu() ? "-DCUBIC_IMAGE" : "-DCUBIC") +
                                            " -DPREINTEGRATED -DEMPTY_SPACE_SKIPPING -DSHADING");

    RenderStats first, second;
    r.render(constantTf(0.5), obliqueCamera(box.volume), 8, 8, plain(0.5), {}, &first);
    const size_t built = sharedContext().programsBuilt();
    r.render(constantTf(0.2), obliqueCamera(box.volume), 8, 8, plain(0.25), {}, &second);
    EXPECT_EQ(first.buildOptions, "-DBOUNDARY_SEGMENT");
    EXPECT_EQ(sharedContext().programsBuilt(), built); // same feature set: no new program
    EXPECT_EQ(second.kernelBuildSeconds, 0);
}

TEST(OpenClRenderer, JitterIsReproducibleFromTheSeed) {
    const SyntheticVolume blob = makeGaussianBlob({24, 24, 24}, {1, 1, 1}, 6, 200);
    TransferFunction tf;
    tf.points = {{0, 0, 0, 0, 0}, {100, 1, 0.5, 0.2, 0.2}, {200, 1, 1, 1, 0.8}};
    OpenClRenderer r(sharedContext(), blob.volume);
    Quality q = plain(1.5);
    q.jitter = true;
    q.seed = 42;
    const Camera cam = obliqueCamera(blob.volume);
    const Image a = r.render(tf, cam, 24, 24, q, {}), b = r.render(tf, cam, 24, 24, q, {});
    q.seed = 43;
    const Image c = r.render(tf, cam, 24, 24, q, {});
    EXPECT_EQ(compareImages(a, b).maxAbs, 0);
    EXPECT_GT(compareImages(a, c).maxAbs, 1e-4);
}

TEST(OpenClRenderer, EarlyTerminationChangesPixelsByLessThanTheRemainingTransmittance) {
    const SyntheticVolume blob = makeGaussianBlob({24, 24, 24}, {1, 1, 1}, 8, 220);
    TransferFunction tf;
    tf.points = {{0, 0, 0, 0, 0}, {50, 1, 0.6, 0.3, 0.6}, {220, 1, 1, 1, 0.95}};
    OpenClRenderer r(sharedContext(), blob.volume);
    const Camera cam = obliqueCamera(blob.volume);
    Quality q = plain(0.5);
    const Image full = r.render(tf, cam, 24, 24, q, {});
    q.earlyTermination = 0.99;
    RenderStats st;
    const Image early = r.render(tf, cam, 24, 24, q, {}, &st);
    // A ray stops once T ≤ 0.01; what lies behind adds at most T·1 to any channel.
    EXPECT_LE(compareImages(early, full).maxAbs, 0.01 + 1e-6);
    EXPECT_GT(st.earlyTerminatedFraction, 0.1); // the switch really did something
}

TEST(OpenClRenderer, AnUnknownDeviceIsAClearError) {
    DeviceOptions o;
    o.device = "no-such-device-xyz";
    try {
        OpenClContext cl(o);
        FAIL();
    } catch (const OpenClError &e) {
        EXPECT_NE(std::string(e.what()).find("no-such-device-xyz"), std::string::npos);
    }
}

} // namespace
} // namespace volcast
