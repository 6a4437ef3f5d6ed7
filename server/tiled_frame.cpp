#include "server/tiled_frame.hpp"

#include <algorithm>
#include <chrono>
#include <cmath>

namespace volcast::server {

TiledFrame::TiledFrame(const Quality &quality, int passes, int width, int height)
    : quality_(quality), passes_(std::max(1, passes)), width_(width), height_(height),
      gridWidth_(raysForScale(width, quality.imageScale)), gridHeight_(raysForScale(height, quality.imageScale)),
      current_(gridWidth_, gridHeight_) {}

double TiledFrame::renderUnit(FrameRenderer &renderer, const TransferFunction &tf, const Camera &camera,
                              const std::vector<ClipPlane> &clipPlanes, int maxRows) {
    const auto t0 = std::chrono::steady_clock::now();
    Quality q = quality_;
    if (passes_ > 1) {
        // Each pass moves the sample positions, so the onion rings of one pass average out.
        q.jitter = true;
        q.seed = quality_.seed + uint64_t(pass_);
    }
    const RayWindow window{0, row_, gridWidth_, std::min(std::max(1, maxRows), gridHeight_ - row_)};
    const Image band = renderer.renderWindow(tf, camera, width_, height_, q, clipPlanes, window);
    std::copy(band.rgba.begin(), band.rgba.end(), current_.pixel(0, row_));
    row_ += window.height;
    raysDone_ += uint64_t(window.width) * uint64_t(window.height);
    ++units_;
    if (row_ >= gridHeight_) {
        if (pass_ == 0)
            sum_ = current_;
        else
            for (size_t i = 0; i < sum_.rgba.size(); ++i) sum_.rgba[i] += current_.rgba[i];
        ++pass_;
        row_ = 0;
    }
    const double ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
    renderMs_ += ms;
    return ms;
}

Image TiledFrame::finish() {
    if (passes_ > 1)
        for (float &v : sum_.rgba) v /= float(passes_);
    if (gridWidth_ == width_ && gridHeight_ == height_) return std::move(sum_);
    return resizeBilinear(sum_, width_, height_);
}

int rowsForBudget(double budgetMs, double msPerRay, int gridWidth, int gridHeight, int bandRows) {
    if (!(msPerRay > 0) || gridWidth <= 0) return std::max(1, gridHeight);
    const double band = std::max(1, bandRows);
    const double rows = std::max(band, std::floor(budgetMs / (msPerRay * gridWidth) / band) * band);
    return int(std::min(rows, double(std::max(1, gridHeight))));
}

} // namespace volcast::server
