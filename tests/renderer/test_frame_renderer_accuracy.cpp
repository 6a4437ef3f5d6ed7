// The accuracy, stability and remedy checks every back end must pass, run against each one
// (value-parameterised: .../OpenCl is the OpenCL ray caster on whatever device OpenCL offers,
// PoCL's CPU device in CI; .../Cpu is the native SIMD path), with closed forms and the
// double-precision reference integrator as the judge. Checks that only concern one back end
// (OpenCL build options and its two cubic fetch paths) stay in test_opencl_renderer.cpp and
// test_opencl_remedies.cpp.

#include "renderer/common/frame_setup.hpp"
#include "renderer/cpu/cpu_renderer.hpp"
#include "renderer/reference/error_metrics.hpp"
#include "renderer/common/minmax_bricks.hpp"
#include "renderer/opencl/opencl_renderer.hpp"
#include "renderer/reference/reference_renderer.hpp"
#include "renderer/model/synthetic.hpp"
#include "opencl_test_context.hpp"
#include "test_scenes.hpp"

#include <gtest/gtest.h>

#include <array>
#include <cmath>
#include <cstdio>
#include <memory>
#include <stdexcept>
#include <string>
#include <random>
#include <tuple>

namespace volcast {
namespace {

enum class Backend { OpenCl, Cpu };

std::string backendName(const testing::TestParamInfo<Backend> &info) {
    return info.param == Backend::Cpu ? "Cpu" : "OpenCl";
}

std::unique_ptr<FrameRenderer> makeRenderer(Backend b, const Volume &v) {
    if (b == Backend::Cpu) return std::make_unique<CpuRenderer>(v);
    return std::make_unique<OpenClRenderer>(test::sharedOpenClContext(), v);
}

class FrameRendererAccuracy : public testing::TestWithParam<Backend> {
  protected:
    std::unique_ptr<FrameRenderer> renderer(const Volume &v) const { return makeRenderer(GetParam(), v); }
};

INSTANTIATE_TEST_SUITE_P(Backends, FrameRendererAccuracy, testing::Values(Backend::OpenCl, Backend::Cpu),
                         backendName);

TransferFunction constantTf(double a) { return test::constantTf(0.9, 0.5, 0.2, a, 1.0); }
Camera obliqueCamera(const Volume &v) { return test::obliqueCamera(v, 30); }
Quality plain(double step) { return test::plainQuality(step); }

using test::blob;
using test::blobTf;

Image reference(const Volume &v, const TransferFunction &tf, Reconstruction rec, const Camera &cam, int w, int h,
                bool shading = false, double tolerance = 1e-6, const std::vector<ClipPlane> &clip = {}) {
    ReferenceRenderer ref(v, tf, rec);
    ref.setShading(shading);
    ReferenceOptions o;
    o.tolerance = tolerance;
    return ref.render(cam, w, h, clip, o);
}

// Largest per-pixel |A − closed form| over the image, and the count of pixels that hit.
double constantBoxAlphaError(const Image &img, const Volume &v, const Camera &cam, double a,
                             const std::vector<ClipPlane> &clip = {}, int *hits = nullptr) {
    const RayGenerator rays(cam, img.width, img.height);
    const ReferenceRenderer ref(v, constantTf(a), Reconstruction::Linear);
    double worst = 0;
    for (int y = 0; y < img.height; ++y)
        for (int x = 0; x < img.width; ++x) {
            double t0, t1;
            const double L = ref.clipRay(rays.pixelRay(x, y), clip, t0, t1) ? t1 - t0 : 0;
            if (hits && L > 0) ++*hits;
            worst = std::max(worst, std::fabs(img.pixel(x, y)[3] - -std::expm1(L * std::log1p(-a))));
        }
    return worst;
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

TEST_P(FrameRendererAccuracy, DescribesItsBackEnd) {
    const auto r = renderer(blob().volume);
    EXPECT_EQ(r->description().rfind(GetParam() == Backend::Cpu ? "cpu: " : "opencl: ", 0), 0u) << r->description();
}

// The scheduler renders refinements cell by cell (FrameRequest::window): a window must be exactly
// the same rays as the whole grid, with jitter, skipping, clip planes, shading, cubic and
// pre-integration on, and in MIP and MinIP, for windows that do not start on a tile or packet
// boundary. (The CPU renderer's MIP wrote a window's rays at their place in the whole grid,
// past the window's buffer: the server's heap broke on the first MIP frame rendered in
// cells, web.browser_modes.)
TEST_P(FrameRendererAccuracy, AWindowIsExactlyThoseRaysOfTheWholeGrid) {
    const SyntheticVolume sphere = makeSphere({48, 40, 44}, {1, 1, 1.2}, 9, 2, 200);
    TransferFunction tf;
    tf.points = {{0, 0, 0, 0, 0}, {60, 0, 0, 0, 0}, {120, 1, 0.6, 0.3, 0.3}, {200, 1, 1, 1, 0.5}};
    const auto r = renderer(sphere.volume);
    EXPECT_TRUE(r->rendersWindowsCheaply()) << r->description() << " casts the whole grid for every window";
    const Camera cam = test::obliqueCamera(sphere.volume, 40);
    const std::vector<ClipPlane> clip = {{{30, 20, 22}, {-0.6, 0, 0.8}}};
    constexpr int kW = 61, kH = 47;
    for (Compositing compositing : {Compositing::EmissionAbsorption, Compositing::Maximum, Compositing::Minimum})
    for (double scale : {1.0, 0.5})
        for (bool cubic : {false, true})
            for (bool preintegrated : {false, true}) {
                if (compositing != Compositing::EmissionAbsorption && (preintegrated || scale != 1)) continue;
                Quality q = plain(0.7);
                q.compositing = compositing;
                q.jitter = true;
                q.seed = 12345;
                q.emptySpaceSkipping = true;
                q.earlyTermination = 0.95;
                q.shading = !preintegrated;
                q.interpolation = cubic ? Interpolation::Cubic : Interpolation::Linear;
                q.preintegrated = preintegrated;
                q.imageScale = scale;
                const char *mode = compositing == Compositing::Maximum   ? " MIP"
                                   : compositing == Compositing::Minimum ? " MinIP"
                                                                         : "";
                const std::string what = "scale " + std::to_string(scale) + (cubic ? " cubic" : " linear") +
                                         (preintegrated ? " pre-integrated" : "") + mode;
                const int gw = raysForScale(kW, scale), gh = raysForScale(kH, scale);
                // At scale 1 the whole grid is render()'s own image; below, its un-upsampled rays.
                const Image whole = scale == 1 ? r->render({tf, cam, kW, kH, q, clip})
                                               : r->render({tf, cam, kW, kH, q, clip, RayWindow{0, 0, gw, gh}});
                ASSERT_EQ(whole.width, gw) << what;
                ASSERT_EQ(whole.height, gh) << what;
                for (const RayWindow w : {RayWindow{0, 0, gw, gh}, RayWindow{0, 7, gw, 3}, RayWindow{3, 5, 17, 9},
                                          RayWindow{gw - 5, gh - 4, 5, 4}, RayWindow{11, 0, 1, gh},
                                          RayWindow{gw / 2 - 7, gh / 2 - 5, 13, 11}}) {   // the last on the sphere
                    RenderStats st;
                    const Image part = r->render({tf, cam, kW, kH, q, clip, w}, &st);
                    ASSERT_EQ(part.width, w.width);
                    ASSERT_EQ(part.height, w.height);
                    int differ = 0;
                    for (int y = 0; y < w.height; ++y)
                        for (int x = 0; x < w.width; ++x)
                            for (int c = 0; c < 4; ++c)
                                differ += part.pixel(x, y)[c] != whole.pixel(w.x + x, w.y + y)[c];
                    EXPECT_EQ(differ, 0) << what << ": window " << w.width << "x" << w.height << "+" << w.x << "+"
                                         << w.y << " differs from the whole grid in " << differ << " values";
                }
            }
    // A window off the grid or empty is refused, with a message naming it (the server logs
    // it as the unit that failed). At image_scale 0.5 the grid is 31x24: x = 40 is inside the
    // full-size grid but off the smaller one.
    Quality half = plain(1);
    half.imageScale = 0.5;
    const struct {
        RayWindow window;
        Quality quality;
        const char *named;
    } refused[] = {{{60, 0, 2, 1}, plain(1), "window 2x1+60+0"},   {{-1, 0, 2, 1}, plain(1), "window 2x1+-1+0"},
                   {{0, 3, 5, 0}, plain(1), "window 5x0+0+3"},     {{0, 46, 1, 2}, plain(1), "window 1x2+0+46"},
                   {{40, 0, 1, 1}, half, "window 1x1+40+0"}};
    for (const auto &bad : refused) {
        try {
            r->render({tf, cam, kW, kH, bad.quality, {}, bad.window});
            ADD_FAILURE() << r->description() << ": " << bad.named << " was rendered, not refused";
        } catch (const std::invalid_argument &e) {
            EXPECT_NE(std::string(e.what()).find(bad.named), std::string::npos)
                << r->description() << ": the refusal \"" << e.what() << "\" does not name " << bad.named;
        }
    }
}

TEST_P(FrameRendererAccuracy, ConstantBoxIsExactWithPartialSegmentsAtAnyStep) {
    const SyntheticVolume box = makeConstantBox({12, 9, 15}, {1.0, 1.5, 0.8}, 100);
    const auto r = renderer(box.volume);
    const Camera cam = obliqueCamera(box.volume);
    for (double step : {0.3, 1.0, 2.7, 40.0}) { // 40: one segment longer than the volume
        const Image img = r->render({constantTf(0.07), cam, 32, 24, plain(step), {}});
        int hits = 0;
        // Float32 ray parameters ~100 world units from the eye carry ~1e-5 absolute error,
        // which moves A by at most τ·1e-5 ≈ 1e-6; summing ≤ 60 segment depths adds ~1e-6.
        EXPECT_LT(constantBoxAlphaError(img, box.volume, cam, 0.07, {}, &hits), 1e-5) << "step " << step;
        EXPECT_GT(hits, 60); // the box really is in view
    }
}

TEST_P(FrameRendererAccuracy, ConstantBoxIsMeasurablyWrongWithoutPartialSegments) {
    const SyntheticVolume box = makeConstantBox({12, 9, 15}, {1.0, 1.5, 0.8}, 100);
    const auto r = renderer(box.volume);
    const Camera cam = obliqueCamera(box.volume);
    Quality q = plain(2.7);
    q.boundarySegment = false;
    const Image img = r->render({constantTf(0.07), cam, 32, 24, q, {}});
    // Dropping up to one 2.7-voxel segment per ray loses up to 1 − 0.93^2.7 ≈ 0.18 of
    // opacity: the jerky edges of the paper's Figure 4.
    EXPECT_GT(constantBoxAlphaError(img, box.volume, cam, 0.07), 0.05);
}

TEST_P(FrameRendererAccuracy, ClipPlaneWithPartialSegmentsIsExactOnAConstantBox) {
    const SyntheticVolume box = makeConstantBox({16, 16, 16}, {1, 1, 1}, 10);
    const auto r = renderer(box.volume);
    const Camera cam = obliqueCamera(box.volume);
    const std::vector<ClipPlane> clip{{{7.5, 7.5, 7.5}, normalize(Vec3d{0.3, -1, 0.5})}};
    const Image img = r->render({constantTf(0.1), cam, 32, 32, plain(1.7), clip});
    EXPECT_LT(constantBoxAlphaError(img, box.volume, cam, 0.1, clip), 1e-5); // as for the box without planes
}

TEST_P(FrameRendererAccuracy, ConvergesToTheReferenceAsTheStepShrinks) {
    const SyntheticVolume b = makeGaussianBlob({32, 32, 32}, {1, 1, 1}, 7, 220);
    TransferFunction tf;
    tf.points = {{0, 0, 0, 0, 0}, {60, 1, 0.4, 0.1, 0.05}, {140, 0.3, 0.7, 1, 0.3}, {220, 1, 1, 1, 0.6}};
    const Camera cam = obliqueCamera(b.volume);
    const Image exact = reference(b.volume, tf, Reconstruction::Linear, cam, 40, 40);
    const auto r = renderer(b.volume);
    double previous = 1;
    for (double step : {2.0, 0.5, 0.125}) {
        const double rmse = compareImages(r->render({tf, cam, 40, 40, plain(step), {}}), exact).rmse;
        // Midpoint sampling is second order: a 4× smaller step cuts the error ≥ 4× until
        // float rounding (~1e-6) is reached.
        EXPECT_LT(rmse, std::max(previous / 4, 2e-6)) << "step " << step;
        previous = rmse;
    }
    EXPECT_LT(previous, 1e-3);
}

TEST_P(FrameRendererAccuracy, JitterIsReproducibleFromTheSeed) {
    const SyntheticVolume b = makeGaussianBlob({24, 24, 24}, {1, 1, 1}, 6, 200);
    TransferFunction tf;
    tf.points = {{0, 0, 0, 0, 0}, {100, 1, 0.5, 0.2, 0.2}, {200, 1, 1, 1, 0.8}};
    const auto r = renderer(b.volume);
    Quality q = plain(1.5);
    q.jitter = true;
    q.seed = 42;
    const Camera cam = obliqueCamera(b.volume);
    const Image a = r->render({tf, cam, 24, 24, q, {}}), again = r->render({tf, cam, 24, 24, q, {}});
    q.seed = 43;
    const Image c = r->render({tf, cam, 24, 24, q, {}});
    EXPECT_EQ(compareImages(a, again).maxAbs, 0);
    EXPECT_GT(compareImages(a, c).maxAbs, 1e-4);
}

TEST_P(FrameRendererAccuracy, EarlyTerminationChangesPixelsByLessThanTheRemainingTransmittance) {
    const SyntheticVolume b = makeGaussianBlob({24, 24, 24}, {1, 1, 1}, 8, 220);
    TransferFunction tf;
    tf.points = {{0, 0, 0, 0, 0}, {50, 1, 0.6, 0.3, 0.6}, {220, 1, 1, 1, 0.95}};
    const auto r = renderer(b.volume);
    const Camera cam = obliqueCamera(b.volume);
    Quality q = plain(0.5);
    const Image full = r->render({tf, cam, 24, 24, q, {}});
    q.earlyTermination = 0.99;
    RenderStats st;
    const Image early = r->render({tf, cam, 24, 24, q, {}}, &st);
    // A ray stops once T ≤ 0.01; what lies behind adds at most T·1 to any channel.
    EXPECT_LE(compareImages(early, full).maxAbs, 0.01 + 1e-6);
    EXPECT_GT(st.earlyTerminatedFraction, 0.1); // the switch really did something
}

TEST_P(FrameRendererAccuracy, EmptySpaceSkippingChangesTheWorkNotTheImage) {
    const SyntheticVolume sphere = makeSphere({48, 40, 44}, {1, 1, 1.2}, 9, 2, 200);
    TransferFunction tf;
    tf.points = {{0, 0, 0, 0, 0}, {60, 0, 0, 0, 0}, {120, 1, 0.6, 0.3, 0.3}, {200, 1, 1, 1, 0.5}};
    const auto r = renderer(sphere.volume);
    const Camera cam = test::obliqueCamera(sphere.volume, 40);
    for (auto interpolation : {Interpolation::Linear, Interpolation::Cubic})
        for (bool preintegrated : {false, true}) {
            Quality q = plain(0.5);
            q.interpolation = interpolation;
            q.preintegrated = preintegrated;
            RenderStats without, with;
            const Image full = r->render({tf, cam, 32, 32, q, {}}, &without);
            q.emptySpaceSkipping = true;
            const Image skipped = r->render({tf, cam, 32, 32, q, {}}, &with);
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

TEST_P(FrameRendererAccuracy, ShadingMatchesTheReferenceLighting) {
    const Camera cam = test::obliqueCamera(blob().volume, 30);
    const Image exactLit = reference(blob().volume, blobTf(), Reconstruction::Linear, cam, 24, 24, true, 1e-5);
    const Image exactUnlit = reference(blob().volume, blobTf(), Reconstruction::Linear, cam, 24, 24);
    const auto r = renderer(blob().volume);
    Quality q = plain(0.125);
    q.shading = true;
    const Image lit = r->render({blobTf(), cam, 24, 24, q, {}});
    expectValidImage(lit, "shaded");
    // The same lighting on the same field: the step's midpoint error (< 1e-3 at 0.125, as
    // unlit) and the reference's 1e-5 tolerance, with a margin for the |n·l| kinks.
    EXPECT_LT(compareImages(lit, exactLit).rmse, 2e-3);
    EXPECT_GT(compareImages(exactLit, exactUnlit).rmse, 10 * compareImages(lit, exactLit).rmse);
}

TEST_P(FrameRendererAccuracy, CubicBSplineMatchesTheReferenceSpline) {
    const Camera cam = test::obliqueCamera(blob().volume, 30);
    const Image exactCubic = reference(blob().volume, blobTf(), Reconstruction::Cubic, cam, 32, 32);
    const auto r = renderer(blob().volume);
    Quality q = plain(0.125);
    const double linearError = compareImages(r->render({blobTf(), cam, 32, 32, q, {}}), exactCubic).rmse;
    q.interpolation = Interpolation::Cubic;
    RenderStats st;
    const double cubicError = compareImages(r->render({blobTf(), cam, 32, 32, q, {}}, &st), exactCubic).rmse;
    // Step 0.125 leaves a midpoint-rule error below 1e-3 (the trilinear convergence test);
    // the same spline on both sides leaves nothing else but float rounding.
    EXPECT_LT(cubicError, 1e-3);
    // And the back end really reconstructs the spline: trilinear is far from it on a σ = 4 blob.
    EXPECT_GT(linearError, 5 * cubicError);
    EXPECT_GT(st.coefficientSeconds, 0);
}

// A linear ramp crossed by a transfer-function spike one data unit wide: the thin slab the
// paper's onion rings come from. Trilinear reconstruction of a linear field is exact, so the
// value along each segment is linear and pre-integration has only its table's error.
TEST_P(FrameRendererAccuracy, PreintegrationCatchesASpikeThatSamplingMisses) {
    const SyntheticVolume ramp = makeLinearRamp({32, 24, 24}, {1, 1, 1}, 0, 248); // 8 units per voxel
    TransferFunction tf;
    tf.points = {{0, 0, 0, 0, 0}, {99.5, 0, 0, 0, 0}, {100, 1, 0.8, 0.3, 0.9}, {100.5, 0, 0, 0, 0}};
    const Camera cam = test::obliqueCamera(ramp.volume, 30);
    const Image exact = reference(ramp.volume, tf, Reconstruction::Linear, cam, 32, 32, false, 1e-7);
    const auto r = renderer(ramp.volume);
    Quality q = plain(2);
    const double sampledError = compareImages(r->render({tf, cam, 32, 32, q, {}}), exact).rmse;
    q.preintegrated = true;
    RenderStats st;
    const double preError = compareImages(r->render({tf, cam, 32, 32, q, {}}, &st), exact).rmse;
    // Each ray crosses the slab once: one or two table lookups at ≤ 1e-3 each, plus float.
    EXPECT_LT(preError, 2e-3);
    EXPECT_LE(st.preintegrationError, 1e-3);
    EXPECT_GT(sampledError, 10 * preError); // step 2 (16 data units) mostly misses the spike
}

TEST_P(FrameRendererAccuracy, PreintegrationConvergesOnASmoothVolume) {
    const Camera cam = test::obliqueCamera(blob().volume, 30);
    const Image exact = reference(blob().volume, blobTf(), Reconstruction::Linear, cam, 32, 32);
    const auto r = renderer(blob().volume);
    Quality q = plain(2);
    q.preintegrated = true;
    const double coarse = compareImages(r->render({blobTf(), cam, 32, 32, q, {}}), exact).rmse;
    q.step = 0.5;
    RenderStats st;
    const double fine = compareImages(r->render({blobTf(), cam, 32, 32, q, {}}, &st), exact).rmse;
    // The value is not linear along a segment here: that error is second order in the step
    // (measured 3.5e-3 at step 2, 1.5e-4 at 0.5). Below that the table's own error (≤ 1e-3
    // per segment, absolute) adds up over more, fainter segments and sets the floor.
    EXPECT_LT(fine, coarse / 8);
    EXPECT_LT(fine, 1e-3);
    EXPECT_LE(st.preintegrationError, 1e-3);
}

TEST_P(FrameRendererAccuracy, MipLevelsKeepAConstantBoxExact) {
    const SyntheticVolume box = makeConstantBox({20, 13, 9}, {1, 1.5, 2}, 70);
    const TransferFunction tf = test::constantTf(0.9, 0.5, 0.2, 0.08, 1.0);
    const auto r = renderer(box.volume);
    const Camera cam = test::obliqueCamera(box.volume, 30);
    for (int level : {1, 2, 4}) {
        Quality q = plain(0.8);
        q.mipLevel = level;
        const Image img = r->render({tf, cam, 24, 24, q, {}});
        // Rays are clipped to the level-0 box at every level, so a constant box keeps its
        // exact chord lengths: the tolerance of the level-0 constant-box test.
        EXPECT_LT(constantBoxAlphaError(img, box.volume, cam, 0.08), 1e-5) << "mip level " << level;
    }
    Quality q = plain(1);
    q.mipLevel = 6; // 20 → 10 → 5 → 3 → 2 → 1: level 5 is the last
    try {
        r->render({tf, cam, 8, 8, q, {}});
        FAIL() << "mip level 6 of a 20×13×9 volume was accepted";
    } catch (const std::invalid_argument &e) {
        EXPECT_NE(std::string(e.what()).find("mip_level"), std::string::npos) << e.what();
    }
}

TEST_P(FrameRendererAccuracy, MipLevelErrorGrowsWithTheLevel) {
    const Camera cam = test::obliqueCamera(blob().volume, 30);
    const Image exact = reference(blob().volume, blobTf(), Reconstruction::Linear, cam, 24, 24);
    const auto r = renderer(blob().volume);
    double previous = 0;
    for (int level : {0, 1, 2}) {
        Quality q = plain(0.25);
        q.mipLevel = level;
        const double e = compareImages(r->render({blobTf(), cam, 24, 24, q, {}}), exact).rmse;
        EXPECT_GT(e, previous) << "level " << level; // coarser data, further from the exact picture
        previous = e;
    }
}

TEST_P(FrameRendererAccuracy, ImageScaleCastsFewerRaysAndUpsamplesThem) {
    const auto r = renderer(blob().volume);
    const Camera cam = test::obliqueCamera(blob().volume, 30);
    Quality q = plain(0.5);
    const Image small = r->render({blobTf(), cam, 15, 10, q, {}});
    q.imageScale = 0.5;
    RenderStats st;
    const Image scaled = r->render({blobTf(), cam, 30, 20, q, {}}, &st);
    EXPECT_EQ(st.raysWide, 15);
    EXPECT_EQ(st.raysHigh, 10);
    ASSERT_EQ(scaled.width, 30);
    ASSERT_EQ(scaled.height, 20);
    // The same rays (same image plane, same aspect) then bilinear upsampling: identical.
    EXPECT_EQ(compareImages(scaled, resizeBilinear(small, 30, 20)).maxAbs, 0);
}

TEST_P(FrameRendererAccuracy, JitteredPassesAveragedBeatOnionRings) {
    const SyntheticVolume ramp = makeLinearRamp({32, 24, 24}, {1, 1, 1}, 0, 248);
    TransferFunction tf;
    // A shell one voxel (8 data units) thick: a 3-voxel step hits or misses it by ray.
    tf.points = {{0, 0, 0, 0, 0}, {96, 0, 0, 0, 0}, {100, 1, 0.7, 0.3, 0.5}, {104, 0, 0, 0, 0}};
    const Camera cam = test::obliqueCamera(ramp.volume, 30);
    const Image exact = reference(ramp.volume, tf, Reconstruction::Linear, cam, 32, 32);
    const auto r = renderer(ramp.volume);
    Quality q = plain(3);
    const double rings = compareImages(r->render({tf, cam, 32, 32, q, {}}), exact).rmse;
    q.jitter = true;
    Image mean(32, 32);
    const int passes = 16;
    for (int pass = 0; pass < passes; ++pass) {
        q.seed = uint64_t(pass);
        const Image img = r->render({tf, cam, 32, 32, q, {}});
        for (size_t i = 0; i < mean.rgba.size(); ++i) mean.rgba[i] += img.rgba[i] / passes;
    }
    // Jitter turns the rings' structured error into noise that averaging shrinks by √16
    // (measured on OpenCL: 0.11 for the rings, 0.042 for the mean of 16 passes).
    EXPECT_LT(compareImages(mean, exact).rmse, 0.5 * rings);
}

// Every pair of switches on together at least once: ten binary factors in six runs. Column
// c is on in the rows of one 3-subset of {0..5} containing row 0 (ten such subsets): any two
// share row 0 (both on), together leave a row out (both off) and differ somewhere.
TEST_P(FrameRendererAccuracy, EveryPairOfSwitchesWorksTogether) {
    std::vector<std::array<int, 3>> subsets;
    for (int a = 1; a < 6; ++a)
        for (int b = a + 1; b < 6; ++b) subsets.push_back({0, a, b});
    ASSERT_EQ(subsets.size(), 10u);
    const Camera cam = test::obliqueCamera(blob().volume, 30);
    const std::vector<ClipPlane> clip{{blob().volume.center(), normalize(Vec3d{0.2, 1, -0.3})}};
    const auto r = renderer(blob().volume);
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
        const std::string what = "row " + std::to_string(row) + ": " + featureNames(q, !planes.empty());
        const Image img = r->render({blobTf(), cam, 24, 24, q, planes});
        expectValidImage(img, what);
        const Image exact = reference(blob().volume, blobTf(), on[2] ? Reconstruction::Cubic : Reconstruction::Linear,
                                      cam, 24, 24, q.shading, 1e-5, planes);
        // A loose bound that still catches a broken combination (a wrong image is off by
        // ~0.1–0.5): mip level 1 and half-resolution rays cost up to a few hundredths here.
        EXPECT_LT(compareImages(img, exact).rmse, 0.05) << what;
    }
}

// --- The two back ends against each other, and the native path's own contract. ---

// The same rays, segments, jitter hash and sums in float on both: images agree to float
// rounding.
TEST(CpuRenderer, DrawsTheOpenClImageToFloatRounding) {
    const Camera cam = test::obliqueCamera(blob().volume, 30);
    const std::vector<ClipPlane> clip{{blob().volume.center(), normalize(Vec3d{0.2, 1, -0.3})}};
    CpuRenderer cpu(blob().volume);
    OpenClRenderer ocl(test::sharedOpenClContext(), blob().volume);
    struct Case {
        const char *what;
        Quality q;
        std::vector<ClipPlane> planes;
    };
    std::vector<Case> cases;
    Quality q = plain(0.5);
    cases.push_back({"plain", q, {}});
    q.jitter = true;
    q.seed = 7;
    q.earlyTermination = 0.98;
    q.emptySpaceSkipping = true;
    cases.push_back({"jitter, early termination, skipping, clip plane", q, clip});
    q.shading = true;
    q.mipLevel = 1;
    q.boundarySegment = false;
    cases.push_back({"shading, mip 1, no boundary segment", q, {}});
    q.interpolation = Interpolation::Cubic;
    q.mipLevel = 0;
    cases.push_back({"cubic, shading, jitter, skipping", q, clip});
    q.preintegrated = true;
    q.boundarySegment = true;
    cases.push_back({"pre-integrated cubic, shading, jitter, skipping, clip plane", q, clip});
    q.interpolation = Interpolation::Linear;
    q.shading = false;
    q.step = 1.3;
    cases.push_back({"pre-integrated at step 1.3, partial segments", q, clip});
    for (const Case &c : cases) {
        RenderStats sc, so;
        const Image a = cpu.render({blobTf(), cam, 40, 40, c.q, c.planes}, &sc);
        const Image b = ocl.render({blobTf(), cam, 40, 40, c.q, c.planes}, &so);
        // The bound from what OpenCL C lets a device do differently from the native path
        // (docs/gpu.md): each multiply-add fused or not (½ ulp apart), quotients to 2.5 ulp,
        // roots, exp and log1p to 3 ulp. A sample's value comes out of at most 64 multiply-adds
        // (the spline's taps; 8 trilinear): ≤ 32 ulp, 2e-6 of its magnitude (the blob's 220),
        // which blobTf (colour up to 1 over 50 values) turns into ≤ 9e-6 of a segment's
        // colour. Its opacity correction, shading and transmittance take ~10 built-ins: ≤ 30
        // ulp, 2e-6 relative. Compensated sums keep the compositing from adding more with the
        // sample count, and the ray set-up is exact where the geometry needs it
        // (DeviceRounding.*): ~1.1e-5 in all, under 2e-5, while a
        // wrong jitter hash or a missed segment is ≥ 5e-3. Measured: PoCL 3.1 against AVX-512
        // 6.6e-7 to 5.5e-6 over the six cases; other devices: printed below, docs/gpu.md.
        const double difference = compareImages(a, b).maxAbs;
        std::printf("CPU vs %s, %s: max |Δ| %.3g\n", ocl.description().c_str(), c.what, difference);
        EXPECT_LT(difference, 2e-5) << c.what;
        EXPECT_EQ(sc.raysHit, so.raysHit) << c.what;
        EXPECT_NEAR(sc.meanSamplesPerRay, so.meanSamplesPerRay, 1e-3 * so.meanSamplesPerRay) << c.what;
    }
}

// Returns the widest cube of empty bricks the native path may cross at once, in bricks.
int skipsBySamplePositionOnBothBackEnds(const Volume &v) {
    SCOPED_TRACE(std::to_string(v.dims.x) + "×" + std::to_string(v.dims.y) + "×" + std::to_string(v.dims.z) + " sphere");
    TransferFunction tf;
    tf.points = {{0, 0, 0, 0, 0}, {60, 0, 0, 0, 0}, {120, 1, 0.6, 0.3, 0.3}, {200, 1, 1, 1, 0.5}};
    const Camera cam = test::obliqueCamera(v, 40);
    constexpr int kSize = 40;
    CpuRenderer cpu(v);
    OpenClRenderer ocl(test::sharedOpenClContext(), v);

    // Segments [t0 + (k − 1)·d, t0 + k·d] ∩ [t0, t1] whose centre is in a visible brick.
    const MinMaxBricks grid = buildMinMaxBricks(v.voxels.data(), v.dims, 8, kTrilinearBorder);
    const RayGenerator rays(cam, kSize, kSize);
    const ReferenceRenderer geometry(v, tf, Reconstruction::Linear);
    const auto expectedSamples = [&](double d) {
        uint64_t taken = 0;
        for (int y = 0; y < kSize; ++y)
            for (int x = 0; x < kSize; ++x) {
                const Ray ray = rays.pixelRay(x, y);
                double t0, t1;
                if (!geometry.clipRay(ray, {}, t0, t1)) continue;
                for (int k = 1; t0 + (k - 1) * d < t1; ++k) {
                    const double mid = 0.5 * (t0 + (k - 1) * d + std::min(t0 + k * d, t1));
                    const Vec3i b = grid.brickOf(v.indexFromWorld(ray.origin + ray.dir * mid));
                    const ValueRange r = grid.range(grid.index(b.x, b.y, b.z));
                    taken += opacityPositiveOn(tf, r.min, r.max);
                }
            }
        return taken;
    };
    const std::vector<int32_t> reach = emptyReach(classifyBricks(grid, tf), grid.bricks);
    const int widestCube = 2 * *std::max_element(reach.begin(), reach.end()) - 1;
    const auto count = [](double perRay, const RenderStats &s) { return std::llround(perRay * double(s.raysHit)); };
    for (bool preintegrated : {false, true})
        for (bool jitter : {false, true}) {
            Quality q = plain(0.7);
            q.preintegrated = preintegrated;
            q.jitter = jitter;
            RenderStats none, sc, so;
            const Image full = cpu.render({tf, cam, kSize, kSize, q, {}}, &none);
            q.emptySpaceSkipping = true;
            const Image a = cpu.render({tf, cam, kSize, kSize, q, {}}, &sc);
            const Image b = ocl.render({tf, cam, kSize, kSize, q, {}}, &so);
            const std::string what = std::string(preintegrated ? "pre-integrated" : "sampled") + (jitter ? ", jitter" : "");
            // Float rounding, as in DrawsTheOpenClImageToFloatRounding (2e-5); a segment
            // wrongly skipped at the sphere's edge (opacity ≥ 0.05 there) would be ≥ 1e-3.
            EXPECT_LT(compareImages(a, full).maxAbs, 2e-5) << what;
            EXPECT_LT(compareImages(a, b).maxAbs, 2e-5) << what;
            EXPECT_EQ(count(sc.meanSamplesPerRay, sc) + count(sc.skippedSegmentsPerRay, sc), count(none.meanSamplesPerRay, none))
                << what << ": taken + skipped must be every segment";
            // A centre within float rounding of a brick wall may fall either way: 1e-3.
            EXPECT_NEAR(sc.meanSamplesPerRay, so.meanSamplesPerRay, 1e-3 * so.meanSamplesPerRay) << what;
            EXPECT_NEAR(sc.skippedSegmentsPerRay, so.skippedSegmentsPerRay, 1e-3 * so.skippedSegmentsPerRay) << what;
            if (!preintegrated && !jitter) {
                const double expected = double(expectedSamples(none.stepUsed * 1.0)); // smallest spacing 1
                EXPECT_NEAR(double(count(sc.meanSamplesPerRay, sc)), expected, 1e-3 * expected) << what;
            }
            std::printf("%s: samples per ray %.2f (CPU), %.2f (OpenCL), %.2f without skipping\n", what.c_str(),
                        sc.meanSamplesPerRay, so.meanSamplesPerRay, none.meanSamplesPerRay);
        }
    return widestCube;
}

// Empty-space skipping by sample position, on both back ends: a sampled segment is not taken
// when its centre lies in a brick the transfer function makes empty, a pre-integrated one when
// it lies wholly in one. Every segment left out would have added exactly 0, so the image is
// the one without skipping, and both back ends draw it to float rounding with the same
// samples. The sampled segments taken are counted independently here, in double: those whose
// centre lies in a visible brick. (Per-segment skipping, the kernel's earlier rule, took the
// segment straddling into each empty brick too: 16.6 samples per ray here against 10.4.)
// Both walks cross a cube of empty bricks in one step (emptyReach); the second sphere, small
// in a large box, leaves cubes up to 11 bricks wide around it, the first up to 3.
TEST(CpuRenderer, SkipsBySamplePositionOnBothBackEnds) {
    EXPECT_EQ(skipsBySamplePositionOnBothBackEnds(makeSphere({48, 40, 44}, {1, 1, 1.2}, 9, 2, 200).volume), 3);
    EXPECT_EQ(skipsBySamplePositionOnBothBackEnds(makeSphere({104, 96, 120}, {1, 1, 1.25}, 12, 2, 200).volume), 11);
}

TEST(CpuRenderer, PreprocessingHappensOnlyWhenASwitchFirstNeedsIt) {
    CpuRenderer r(blob().volume);
    const Camera cam = test::obliqueCamera(blob().volume, 30);
    TransferFunction tf = blobTf();
    r.render({tf, cam, 8, 8, plain(1), {}});
    r.render({tf, cam, 8, 8, plain(0.5), {}});
    EXPECT_EQ(r.preprocessCounts().tfTables, 1);
    EXPECT_EQ(r.preprocessCounts().brickGrids, 0);
    Quality q = plain(1);
    q.emptySpaceSkipping = true;
    r.render({tf, cam, 8, 8, q, {}});
    tf.points[2].a = 0.3; // a new transfer function re-classifies the same grid
    r.render({tf, cam, 8, 8, q, {}});
    EXPECT_EQ(r.preprocessCounts().brickGrids, 1);
    EXPECT_EQ(r.preprocessCounts().brickClassifications, 2);
    EXPECT_EQ(r.preprocessCounts().mipLevels, 0);
    q.mipLevel = 2;
    r.render({tf, cam, 8, 8, q, {}});
    q.mipLevel = 1;
    r.render({tf, cam, 8, 8, q, {}});
    EXPECT_EQ(r.preprocessCounts().mipLevels, 2); // levels 1 and 2, once
    EXPECT_EQ(r.preprocessCounts().coefficientVolumes, 0); // no cubic asked for yet
    q.interpolation = Interpolation::Cubic;
    r.render({tf, cam, 8, 8, q, {}});
    r.render({tf, cam, 8, 8, q, {}});
    EXPECT_EQ(r.preprocessCounts().coefficientVolumes, 1);
    EXPECT_EQ(r.preprocessCounts().brickGrids, 4); // levels 0, 2 and 1, and level 1's spline
    EXPECT_EQ(r.preprocessCounts().preintegrationTables, 0);
    q.preintegrated = true;
    r.render({tf, cam, 8, 8, q, {}});
    r.render({tf, cam, 8, 8, q, {}});
    EXPECT_EQ(r.preprocessCounts().preintegrationTables, 1); // same transfer function and step: reused
    q.step = 0.7;
    r.render({tf, cam, 8, 8, q, {}});
    EXPECT_EQ(r.preprocessCounts().preintegrationTables, 2); // the table depends on the step
}

TEST(NarrowSamples, WidthTakesExactlyTheIntegersEightAndSixteenBitsHold) {
    using W = NarrowWidth;
    const auto width = [](std::vector<float> v) { return narrowWidth(v); };
    const auto is = [](W w, int bytes, float offset) { return w.bytes == bytes && w.offset == offset; };
    EXPECT_TRUE(is(width({0, 255, 17}), 1, 0));
    EXPECT_TRUE(is(width({-1024, -769}), 1, -1024)); // 256 values: 8 bits from the lowest
    EXPECT_TRUE(is(width({-1024, -768}), 2, -1024)); // 257 values
    EXPECT_TRUE(is(width({-1024, 3071, 0}), 2, -1024));
    EXPECT_TRUE(is(width({0, 65535}), 2, 0));
    EXPECT_TRUE(is(width({16777216, 16777216 - 65535}), 2, 16777216 - 65535));
    EXPECT_EQ(width({0, 65536}).bytes, 4) << "17 bits";
    EXPECT_EQ(width({0, 0.5f}).bytes, 4) << "not an integer";
    EXPECT_EQ(width({1, -0.0f}).bytes, 4) << "−0 would come back as +0";
    EXPECT_EQ(width({1, std::nanf("")}).bytes, 4);
    EXPECT_EQ(width({1, INFINITY}).bytes, 4);
    EXPECT_EQ(width({16777218.0f, 16777220.0f}).bytes, 4) << "beyond 2^24 float no longer holds every integer";
    EXPECT_EQ(width({}).bytes, 4);
}

// The statistics of a narrow store (counted per stored code) are those of the same samples
// held as float, bin for bin: the range and histogram the client's transfer-function editor
// shows do not depend on which store the loader chose.
TEST(NarrowSamples, StatisticsEqualThoseOfTheFloatCopy) {
    struct Scan {
        const char *what;
        double scale, offset;
        int bytes;
    };
    // value = round(blob / its peak · scale) + offset
    for (const Scan &scan : {Scan{"8-bit", 255.0, 0.0, 1}, Scan{"16-bit CT-like", 4095.0, -1024.0, 2},
                             Scan{"a few values", 7.0, 41.0, 1}, Scan{"constant", 0.0, 12.0, 1}}) {
        Volume v = blob().volume;
        const float peak = *std::max_element(v.voxels.begin(), v.voxels.end());
        for (float &x : v.voxels) x = float(std::round(double(x) / peak * scan.scale) + scan.offset);
        Volume held = v;
        computeStatistics(v);
        ASSERT_TRUE(holdNarrow(held)) << scan.what;
        ASSERT_EQ(held.narrow.bytes, scan.bytes) << scan.what;
        computeStatistics(held);
        EXPECT_EQ(held.range.min, v.range.min) << scan.what;
        EXPECT_EQ(held.range.max, v.range.max) << scan.what;
        EXPECT_EQ(held.histogram.range.min, v.histogram.range.min) << scan.what;
        EXPECT_EQ(held.histogram.range.max, v.histogram.range.max) << scan.what;
        EXPECT_EQ(held.histogram.counts, v.histogram.counts) << scan.what;
    }
}

// An 8- or 16-bit scan held in the narrow store draws the image of the same samples held as
// float bit for bit, in every switch that samples trilinearly (and with the same samples):
// sampled in place with no copy of level 0 at all (SampleLayout::Slices), or from its bricked
// copy (Bricks, the one copy made). Only the widening differs, and it is exact.
TEST(CpuRenderer, EightAndSixteenBitSamplesDrawTheFloatCopysImageBitForBit) {
    const Camera cam = test::obliqueCamera(blob().volume, 30);
    const std::vector<ClipPlane> clip{{blob().volume.center(), normalize(Vec3d{0.2, 1, -0.3})}};
    struct Scan {
        const char *what;
        double scale, offset; // value = round(blob·scale) + offset, and the tf's points alike
        int bytes;
    };
    for (const Scan &scan : {Scan{"8-bit", 1.0, 0.0, 1}, Scan{"16-bit CT-like", 40.0, -1024.0, 2}}) {
        Volume v = blob().volume;
        for (float &x : v.voxels) x = float(std::round(double(x) * scan.scale) + scan.offset);
        computeStatistics(v);
        TransferFunction tf = blobTf();
        for (auto &pt : tf.points) pt.value = pt.value * scan.scale + scan.offset;
        Volume held = v;
        ASSERT_TRUE(holdNarrow(held)) << scan.what;
        ASSERT_EQ(held.narrow.bytes, scan.bytes) << scan.what;
        EXPECT_TRUE(held.voxels.empty()) << scan.what << ": the float store is given up";
        EXPECT_EQ(held.sampleBytes(), uint64_t(24 * 24 * 24) * uint64_t(scan.bytes) + kNarrowSlack) << scan.what;
        for (const SampleLayout layout : {SampleLayout::Bricks, SampleLayout::Slices}) {
            const bool bricks = layout == SampleLayout::Bricks;
            const std::string heldAs = std::string(scan.what) + (bricks ? " in bricks" : " in slices");
            CpuRenderer narrow(held, CpuRendererOptions{.layout = layout}), wide(v);
            EXPECT_EQ(narrow.memoryBytes(), bricks ? cpu::BrickedSamples::plannedBytes(v.dims, scan.bytes) : 0)
                << heldAs << ": level 0 is sampled in place, or from its one bricked copy";
            EXPECT_EQ(CpuRenderer::plannedBytes(v.dims, CpuRendererOptions{.layout = layout}, scan.bytes) -
                          CpuRenderer::plannedBytes(v.dims, CpuRendererOptions{.layout = SampleLayout::Slices}, scan.bytes),
                      narrow.memoryBytes())
                << heldAs << ": the server's budget counts the copy, and nothing else for it";
            EXPECT_EQ(wide.memoryBytes(), 0) << heldAs << ": a float level 0 is sampled in place";
            Quality q = plain(0.5);
            std::vector<std::pair<std::string, Quality>> cases{{"plain", q}};
            q.jitter = true;
            q.seed = 3;
            q.earlyTermination = 0.98;
            q.emptySpaceSkipping = true;
            cases.push_back({"jitter, early termination, skipping", q});
            q.shading = true;
            cases.push_back({"shading", q});
            q.preintegrated = true;
            q.step = 1.3;
            cases.push_back({"pre-integrated, shading", q});
            q = plain(0.5);
            q.compositing = Compositing::Maximum;
            cases.push_back({"MIP", q});
            q = plain(0.5);
            q.imageScale = 0.5;
            cases.push_back({"image scale 1/2", q});
            for (const auto &[what, quality] : cases) {
                const std::string label = heldAs + ", " + what;
                for (const auto &planes : {std::vector<ClipPlane>{}, clip}) {
                    RenderStats sn, sw;
                    const Image a = narrow.render({tf, cam, 40, 40, quality, planes}, &sn);
                    const Image b = wide.render({tf, cam, 40, 40, quality, planes}, &sw);
                    EXPECT_EQ(compareImages(a, b).maxAbs, 0) << label;
                    EXPECT_EQ(sn.meanSamplesPerRay, sw.meanSamplesPerRay) << label;
                    EXPECT_GT(compareImages(a, Image(40, 40)).maxAbs, 0.05) << label << ": nothing drawn";
                }
            }
        }
    }
}

// Levels are sampled where they lie, float or narrow, with no edge copies: on the last column,
// row and slice the sampler must take the sample itself as the upper tap. Random integer
// samples, non-zero up to every face, seen through the high faces and the low ones, with
// boundary segments reaching half a voxel past the outermost samples, at mip levels 0 and 1;
// flat axes (one sample) too; 9 samples, a brick and one more, for the bricked copy, whose
// last brick then holds one cell's corner and repeats the last sample. The judge is the
// OpenCL kernel, which clamps every tap on its own (2e-5: DrawsTheOpenClImageToFloatRounding);
// narrow (in bricks and in slices) and float agree bit for bit. A wrong edge tap changes
// pixels here; a blob that fades to zero before the faces would hide it.
TEST(CpuRenderer, LevelsSampledInPlaceDrawTheOpenClImageAtEveryFace) {
    std::mt19937 rng(11);
    for (const auto &[dims, lo, hi] : {std::tuple{Vec3i{13, 11, 9}, 0, 255}, std::tuple{Vec3i{13, 11, 9}, -1024, 3071},
                                       std::tuple{Vec3i{7, 1, 5}, 0, 255}, std::tuple{Vec3i{6, 5, 1}, -1024, 3071},
                                       std::tuple{Vec3i{1, 4, 3}, 0, 255}}) {
        Volume v;
        v.name = "random integers";
        v.dims = dims;
        v.voxels.resize(v.voxelCount());
        std::uniform_int_distribution<int> value(lo, hi);
        for (float &x : v.voxels) x = float(value(rng));
        computeStatistics(v);
        Volume held = v;
        ASSERT_TRUE(holdNarrow(held));
        TransferFunction tf;
        tf.points = {{double(lo), 0.2, 0.5, 1, 0.05}, {double(hi), 1, 0.6, 0.2, 0.6}};
        tf.opacityUnit = 1;
        CpuRenderer narrow(held), bricks(held, CpuRendererOptions{.layout = SampleLayout::Bricks}), wide(v);
        OpenClRenderer judge(test::sharedOpenClContext(), v);
        Camera high = test::obliqueCamera(v, 40), low = high;
        low.eye = v.center() - (high.eye - v.center());
        for (const auto &[cam, side] : {std::pair{high, ", high faces"}, std::pair{low, ", low faces"}})
            for (const int mip : {0, 1}) {
                Quality q = plain(0.37);
                q.mipLevel = mip;
                const std::string label = std::to_string(dims.x) + "×" + std::to_string(dims.y) + "×" +
                                          std::to_string(dims.z) + (held.narrow.bytes == 1 ? " 8-bit" : " 16-bit") +
                                          side + ", mip " + std::to_string(mip);
                const Image a = narrow.render({tf, cam, 48, 48, q, {}});
                const Image b = wide.render({tf, cam, 48, 48, q, {}});
                EXPECT_EQ(compareImages(a, b).maxAbs, 0) << label << ", slices";
                EXPECT_EQ(compareImages(bricks.render({tf, cam, 48, 48, q, {}}), b).maxAbs, 0) << label << ", bricks";
                EXPECT_LT(compareImages(b, judge.render({tf, cam, 48, 48, q, {}})).maxAbs, 2e-5) << label;
                EXPECT_GT(compareImages(a, Image(48, 48)).maxAbs, 0.05) << label << ": nothing drawn";
            }
    }
}

// The same on the OpenCL back end: its buffer of uchar or ushort samples (VOXEL_BYTES) draws
// the float buffer's image bit for bit, and the native path's to float rounding.
TEST(OpenClRenderer, EightAndSixteenBitSamplesDrawTheFloatBuffersImageBitForBit) {
    const Camera cam = test::obliqueCamera(blob().volume, 30);
    const std::vector<ClipPlane> clip{{blob().volume.center(), normalize(Vec3d{0.2, 1, -0.3})}};
    for (const auto &[what, scale, offset, bytes] :
         {std::tuple{"8-bit", 1.0, 0.0, 1}, std::tuple{"16-bit CT-like", 40.0, -1024.0, 2}}) {
        Volume v = blob().volume;
        for (float &x : v.voxels) x = float(std::round(double(x) * scale) + offset);
        computeStatistics(v);
        TransferFunction tf = blobTf();
        for (auto &pt : tf.points) pt.value = pt.value * scale + offset;
        Volume held = v;
        ASSERT_TRUE(holdNarrow(held)) << what;
        OpenClRenderer narrow(test::sharedOpenClContext(), held), wide(test::sharedOpenClContext(), v);
        CpuRenderer cpu(held);
        Quality q = plain(0.5);
        q.jitter = true;
        q.seed = 3;
        q.earlyTermination = 0.98;
        q.emptySpaceSkipping = true;
        q.shading = true;
        RenderStats sn, sw, sc;
        const Image a = narrow.render({tf, cam, 40, 40, q, clip}, &sn);
        const Image b = wide.render({tf, cam, 40, 40, q, clip}, &sw);
        EXPECT_NE(sn.buildOptions.find("-DVOXEL_BYTES=" + std::to_string(bytes)), std::string::npos)
            << what << ": " << sn.buildOptions;
        EXPECT_EQ(sw.buildOptions.find("VOXEL_BYTES"), std::string::npos) << what << ": " << sw.buildOptions;
        EXPECT_EQ(compareImages(a, b).maxAbs, 0) << what;
        EXPECT_EQ(sn.meanSamplesPerRay, sw.meanSamplesPerRay) << what;
        EXPECT_GT(compareImages(a, Image(40, 40)).maxAbs, 0.05) << what << ": nothing drawn";
        // As DrawsTheOpenClImageToFloatRounding: 2e-5.
        EXPECT_LT(compareImages(a, cpu.render({tf, cam, 40, 40, q, clip}, &sc)).maxAbs, 2e-5) << what;
    }
}

TEST(CpuRenderer, ThreadCountDoesNotChangeTheImage) {
    CpuRendererOptions one;
    one.threads = 1;
    CpuRendererOptions three;
    three.threads = 3;
    CpuRenderer a(blob().volume, one), b(blob().volume, three);
    Quality q = plain(0.7);
    q.jitter = true;
    q.emptySpaceSkipping = true;
    const Camera cam = test::obliqueCamera(blob().volume, 30);
    // Each ray is one lane of one packet whatever thread runs its tile: bit-identical.
    EXPECT_EQ(compareImages(a.render({blobTf(), cam, 37, 29, q, {}}), b.render({blobTf(), cam, 37, 29, q, {}})).maxAbs, 0);
}

} // namespace
} // namespace volcast
