#include "server/tiled_frame.hpp"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <tuple>

namespace volcast::server {

std::vector<int> middleOutOrder(int n) {
    std::vector<int> order;
    if (n <= 0) return order;
    int bits = 0;
    while ((1 << bits) < n) ++bits;
    for (int i = 0; i < (1 << bits); ++i) {
        int r = 0;
        for (int b = 0; b < bits; ++b)
            if (i & (1 << b)) r |= 1 << (bits - 1 - b);
        if (r < n) order.push_back((r + n / 2) % n);
    }
    return order;
}

TiledFrame::TiledFrame(FrameRequest request, int passes, int bandRows, bool encodedOnly)
    : request_(std::move(request)), passes_(std::max(1, passes)),
      gridWidth_(raysForScale(request_.width, request_.quality.imageScale)),
      gridHeight_(raysForScale(request_.height, request_.quality.imageScale)),
      rgba8_(encodedOnly && passes_ == 1) {
    request_.window.reset();
    if (rgba8_) {
        bytes_.width = gridWidth_;
        bytes_.height = gridHeight_;
        // Zeroed, not left as the heap had it: no byte of another frame may reach a client.
        bytes_.rgba.assign(size_t(gridWidth_) * size_t(gridHeight_) * 4, uint8_t(0));
    } else {
        current_ = Image(gridWidth_, gridHeight_);
    }
    const int rows = std::max(1, bandRows);
    const int bands = (gridHeight_ + rows - 1) / rows;
    const int columns = (gridWidth_ + kCellColumns - 1) / kCellColumns;
    cellRays_ = rows * std::min(gridWidth_, kCellColumns);
    for (int band : middleOutOrder(bands))
        for (int k = 0; k < columns; ++k) {
            const int column = (columns / 2 + k) % columns;   // from the centre column, wrapping
            const int x = column * kCellColumns, y = band * rows;
            order_.push_back({x, y, std::min(kCellColumns, gridWidth_ - x), std::min(rows, gridHeight_ - y)});
        }
}

double TiledFrame::msPerRayEstimate() const {
    if (raysDone_ == 0) return 0;
    return std::max(lastUnitMsPerRay_, renderMs_ / double(raysDone_));
}

double TiledFrame::renderUnit(FrameRenderer &renderer, int cells) {
    const auto t0 = std::chrono::steady_clock::now();
    FrameRequest unit = request_;
    if (passes_ > 1) {
        // Each pass moves the sample positions, so the onion rings of one pass average out.
        unit.quality.jitter = true;
        unit.quality.seed = request_.quality.seed + uint64_t(pass_);
    }
    const int take = std::clamp(cells, 1, cellsLeftInPass());
    // The unit's cells as few windows as cover them: cells side by side in a band join, and
    // bands of the same columns one above the other join (a unit of the whole frame is one
    // window, one call).
    std::vector<Cell> windows(order_.begin() + next_, order_.begin() + next_ + take);
    std::sort(windows.begin(), windows.end(), [](const Cell &a, const Cell &b) { return std::tie(a.y, a.x) < std::tie(b.y, b.x); });
    std::vector<Cell> joined;
    for (const Cell &c : windows)
        if (!joined.empty() && joined.back().y == c.y && joined.back().x + joined.back().width == c.x)
            joined.back().width += c.width;
        else
            joined.push_back(c);
    std::sort(joined.begin(), joined.end(), [](const Cell &a, const Cell &b) { return std::tie(a.x, a.width, a.y) < std::tie(b.x, b.width, b.y); });
    windows.clear();
    for (const Cell &c : joined)
        if (!windows.empty() && windows.back().x == c.x && windows.back().width == c.width &&
            windows.back().y + windows.back().height == c.y)
            windows.back().height += c.height;
        else
            windows.push_back(c);

    uint64_t rays = 0;
    for (const Cell &c : windows) {
        unit.window = RayWindow{c.x, c.y, c.width, c.height};
        if (rgba8_) {
            const Rgba8Image part = renderer.renderRgba8(unit);
            for (int row = 0; row < c.height; ++row)
                std::copy_n(part.pixel(0, row), size_t(c.width) * 4, bytes_.pixel(c.x, c.y + row));
        } else {
            const Image part = renderer.render(unit);
            for (int row = 0; row < c.height; ++row)
                std::copy_n(part.pixel(0, row), size_t(c.width) * 4, current_.pixel(c.x, c.y + row));
        }
        rays += uint64_t(c.width) * uint64_t(c.height);
    }
    next_ += take;
    ++units_;
    lastUnitCells_ = take;
    if (next_ >= cellsPerPass()) {
        // 8-bit: one pass, its bytes already in place.
        if (!rgba8_ && pass_ == 0)
            sum_ = current_;
        else if (!rgba8_)
            for (size_t i = 0; i < sum_.rgba.size(); ++i) sum_.rgba[i] += current_.rgba[i];
        ++pass_;
        next_ = 0;
    }
    const double ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
    renderMs_ += ms;
    raysDone_ += rays;
    lastUnitMsPerRay_ = ms / double(std::max<uint64_t>(rays, 1));
    return ms;
}

Image TiledFrame::finish() {
    if (passes_ > 1)
        for (float &v : sum_.rgba) v /= float(passes_);
    return std::move(sum_);
}

Rgba8Image TiledFrame::finishRgba8() { return std::move(bytes_); }

int cellsForBudget(double budgetMs, double msPerRay, int cellRays, int previousUnitCells) {
    if (!(msPerRay > 0) || cellRays <= 0) return 1;
    const double fit = std::floor(budgetMs / (msPerRay * double(cellRays)));
    double cells = std::max(1.0, std::min(fit, 1e9));
    if (previousUnitCells > 0) cells = std::min(cells, 2.0 * previousUnitCells);
    return int(cells);
}

} // namespace volcast::server
