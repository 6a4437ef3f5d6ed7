#include "renderer/common/frame_setup.hpp"

#include "renderer/common/mip_pyramid.hpp"
#include "renderer/model/camera.hpp"
#include "renderer/model/orientation_correction.hpp"

#include <spdlog/spdlog.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <limits>

namespace volcast {

Quality compositedQuality(const Quality &quality) {
    Quality q = quality;
    if (q.compositing != Compositing::EmissionAbsorption) {
        q.preintegrated = false;
        q.shading = false;
        q.earlyTermination = 1;
        q.emptySpaceSkipping = false;
        q.adaptiveStep = false;
    }
    return q;
}

double frameStep(const Volume &volume, const Quality &quality, RenderStats &stats, double brickEdge) {
    const double smallest = minComponent(volume.spacing);
    double step = quality.step * smallest;
    if (quality.adaptiveStep && brickEdge > 0 && step > brickEdge) step = brickEdge;
    // The 16 spare segments cover a jittered first segment and rounding (the adaptive step
    // re-jitters after each skip, at most one segment more per brick crossed; the range's
    // factor leaves room for them).
    const double range = quality.adaptiveStep ? kAdaptiveStepRange * 2 : 1;
    const double shortestStep = length(volume.extent()) / (FrameRenderer::kMaxSamplesPerRay - 16) * range;
    if (step < shortestStep) {
        spdlog::warn("{}: quality.step {:g} voxels would take more than {} samples per ray across the volume; "
                     "using {:g} voxels",
                     volume.name, quality.step, FrameRenderer::kMaxSamplesPerRay, shortestStep / smallest);
        step = shortestStep;
        stats.stepRaised = true;
    }
    stats.stepUsed = step / smallest;
    return step;
}

FrameFeatures frameFeatures(const Quality &q, bool hasClipPlanes) {
    FrameFeatures f;
    f.jitter = q.jitter;
    f.boundarySegment = q.boundarySegment;
    f.earlyTermination = q.earlyTermination < 1;
    f.clipPlanes = hasClipPlanes;
    f.emptySpaceSkipping = q.emptySpaceSkipping;
    f.shading = q.shading;
    f.cubic = q.interpolation == Interpolation::Cubic;
    f.preintegrated = q.preintegrated;
    f.adaptiveStep = q.adaptiveStep;
    f.intensityProjection = q.compositing == Compositing::Maximum ? 1 : q.compositing == Compositing::Minimum ? -1 : 0;
    return f;
}

std::string featureNames(const FrameFeatures &f) {
    std::string o;
    if (f.jitter) o += " JITTER";
    if (f.boundarySegment) o += " BOUNDARY_SEGMENT";
    if (f.earlyTermination) o += " EARLY_TERMINATION";
    if (f.clipPlanes) o += " CLIP_PLANES";
    if (f.cubic) o += " CUBIC";
    if (f.preintegrated) o += " PREINTEGRATED";
    if (f.emptySpaceSkipping) o += " EMPTY_SPACE_SKIPPING";
    if (f.shading) o += " SHADING";
    if (f.adaptiveStep) o += " ADAPTIVE_STEP";
    if (f.intensityProjection > 0) o += " COMPOSITING_MAX";
    if (f.intensityProjection < 0) o += " COMPOSITING_MIN";
    return o.empty() ? o : o.substr(1);
}

FrameSetup setUpFrame(const Volume &volume, const FrameRequest &request, int maxMipLevel, int brickSize) {
    validateFrameRequest(volume, request, maxMipLevel);
    FrameSetup s;
    // The switches the frame uses, by name (the OpenCL program's feature set, the stats).
    s.quality = compositedQuality(request.quality);
    const Quality &q = s.quality;
    s.use = frameFeatures(q, !request.clipPlanes.empty());
    s.features = featureNames(s.use);

    // The ray grid, the window of it cast, and whether the grid is upsampled to the frame.
    s.raysWide = raysForScale(request.width, q.imageScale);
    s.raysHigh = raysForScale(request.height, q.imageScale);
    s.stats.raysWide = s.raysWide;
    s.stats.raysHigh = s.raysHigh;
    s.cast = request.window ? *request.window : RayWindow{0, 0, s.raysWide, s.raysHigh};
    s.upsample = !request.window && (s.raysWide != request.width || s.raysHigh != request.height);

    // The camera's ray frame for the frame's pixels (rays of a smaller grid span the same plane).
    const RayGenerator rays(request.camera, request.width, request.height);
    s.eye = request.camera.eye;
    s.forward = rays.forward;
    s.right = rays.right * rays.halfWidth();
    s.up = rays.up * rays.halfHeight();
    s.orthographic = request.camera.projection == Projection::Orthographic;

    // indexFromWorld(x) = Dᵀ(x − origin) / s, as rows (linear part, translation), with the
    // volume where this frame's orientation correction puts it (orientation_correction.hpp).
    const VolumePlacement placed = correctedPlacement(volume, q.orientationCorrection);
    const Mat3d dt = placed.direction.transposed();
    for (int r = 0; r < 3; ++r) {
        const Vec3d row{dt(r, 0) / volume.spacing[r], dt(r, 1) / volume.spacing[r], dt(r, 2) / volume.spacing[r]};
        s.indexFromWorld[r][0] = row.x;
        s.indexFromWorld[r][1] = row.y;
        s.indexFromWorld[r][2] = row.z;
        s.indexFromWorld[r][3] = -dot(row, placed.origin);
    }
    // Clip planes as (n, −n·p): dot(n, x) + w >= 0 keeps the half-space n points into.
    s.clipPlaneCount = int(request.clipPlanes.size());
    for (int c = 0; c < s.clipPlaneCount; ++c) {
        const ClipPlane &plane = request.clipPlanes[size_t(c)];
        s.clipPlanes[c][0] = plane.normal.x;
        s.clipPlanes[c][1] = plane.normal.y;
        s.clipPlanes[c][2] = plane.normal.z;
        s.clipPlanes[c][3] = -dot(plane.normal, plane.point);
    }
    // The crop box in level-0 index space: [−1/2 + min·n, −1/2 + max·n] per axis (scene.hpp).
    for (int a = 0; a < 3; ++a) {
        const double n = double(volume.dims[a]);
        s.boxLo[a] = -0.5 + q.crop.min[a] * n;
        s.boxHi[a] = -0.5 + q.crop.max[a] * n;
    }

    // The level sampled and, for empty-space skipping, the bricks over it (minmax_bricks.hpp).
    s.dims = volume.dims;
    s.levelDims = mipLevelDims(volume.dims, q.mipLevel);
    s.levelScale = std::ldexp(1.0, -q.mipLevel);
    s.brickSize = brickSize;
    if (q.emptySpaceSkipping || q.adaptiveStep)
        for (int a = 0; a < 3; ++a) s.bricks[a] = (s.levelDims[a] + brickSize - 1) / brickSize;
    for (int a = 0; a < 3; ++a) s.levelVoxel[a] = volume.spacing[a] / s.levelScale;

    // The march: the step (raised if rays would be too long; with the adaptive step at most a
    // brick's edge along the axis of the smallest level voxel), the opacity unit, early
    // termination as an optical depth (compared without an exp per sample), the jitter's seed.
    s.step = frameStep(volume, q, s.stats, double(brickSize) * minComponent(s.levelVoxel));
    s.shortestStep = q.adaptiveStep ? s.step / kAdaptiveStepRange : s.step;
    s.opacityUnit = request.transferFunction.opacityUnit ? *request.transferFunction.opacityUnit
                                                         : minComponent(volume.spacing);
    s.terminationDepth =
        q.earlyTermination < 1 ? -std::log1p(-q.earlyTermination) : std::numeric_limits<double>::infinity();
    s.seed = uint32_t(q.seed ^ (q.seed >> 32));

    // The pre-integration table's value range. A constant volume has no range to tabulate;
    // any range starting at its value serves, with that value exactly on the first node.
    s.valueLo = volume.range.min;
    s.valueHi = volume.range.max > s.valueLo ? double(volume.range.max)
                                             : s.valueLo + std::max(1.0, std::fabs(s.valueLo)) * 1e-3;
    return s;
}

bool BrickClassification::update(const MinMaxBricks &bricks, const TransferFunction &tf, RenderStats &st) {
    if (classifiedFor && *classifiedFor == tf) {
        st.emptyBrickFraction = emptyFraction;
        return false;
    }
    const auto t = std::chrono::steady_clock::now();
    visible = classifyBricks(bricks, tf);
    reach_.clear();
    const size_t empty = size_t(std::count(visible.begin(), visible.end(), uint8_t(0)));
    emptyFraction = visible.empty() ? 0 : double(empty) / double(visible.size());
    classifiedFor = tf;
    st.brickClassifySeconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t).count();
    st.emptyBrickFraction = emptyFraction;
    return true;
}

