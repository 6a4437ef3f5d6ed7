#pragma once
// What every back end that draws frames offers (the OpenCL ray caster, the native CPU one),
// so that tools, tests and the server depend on this interface and not on a back end: a
// FrameRequest in, an image out. Also the checks every back end makes the same way (the rest
// of a frame's set-up is frame_setup.hpp's).

#include "renderer/model/camera.hpp"
#include "renderer/model/image.hpp"
#include "renderer/model/scene.hpp"
#include "renderer/model/transfer_function.hpp"
#include "renderer/model/volume.hpp"

#include <cstdint>
#include <optional>
#include <string>
#include <utility>
#include <vector>

namespace volcast {

// Seconds of preprocessing a frame caused (0: it was cached) and what the ray caster did.
struct RenderStats {
    std::string buildOptions;       // the feature set the program was built with (or dispatched)
    double kernelBuildSeconds = 0;  // 0 when the program was already built
    double tfTableSeconds = 0;
    int tfTableEntries = 0;
    double tfTableError = 0;
    double mipSeconds = 0;          // building the mip level(s) this frame needed
    double coefficientSeconds = 0;  // B-spline prefilter (on the device) and upload
    double brickGridSeconds = 0;    // min-max grid of the sampled data
    double brickClassifySeconds = 0;
    double adaptiveStepSeconds = 0; // the adaptive step's per-brick gradients and steps
    double adaptiveMeanStep = 0;    // voxels: the adaptive step's mean over the bricks marched
    double emptyBrickFraction = 0;  // under the current transfer function
    double preintegrationSeconds = 0;
    int preintegrationNodes = 0;
    double preintegrationError = 0; // the table's own measured error
    double renderSeconds = 0;       // ray casting, read-back and upsampling
    // The frame's parts (renderSeconds is their whole, wall clock). On OpenCL the device's
    // own times from profiling events: what the queue spent on each command, not counting
    // the wait before it started. The native path fills hostConvertSeconds only.
    double hostSetUpSeconds = 0;      // the frame's set-up on the host up to the first command
    double deviceKernelSeconds = 0;   // the ray-casting kernel (with renderRgba8, its bytes too)
    double deviceReadBackSeconds = 0; // the image and the counters to the host
    double hostConvertSeconds = 0;    // float to 8-bit RGBA on the host (renderRgba8's default)
    int raysWide = 0, raysHigh = 0; // rays cast (image_scale < 1 casts fewer, then upsamples)
    uint64_t raysHit = 0;           // rays that entered the volume
    double meanSamplesPerRay = 0;   // over rays that hit the volume
    double skippedSegmentsPerRay = 0; // empty-space skipping, over rays that hit
    double earlyTerminatedFraction = 0;
    uint64_t raysTruncated = 0;     // rays that hit the per-ray sample bound
    double stepUsed = 0;            // voxels: quality.step, or the shortest step that keeps a ray
    bool stepRaised = false;        // across the volume within kMaxSamplesPerRay (then true)
};

// How often each kind of preprocessing has run: the evidence that it is lazy.
struct PreprocessCounts {
    int tfTables = 0;
    int mipLevels = 0;            // levels below 0 built
    int coefficientVolumes = 0;   // B-spline prefilter runs
    int brickGrids = 0;
    int brickClassifications = 0;
    int preintegrationTables = 0;
};

// A rectangle of a frame's ray grid (raysForScale of the frame's size and image_scale), x
// to the right and y down from the top-left ray: a frame rendered in pieces, so that a
// server can interleave other work between them.
struct RayWindow {
    int x = 0, y = 0, width = 0, height = 0;
};

// One frame as asked for: the scene's pieces, the frame's size and quality, and, when only
// part of it is wanted, the window of its ray grid to cast.
struct FrameRequest {
    FrameRequest() = default;
    FrameRequest(TransferFunction transferFunction_, Camera camera_, int width_, int height_, Quality quality_,
                 std::vector<ClipPlane> clipPlanes_, std::optional<RayWindow> window_ = std::nullopt)
        : transferFunction(std::move(transferFunction_)), camera(camera_), width(width_), height(height_),
          quality(std::move(quality_)), clipPlanes(std::move(clipPlanes_)), window(window_) {}

