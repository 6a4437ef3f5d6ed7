// Maximum and minimum intensity projection and the crop box, on both back ends (OpenCL and
// the native CPU march) and the double-precision reference, against closed forms.

#include "renderer/cpu/cpu_renderer.hpp"
#include "renderer/reference/error_metrics.hpp"
#include "renderer/opencl/opencl_renderer.hpp"
#include "renderer/reference/reference_renderer.hpp"
#include "renderer/model/synthetic.hpp"
#include "opencl_test_context.hpp"
#include "test_scenes.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <limits>
#include <memory>

namespace volcast {
namespace {

enum class Backend { OpenCl, Cpu };

std::string backendName(const testing::TestParamInfo<Backend> &info) {
    return info.param == Backend::Cpu ? "Cpu" : "OpenCl";
}

class CompositingAndCrop : public testing::TestWithParam<Backend> {
  protected:
    std::unique_ptr<FrameRenderer> renderer(const Volume &v) const {
        if (GetParam() == Backend::Cpu) return std::make_unique<CpuRenderer>(v);
        return std::make_unique<OpenClRenderer>(test::sharedOpenClContext(), v);
    }
};

INSTANTIATE_TEST_SUITE_P(Backends, CompositingAndCrop, testing::Values(Backend::OpenCl, Backend::Cpu), backendName);

using test::plainQuality;

// Opacity a(v) = v / 1000 on [0, 1000], white: a MIP pixel's alpha is the maximum / 1000.
TransferFunction rampTf() {
    TransferFunction tf;
    tf.points = {{0, 1, 1, 1, 0}, {1000, 1, 1, 1, 1}};
    tf.opacityUnit = 1.0;
    return tf;
}

// Parameter interval of a ray inside an axis-aligned world box (slab test, double).
bool slabs(const Ray &ray, const Vec3d &lo, const Vec3d &hi, double &t0, double &t1) {
    t0 = 0;
    t1 = std::numeric_limits<double>::infinity();
    for (int a = 0; a < 3; ++a) {
        if (ray.dir[a] == 0) {
            if (ray.origin[a] < lo[a] || ray.origin[a] > hi[a]) return false;
            continue;
        }
        double ta = (lo[a] - ray.origin[a]) / ray.dir[a], tb = (hi[a] - ray.origin[a]) / ray.dir[a];
        if (ta > tb) std::swap(ta, tb);
        t0 = std::max(t0, ta);
        t1 = std::min(t1, tb);
    }
    return t1 > t0;
}

// The crop box in world space for an axis-aligned volume, computed here from the definition
// (normalised box coordinates: 0 and 1 are the outer faces of the outermost cells).
void cropInWorld(const Volume &v, const CropBox &c, Vec3d &lo, Vec3d &hi) {
    for (int a = 0; a < 3; ++a) {
        const double faceLo = v.origin[a] - 0.5 * v.spacing[a];
        const double extent = double(v.dims[a]) * v.spacing[a];
        lo[a] = faceLo + c.min[a] * extent;
        hi[a] = faceLo + c.max[a] * extent;
    }
}

// Largest |A − (1 − (1 − a)^(L/u))| over the image, L the chord through the crop box.
double croppedBoxAlphaError(const Image &img, const Volume &v, const Camera &cam, const CropBox &crop, double a,
                            int *hits) {
    const RayGenerator rays(cam, img.width, img.height);
    Vec3d lo, hi;
    cropInWorld(v, crop, lo, hi);
    double worst = 0;
    for (int y = 0; y < img.height; ++y)
        for (int x = 0; x < img.width; ++x) {
            double t0, t1;
            const double L = slabs(rays.pixelRay(x, y), lo, hi, t0, t1) ? t1 - t0 : 0;
            if (L > 0) ++*hits;
            worst = std::max(worst, std::fabs(img.pixel(x, y)[3] - -std::expm1(L * std::log1p(-a))));
        }
    return worst;
}

const CropBox kCrop{{0.1, 0.25, 0.3}, {0.8, 0.9, 0.65}};

TEST_P(CompositingAndCrop, CropBoxWithPartialSegmentsIsExactOnAConstantBox) {
    const SyntheticVolume box = makeConstantBox({12, 9, 15}, {1.0, 1.5, 0.8}, 100);
    const auto r = renderer(box.volume);
    const Camera cam = test::obliqueCamera(box.volume, 30);
    for (double step : {0.3, 1.7, 40.0}) {
        Quality q = plainQuality(step);
        q.crop = kCrop;
        const Image img = r->render({test::constantTf(0.9, 0.5, 0.2, 0.07, 1.0), cam, 32, 24, q, {}});
        int hits = 0;
        // As for the whole box (test_frame_renderer_accuracy.cpp): float ray parameters ~100
        // world units from the eye move A by ~1e-6, the depth sum by ~1e-6.
        EXPECT_LT(croppedBoxAlphaError(img, box.volume, cam, kCrop, 0.07, &hits), 1e-5) << "step " << step;
        EXPECT_GT(hits, 30) << "the crop box must be in view";
    }
}

TEST_P(CompositingAndCrop, CropBoxWithoutPartialSegmentsHasJerkyEdges) {
    const SyntheticVolume box = makeConstantBox({12, 9, 15}, {1.0, 1.5, 0.8}, 100);
    const auto r = renderer(box.volume);
    const Camera cam = test::obliqueCamera(box.volume, 30);
    Quality q = plainQuality(2.7);
    q.crop = kCrop;
    q.boundarySegment = false;
    const Image img = r->render({test::constantTf(0.9, 0.5, 0.2, 0.07, 1.0), cam, 32, 24, q, {}});
    int hits = 0;
    // Dropping up to one 2.7-voxel segment per ray loses up to 1 − 0.93^2.7 ≈ 0.18 of opacity.
    EXPECT_GT(croppedBoxAlphaError(img, box.volume, cam, kCrop, 0.07, &hits), 0.05);
}

TEST_P(CompositingAndCrop, CropBoxAndClipPlaneTogether) {
    const SyntheticVolume box = makeConstantBox({16, 16, 16}, {1, 1, 1}, 10);
    const auto r = renderer(box.volume);
    const Camera cam = test::obliqueCamera(box.volume, 30);
    const std::vector<ClipPlane> clip{{{7.5, 7.5, 7.5}, normalize(Vec3d{0.3, -1, 0.5})}};
    Quality q = plainQuality(1.3);
    q.crop = kCrop;
    const TransferFunction tf = test::constantTf(0.9, 0.5, 0.2, 0.1, 1.0);
    const Image img = r->render({tf, cam, 32, 32, q, clip});
    ReferenceRenderer ref(box.volume, tf, Reconstruction::Linear);
    ref.setCrop(kCrop);
    const RayGenerator rays(cam, 32, 32);
    double worst = 0;
    int hits = 0;
    for (int y = 0; y < 32; ++y)
        for (int x = 0; x < 32; ++x) {
            double t0, t1;
            const double L = ref.clipRay(rays.pixelRay(x, y), clip, t0, t1) ? t1 - t0 : 0;
            hits += L > 0;
            worst = std::max(worst, std::fabs(img.pixel(x, y)[3] - -std::expm1(L * std::log1p(-0.1))));
        }
    EXPECT_LT(worst, 1e-5); // as above
    EXPECT_GT(hits, 20);
}

// A sheet one voxel thick (x = 16) in a volume of zeros: along any ray that crosses the
// plane x = 16 inside the box, the trilinear field is a tent of half-width one voxel in x
// whose top is 1000: the MIP is exactly 1000 there, 0 elsewhere.
SyntheticVolume sheet() {
    return sampleField("sheet", {33, 20, 20}, {1, 1, 1}, {0, 0, 0},
                       [](const Vec3d &p) { return std::fabs(p.x - 16) < 0.5 ? 1000.0 : 0.0; });
}

Camera sheetCamera() {
    Camera c;
    c.projection = Projection::Orthographic;
    c.eye = {-20, 3, 2};
    c.target = {16, 9.5, 9.5};
    c.up = {0, 1, 0};
    c.height = 22;
    return c;
}

TEST(ReferenceIntensityProjection, FindsTheExactMaximumOfAThinSheet) {
    const SyntheticVolume v = sheet();
    ReferenceRenderer ref(v.volume, rampTf(), Reconstruction::Linear);
    ref.setCompositing(Compositing::Maximum);
    const Camera cam = sheetCamera();
    const RayGenerator rays(cam, 24, 24);
    int crossing = 0;
    for (int y = 0; y < 24; ++y)
        for (int x = 0; x < 24; ++x) {
            const Ray ray = rays.pixelRay(x, y);
            double t0, t1;
            if (!ref.clipRay(ray, {}, t0, t1)) continue;
            const double xa = ray.origin.x + t0 * ray.dir.x, xb = ray.origin.x + t1 * ray.dir.x;
            const RayIntegral r = ref.integrate(ray, {}, 1e-9);
            if (std::min(xa, xb) < 16 && std::max(xa, xb) > 16) {
                ++crossing;
                // The maximum is 1000 at the crossing, found by subdivision to 1e-12 of itself.
                EXPECT_NEAR(r.color.a, 1.0, 1e-9) << "pixel " << x << "," << y << " chord x " << xa << " … " << xb
                                                  << " y " << ray.origin.y + t0 * ray.dir.y << " … " << ray.origin.y + t1 * ray.dir.y
                                                  << " z " << ray.origin.z + t0 * ray.dir.z << " … " << ray.origin.z + t1 * ray.dir.z;
            }
        }
    EXPECT_GT(crossing, 100);
}

TEST(ReferenceIntensityProjection, MatchesDenseSamplingOfTheCubicSplineFromAbove) {
    // The exact maximum is at least every sampled value and, with 20000 samples per ray, no
    // more than the spline's slope times half a sample spacing above the best of them.
    const SyntheticVolume b = makeGaussianBlob({16, 16, 16}, {1, 1, 1}, 1.2, 900);
    ReferenceRenderer ref(b.volume, rampTf(), Reconstruction::Cubic);
    ref.setCompositing(Compositing::Maximum);
    const CubicBSplineField field(b.volume);
    const Camera cam = test::obliqueCamera(b.volume, 20);
    const RayGenerator rays(cam, 12, 12);
    for (int y = 0; y < 12; ++y)
        for (int x = 0; x < 12; ++x) {
            const Ray ray = rays.pixelRay(x, y);
            double t0, t1;
            if (!ref.clipRay(ray, {}, t0, t1)) continue;
            double sampled = -1e300;
            const int n = 20000;
            for (int i = 0; i <= n; ++i)
                sampled = std::max(sampled, field(b.volume.indexFromWorld(ray.origin + ray.dir * (t0 + (t1 - t0) * i / n))));
            const double exact = ref.integrate(ray, {}, 1e-9).color.a * 1000; // a = v/1000 below 1000
            // 900·e^-½/1.2 ≈ 455 per voxel is the blob's steepest slope; the sample spacing is
            // under 28/20000 voxels: at most ~0.3 above, plus the quadratic near the top.
            EXPECT_GE(exact, std::min(sampled, 1000.0) - 1e-9) << "pixel " << x << "," << y;
            EXPECT_LE(exact, sampled + 0.35) << "pixel " << x << "," << y;
        }
}

TEST(ReferenceIntensityProjection, MinimumOfALinearRampIsAtTheNearerEnd) {
    // v = 100 + 10·i along x (clamped beyond the outer samples): the minimum along a ray is
    // v at the smaller clamped x of its two ends.
    const SyntheticVolume ramp = makeLinearRamp({11, 8, 8}, {1, 1, 1}, 100, 200);
    TransferFunction tf;
    tf.points = {{100, 0.5, 0.5, 0.5, 0}, {200, 0.5, 0.5, 0.5, 1}};
    ReferenceRenderer ref(ramp.volume, tf, Reconstruction::Linear);
    ref.setCompositing(Compositing::Minimum);
    const Camera cam = test::obliqueCamera(ramp.volume, 12);
    const RayGenerator rays(cam, 16, 16);
    int hits = 0;
    for (int y = 0; y < 16; ++y)
        for (int x = 0; x < 16; ++x) {
            const Ray ray = rays.pixelRay(x, y);
            double t0, t1;
            if (!ref.clipRay(ray, {}, t0, t1)) continue;
            ++hits;
            const double xa = ray.origin.x + t0 * ray.dir.x, xb = ray.origin.x + t1 * ray.dir.x;
            const double xmin = std::clamp(std::min(xa, xb), 0.0, 10.0);
            const double a = (10 * xmin) / 100; // (v − 100)/100
            const RayIntegral r = ref.integrate(ray, {}, 1e-9);
            EXPECT_NEAR(r.color.a, a, 1e-9);
            EXPECT_NEAR(r.color.r, 0.5 * a, 1e-9); // premultiplied
        }
    EXPECT_GT(hits, 50);
}

TEST_P(CompositingAndCrop, MipMissesAThinSheetAtACoarseStepAndConvergesAsItShrinks) {
    const SyntheticVolume v = sheet();
    const auto r = renderer(v.volume);
    const Camera cam = sheetCamera();
    ReferenceRenderer ref(v.volume, rampTf(), Reconstruction::Linear);
    ref.setCompositing(Compositing::Maximum);
    ReferenceOptions o;
    o.tolerance = 1e-9;
    const Image exact = ref.render(cam, 48, 48, {}, o);
    // Every point of a chord is within half a segment of a segment's centre, and the tent
    // falls by 1000 per voxel of x, |dir.x| of it per world unit along these rays: a pixel's
    // alpha is at most |dir.x|·step/2 short (the onion-ring bound), plus the transfer-function
    // table's 1e-4. The RMSE need not fall at every halving: parallel rays meet the sheet
    // in phase, so a step can land samples nearer the top than half as long a one.
    const double dirX = std::fabs(RayGenerator(cam, 48, 48).pixelRay(24, 24).dir.x);
    std::vector<double> errors;
    for (double step : {4.0, 2.0, 1.0, 0.5, 0.25, 0.125, 0.0625}) {
        Quality q = plainQuality(step);
        q.compositing = Compositing::Maximum;
        const Image img = r->render({rampTf(), cam, 48, 48, q, {}});
        const ImageError e = compareImages(img, exact);
        errors.push_back(e.rmse);
        std::printf("MIP of a one-voxel sheet, step %g voxels: RMSE %.3e, worst pixel %.3e\n", step, e.rmse, e.maxAbs);
        EXPECT_LE(e.maxAbs, std::min(1.0, dirX * step / 2) + 1e-4) << "step " << step;
    }
    EXPECT_GT(errors.front(), 0.5) << "at step 4 most rays step over the 2-voxel tent";
    EXPECT_LT(errors.back(), 0.05 * errors.front());
}

TEST_P(CompositingAndCrop, MipOfABlobMatchesTheReferenceAndMinipOfARamp) {
    const SyntheticVolume b = makeGaussianBlob({24, 24, 24}, {1, 1, 1}, 4, 900);
    const auto r = renderer(b.volume);
    const Camera cam = test::obliqueCamera(b.volume, 30);
    for (Interpolation interp : {Interpolation::Linear, Interpolation::Cubic}) {
        ReferenceRenderer ref(b.volume, rampTf(),
                              interp == Interpolation::Cubic ? Reconstruction::Cubic : Reconstruction::Linear);
        ref.setCompositing(Compositing::Maximum);
        const Image exact = ref.render(cam, 32, 32, {}, {});
        Quality q = plainQuality(0.25);
        q.interpolation = interp;
        q.compositing = Compositing::Maximum;
        const Image img = r->render({rampTf(), cam, 32, 32, q, {}});
        // A smooth maximum missed by at most a quarter step: ~½·|v''|·(step/2)² = ½·56·0.016 ≈ 0.5
        // of 1000 in value, 5e-4 in alpha; the transfer-function table adds ≤ 1e-4.
        const ImageError c = compareImages(img, exact);
        EXPECT_LT(c.maxAbs, 2e-3) << (interp == Interpolation::Cubic ? "cubic" : "linear");
    }
    const SyntheticVolume ramp = makeLinearRamp({11, 8, 8}, {1, 1, 1}, 100, 200);
    TransferFunction tf;
    tf.points = {{100, 0.5, 0.5, 0.5, 0}, {200, 0.5, 0.5, 0.5, 1}};
    ReferenceRenderer ref(ramp.volume, tf, Reconstruction::Linear);
    ref.setCompositing(Compositing::Minimum);
    const Camera rampCam = test::obliqueCamera(ramp.volume, 30);
    const Image exact = ref.render(rampCam, 24, 24, {}, {});
    Quality q = plainQuality(0.1);
    q.compositing = Compositing::Minimum;
    const Image img = renderer(ramp.volume)->render({tf, rampCam, 24, 24, q, {}});
    // The minimum is at an end of the chord; the nearest sample is half a step (0.05 voxel)
    // inside it: 10 values per voxel · 0.05 = 0.5 of the 100-unit ramp, 5e-3 in alpha.
    EXPECT_LT(compareImages(img, exact).maxAbs, 6e-3);
}

TEST_P(CompositingAndCrop, SkippingTerminationAndPreintegrationDoNotChangeAProjection) {
    const SyntheticVolume b = makeGaussianBlob({24, 24, 24}, {1, 1, 1}, 4, 900);
    const auto r = renderer(b.volume);
    const Camera cam = test::obliqueCamera(b.volume, 30);
    // Transparent below 300: bricks of the blob's outskirts are "empty" for emission–absorption,
    // yet under MinIP their low values are the answer.
    TransferFunction tf;
    tf.points = {{0, 1, 1, 1, 0}, {300, 1, 1, 1, 0}, {900, 1, 0.5, 0.2, 1}};
    for (Compositing mode : {Compositing::Maximum, Compositing::Minimum}) {
        Quality plain = plainQuality(0.7);
        plain.compositing = mode;
        Quality everything = plain;
        everything.emptySpaceSkipping = true;
        everything.earlyTermination = 0.5;
        everything.preintegrated = true;
        everything.shading = true;
        RenderStats st;
        const Image a = r->render({tf, cam, 32, 32, plain, {}});
        const Image c = r->render({tf, cam, 32, 32, everything, {}}, &st);
        EXPECT_EQ(compareImages(a, c).maxAbs, 0.0);
        EXPECT_EQ(st.buildOptions.find("EMPTY_SPACE_SKIPPING"), std::string::npos) << st.buildOptions;
        EXPECT_EQ(st.buildOptions.find("EARLY_TERMINATION"), std::string::npos) << st.buildOptions;
        EXPECT_NE(st.buildOptions.find(mode == Compositing::Maximum ? "COMPOSITING_MAX" : "COMPOSITING_MIN"),
                  std::string::npos)
            << st.buildOptions;
    }
    RenderStats st;
    r->render({tf, cam, 8, 8, plainQuality(1), {}}, &st);
    EXPECT_EQ(st.buildOptions.find("COMPOSITING"), std::string::npos) << "emission–absorption builds no projection";
}

TEST_P(CompositingAndCrop, MipInsideACropBoxSeesOnlyTheBox) {
    // The sheet at x = 16 lies outside a crop box ending at x = 0.4·33 − ½ ≈ 12.7: nothing to see.
    const SyntheticVolume v = sheet();
    const auto r = renderer(v.volume);
    Quality q = plainQuality(0.25);
    q.compositing = Compositing::Maximum;
    q.crop = CropBox{{0, 0, 0}, {0.4, 1, 1}};
    const Image img = r->render({rampTf(), sheetCamera(), 24, 24, q, {}});
    // The tent reaches x = 15 at most, so everything left of 12.7 is exactly 0.
    double worst = 0;
    for (int y = 0; y < 24; ++y)
        for (int x = 0; x < 24; ++x) worst = std::max(worst, double(img.pixel(x, y)[3]));
    EXPECT_EQ(worst, 0.0);
    q.crop = CropBox{{0.45, 0, 0}, {0.55, 1, 1}}; // x in [14.35, 17.65]: the sheet and its tent
    const Image inside = r->render({rampTf(), sheetCamera(), 24, 24, q, {}});
    ReferenceRenderer ref(v.volume, rampTf(), Reconstruction::Linear);
    ref.setCompositing(Compositing::Maximum);
    ref.setCrop(q.crop);
    const Image exact = ref.render(sheetCamera(), 24, 24, {}, {});
    // Step 0.25 voxel along an oblique ray: the nearest sample is within 0.125 voxel of the
    // tent's top, 12.5 % of its height.
    EXPECT_LT(compareImages(inside, exact).maxAbs, 0.13);
}

// A windowed projection is grey clamp((v − (L − W/2)) / W, 0, 1), opaque where the ray
// crosses the box, whatever the scene's transfer function: the renderers get it from
// resolvedTransferFunction, the one place that makes the projection's ramp. On a constant box
// of 100 with W = 200, L = 50 every hit pixel is 0.75 grey with alpha 1, exactly 0 off the box.
// The grey passes through the transfer-function table (linear between entries, exact for a
// ramp up to float rounding): 1e-5.
TEST_P(CompositingAndCrop, WindowedProjectionIsOpaqueGreyOnAConstantBox) {
    const SyntheticVolume box = makeConstantBox({12, 9, 15}, {1.0, 1.5, 0.8}, 100);
    Scene scene;
    scene.transferFunction = rampTf();   // ignored by projections
    for (Compositing mode : {Compositing::Maximum, Compositing::Minimum}) {
        scene.quality = plainQuality(0.5);
        scene.quality.compositing = mode;
        scene.quality.projectionWindow = ProjectionWindow{200, 50};
        const TransferFunction tf = resolvedTransferFunction(scene, box.volume.range);
        const Camera cam = test::obliqueCamera(box.volume, 30);
        ReferenceRenderer ref(box.volume, tf, Reconstruction::Linear);
        ref.setQuality(scene.quality);
        const Image exact = ref.render(cam, 24, 20, {}, {});
        const Image img = renderer(box.volume)->render({tf, cam, 24, 20, scene.quality, {}});
        const RayGenerator rays(cam, 24, 20);
        int hits = 0;
        for (int y = 0; y < 20; ++y)
            for (int x = 0; x < 24; ++x) {
                double t0, t1;
                const Vec3d lo = box.volume.origin - box.volume.spacing * 0.5;
                const Vec3d hi = box.volume.origin + mul(Vec3d(box.volume.dims) - Vec3d{0.5, 0.5, 0.5}, box.volume.spacing);
                const bool crosses = slabs(rays.pixelRay(x, y), lo, hi, t0, t1);
                for (const Image *im : {&exact, &img}) {
                    const float *p = im->pixel(x, y);
                    if (!crosses) {
                        EXPECT_EQ(p[3], 0.0f) << x << "," << y;
                        continue;
                    }
                    // A ray grazing an edge by less than a sample's reach may be missed by the
                    // sampled back end; the reference never misses.
                    if (im == &img && t1 - t0 < 0.5) continue;
                    EXPECT_EQ(p[3], 1.0f) << x << "," << y;
                    for (int ch = 0; ch < 3; ++ch) EXPECT_NEAR(p[ch], 0.75, 1e-5) << x << "," << y;
                }
                hits += crosses;
            }
        EXPECT_GT(hits, 60);
    }
}

// Without a window the ramp spans the volume's value range; on a smooth blob each back end
// matches the reference's grey to the bound of MipOfABlobMatchesTheReference rescaled: that
// test allows 2 of 1000 in value (2e-3 of its ramp), which is 5e-3 of a W = 400 window.
TEST_P(CompositingAndCrop, WindowedMipOfABlobMatchesTheReference) {
    const SyntheticVolume b = makeGaussianBlob({24, 24, 24}, {1, 1, 1}, 4, 900);
    Scene scene;
    scene.quality = plainQuality(0.25);
    scene.quality.compositing = Compositing::Maximum;
    const TransferFunction whole = resolvedTransferFunction(scene, b.volume.range);
    ASSERT_EQ(whole.points.size(), 2u);
    EXPECT_EQ(whole.points[0].value, b.volume.range.min);
    EXPECT_EQ(whole.points[1].value, b.volume.range.max);
    scene.quality.projectionWindow = ProjectionWindow{400, 600};
    const TransferFunction tf = resolvedTransferFunction(scene, b.volume.range);
    const Camera cam = test::obliqueCamera(b.volume, 30);
    ReferenceRenderer ref(b.volume, tf, Reconstruction::Linear);
    ref.setQuality(scene.quality);
    const Image exact = ref.render(cam, 32, 32, {}, {});
    const Image img = renderer(b.volume)->render({tf, cam, 32, 32, scene.quality, {}});
    EXPECT_LT(compareImages(img, exact).maxAbs, 5e-3);
    // Grey, and saturated at the blob's centre (900 > 600 + 200).
    const float *centre = exact.pixel(16, 16);
    EXPECT_EQ(centre[3], 1.0f);
    EXPECT_EQ(centre[0], 1.0f);
    EXPECT_EQ(centre[0], centre[1]);
}

TEST(SceneCompositingAndCrop, ReadsWritesAndRefuses) {
    const std::string base = R"({"volume": "builtin:gaussian_blob", "transfer_function": {"preset": "ct_bone"},
        "camera": {"eye": [0, 0, 100], "target": [0, 0, 0], "up": [0, 1, 0]}, "image": {"width": 8, "height": 8},
        "quality": )";
    const Scene s = parseScene(base + R"({"compositing": "mip", "crop": {"min": [0.1, 0, 0.2], "max": [1, 0.5, 0.9]}}})");
    EXPECT_EQ(s.quality.compositing, Compositing::Maximum);
    EXPECT_EQ(s.quality.crop.min, (Vec3d{0.1, 0, 0.2}));
    EXPECT_EQ(s.quality.crop.max, (Vec3d{1, 0.5, 0.9}));
    EXPECT_EQ(parseScene(sceneToJson(s)), s);
    EXPECT_EQ(parseScene(base + R"({"compositing": "minip"}})").quality.compositing, Compositing::Minimum);