const std::vector<int32_t> &BrickClassification::reachFor(const MinMaxBricks &bricks, RenderStats &st) {
    if (reach_.empty()) {
        const auto t = std::chrono::steady_clock::now();
        reach_ = emptyReach(visible, bricks.bricks);
        st.brickClassifySeconds += std::chrono::duration<double>(std::chrono::steady_clock::now() - t).count();
    }
    return reach_;
}

bool AdaptiveStepTable::update(const MinMaxBricks &bricks, const BrickGradients &gradients, const TransferFunction &tf,
                               const TfTable &table, const FrameSetup &setup, const std::vector<uint8_t> *visible,
                               RenderStats &st) {
    AdaptiveStepInput in;
    in.longest = setup.step;
    in.shortest = setup.shortestStep;
    in.opacityUnit = setup.opacityUnit;
    in.levelVoxel = setup.levelVoxel;
    in.skipEmpty = setup.use.emptySpaceSkipping;
    const double voxel = minComponent(setup.levelVoxel) * setup.levelScale; // the smallest spacing
    const bool same = stepsFor && *stepsFor == tf && input.longest == in.longest && input.shortest == in.shortest &&
                      input.opacityUnit == in.opacityUnit && input.levelVoxel == in.levelVoxel &&
                      input.skipEmpty == in.skipEmpty;
    if (!same) {
        const auto t = std::chrono::steady_clock::now();
        steps = adaptiveBrickSteps(bricks, gradients, table, in, in.skipEmpty ? visible : nullptr);
        stepsFor = tf;
        input = in;
        st.adaptiveStepSeconds += std::chrono::duration<double>(std::chrono::steady_clock::now() - t).count();
    }
    st.adaptiveMeanStep = steps.meanStep / voxel;
    return !same;
}

