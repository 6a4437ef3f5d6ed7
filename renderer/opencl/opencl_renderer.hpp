#pragma once
// The fast path: ray casting in OpenCL with the paper's remedies as switches. Each scene
// builds (or reuses) a program with only the features it uses, and preprocessing happens on
// first need only: B-spline coefficients for cubic interpolation, mip levels below 0, the
// min-max brick grid for empty-space skipping (re-classified, not rebuilt, when the transfer
// function changes), the pre-integration table (rebuilt when the transfer function or the
// step changes). Everything is cached for the renderer's life.

#include "renderer/common/frame_renderer.hpp"
#include "renderer/common/frame_setup.hpp"
#include "renderer/model/image.hpp"
#include "renderer/common/minmax_bricks.hpp"
#include "renderer/common/mip_pyramid.hpp"
#include "renderer/common/narrow_samples.hpp"
#include "renderer/opencl/opencl_context.hpp"
#include "renderer/opencl/kernels/raycast_shared.h"
#include "renderer/model/scene.hpp"
#include "renderer/model/volume.hpp"

#include <chrono>
#include <map>
#include <memory>
#include <mutex>
#include <optional>
#include <string>

namespace volcast {

// Where the tricubic B-spline reads its 64 coefficients from: a buffer, tap by tap, or a
// 3-D image, as 8 trilinear fetches (Sigg and Hadwiger). The fetches are filtered by the
// device's texture unit, whose weights OpenCL leaves to the device: NVIDIA's hold 8
// fractional bits, and the image then differs from the spline by up to 0.037 in opacity on
// the stability cases (docs/gpu.md). Auto is therefore the buffer, on every device, unless
// VOLCAST_CUBIC_FETCH says `image` (for measuring that difference on a device).
enum class CubicFetch { Auto, Taps64, Trilinear8 };

// Where renderRgba8 turns floats into bytes. On a GPU the ray caster writes the bytes and a
// quarter of them cross the bus; on a CPU device (PoCL) the read-back is a memcpy, and the
// host's vectorised loop beat the separate conversion kernel this path once had (0.6–1
// against 2–3 ms at 512²); the ray caster writing bytes there is not measured (docs/gpu.md).
enum class Rgba8Conversion { Auto, Device, Host };

// How a frame's image and counters come back. Direct: the image read straight into the
// frame's memory, then the counters' read, blocking. On an H100 the counters' read waited
// ~0.2 ms behind the driver's copy of the image from its pinned staging memory into the
// frame's pageable memory (docs/gpu.md), so two remedies are built for a card to decide
// between: CountersFirst (the counters' read right after the kernel, the image's last and
// blocking) and Pinned (the image read into host memory the device can reach directly,
// CL_MEM_ALLOC_HOST_PTR mapped once, then copied into the frame on the host). Auto is Direct
// unless VOLCAST_OPENCL_READBACK says `counters-first` or `pinned`.
enum class ReadBack { Auto, Direct, CountersFirst, Pinned };

struct OpenClRendererOptions {
    CubicFetch cubicFetch = CubicFetch::Auto;
    Rgba8Conversion rgba8Conversion = Rgba8Conversion::Auto;   // Auto: Device on a GPU, else Host
    ReadBack readBack = ReadBack::Auto;
    int brickSize = 8; // level voxels per min-max brick edge
};

class OpenClRenderer : public FrameRenderer {
  public:
    // Shares the context (several renderers may draw on one device) and the volume: mip
    // levels, bricks and coefficients are computed from it on demand.
    OpenClRenderer(std::shared_ptr<OpenClContext> cl, std::shared_ptr<const Volume> volume,
                   OpenClRendererOptions options = {});
    // Convenience for tools and tests: keeps a copy of the volume.
    OpenClRenderer(std::shared_ptr<OpenClContext> cl, const Volume &volume, OpenClRendererOptions options = {});
    ~OpenClRenderer() override;

    // Thread-safe; frames are rendered one at a time. A window casts only its own rays.
    Image render(const FrameRequest &request, RenderStats *stats = nullptr) override;
    // Converted to 8 bits on the device (the ray caster writes them), a quarter of the bytes
    // read back (Rgba8Conversion); a whole frame with image_scale < 1 is upsampled and
    // converted on the host.
    Rgba8Image renderRgba8(const FrameRequest &request, RenderStats *stats = nullptr) override;
    bool rendersWindowsCheaply() const override { return true; }
    int bandRows() const override;   // the work-group's height
    std::string description() const override;

