#pragma once
// The native CPU back end: the OpenCL kernel's ray casting, written for the CPU with Highway
// (SIMD packets of rays from small screen blocks, one ray per lane, a mask of lanes still
// marching, gathers for the trilinear taps and the table look-ups), threads over screen
// tiles, dispatched at run time to the widest instruction set the CPU has.
//
// Supported quality switches: step with opacity correction, jitter, boundary segments,
// clip planes, early termination, empty-space skipping, mip levels, image scale, shading,
// cubic B-spline, pre-integration: every switch of the scene contract.

#include "renderer/common/frame_renderer.hpp"
#include "renderer/common/frame_setup.hpp"
#include "renderer/common/minmax_bricks.hpp"
#include "renderer/common/mip_pyramid.hpp"
#include "renderer/common/narrow_samples.hpp"
#include "renderer/cpu/bricked_samples.hpp"

#include <atomic>
#include <map>
#include <memory>
#include <mutex>
#include <optional>

namespace volcast {

// How the native path holds an 8- or 16-bit level 0 (the only narrow level) for its trilinear
// samples. Slices is the default: the bricked copy takes 1.5× the store's bytes again, and
// its frames took 0.88–1.02× as long on a 200 MiB scan, 0.96–1.13× on a 4 MiB one
// (docs/cpu_renderer.md, "Sample layout").
enum class SampleLayout {
    Slices, // the volume's own store, slice after slice: no copy
    Bricks, // a bricked copy beside it (bricked_samples.hpp): fewer cache lines per sample
};

struct CpuRendererOptions {
    int threads = 0;   // 0: one per core
    int brickSize = 8; // level voxels per min-max brick edge
    SampleLayout layout = SampleLayout::Slices;
};

class CpuRenderer : public FrameRenderer {
  public:
    explicit CpuRenderer(std::shared_ptr<const Volume> volume, CpuRendererOptions options = {});
    // Convenience for tools and tests: keeps a copy.
    explicit CpuRenderer(const Volume &volume, CpuRendererOptions options = {});

    // A window casts only its own rays (the tiles over it), each exactly as the whole frame does.
    Image render(const FrameRequest &request, RenderStats *stats = nullptr) override;
    bool rendersWindowsCheaply() const override { return true; }
    int bandRows() const override;   // the ray packet's height
    std::string description() const override;
    PreprocessCounts preprocessCounts() const override;
    const Volume &volume() const override { return *volume_; }

    // Bytes of volume-sized data the renderer holds now, beyond the volume's own samples: mip
    // levels, B-spline coefficients, brick grids. Trilinear frames sample every level where
    // it lies, with no copy.
    // (The transfer-function and pre-integration tables, at most ~17 MiB per renderer
    // whatever the volume, are not counted.) Never waits for a frame.
    uint64_t memoryBytes() const { return heldBytes_.load(); }
    // What memoryBytes() reaches at most for a volume of `dims`: every mip level sampled,
    // trilinear and cubic, with empty-space skipping. The server's memory budget counts it.
    // `level0Bytes`: the volume's bytes per sample (Volume::narrow.bytes). Trilinear frames
    // copy no level but a narrow level 0 into bricks (SampleLayout::Bricks), or into floats
    // where its byte offsets pass int32.
    static uint64_t plannedBytes(Vec3i dims, const CpuRendererOptions &options = {}, int level0Bytes = 4);

    // What description() says for a renderer with these options, before any volume exists
    // (the server's start-up log and hello).
    static std::string describe(const CpuRendererOptions &options = {});

  private:
    // The data a frame samples: a mip level's voxels, or its B-spline coefficients.
    struct DataSet {
        Vec3i dims;
        bool cubic = false;
        // Trilinear: the level's samples where they lie (the volume's or the pyramid's), float
        // or narrow. A narrow store too large for int32 byte offsets is widened into `widened`.
        const float *floats = nullptr;
        const unsigned char *narrow = nullptr;
        NarrowWidth width;
        std::vector<float> widened;
        std::optional<cpu::BrickedSamples> bricked; // the narrow level bricked (SampleLayout::Bricks)
        std::vector<float> padded; // cubic: coefficients, mirrored 1 before and 2 after each axis
        std::optional<MinMaxBricks> bricks;
        BrickClassification classification;
        std::optional<BrickGradients> gradients; // the adaptive step's, on first need
        AdaptiveStepTable adaptive;
    };

    DataSet &dataSet(int level, bool cubic, RenderStats &st);
    static bool bricksFit(Vec3i dims, const CpuRendererOptions &options, int bytes);
    void classify(DataSet &data, int level, const TransferFunction &tf, RenderStats &st);
    // The bricks' min-max grid over the data set, built on first need.
    const MinMaxBricks &bricks(DataSet &data, int level, RenderStats &st);
    // The adaptive step's per-brick steps for this frame (gradients built on first need).
    void adaptSteps(DataSet &data, int level, const TransferFunction &tf, const FrameSetup &setup, RenderStats &st);

    std::shared_ptr<const Volume> volume_;
    CpuRendererOptions options_;
    int threads_ = 1;
    MipPyramid pyramid_;
    std::mutex mutex_;
    std::map<std::pair<int, bool>, DataSet> dataSets_; // by (mip level, cubic)
    FrameTables tables_;
    PreprocessCounter counts_;
    std::atomic<uint64_t> heldBytes_{0};
};

} // namespace volcast
