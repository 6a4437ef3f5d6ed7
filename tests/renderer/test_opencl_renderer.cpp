// What only the OpenCL ray caster has: its device, programs built per feature set, device
// errors. Its accuracy against closed forms and the reference integrator is checked with
// the native CPU path's in test_frame_renderer_accuracy.cpp. Each new feature set costs PoCL
// about a second to build, so the tests share one context and few combinations.

#include "renderer/reference/error_metrics.hpp"
#include "renderer/opencl/opencl_renderer.hpp"
#include "renderer/reference/reference_renderer.hpp"
#include "renderer/model/synthetic.hpp"
#include "opencl_test_context.hpp"
#include "test_scenes.hpp"

#include <gtest/gtest.h>


namespace volcast {
namespace {

const std::shared_ptr<OpenClContext> &sharedContext() { return test::sharedOpenClContext(); }

TransferFunction constantTf(double a) { return test::constantTf(0.9, 0.5, 0.2, a, 1.0); }
Camera obliqueCamera(const Volume &v) { return test::obliqueCamera(v, 30); }

Quality plain(double step) { return test::plainQuality(step); }

TEST(OpenClRenderer, ReportsItsDevice) { EXPECT_FALSE(sharedContext()->deviceName().empty()); }

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
    // The spline from buffer taps on every device, GPUs too: texture filtering's weights are
    // the device's choice (docs/gpu.md).
    EXPECT_EQ(r.buildOptions(q, false),
              "-DJITTER -DBOUNDARY_SEGMENT -DEARLY_TERMINATION -DCUBIC -DPREINTEGRATED -DEMPTY_SPACE_SKIPPING -DSHADING");

    RenderStats first, second;
    r.render({constantTf(0.5), obliqueCamera(box.volume), 8, 8, plain(0.5), {}}, &first);
    const size_t built = sharedContext()->programsBuilt();
    r.render({constantTf(0.2), obliqueCamera(box.volume), 8, 8, plain(0.25), {}}, &second);
    // The box is built as float32 and not held narrow (only loaders and holdNarrow do that).
    EXPECT_EQ(first.buildOptions, "-DBOUNDARY_SEGMENT");
    EXPECT_EQ(sharedContext()->programsBuilt(), built); // same feature set: no new program
    EXPECT_EQ(second.kernelBuildSeconds, 0);
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