    TransferFunction transferFunction;
    Camera camera;
    int width = 0, height = 0;              // pixels
    Quality quality;
    std::vector<ClipPlane> clipPlanes;
    // The rays of this window exactly as the whole frame casts them, not upsampled (a window
    // of a frame with image_scale < 1 is a window of its smaller grid). None: the whole frame.
    std::optional<RayWindow> window;
};

// A frame as 8-bit premultiplied RGBA, rows top down: each channel round(clamp(v, 0, 1) · 255)
// (byteFromUnit), the float image's bytes as a JPEG of it over black takes them (RGBX).
struct Rgba8Image {
    int width = 0, height = 0;
    PixelVector<uint8_t> rgba;   // width × height × 4 (resize leaves it unfilled: model/image.hpp)
    const uint8_t *pixel(int x, int y) const { return rgba.data() + (size_t(y) * size_t(width) + size_t(x)) * 4; }
    uint8_t *pixel(int x, int y) { return rgba.data() + (size_t(y) * size_t(width) + size_t(x)) * 4; }
};

// clamp(v) to [0, 1], NaN to 0: comparisons, so that loops of it vectorise (std::fmin is a
// library call), and the same in OpenCL C (raycast.cl, rgba8FromUnit).
inline float clampUnit(float v) {
    const float c = v > 0.0f ? v : 0.0f;
    return c < 1.0f ? c : 1.0f;
}

// round(c · 255) for c in [0, 1] with lround's rounding (half away from zero): the product's
// whole part and its fraction are both exact in float, so comparing the fraction with one
// half rounds exactly as lround does, and loops of it vectorise. The device's conversion
// kernel does the same operations, each exact or correctly rounded in OpenCL C (a product,
// a conversion toward zero, a subtraction), so its bytes are these bit for bit.
inline uint8_t byteFromUnit(float c) {
    const float p = c * 255.0f;
    const int whole = int(p);
    return uint8_t(whole + int(p - float(whole) >= 0.5f));
}

// The host conversion: byteFromUnit(clampUnit(v)) for every channel, alpha included.
Rgba8Image rgba8FromImage(const Image &image);

class FrameRenderer {
  public:
    virtual ~FrameRenderer() = default;
    // The request's frame (width × height), or with request.window that window's rays
    // (window.width × window.height). Thread-safe; frames are rendered one at a time. Throws
    // std::invalid_argument for a request the scene contract forbids (validateFrameRequest).
    virtual Image render(const FrameRequest &request, RenderStats *stats = nullptr) = 0;
    // The same frame (or window) as 8-bit RGBA (Rgba8Image), for frames that are encoded
    // and nothing else: the bytes are rgba8FromImage(render(request)) exactly. This default
    // converts on the host; a back end on a device overrides it to convert there and read
    // back a quarter of the bytes.
    virtual Rgba8Image renderRgba8(const FrameRequest &request, RenderStats *stats = nullptr);
    // Whether a window costs only its own rays. Both back ends cast a window alone; a back
    // end that answers false (one that casts the whole grid for any window) makes the
    // server's scheduler render each pass whole.
    virtual bool rendersWindowsCheaply() const { return false; }
    // The rows a window's cost is rounded up to: a window of fewer rows costs about as much
    // (OpenCL work-groups, SIMD packets of rays several rows high). The server's scheduler
    // renders frames in bands of a multiple of it.
    virtual int bandRows() const { return 1; }
    // Which back end and device draws, for logs and reports: "cpu: …", "opencl: …".
    virtual std::string description() const = 0;
    virtual PreprocessCounts preprocessCounts() const = 0;
    virtual const Volume &volume() const = 0;

    // Samples a ray may take at most: shorter steps are raised to keep every ray within it
    // (RenderStats::stepRaised); rays past it, should any be, stop and are counted.
    static constexpr int kMaxSamplesPerRay = 1 << 20;
    static constexpr int kMaxClipPlanes = 6;
};

// The checks every back end makes before it allocates anything: camera, transfer function,
// image size, clip planes, mip level (levels 0 … maxMipLevel), image scale, crop box,
// orientation correction, and the window when there is one.
void validateFrameRequest(const Volume &volume, const FrameRequest &request, int maxMipLevel);

// Rays cast across and down for image_scale < 1, on the full image's plane.
int raysForScale(int pixels, double imageScale);

// Throws std::invalid_argument unless the window is non-empty and inside the frame's ray grid.
void validateRayWindow(const RayWindow &window, int width, int height, const Quality &quality);

} // namespace volcast
