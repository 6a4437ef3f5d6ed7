#include "renderer/frame_renderer.hpp"

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

} // namespace volcast
