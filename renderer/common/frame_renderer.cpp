#include "renderer/common/frame_renderer.hpp"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <stdexcept>

namespace volcast {

void validateFrameRequest(const Volume &volume, const FrameRequest &request, int maxMipLevel) {
    const Quality &quality = request.quality;
    const std::vector<ClipPlane> &clipPlanes = request.clipPlanes;
    request.camera.validate();
    request.transferFunction.validate();
    validateImageSize(request.width, request.height); // before anything is allocated
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
    if (request.window) validateRayWindow(*request.window, request.width, request.height, quality);
}

Rgba8Image rgba8FromImage(const Image &image) {
    Rgba8Image out;
    out.width = image.width;
    out.height = image.height;
    out.rgba.resize(image.rgba.size());
    const float *in = image.rgba.data();
    uint8_t *bytes = out.rgba.data();
    for (size_t i = 0, n = image.rgba.size(); i < n; ++i) bytes[i] = byteFromUnit(clampUnit(in[i]));
    return out;
}

Rgba8Image FrameRenderer::renderRgba8(const FrameRequest &request, RenderStats *stats) {
    RenderStats st;
    const Image image = render(request, &st);
    const auto t = std::chrono::steady_clock::now();
    Rgba8Image out = rgba8FromImage(image);
    st.hostConvertSeconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t).count();
    st.renderSeconds += st.hostConvertSeconds;
    if (stats) *stats = st;
    return out;
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

} // namespace volcast
