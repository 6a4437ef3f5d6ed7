// The --device choice: what each value means, and that a wrong one is a clear error.

#include "renderer/make_frame_renderer.hpp"
#include "renderer/model/synthetic.hpp"
#include "test_scenes.hpp"

#include <gtest/gtest.h>

namespace volcast {
namespace {

TEST(DeviceChoice, ParsesEveryDocumentedForm) {
    EXPECT_EQ(DeviceChoice::parse("cpu").kind, DeviceChoice::Kind::Cpu);
    EXPECT_EQ(DeviceChoice::parse("auto").kind, DeviceChoice::Kind::Auto);
    EXPECT_EQ(DeviceChoice::parse("opencl").kind, DeviceChoice::Kind::OpenCl);
    EXPECT_EQ(DeviceChoice::parse("opencl").openClDevice, "");
    const DeviceChoice named = DeviceChoice::parse("opencl:pthread");
    EXPECT_EQ(named.kind, DeviceChoice::Kind::OpenCl);
    EXPECT_EQ(named.openClDevice, "pthread");
    for (const char *text : {"cpu", "auto", "opencl", "opencl:gpu"}) EXPECT_EQ(DeviceChoice::parse(text).text(), text);
}

TEST(DeviceChoice, AnUnknownValueIsAClearError) {
    for (const char *text : {"gpu", "opencl:", "CPU", "cuda"}) {
        try {
            DeviceChoice::parse(text);
            FAIL() << text << " was accepted";
        } catch (const std::invalid_argument &e) {
            EXPECT_NE(std::string(e.what()).find(std::string("'") + text + "'"), std::string::npos) << e.what();
        }
    }
}

TEST(MakeFrameRenderer, CpuIsTheNativePathAndOpenClAnOpenClDevice) {
    const auto box = std::make_shared<const Volume>(makeConstantBox({4, 4, 4}, {1, 1, 1}, 1).volume);
    EXPECT_EQ(makeFrameRenderer(DeviceChoice::parse("cpu"), box)->description().rfind("cpu: ", 0), 0u);
    EXPECT_EQ(makeFrameRenderer(DeviceChoice::parse("opencl"), box)->description().rfind("opencl: ", 0), 0u);
    // Auto takes an OpenCL GPU if there is one, never PoCL's CPU device.
    const std::string automatic = makeFrameRenderer(DeviceChoice::parse("auto"), box)->description();
    if (automatic.rfind("opencl: ", 0) == 0) EXPECT_EQ(automatic.find("pthread"), std::string::npos) << automatic;
    else EXPECT_EQ(automatic.rfind("cpu: ", 0), 0u) << automatic;
}

// The renderer made for OpenCL is the OpenCL ray caster with all it offers the server's
// scheduler: a window casts only its own rays, and frames are cut in bands of its
// work-group's height. A renderer that forwarded only render() would cast the whole grid for
// every window, so that one scheduler unit would cost a whole pass.
TEST(MakeFrameRenderer, OpenClCastsAWindowAloneAndReportsItsBandRows) {
    const auto box = std::make_shared<const Volume>(makeConstantBox({16, 16, 16}, {1, 1, 1}, 1).volume);
    const auto r = makeFrameRenderer(DeviceChoice::parse("opencl"), box);
    EXPECT_TRUE(r->rendersWindowsCheaply());
    EXPECT_EQ(r->bandRows(), 8) << "the OpenCL work-group is 8 rows high";
    const TransferFunction tf = test::constantTf(1, 1, 1, 0.5, 1);
    const Camera camera = test::obliqueCamera(*box, 10); // the box fills the view: every ray hits
    const Quality q = test::plainQuality(1);
    RenderStats whole, part;
    const Image frame = r->render({tf, camera, 32, 32, q, {}}, &whole);
    ASSERT_EQ(whole.raysHit, 32u * 32u) << "the box must fill the view for the window's count to tell";
    const RayWindow window{8, 16, 8, 8};
    const Image cast = r->render({tf, camera, 32, 32, q, {}, window}, &part);
    EXPECT_LE(part.raysHit, uint64_t(window.width * window.height)) << "the whole grid was cast for one window";
    // Each ray of the window exactly as the whole frame casts it.
    for (int y = 0; y < window.height; ++y)
        for (int x = 0; x < window.width; ++x)
            for (int c = 0; c < 4; ++c)
                ASSERT_EQ(cast.pixel(x, y)[c], frame.pixel(window.x + x, window.y + y)[c]) << x << "," << y;
}

} // namespace
} // namespace volcast
