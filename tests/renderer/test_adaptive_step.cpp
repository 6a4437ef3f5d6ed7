// The adaptive step (quality.adaptive_step, renderer/common/adaptive_step.hpp) on both back
// ends: exact opacity correction whatever mix of segment lengths a ray takes, convergence to
// the reference integrator, fewer samples than the uniform step it is bounded by, and every
// other switch still working with it. Judges: closed forms and the reference integrator.

#include "renderer/common/adaptive_step.hpp"
#include "renderer/common/frame_setup.hpp"
#include "renderer/cpu/cpu_renderer.hpp"
#include "renderer/model/synthetic.hpp"
#include "renderer/opencl/opencl_renderer.hpp"
#include "renderer/reference/error_metrics.hpp"
#include "renderer/reference/reference_renderer.hpp"
#include "opencl_test_context.hpp"
#include "test_scenes.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <memory>
#include <string>

namespace volcast {
namespace {

enum class Backend { OpenCl, Cpu };

std::unique_ptr<FrameRenderer> makeRenderer(Backend b, const Volume &v) {
    if (b == Backend::Cpu) return std::make_unique<CpuRenderer>(v);
    return std::make_unique<OpenClRenderer>(test::sharedOpenClContext(), v);
}

class AdaptiveStep : public testing::TestWithParam<Backend> {
  protected:
    std::unique_ptr<FrameRenderer> renderer(const Volume &v) const { return makeRenderer(GetParam(), v); }
};
INSTANTIATE_TEST_SUITE_P(Backends, AdaptiveStep, testing::Values(Backend::OpenCl, Backend::Cpu),
                         [](const testing::TestParamInfo<Backend> &i) {
                             return i.param == Backend::Cpu ? std::string("Cpu") : std::string("OpenCl");
                         });

Quality adaptive(double longest) {
    Quality q = test::plainQuality(longest);
    q.adaptiveStep = true;
    return q;
}

Image reference(const Volume &v, const TransferFunction &tf, Reconstruction rec, const Camera &cam, int w, int h,
                bool shading = false, const std::vector<ClipPlane> &clip = {}) {
    ReferenceRenderer ref(v, tf, rec);
    ref.setShading(shading);
    ReferenceOptions o;
    o.tolerance = 1e-6;
    return ref.render(cam, w, h, clip, o);
}

// A volume whose values vary (a Gaussian blob) under a transfer function of one opacity and a
// colour ramp: the steps vary with the blob's gradient (the colour's slope times sigma),
// while the opacity along a ray is 1 − (1 − a)^(L/u) for its length L in the box, exactly.
TransferFunction constantOpacityColourRamp(double a) {
    TransferFunction tf;
    tf.points = {{0, 0, 0.2, 1, a}, {60, 1, 0.3, 0, a}, {140, 0.1, 1, 0.5, a}, {220, 1, 1, 1, a}};
    tf.opacityUnit = 1.0;
    return tf;
}

double alphaErrorAgainstClosedForm(const Image &img, const Volume &v, const Camera &cam, double a,
                                   const std::vector<ClipPlane> &clip, int *hits) {
    const RayGenerator rays(cam, img.width, img.height);
    const ReferenceRenderer ref(v, test::constantTf(1, 1, 1, a, 1.0), Reconstruction::Linear);
    double worst = 0;
    for (int y = 0; y < img.height; ++y)
        for (int x = 0; x < img.width; ++x) {
            double t0, t1;
            const double L = ref.clipRay(rays.pixelRay(x, y), clip, t0, t1) ? t1 - t0 : 0;
            if (L > 0) ++*hits;
            worst = std::max(worst, std::fabs(img.pixel(x, y)[3] - -std::expm1(L * std::log1p(-a))));
        }
    return worst;
}

TEST_P(AdaptiveStep, OpacityCorrectionIsExactAtAnyMixOfSegmentLengths) {
    const SyntheticVolume b = makeGaussianBlob({80, 64, 72}, {1, 1, 1}, 14, 220);
    const auto r = renderer(b.volume);
    const Camera cam = test::obliqueCamera(b.volume, 30);
    const std::vector<ClipPlane> clip{{b.volume.center(), normalize(Vec3d{0.3, -1, 0.5})}};
    for (const bool jitter : {false, true})
        for (const bool planes : {false, true}) {
            Quality q = adaptive(6);
            q.jitter = jitter;
            const std::vector<ClipPlane> cut = planes ? clip : std::vector<ClipPlane>{};
            RenderStats st;
            const Image img = r->render({constantOpacityColourRamp(0.05), cam, 32, 24, q, cut}, &st);
            const std::string what = std::string(jitter ? "jitter" : "no jitter") + (planes ? ", clip plane" : "");
            int hits = 0;
            // As the constant box at a uniform step (test_frame_renderer_accuracy): float ray
            // parameters and ≤ 100 summed segment depths, each ~1e-6.
            EXPECT_LT(alphaErrorAgainstClosedForm(img, b.volume, cam, 0.05, cut, &hits), 1e-5) << what;
            EXPECT_GT(hits, 60) << what;
            // A real mix: the bricks' mean step lies strictly between the shortest and longest.
            EXPECT_GT(st.adaptiveMeanStep, 6 / kAdaptiveStepRange * 1.05) << what;
            EXPECT_LT(st.adaptiveMeanStep, 6 * 0.95) << what;
        }
}

TEST_P(AdaptiveStep, ConvergesToTheReferenceAsTheLongestStepShrinks) {
    const SyntheticVolume b = makeGaussianBlob({32, 32, 32}, {1, 1, 1}, 7, 220);
    TransferFunction tf;
    tf.points = {{0, 0, 0, 0, 0}, {60, 1, 0.4, 0.1, 0.05}, {140, 0.3, 0.7, 1, 0.3}, {220, 1, 1, 1, 0.6}};
    const Camera cam = test::obliqueCamera(b.volume, 30);
    const Image exact = reference(b.volume, tf, Reconstruction::Linear, cam, 40, 40);
    const auto r = renderer(b.volume);
    double previous = 1;
    for (double step : {8.0, 2.0, 0.5}) {
        const double rmse = compareImages(r->render({tf, cam, 40, 40, adaptive(step), {}}), exact).rmse;
        // Every brick's step scales with the longest, and the midpoint rule is second order:
        // a 4× shorter longest step cuts the error ≥ 4× until float rounding (~1e-6).
        EXPECT_LT(rmse, std::max(previous / 4, 2e-6)) << "longest step " << step;
        previous = rmse;
    }
    EXPECT_LT(previous, 1e-3);
}

TEST_P(AdaptiveStep, BeatsTheUniformStepOfItsLongestAndSamplesLessThanItsShortest) {
    const SyntheticVolume b = makeGaussianBlob({96, 96, 96}, {1, 1, 1}, 16, 220);
    TransferFunction tf; // one narrow band: steep where the blob crosses it, flat elsewhere
    tf.points = {{0, 0, 0, 0, 0}, {100, 0.2, 0.3, 1, 0}, {120, 1, 0.6, 0.2, 0.4}, {140, 1, 1, 1, 0}, {220, 1, 1, 1, 0.02}};
    const Camera cam = test::obliqueCamera(b.volume, 30);
    const Image exact = reference(b.volume, tf, Reconstruction::Linear, cam, 40, 40);
    const auto r = renderer(b.volume);
    RenderStats adaptiveStats, longStats, shortStats;
    const double adaptiveError = compareImages(r->render({tf, cam, 40, 40, adaptive(4), {}}, &adaptiveStats), exact).rmse;
    const double longError = compareImages(r->render({tf, cam, 40, 40, test::plainQuality(4), {}}, &longStats), exact).rmse;
    const double shortError =
        compareImages(r->render({tf, cam, 40, 40, test::plainQuality(4 / kAdaptiveStepRange), {}}, &shortStats), exact).rmse;
    std::printf("adaptive 4: rmse %.3g, %.1f samples/ray; uniform 4: %.3g, %.1f; uniform 0.5: %.3g, %.1f\n",
                adaptiveError, adaptiveStats.meanSamplesPerRay, longError, longStats.meanSamplesPerRay, shortError,
                shortStats.meanSamplesPerRay);
    EXPECT_LT(adaptiveError, longError / 4);
    EXPECT_LT(adaptiveStats.meanSamplesPerRay, shortStats.meanSamplesPerRay * 0.75);
}

// Each other switch with the adaptive step, against the reference: a loose bound that still
// catches a broken combination (a wrong image is off by ~0.1–0.5; EveryPairOfSwitchesWorksTogether).
TEST_P(AdaptiveStep, WorksWithEveryOtherSwitch) {
    const Volume &v = test::blob().volume;
    const Camera cam = test::obliqueCamera(v, 30);
    const std::vector<ClipPlane> clip{{v.center(), normalize(Vec3d{0.2, 1, -0.3})}};
    const auto r = renderer(v);
    struct Case {
        const char *name;
        void (*set)(Quality &);
        bool clip = false;
    };
    const Case cases[] = {
        {"jitter", [](Quality &q) { q.jitter = true; }},
        {"preintegrated", [](Quality &q) { q.preintegrated = true; }},
        {"cubic", [](Quality &q) { q.interpolation = Interpolation::Cubic; }},
        {"no boundary segment", [](Quality &q) { q.boundarySegment = false; }},
        {"early termination", [](Quality &q) { q.earlyTermination = 0.98; }},
        {"empty-space skipping", [](Quality &q) { q.emptySpaceSkipping = true; }},
        {"skipping, jitter, pre-integration", [](Quality &q) {
             q.emptySpaceSkipping = q.jitter = q.preintegrated = true;
         }},
        {"shading", [](Quality &q) { q.shading = true; }},
        {"clip plane", [](Quality &) {}, true},
        {"mip level 1", [](Quality &q) { q.mipLevel = 1; }},
        {"image scale 0.5", [](Quality &q) { q.imageScale = 0.5; }},
    };
    for (const Case &c : cases) {
        Quality q = adaptive(2);
        c.set(q);
        const std::vector<ClipPlane> planes = c.clip ? clip : std::vector<ClipPlane>{};
        RenderStats st;
        const Image img = r->render({test::blobTf(), cam, 24, 24, q, planes}, &st);
        EXPECT_NE(st.buildOptions.find("ADAPTIVE_STEP"), std::string::npos) << c.name << ": " << st.buildOptions;
        const Image exact = reference(v, test::blobTf(), q.interpolation == Interpolation::Cubic ? Reconstruction::Cubic
                                                                                                : Reconstruction::Linear,
                                      cam, 24, 24, q.shading, planes);
        const double bound = q.boundarySegment ? 0.05 : 0.15; // dropping partial segments is the jerky-edge artifact
        EXPECT_LT(compareImages(img, exact).rmse, bound) << c.name;
        EXPECT_EQ(st.raysTruncated, 0u) << c.name;
    }
}

// Skipping restarts a ray at the transparent brick's exit: the picture keeps its error.
TEST_P(AdaptiveStep, EmptySpaceSkippingChangesTheWorkNotTheError) {
    const SyntheticVolume b = makeGaussianBlob({48, 48, 48}, {1, 1, 1}, 6, 220);
    const TransferFunction tf = test::blobTf();
    const Camera cam = test::obliqueCamera(b.volume, 30);
    const Image exact = reference(b.volume, tf, Reconstruction::Linear, cam, 40, 40);
    const auto r = renderer(b.volume);
    Quality q = adaptive(2);
    RenderStats plainStats, skipStats;
    const double plainError = compareImages(r->render({tf, cam, 40, 40, q, {}}, &plainStats), exact).rmse;
    q.emptySpaceSkipping = true;
    const double skipError = compareImages(r->render({tf, cam, 40, 40, q, {}}, &skipStats), exact).rmse;
    EXPECT_LT(skipError, plainError * 1.5 + 1e-5);
    EXPECT_LT(skipStats.meanSamplesPerRay, plainStats.meanSamplesPerRay * 0.9);
    EXPECT_GT(skipStats.skippedSegmentsPerRay, 0.5);
}

// The same segments on both back ends: images agree to float rounding (the bound of
// CpuRenderer.DrawsTheOpenClImageToFloatRounding).
TEST(AdaptiveStepBackEnds, CpuDrawsTheOpenClImageToFloatRounding) {
    const Volume &v = test::blob().volume;
    const Camera cam = test::obliqueCamera(v, 30);
    CpuRenderer cpu(v);
    OpenClRenderer gpu(test::sharedOpenClContext(), v);
    for (const bool more : {false, true}) {
        Quality q = adaptive(2.5);
        q.jitter = q.emptySpaceSkipping = more;
        q.earlyTermination = more ? 0.97 : 1;
        RenderStats a, b;
        const Image x = cpu.render({test::blobTf(), cam, 32, 32, q, {}}, &a);
        const Image y = gpu.render({test::blobTf(), cam, 32, 32, q, {}}, &b);
        EXPECT_LT(compareImages(x, y).maxAbs, 2e-5) << (more ? "jitter, skipping, early termination" : "plain");
        EXPECT_NEAR(a.meanSamplesPerRay, b.meanSamplesPerRay, 0.05 * a.meanSamplesPerRay);
    }
}

TEST(AdaptiveStepSetUp, IsOffForIntensityProjectionsAndBoundedByABrick) {
    Quality q = adaptive(1000);
    q.compositing = Compositing::Maximum;
    EXPECT_FALSE(compositedQuality(q).adaptiveStep);
    q.compositing = Compositing::EmissionAbsorption;
    const Volume &v = test::blob().volume;
    const FrameSetup s = setUpFrame(v, {test::blobTf(), test::obliqueCamera(v, 30), 8, 8, q, {}}, 4, 8);
    // A segment may be at most a brick's edge long (it must stay within a brick's neighbours).
    EXPECT_DOUBLE_EQ(s.step, 8.0);
    EXPECT_DOUBLE_EQ(s.shortestStep, 8.0 / kAdaptiveStepRange);
    EXPECT_NE(s.features.find("ADAPTIVE_STEP"), std::string::npos);
}

} // namespace
} // namespace volcast
