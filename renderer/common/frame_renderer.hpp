#pragma once
// What every back end that draws frames offers (the OpenCL ray caster, the native CPU one),
// so that tools, tests and the server depend on this interface and not on a back end. Also
// the checks and the step choice every back end must make the same way.

#include "renderer/model/camera.hpp"
#include "renderer/model/image.hpp"
#include "renderer/model/scene.hpp"
#include "renderer/model/transfer_function.hpp"
#include "renderer/model/volume.hpp"

#include <cstdint>
#include <string>
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
    double emptyBrickFraction = 0;  // under the current transfer function
    double preintegrationSeconds = 0;
    int preintegrationNodes = 0;
    double preintegrationError = 0; // the table's own measured error
    double renderSeconds = 0;       // ray casting, read-back and upsampling
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

class FrameRenderer {
  public:
    virtual ~FrameRenderer() = default;
    // Thread-safe; frames are rendered one at a time. Throws std::invalid_argument for a
    // request the scene contract forbids, and names a quality switch the back end lacks.
    virtual Image render(const TransferFunction &tf, const Camera &camera, int width, int height,
                         const Quality &quality, const std::vector<ClipPlane> &clipPlanes,
                         RenderStats *stats = nullptr) = 0;
    // The rays of `window` exactly as render() casts them for this frame, not upsampled (a
    // window of a frame with image_scale < 1 is a window of its smaller grid). Throws
    // std::invalid_argument for a window outside the grid. This default casts the whole grid
    // and crops it; a back end that can cast the window's rays alone overrides it and
    // answers true to rendersWindowsCheaply().
    virtual Image renderWindow(const TransferFunction &tf, const Camera &camera, int width, int height,
                               const Quality &quality, const std::vector<ClipPlane> &clipPlanes,
                               const RayWindow &window, RenderStats *stats = nullptr);
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
// image size, clip planes, mip level (levels 0 … maxMipLevel), image scale, crop box.
void validateFrameRequest(const Volume &volume, const TransferFunction &tf, const Camera &camera, int width,
                          int height, const Quality &quality, const std::vector<ClipPlane> &clipPlanes,
                          int maxMipLevel);

// The switches a frame really uses: an intensity projection (MIP, MinIP) takes no
// pre-integration, shading, early termination or empty-space skipping (a projection has no
// opacity to terminate on, and a brick the transfer function makes transparent can still hold
// the ray's maximum), so they are turned off here, in one place for both back ends.
Quality compositedQuality(const Quality &quality);

// The crop box in level-0 index space: [−1/2 + min·n, −1/2 + max·n] per axis (scene.hpp).
void cropBoxInIndexSpace(const Volume &volume, const CropBox &crop, double lo[3], double hi[3]);

// The step in world units for quality.step (in smallest spacings): raised, with a warning,
// when a ray across the whole volume would take more than kMaxSamplesPerRay segments, so
// that rays are never cut off by the bound (which would drop the back of the volume) and a
// frame costs at most rays × kMaxSamplesPerRay samples. Fills stats.stepUsed/stepRaised.
double frameStep(const Volume &volume, const Quality &quality, RenderStats &stats);

// Rays cast across and down for image_scale < 1, on the full image's plane.
int raysForScale(int pixels, double imageScale);

// Throws std::invalid_argument unless the window is non-empty and inside the frame's ray grid.
void validateRayWindow(const RayWindow &window, int width, int height, const Quality &quality);

} // namespace volcast