    // The defaults are not written: scenes without the new keys read and write as before.
    const std::string plain = sceneToJson(parseScene(base + "{}}"));
    EXPECT_EQ(plain.find("compositing"), std::string::npos);
    EXPECT_EQ(plain.find("crop"), std::string::npos);

    auto error = [&](const std::string &quality) {
        try {
            parseScene(base + quality + "}");
        } catch (const SceneError &e) {
            return std::string(e.what());
        }
        return std::string("no error");
    };
    EXPECT_NE(error(R"({"compositing": "max"})").find("quality.compositing"), std::string::npos);
    EXPECT_NE(error(R"({"crop": {"min": [0, 0, -0.1]}})").find("quality.crop.min[2]"), std::string::npos);
    EXPECT_NE(error(R"({"crop": {"min": [0.5, 0, 0], "max": [0.5, 1, 1]}})").find("quality.crop.max[0]"),
              std::string::npos);
    EXPECT_NE(error(R"({"crop": {"lo": [0, 0, 0]}})").find("quality.crop.lo"), std::string::npos);
}

TEST(SceneCompositingAndCrop, ProjectionWindowReadsWritesAndRefuses) {
    const std::string base = R"({"volume": "builtin:gaussian_blob", "transfer_function": {"preset": "ct_bone"},
        "camera": {"eye": [0, 0, 100], "target": [0, 0, 0], "up": [0, 1, 0]}, "image": {"width": 8, "height": 8},
        "quality": )";
    const Scene s = parseScene(base + R"({"compositing": "mip", "projection_window": {"window": 400, "level": 40}}})");
    ASSERT_TRUE(s.quality.projectionWindow);
    EXPECT_EQ(*s.quality.projectionWindow, (ProjectionWindow{400, 40}));
    EXPECT_EQ(parseScene(sceneToJson(s)), s);
    // The projection's ramp replaces the preset: black at L − W/2, white at L + W/2, opaque.
    const TransferFunction tf = resolvedTransferFunction(s, {-1000, 3000});
    ASSERT_EQ(tf.points.size(), 2u);
    EXPECT_EQ(tf.points[0], (ControlPoint{-160, 0, 0, 0, 1}));
    EXPECT_EQ(tf.points[1], (ControlPoint{240, 1, 1, 1, 1}));
    // Emission–absorption keeps its own transfer function, window or not.
    Scene ea = s;
    ea.quality.compositing = Compositing::EmissionAbsorption;
    EXPECT_EQ(resolvedTransferFunction(ea, {-1000, 3000}), presetTransferFunction("ct_bone", {-1000, 3000}));
    // Not written when unset.
    EXPECT_EQ(sceneToJson(parseScene(base + R"({"compositing": "mip"}})")).find("projection_window"), std::string::npos);
    // A constant volume gets a window of 1 around its value.
    const TransferFunction flat = projectionTransferFunction(std::nullopt, {7, 7});
    EXPECT_EQ(flat.points[0].value, 6.5);
    EXPECT_EQ(flat.points[1].value, 7.5);

    auto error = [&](const std::string &quality) {
        try {
            parseScene(base + quality + "}");
        } catch (const SceneError &e) {
            return std::string(e.what());
        }
        return std::string("no error");
    };
    for (const char *bad : {R"({"projection_window": {"window": 0, "level": 1}})",
                            R"({"projection_window": {"window": -5, "level": 1}})",
                            R"({"projection_window": {"window": "wide", "level": 1}})",
                            R"({"projection_window": {"window": 1e-300, "level": 1e300}})",
                            R"({"projection_window": {"window": 1.7e308, "level": 1.7e308}})"})
        EXPECT_NE(error(bad).find("quality.projection_window.window"), std::string::npos) << bad << ": " << error(bad);
    EXPECT_NE(error(R"({"projection_window": {"window": 10}})").find("quality.projection_window.level"),
              std::string::npos);
    EXPECT_NE(error(R"({"projection_window": [10, 1]})").find("quality.projection_window"), std::string::npos);
    EXPECT_NE(error(R"({"projection_window": {"window": 10, "level": 1, "gamma": 2}})")
                  .find("quality.projection_window.gamma"),
              std::string::npos);
}

} // namespace
} // namespace volcast
