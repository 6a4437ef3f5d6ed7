// The --device choice: what each value means, and that a wrong one is a clear error.

#include "renderer/make_frame_renderer.hpp"
#include "renderer/model/synthetic.hpp"

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

} // namespace
} // namespace volcast
