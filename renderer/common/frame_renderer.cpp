#include "renderer/common/frame_renderer.hpp"

#include <spdlog/spdlog.h>

#include <algorithm>
#include <cmath>
#include <stdexcept>

namespace volcast {

void validateFrameRequest(const Volume &volume, const TransferFunction &tf, const Camera &camera, int width,
                          int height, const Quality &quality, const std::vector<ClipPlane> &clipPlanes,
                          int maxMipLevel) {
    camera.validate();
    tf.validate();
    validateImageSize(width, height); // before anything is allocated
    if (clipPlanes.size() > size_t(FrameRenderer::kMaxClipPlanes))
        throw std::invalid_argument("clip_planes: at most " + std::to_string(FrameRenderer::kMaxClipPlanes) +
                                    " are supported");
    for (size_t c = 0; c < clipPlanes.size(); ++c)
        if (!(length(clipPlanes[c].normal) > 0))
            throw std::invalid_argument("clip_planes[" + std::to_string(c) + "].normal: zero length");
    if (quality.mipLevel < 0 || quality.mipLevel > maxMipLevel)
        throw std::invalid_argument("quality.mip_level: " + std::to_string(quality.mipLevel) + " is outside 0…" +
                                    std::to_string(maxMipLevel) + " for volume " + volume.name);
    if (!(quality.imageScale > 0 && quality.imageScale <= 1))
        throw std::invalid_argument("quality.image_scale: must be in (0, 1]");
    for (int a = 0; a < 3; ++a)
        if (!(quality.crop.min[a] >= 0 && quality.crop.min[a] < quality.crop.max[a] && quality.crop.max[a] <= 1))
            throw std::invalid_argument("quality.crop: axis " + std::to_string(a) +
                                        " must have 0 <= min < max <= 1 (normalised box coordinates)");
    if (const std::string problem = signedPermutationProblem(quality.orientationCorrection); !problem.empty())
        throw std::invalid_argument("quality.orientation_correction: is not a signed permutation: " + problem);
}

Quality compositedQuality(const Quality &quality) {
    Quality q = quality;
    if (q.compositing != Compositing::EmissionAbsorption) {
        q.preintegrated = false;
        q.shading = false;
        q.earlyTermination = 1;
        q.emptySpaceSkipping = false;
    }
    return q;
}

void cropBoxInIndexSpace(const Volume &volume, const CropBox &crop, double lo[3], double hi[3]) {
    for (int a = 0; a < 3; ++a) {
        const double n = double(volume.dims[a]);
        lo[a] = -0.5 + crop.min[a] * n;
        hi[a] = -0.5 + crop.max[a] * n;
    }
}

double frameStep(const Volume &volume, const Quality &quality, RenderStats &stats) {
    const double smallest = minComponent(volume.spacing);
    double step = quality.step * smallest;
    // The 16 spare segments cover a jittered first segment and rounding.
    const double shortestStep = length(volume.extent()) / (FrameRenderer::kMaxSamplesPerRay - 16);
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

int raysForScale(int pixels, double imageScale) { return std::max(1, int(std::lround(pixels * imageScale))); }

void validateRayWindow(const RayWindow &window, int width, int height, const Quality &quality) {
    const int w = raysForScale(width, quality.imageScale), h = raysForScale(height, quality.imageScale);
    if (window.width < 1 || window.height < 1 || window.x < 0 || window.y < 0 || window.x + window.width > w ||
        window.y + window.height > h)
        throw std::invalid_argument("window " + std::to_string(window.width) + "x" + std::to_string(window.height) +
                                    "+" + std::to_string(window.x) + "+" + std::to_string(window.y) +
                                    " is outside the frame's " + std::to_string(w) + "x" + std::to_string(h) +
                                    " rays");
}

Image FrameRenderer::renderWindow(const TransferFunction &tf, const Camera &camera, int width, int height,
                                  const Quality &quality, const std::vector<ClipPlane> &clipPlanes,
                                  const RayWindow &window, RenderStats *stats) {
    validateRayWindow(window, width, height, quality);
    const int w = raysForScale(width, quality.imageScale), h = raysForScale(height, quality.imageScale);
    // The grid itself at image_scale 1: the same rays (within rounding of the grid's aspect).
    Quality whole = quality;
    whole.imageScale = 1;
    const Image grid = render(tf, camera, w, h, whole, clipPlanes, stats);
    Image out(window.width, window.height);
    for (int y = 0; y < window.height; ++y)
        std::copy_n(grid.pixel(window.x, window.y + y), size_t(window.width) * 4, out.pixel(0, y));
    return out;
}

} // namespace volcast