FrameTables::Rebuilt FrameTables::update(const TransferFunction &tf, const FrameSetup &setup, RenderStats &st) {
    using Clock = std::chrono::steady_clock;
    const auto secondsSince = [](Clock::time_point t) { return std::chrono::duration<double>(Clock::now() - t).count(); };
    Rebuilt rebuilt;
    if (!tfTableFor_ || !(*tfTableFor_ == tf)) {
        const auto t = Clock::now();
        tfTable_ = buildTfTable(tf);
        tfTableFor_ = tf;
        st.tfTableSeconds = secondsSince(t);
        rebuilt.tfTable = true;
    }
    if (!setup.quality.preintegrated) {
        st.tfTableEntries = tfTable_.entries();
        st.tfTableError = tfTable_.maxError;
        return rebuilt;
    }
    // Rebuilt when the transfer function or the step changes (the table holds whole steps).
    if (!preintegration_ || !(preintegrationFor_ == tf) || preintegration_->step != setup.step ||
        preintegration_->opacityUnit != setup.opacityUnit) {
        const auto t = Clock::now();
        preintegration_ = std::make_unique<PreintegrationTable>(
            buildPreintegrationTable(tf, setup.step, setup.opacityUnit, setup.valueLo, setup.valueHi));
        preintegrationFor_ = tf;
        st.preintegrationSeconds = secondsSince(t);
        rebuilt.preintegration = true;
    }
    st.preintegrationNodes = preintegration_->nodeCount();
    st.preintegrationError = preintegration_->maxError;
    return rebuilt;
}

} // namespace volcast
