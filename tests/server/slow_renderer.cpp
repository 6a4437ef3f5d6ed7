#include "slow_renderer.hpp"

#include "renderer/model/camera.hpp"

#include <chrono>
#include <thread>

namespace volcast::server::slow {

SlowRenderer::SlowRenderer(std::shared_ptr<const Volume> volume, double msPerRay, double prepareMs)
    : volume_(std::move(volume)), msPerRay_(msPerRay), prepareMs_(prepareMs) {}

PreprocessCounts SlowRenderer::preprocessCounts() const {
    PreprocessCounts c;
    c.coefficientVolumes = preparations_;
    return c;
}

Image SlowRenderer::render(const FrameRequest &request, RenderStats *stats) {
    validateFrameRequest(*volume_, request, 8);
    const Quality &quality = request.quality;
    const int gw = raysForScale(request.width, quality.imageScale), gh = raysForScale(request.height, quality.imageScale);
    const RayWindow window = request.window ? *request.window : RayWindow{0, 0, gw, gh};
    std::lock_guard lock(mutex_);
    if (++active_ > 1) ++overlaps_;
    const auto t0 = std::chrono::steady_clock::now();
    const bool slowFeature = quality.interpolation == Interpolation::Cubic || quality.preintegrated || quality.shading;
    if (slowFeature && prepared_
                           .insert({quality.mipLevel, quality.interpolation == Interpolation::Cubic,
                                    quality.preintegrated, quality.shading})
                           .second) {
        ++preparations_;
        std::this_thread::sleep_for(std::chrono::duration<double, std::milli>(prepareMs_));
    }
    const auto t1 = std::chrono::steady_clock::now();
    const RayGenerator rays(request.camera, gw, gh);
    const ReferenceRenderer exact(*volume_, request.transferFunction, Reconstruction::Linear);
    Image out(window.width, window.height);
    for (int y = 0; y < window.height; ++y)
        for (int x = 0; x < window.width; ++x) {
            const RayIntegral r = exact.integrate(rays.pixelRay(window.x + x, window.y + y), request.clipPlanes, 1e-2);
            float *p = out.pixel(x, y);
            p[0] = float(r.color.r);
            p[1] = float(r.color.g);
            p[2] = float(r.color.b);
            p[3] = float(r.color.a);
        }
    std::this_thread::sleep_until(
        t1 + std::chrono::duration_cast<std::chrono::steady_clock::duration>(
                 std::chrono::duration<double, std::milli>(msPerRay_ * double(window.width) * window.height)));
    if (stats) {
        stats->raysWide = window.width;
        stats->raysHigh = window.height;
        stats->renderSeconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    }
    --active_;
    // A whole frame of fewer rays than pixels is upsampled; a window is returned as cast.
    if (request.window || (gw == request.width && gh == request.height)) return out;
    return resizeBilinear(out, request.width, request.height);
}

} // namespace volcast::server::slow
