#pragma once
// One frame rendered in bounded units: bands of rows of its ray grid, pass after pass (a
// jittered level accumulates several passes). The scheduler renders one band, then serves
// other sessions, then comes back; new input drops the frame between bands. A band is as
// many rows as fit the unit's time budget at the level's measured cost per ray.

#include "renderer/frame_renderer.hpp"
#include "server/quality_ladder.hpp"

#include <cstdint>
#include <vector>

namespace volcast::server {

class TiledFrame {
  public:
    // quality: what is rendered (the level's, or its substitute while its preparation runs).
    TiledFrame(const Quality &quality, int passes, int width, int height);

    // Renders the next band of at most maxRows rows (at least one); returns its ms.
    double renderUnit(FrameRenderer &renderer, const TransferFunction &tf, const Camera &camera,
                      const std::vector<ClipPlane> &clipPlanes, int maxRows);
    bool done() const { return pass_ >= passes_; }
    // The averaged passes, brought to the frame's size; only once done().
    Image finish();

    const Quality &quality() const { return quality_; }
    int gridWidth() const { return gridWidth_; }
    int gridHeight() const { return gridHeight_; }
    int passes() const { return passes_; }
    int units() const { return units_; }
    double renderMs() const { return renderMs_; }   // the units' sum
    // Measured by this frame's units so far; 0 before its first unit.
    double msPerRay() const { return raysDone_ > 0 ? renderMs_ / double(raysDone_) : 0; }

  private:
    Quality quality_;
    int passes_;
    int width_, height_;          // the frame
    int gridWidth_, gridHeight_;  // rays cast (image_scale < 1: fewer, upsampled at the end)
    int pass_ = 0, row_ = 0;
    int units_ = 0;
    uint64_t raysDone_ = 0;
    double renderMs_ = 0;
    Image sum_, current_;
};

// Rows of a w-ray-wide grid that fit budgetMs at msPerRay: a multiple of bandRows (the
// renderer's FrameRenderer::bandRows()), at least bandRows even where that overruns the
// budget, at most gridHeight. A thinner band costs as much as bandRows rows (the OpenCL
// renderer's work-groups are 8 rows high, the CPU renderer's ray packets 4) and would measure
// a cost per ray several times too high, sizing the next band thinner still: under load a
// frame then crawled one row per unit at 4 to 8 times its real cost (docs/service.md,
// "Scheduling and fairness").
int rowsForBudget(double budgetMs, double msPerRay, int gridWidth, int gridHeight, int bandRows);

} // namespace volcast::server
