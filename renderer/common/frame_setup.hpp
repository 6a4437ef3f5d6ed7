#pragma once
// The set-up of one frame, made once for both back ends: the request checked, the switches
// the frame really uses, the step, the camera's ray frame, where the volume lies
// (indexFromWorld), the clip planes and crop box in index space, the level and brick grid
// sampled, the rays cast. A back end only translates it to its parameter struct
// (cpu::FrameParams, RayCastParams) and launches, so both cast the same rays from the same
// numbers. The steps, in order, are setUpFrame's.

#include "renderer/common/adaptive_step.hpp"
#include "renderer/common/frame_renderer.hpp"
#include "renderer/common/minmax_bricks.hpp"
#include "renderer/common/preintegration.hpp"
#include "renderer/common/tf_table.hpp"
#include "renderer/model/math.hpp"

#include <cstdint>
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <vector>

namespace volcast {

// The switches a frame uses, as the ray march branches on them: cpu::FrameParams::features,
// and the OpenCL program's -D macros of the same names (featureNames).
struct FrameFeatures {
    bool jitter = false;
    bool boundarySegment = true;
    bool earlyTermination = false;
    bool clipPlanes = false;
    bool emptySpaceSkipping = false;
    bool shading = false;
    bool cubic = false;             // prefiltered tricubic B-spline
    bool preintegrated = false;
    bool adaptiveStep = false;      // per-brick segment lengths (adaptive_step.hpp)
    int intensityProjection = 0;    // +1 maximum (MIP), −1 minimum (MinIP), 0 emission–absorption
};

struct FrameSetup {
    Quality quality;                // compositedQuality(request.quality): the switches in use
    FrameFeatures use;              // the same, as the march branches on them
    std::string features;           // featureNames(use): "JITTER CLIP_PLANES …"
    RenderStats stats;              // what the set-up knows already: stepUsed, stepRaised, raysWide, raysHigh

    // The rays: the frame's grid (image_scale < 1 casts fewer, then upsamples), the part of it
    // cast (the request's window, or all of it), and whether the cast grid is resized to the
    // frame's pixels afterwards (a whole frame whose grid is not its size).
    int raysWide = 0, raysHigh = 0;
    RayWindow cast;
    bool upsample = false;

    // The camera's ray frame exactly as RayGenerator builds it for the frame's pixels.
    Vec3d eye, forward;
    Vec3d right, up;                // image axes scaled by the view's half-width and half-height
    bool orthographic = false;

    // Where the volume lies (after the frame's orientation correction): rows of the affine
    // map world -> level-0 index space, linear part and translation.
    double indexFromWorld[3][4] = {};
    // (n, w) per plane: keeps dot(n, x) + w >= 0, world.
    double clipPlanes[FrameRenderer::kMaxClipPlanes][4] = {};
    int clipPlaneCount = 0;
    // The box rays are clipped to, level-0 index space: [−1/2, n − 1/2] per axis or the crop box.
    Vec3d boxLo, boxHi;

    // The data sampled: level 0's and the mip level's samples per axis, and the min-max
    // brick grid over the level (empty-space skipping and the adaptive step; 0 without them).
    Vec3i dims, levelDims;
    double levelScale = 1;          // 2^-mip_level: level index = (index + 1/2)·scale − 1/2
    int brickSize = 0;
    Vec3i bricks{0, 0, 0};

    // The march.
    double step = 0;                // world units (frameStep); the longest with the adaptive step
    double shortestStep = 0;        // world units: the adaptive step's shortest, else step
    Vec3d levelVoxel;               // world length of a level voxel along each axis
    double opacityUnit = 0;         // world units: the transfer function's, else the smallest spacing
    double terminationDepth = 0;    // optical depth of the early-termination opacity; ∞ without it
    uint32_t seed = 0;              // the jitter's, folded to 32 bits

