// The OpenCL frame's parts: 8-bit frames converted on the device, the per-frame breakdown
// of RenderStats, and the buffers and kernels a renderer keeps between frames.

#include "renderer/make_frame_renderer.hpp"
#include "renderer/opencl/embedded_kernels.hpp"
#include "renderer/opencl/opencl_renderer.hpp"
#include "opencl_test_context.hpp"
#include "test_scenes.hpp"

#include <gtest/gtest.h>

#include <chrono>
#include <cmath>
#include <limits>

namespace volcast {
namespace {

using Clock = std::chrono::steady_clock;

const std::shared_ptr<OpenClContext> &sharedContext() { return test::sharedOpenClContext(); }

// A frame of the blob with the features named, so that several programs are used in turn.
FrameRequest blobFrame(int width, int height, bool shaded, bool preintegrated, bool clipped,
                       std::optional<RayWindow> window = std::nullopt) {
    Quality q = test::plainQuality(0.5);
    q.shading = shaded;
    q.preintegrated = preintegrated;
    q.emptySpaceSkipping = preintegrated;
    std::vector<ClipPlane> planes;
    if (clipped) planes.push_back({test::blob().volume.center(), {0.3, 1, -0.2}});
    return {test::blobTf(), test::obliqueCamera(test::blob().volume, 30), width, height, q, planes, window};
}

// The device's conversion whatever the device (Auto converts on the host on PoCL).
OpenClRendererOptions onDevice() {
    OpenClRendererOptions o;
    o.rgba8Conversion = Rgba8Conversion::Device;
    return o;
}

OpenClRenderer &sharedRenderer() {
    static OpenClRenderer r(sharedContext(), test::blob().volume, onDevice());
    return r;
}

// The ray caster's conversion (raycast.cl's rgba8FromUnit, called by a kernel added to its
// source here) on values chosen to hit every edge: each byte's exact half-way point and the
// floats beside it, 0, 1, beyond both, infinities, NaN and denormals.
TEST(OpenClFrameParts, TheDeviceConvertsToBytesExactlyAsTheHost) {
    std::vector<float> values = {0.0f, -0.0f, 1.0f, -1.0f, 2.0f, std::numeric_limits<float>::infinity(),
                                 -std::numeric_limits<float>::infinity(), std::numeric_limits<float>::quiet_NaN(),
                                 std::numeric_limits<float>::denorm_min(), -std::numeric_limits<float>::denorm_min(),
                                 1e-30f, 0.9999999f, 1.0000001f};
    for (int k = 0; k <= 255; ++k)
        for (const double at : {k / 255.0, (k + 0.5) / 255.0}) {
            float v = float(at);
            for (int step = 0; step < 3; ++step) v = std::nextafter(v, -1.0f);
            for (int step = 0; step < 7; ++step, v = std::nextafter(v, 2.0f)) values.push_back(v);
        }
    while (values.size() % 4) values.push_back(0.5f);
    const int pixels = int(values.size() / 4);

    OpenClContext &cl = *sharedContext();
    const std::string source = std::string(kRaycastKernelSource) + R"(
__kernel void bytesOfValues(__global const float4 *image, __global uchar4 *bytes, const int count) {
    const int i = get_global_id(0);
    if (i < count) bytes[i] = rgba8FromUnit(image[i]);
})";
    const auto built = cl.program(source, "");
    cl::Kernel convert(built.program, "bytesOfValues");
    cl::Buffer in(cl.context(), CL_MEM_READ_ONLY | CL_MEM_COPY_HOST_PTR, values.size() * sizeof(float), values.data());
    cl::Buffer out(cl.context(), CL_MEM_WRITE_ONLY, values.size());
    convert.setArg(0, in);
    convert.setArg(1, out);
    convert.setArg(2, cl_int(pixels));
    cl.queue().enqueueNDRangeKernel(convert, cl::NullRange, cl::NDRange(size_t(pixels + 63) / 64 * 64), cl::NDRange(64));
    std::vector<uint8_t> device(values.size());
    cl.queue().enqueueReadBuffer(out, CL_TRUE, 0, device.size(), device.data());

