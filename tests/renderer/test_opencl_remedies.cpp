// What only the OpenCL ray caster's remedies have: its two cubic fetch paths, and its lazy
// preprocessing on the device. The remedies themselves are checked against the reference
// integrator on both back ends in test_frame_renderer_accuracy.cpp.

#include "renderer/reference/error_metrics.hpp"
#include "renderer/opencl/opencl_renderer.hpp"
#include "renderer/reference/reference_renderer.hpp"
#include "renderer/model/synthetic.hpp"
#include "opencl_test_context.hpp"
#include "test_scenes.hpp"

#include <gtest/gtest.h>


namespace volcast {
namespace {

const std::shared_ptr<OpenClContext> &cl() { return test::sharedOpenClContext(); }

Quality plain(double step) { return test::plainQuality(step); }

using test::blob;
using test::blobTf;

TEST(OpenClRemedies, PreprocessingHappensOnlyWhenASwitchFirstNeedsIt) {
    OpenClRenderer r(cl(), blob().volume);
    const Camera cam = test::obliqueCamera(blob().volume, 30);
    TransferFunction tf = blobTf();
    auto counts = [&] { return r.preprocessCounts(); };

    r.render({tf, cam, 8, 8, plain(1), {}});
    EXPECT_EQ(counts().tfTables, 1);
    EXPECT_EQ(counts().coefficientVolumes, 0); // no cubic asked for: no B-spline coefficients
    EXPECT_EQ(counts().preintegrationTables, 0);
    EXPECT_EQ(counts().brickGrids, 0);
    EXPECT_EQ(counts().mipLevels, 0);

    r.render({tf, cam, 8, 8, plain(0.5), {}}); // a new step needs no new 1-D table
    EXPECT_EQ(counts().tfTables, 1);

    Quality q = plain(1);
    q.emptySpaceSkipping = true;
    r.render({tf, cam, 8, 8, q, {}});
    EXPECT_EQ(counts().brickGrids, 1);
    EXPECT_EQ(counts().brickClassifications, 1);
    tf.points[2].a = 0.3; // a new transfer function re-classifies the same grid
    r.render({tf, cam, 8, 8, q, {}});
    EXPECT_EQ(counts().brickGrids, 1);
    EXPECT_EQ(counts().brickClassifications, 2);
    EXPECT_EQ(counts().tfTables, 2);

    q.preintegrated = true;
    r.render({tf, cam, 8, 8, q, {}});
    r.render({tf, cam, 8, 8, q, {}});
    EXPECT_EQ(counts().preintegrationTables, 1); // same transfer function and step: reused
    q.step = 0.7;
    r.render({tf, cam, 8, 8, q, {}});
    EXPECT_EQ(counts().preintegrationTables, 2); // the table depends on the step
    EXPECT_EQ(counts().coefficientVolumes, 0);

    q.interpolation = Interpolation::Cubic;
    r.render({tf, cam, 8, 8, q, {}});
    r.render({tf, cam, 8, 8, q, {}});
    EXPECT_EQ(counts().coefficientVolumes, 1);
    EXPECT_EQ(counts().brickGrids, 2); // the spline's bricks bound its coefficients
    EXPECT_EQ(counts().mipLevels, 0);

    q.mipLevel = 2;
    r.render({tf, cam, 8, 8, q, {}});
    EXPECT_EQ(counts().mipLevels, 2); // levels 1 and 2, once
    q.mipLevel = 1;
    r.render({tf, cam, 8, 8, q, {}});
    EXPECT_EQ(counts().mipLevels, 2);
}

TEST(OpenClRemedies, CubicFromEightTrilinearFetchesEqualsSixtyFourTaps) {
    OpenClRendererOptions taps, fetches;
    taps.cubicFetch = CubicFetch::Taps64;
    fetches.cubicFetch = CubicFetch::Trilinear8;
    OpenClRenderer a(cl(), blob().volume, taps), b(cl(), blob().volume, fetches);
    Quality q = plain(0.5);
    q.interpolation = Interpolation::Cubic;
    const Camera cam = test::obliqueCamera(blob().volume, 30);
    const Image ia = a.render({blobTf(), cam, 24, 24, q, {}}), ib = b.render({blobTf(), cam, 24, 24, q, {}});
    EXPECT_NE(a.buildOptions(q, false), b.buildOptions(q, false));
    // PoCL filters 3-D images in float (docs/platform.md: 1.2e-7 of a trilinear); GPUs use ~8-bit
    // weights, 1/256 of a coefficient step, which an opacity of 0.7 turns into ~1e-2.
    EXPECT_LT(compareImages(ia, ib).maxAbs, cl()->isGpu() ? 2e-2 : 1e-4);
}

} // namespace
} // namespace volcast