    // The tables: the 1-D transfer-function table always (without pre-integration every
    // segment reads it, with it the partial segments too opaque for the table's alpha), the
    // pre-integration table when quality.preintegrated, over [valueLo, valueHi].
    double valueLo = 0, valueHi = 0;
};

// Checks the request (validateFrameRequest) and computes the frame's set-up. `maxMipLevel`:
// the coarsest level the back end's pyramid has; `brickSize`: its bricks' edge in level voxels.
// Logs a warning when the step is raised (frameStep).
FrameSetup setUpFrame(const Volume &volume, const FrameRequest &request, int maxMipLevel, int brickSize);

// The host tables frames read, kept between frames and rebuilt only when what they depend on
// changes: the 1-D transfer-function table (on the transfer function) and the pre-integration
// table (on it, the step and the opacity unit; built only for frames that use it). A back end
// uploads or points at them. Not thread-safe: a back end updates them under its frame lock.
class FrameTables {
  public:
    struct Rebuilt {
        bool tfTable = false, preintegration = false;
    };
    // Brings the tables `setup` uses up to date for `tf`; fills the tables' fields of `st`.
    Rebuilt update(const TransferFunction &tf, const FrameSetup &setup, RenderStats &st);
    const TfTable &tfTable() const { return tfTable_; }
    // Only after an update for a pre-integrated frame.
    const PreintegrationTable &preintegration() const { return *preintegration_; }

  private:
    std::optional<TransferFunction> tfTableFor_;
    TfTable tfTable_;
    TransferFunction preintegrationFor_;
    std::unique_ptr<PreintegrationTable> preintegration_;
};

// A level's min-max bricks classified for a transfer function (empty-space skipping), kept
// until the transfer function changes.
struct BrickClassification {
    std::optional<TransferFunction> classifiedFor;
    std::vector<uint8_t> visible; // per brick: 1 where the transfer function makes some value visible
    double emptyFraction = 0;
    // Classifies `bricks` for `tf` unless they already are; true when it did (a back end then
    // drops what it made of the last classification). Fills st.emptyBrickFraction and, when
    // it classifies, st.brickClassifySeconds.
    bool update(const MinMaxBricks &bricks, const TransferFunction &tf, RenderStats &st);
    // Per brick emptyReach(visible), 0 where visible: what the brick walks read when they
    // skip (the adaptive step's walk reads its steps instead). Made on first need after each
    // classification, its time added to st.brickClassifySeconds.
    const std::vector<int32_t> &reachFor(const MinMaxBricks &bricks, RenderStats &st);

  private:
    std::vector<int32_t> reach_; // empty: not made for this classification yet
};

// A level's adaptive steps (adaptive_step.hpp), kept until the transfer function, the steps,
// the opacity unit or skipping change.
struct AdaptiveStepTable {
    std::optional<TransferFunction> stepsFor;
    AdaptiveStepInput input;
    AdaptiveSteps steps;
    // Brings the steps up to date for `tf` (tabulated in `table`) and the frame; true when it
    // recomputed them (a back end then uploads `steps.step`). `visible`: the bricks'
    // classification when the frame skips empty space. Fills st.adaptiveMeanStep and, when
    // it recomputes, st.adaptiveStepSeconds.
    bool update(const MinMaxBricks &bricks, const BrickGradients &gradients, const TransferFunction &tf,
                const TfTable &table, const FrameSetup &setup, const std::vector<uint8_t> *visible, RenderStats &st);
};

// PreprocessCounts that a frame adds to while another thread may read them (preprocessCounts()).
class PreprocessCounter {
  public:
    PreprocessCounts get() const {
        std::lock_guard lock(mutex_);
        return counts_;
    }
    void add(int PreprocessCounts::*kind, int n = 1) {
        std::lock_guard lock(mutex_);
        counts_.*kind += n;
    }