    for (size_t i = 0; i < values.size(); ++i)
        ASSERT_EQ(int(device[i]), int(byteFromUnit(clampUnit(values[i])))) << "value " << values[i] << " at " << i;
    // The host formula itself: halves away from zero, as lround.
    for (int k = 0; k < 255; ++k) EXPECT_EQ(int(byteFromUnit(float((k + 0.5) / 255.0))), int(std::lround(float((k + 0.5) / 255.0) * 255.0f)));
}

// Bit for bit: the device's bytes of a frame are the host's conversion of its floats, for
// whole frames, windows (whose width is not a multiple of the work-group) and feature sets.
TEST(OpenClFrameParts, EightBitFramesAreTheHostConversionOfTheFloatFrames) {
    OpenClRenderer &r = sharedRenderer();
    const std::vector<FrameRequest> frames = {
        blobFrame(48, 40, false, false, false),
        blobFrame(45, 37, true, true, true),
        blobFrame(64, 64, false, false, true, RayWindow{5, 9, 29, 13}),
        blobFrame(64, 64, true, false, false, RayWindow{0, 60, 64, 4}),
    };
    for (size_t i = 0; i < frames.size(); ++i) {
        RenderStats floatStats, byteStats;
        const Image floats = r.render(frames[i], &floatStats);
        const Rgba8Image bytes = r.renderRgba8(frames[i], &byteStats);
        const Rgba8Image host = rgba8FromImage(floats);
        EXPECT_EQ(bytes.width, floats.width) << i;
        EXPECT_EQ(bytes.height, floats.height) << i;
        EXPECT_EQ(bytes.rgba, host.rgba) << "frame " << i;
        EXPECT_EQ(byteStats.hostConvertSeconds, 0) << i;
        EXPECT_EQ(byteStats.raysHit, floatStats.raysHit) << i;
    }
    // image_scale < 1: upsampled on the host, so converted there, and still the same bytes.
    FrameRequest scaled = blobFrame(40, 30, false, false, false);
    scaled.quality.imageScale = 0.5;
    RenderStats st;
    EXPECT_EQ(r.renderRgba8(scaled, &st).rgba, rgba8FromImage(r.render(scaled)).rgba);
    EXPECT_GT(st.hostConvertSeconds, 0);
}

// Asked to convert on the host, the OpenCL renderer reads floats back and converts them there.
TEST(OpenClFrameParts, TheHostConversionReadsBackFloats) {
    OpenClRendererOptions o;
    o.rgba8Conversion = Rgba8Conversion::Host;
    OpenClRenderer r(sharedContext(), test::blob().volume, o);
    const FrameRequest frame = blobFrame(40, 36, false, false, false);
    RenderStats st;
    EXPECT_EQ(r.renderRgba8(frame, &st).rgba, rgba8FromImage(r.render(frame)).rgba);
    EXPECT_GT(st.hostConvertSeconds, 0);
    EXPECT_GT(st.deviceKernelSeconds, 0);
}

// The native path converts on the host (FrameRenderer's default), to the same bytes.
TEST(OpenClFrameParts, TheDefaultConversionIsTheHostsOnTheNativePath) {
    const auto cpu = makeFrameRenderer(nullptr, std::make_shared<const Volume>(test::blob().volume));
    const FrameRequest frame = blobFrame(40, 36, true, false, false);
    RenderStats st;
    EXPECT_EQ(cpu->renderRgba8(frame, &st).rgba, rgba8FromImage(cpu->render(frame)).rgba);
    EXPECT_GT(st.hostConvertSeconds, 0);
    EXPECT_EQ(st.deviceKernelSeconds, 0);
}

// The breakdown: each part measured, and together no longer than the call. The device's
// times are intervals of commands the in-order queue ran one after another between the
// first enqueue and the final read's end, so their sum cannot pass that wall-clock span.
TEST(OpenClFrameParts, TheFramesPartsAreMeasuredAndAddUpToNoMoreThanTheFrame) {
    OpenClRenderer &r = sharedRenderer();
    for (const bool bytes : {false, true}) {
        const FrameRequest frame = blobFrame(72, 56, true, false, false);
        r.render(frame); // program and tables ready: the frame timed below is a later one
        RenderStats st;
        const auto t0 = Clock::now();
        if (bytes)
            r.renderRgba8(frame, &st);
        else
            r.render(frame, &st);
        const double wall = std::chrono::duration<double>(Clock::now() - t0).count();
        SCOPED_TRACE(bytes ? "8-bit" : "float");
        EXPECT_GT(st.deviceKernelSeconds, 0);
        EXPECT_GT(st.hostSetUpSeconds, 0);
        EXPECT_GE(st.deviceReadBackSeconds, 0);
        EXPECT_EQ(st.hostConvertSeconds, 0);
        const double device = st.deviceKernelSeconds + st.deviceReadBackSeconds;
        EXPECT_LE(device, st.renderSeconds);
        EXPECT_LE(st.hostSetUpSeconds + st.renderSeconds, wall);
    }
}

// Kept buffers and kernels must not carry anything from one frame to the next: a renderer
// that drew other sizes, windows and feature sets before gives each frame bit for bit as a
// fresh renderer does, counters included (a smaller frame after a larger one reads only its
// own part of the grown buffer; the counters, running totals, give each frame its own counts).
TEST(OpenClFrameParts, AReusedRendererDrawsEachFrameAsAFreshOne) {
    const std::vector<FrameRequest> frames = {
        blobFrame(96, 64, true, true, false),
        blobFrame(32, 24, false, false, false),
        blobFrame(64, 64, false, false, true, RayWindow{3, 3, 17, 9}),
        blobFrame(96, 64, true, true, false, RayWindow{40, 8, 56, 56}),
        blobFrame(31, 47, false, true, true),
        blobFrame(32, 24, false, false, false),
    };
    OpenClRenderer reused(sharedContext(), test::blob().volume, onDevice());
    for (size_t i = 0; i < frames.size(); ++i) {
        RenderStats again, fresh;
        const Image a = reused.render(frames[i], &again);
        const Rgba8Image a8 = reused.renderRgba8(frames[i]);
        OpenClRenderer once(sharedContext(), test::blob().volume);
        const Image b = once.render(frames[i], &fresh);
        EXPECT_EQ(a.rgba, b.rgba) << "frame " << i;
        EXPECT_EQ(a8.rgba, rgba8FromImage(b).rgba) << "frame " << i;
        EXPECT_EQ(again.raysHit, fresh.raysHit) << i;
        EXPECT_EQ(again.meanSamplesPerRay, fresh.meanSamplesPerRay) << i;
        EXPECT_EQ(again.skippedSegmentsPerRay, fresh.skippedSegmentsPerRay) << i;
    }
}

// The three ways to read a frame back (ReadBack) bring back the same image and the same
// counts, float and 8-bit, as the pinned memory grows with the frames and is reused by
// smaller ones.
TEST(OpenClFrameParts, EveryReadBackBringsBackTheSameFrameAndCounts) {
    const std::vector<FrameRequest> frames = {
        blobFrame(32, 24, false, false, false),
        blobFrame(96, 64, true, true, false),
        blobFrame(64, 64, false, false, true, RayWindow{3, 3, 17, 9}),
        blobFrame(31, 47, false, true, true),
    };
    OpenClRendererOptions direct = onDevice();
    direct.readBack = ReadBack::Direct;
    OpenClRenderer reference(sharedContext(), test::blob().volume, direct);
    for (const ReadBack how : {ReadBack::CountersFirst, ReadBack::Pinned}) {
        OpenClRendererOptions o = onDevice();
        o.readBack = how;
        OpenClRenderer r(sharedContext(), test::blob().volume, o);
        SCOPED_TRACE(how == ReadBack::Pinned ? "pinned" : "counters first");
        for (size_t i = 0; i < frames.size(); ++i) {
            RenderStats got, want;
            const Image a = r.render(frames[i], &got);
            const Image b = reference.render(frames[i], &want);
            EXPECT_EQ(a.rgba, b.rgba) << "frame " << i;
            EXPECT_EQ(r.renderRgba8(frames[i]).rgba, reference.renderRgba8(frames[i]).rgba) << "frame " << i;
            EXPECT_EQ(got.raysHit, want.raysHit) << i;
            EXPECT_EQ(got.meanSamplesPerRay, want.meanSamplesPerRay) << i;
            EXPECT_EQ(got.skippedSegmentsPerRay, want.skippedSegmentsPerRay) << i;
            EXPECT_GT(got.deviceReadBackSeconds, 0) << i;
        }
    }
}

// A window casts its rays and no others: windows tiling a frame (widths and heights that are
// not multiples of the work-group's 8) hit as many rays and sample as often as the frame,
// and hold its pixels.
TEST(OpenClFrameParts, WindowsCastOnlyTheirRays) {
    OpenClRenderer &r = sharedRenderer();
    const FrameRequest whole = blobFrame(37, 29, false, false, false);
    RenderStats all;
    const Image frame = r.render(whole, &all);
    ASSERT_GT(all.raysHit, 0u);
    uint64_t hit = 0;
    double samples = 0;
    for (const RayWindow w : {RayWindow{0, 0, 13, 29}, RayWindow{13, 0, 24, 11}, RayWindow{13, 11, 24, 18}}) {
        FrameRequest part = whole;
        part.window = w;
        RenderStats st;
        const Image image = r.render(part, &st);
        hit += st.raysHit;
        samples += st.meanSamplesPerRay * double(st.raysHit);
        for (int y = 0; y < w.height; ++y)
            for (int x = 0; x < w.width; ++x)
                for (int c = 0; c < 4; ++c)
                    ASSERT_EQ(image.pixel(x, y)[c], frame.pixel(w.x + x, w.y + y)[c]) << x << "," << y;
    }
    EXPECT_EQ(hit, all.raysHit);
    // Sums of whole sample counts, each exact in double: a ray counted twice would show.
    EXPECT_EQ(std::llround(samples), std::llround(all.meanSamplesPerRay * double(all.raysHit)));
}

} // namespace
} // namespace volcast