    // The -D options a scene's program is built with: only the features it uses.
    // `voxelBytes`: how the sampled data holds a sample, 4 (float) or 1 or 2 (narrow).
    std::string buildOptions(const Quality &quality, bool hasClipPlanes, int voxelBytes = 4) const;
    PreprocessCounts preprocessCounts() const override;
    const Volume &volume() const override { return *volume_; }

    using Clock = std::chrono::steady_clock;

  private:
    // The data a frame samples: a mip level's voxels, or its B-spline coefficients.
    struct DataSet {
        int level = 0;
        bool cubic = false;
        Vec3i dims;
        cl::Buffer buffer;           // voxels, or coefficients padded for the 64-tap path
        NarrowWidth width;           // trilinear voxels of an 8- or 16-bit scan: narrow in `buffer`
        cl::Image3D image;           // padded coefficients for the 8-fetch path
        std::optional<MinMaxBricks> bricks;
        BrickClassification classification;
        cl::Buffer brickReach;             // classification.reachFor on the device; null until a frame walks it
        std::optional<BrickGradients> gradients; // the adaptive step's, on first need
        AdaptiveStepTable adaptive;
        cl::Buffer brickStep;              // adaptive.steps.step on the device
    };

    bool cubicFromImage() const;
    ReadBack readBack() const;
    // The pinned host memory of ReadBack::Pinned, at least `bytes`, mapped for the renderer's
    // life (grown, remapped, as the output buffers grow).
    void *pinnedHost(size_t bytes);
    DataSet &dataSet(int level, bool cubic, RenderStats &st);
    // Classifies the bricks for `tf`, and for a frame whose walk reads it (not the adaptive
    // step's) uploads their reach.
    void classify(DataSet &data, const Quality &quality, const TransferFunction &tf, RenderStats &st);
    // The bricks' min-max grid over the data set, built on first need.
    const MinMaxBricks &bricks(DataSet &data, RenderStats &st);
    // The adaptive step's per-brick steps for this frame, uploaded when they change.
    void adaptSteps(DataSet &data, const TransferFunction &tf, const FrameSetup &setup, RenderStats &st);
    std::vector<float> readBackCoefficients(const DataSet &data);
    // Casts setup.cast's rays on the device and reads them into `floats` (float RGBA) or,
    // converted there, into `bytes` (Rgba8Image's); fills st's device times. Returns when the
    // first command was queued (start: when the frame's call began). Under mutex_.
    Clock::time_point castRays(const FrameRequest &request, const FrameSetup &setup, RenderStats &st,
                               Clock::time_point start, float *floats, uint8_t *bytes);

    std::shared_ptr<OpenClContext> cl_;
    std::shared_ptr<const Volume> volume_;
    OpenClRendererOptions options_;
    MipPyramid pyramid_;
    std::mutex mutex_;
    std::map<std::pair<int, bool>, DataSet> dataSets_; // by (mip level, cubic)
    FrameTables tables_;              // on the host; uploaded into the buffers below when rebuilt
    cl::Buffer tfTable_;
    cl::Buffer preRgba_, preNodes_, preLocator_;
    PreprocessCounter counts_;

    // What every frame uses and that does not change between frames, kept: the kernels of
    // each program (by build options) with the memory objects set as their arguments, the
    // counters and the output buffers (grown to the largest window).
    struct FrameKernels {
        cl::Kernel raycast;
        std::vector<cl::Memory> raycastArgs;   // by argument index
    };
    std::map<std::string, FrameKernels> kernels_;
    cl::Buffer counters_, floatOut_, byteOut_;
    size_t floatOutBytes_ = 0, byteOutBytes_ = 0;
    cl::Buffer pinned_;
    void *pinnedHost_ = nullptr;
    size_t pinnedBytes_ = 0;
    cl_uint hostCounts_[VC_STAT_COUNT] = {}; // the counters' running totals as last read
};

} // namespace volcast