  private:
    mutable std::mutex mutex_;
    PreprocessCounts counts_;
};

// The switches a frame really uses: an intensity projection (MIP, MinIP) takes no
// pre-integration, shading, early termination, empty-space skipping or adaptive step (a
// projection has no opacity to terminate on or to estimate an error from, and a brick the
// transfer function makes transparent can still hold the ray's maximum), so they are turned
// off here, in one place for both back ends.
Quality compositedQuality(const Quality &quality);

// The step in world units for quality.step (in smallest spacings): raised, with a warning,
// when a ray across the whole volume would take more than kMaxSamplesPerRay segments (with
// the adaptive step: of its shortest, step / kAdaptiveStepRange), so that rays are never cut
// off by the bound (which would drop the back of the volume) and a frame costs at most
// rays × kMaxSamplesPerRay samples. With the adaptive step, also lowered to a brick's edge
// (`brickEdge`, world units), which a segment may not be longer than (adaptive_step.hpp).
// Fills stats.stepUsed/stepRaised.
double frameStep(const Volume &volume, const Quality &quality, RenderStats &stats, double brickEdge = 0);

// The switches of `quality` (as composited) as the march branches on them.
FrameFeatures frameFeatures(const Quality &quality, bool hasClipPlanes);

// The switches in use by the kernel's macro names, space-separated, in one order: JITTER
// BOUNDARY_SEGMENT EARLY_TERMINATION CLIP_PLANES CUBIC PREINTEGRATED EMPTY_SPACE_SKIPPING
// SHADING ADAPTIVE_STEP COMPOSITING_MAX COMPOSITING_MIN.
std::string featureNames(const FrameFeatures &use);
inline std::string featureNames(const Quality &quality, bool hasClipPlanes) {
    return featureNames(frameFeatures(quality, hasClipPlanes));
}

// The parameter fields both back ends' structs name alike (cpu::FrameParams in C++,
// RayCastParams shared with OpenCL C), filled from the set-up in one place. Vectors are
// float[3] there and cl_float4 here (its lanes in .s); the fourth lane of a point or
// direction is 0.
namespace frame_params {
inline void set(float (&out)[3], const Vec3d &v) {
    out[0] = float(v.x);
    out[1] = float(v.y);
    out[2] = float(v.z);
}
inline void set(float (&out)[4], const double (&v)[4]) {
    for (int i = 0; i < 4; ++i) out[i] = float(v[i]);
}
template <typename Float4>
    requires requires(Float4 f) { f.s[3] = 0.0f; }
void set(Float4 &out, const Vec3d &v) {
    out.s[0] = float(v.x);
    out.s[1] = float(v.y);
    out.s[2] = float(v.z);
    out.s[3] = 0.0f;
}
template <typename Float4>
    requires requires(Float4 f) { f.s[3] = 0.0f; }
void set(Float4 &out, const double (&v)[4]) {
    for (int i = 0; i < 4; ++i) out.s[i] = float(v[i]);
}
} // namespace frame_params

template <typename Params>
void fillCommonParams(const FrameSetup &s, Params &p) {
    frame_params::set(p.eye, s.eye);
    frame_params::set(p.forward, s.forward);
    frame_params::set(p.right, s.right);
    frame_params::set(p.up, s.up);
    p.orthographic = s.orthographic;
    for (int r = 0; r < 3; ++r) frame_params::set(p.indexFromWorld[r], s.indexFromWorld[r]);
    for (int c = 0; c < s.clipPlaneCount; ++c) frame_params::set(p.clipPlanes[c], s.clipPlanes[c]);
    p.clipPlaneCount = s.clipPlaneCount;
    frame_params::set(p.boxLo, s.boxLo);
    frame_params::set(p.boxHi, s.boxHi);
    for (int a = 0; a < 3; ++a) {
        p.dims[a] = int(s.dims[a]);
        p.levelDims[a] = int(s.levelDims[a]);
        p.bricks[a] = int(s.bricks[a]);
    }
    p.levelScale = float(s.levelScale);
    p.brickSize = s.brickSize;
    p.width = s.raysWide;
    p.height = s.raysHigh;
    p.inverseWidth = float(1.0 / s.raysWide);
    p.inverseHeight = float(1.0 / s.raysHigh);
    p.maxSamples = FrameRenderer::kMaxSamplesPerRay;
    p.step = float(s.step);
    p.opacityUnit = float(s.opacityUnit);
    p.terminationDepth = float(s.terminationDepth);
    p.seed = s.seed;
}

} // namespace volcast
