#pragma once
// One frame rendered in bounded units: cells of its ray grid, pass after pass (a jittered
// level accumulates several passes). The scheduler renders one unit of cells, then serves
// other sessions, then comes back; new input drops the frame between units.
//
// A cell is bandRows rows (the renderer's FrameRenderer::bandRows(): a thinner window costs
// as much) by kCellColumns rays, so that one cell of an expensive frame (cubic, shaded, a
// fine step, a wide viewport) still fits a unit where a whole band of rows would not. Cells
// are visited middle out and spread over the frame (the centre band of rows first, then the
// top, three quarters, a quarter, ...; in each band from the centre column), so the first
// units measure the rays that hit the volume rather than the empty rows above it, and each
// unit's cost per ray stands for the rest of the frame: a frame whose top rows are empty no
// longer measures a cost near zero there and then plans one unit for everything below.

#include "renderer/common/frame_renderer.hpp"
#include "server/quality_ladder.hpp"

#include <cstdint>
#include <vector>

namespace volcast::server {

class TiledFrame {
  public:
    static constexpr int kCellColumns = 64;   // a multiple of the CPU tile (16) and the OpenCL work-group (8)

    // request: the whole frame, its quality what is rendered (the level's, or its substitute
    // while its preparation runs); its window is ignored (the frame sets one per unit).
    // encodedOnly: the frame will only be encoded as a JPEG; then, when one pass makes its
    // bytes the cells' bytes (no averaging on floats), the cells are rendered as 8-bit RGBA (FrameRenderer::renderRgba8: on OpenCL converted
    // on the device, a quarter of the read-back) and finishRgba8 gives the frame.
    TiledFrame(FrameRequest request, int passes, int bandRows, bool encodedOnly = false);

    // Renders the next `cells` cells of this pass (at least one, at most cellsLeftInPass());
    // returns the unit's ms.
    double renderUnit(FrameRenderer &renderer, int cells);
    bool done() const { return pass_ >= passes_; }
    // The averaged passes at the ray grid's size (image_scale < 1: smaller than the view; it
    // is sent so, and clients scale it up); only once done() and !rgba8().
    Image finish();
    // Whether the cells are rendered as 8-bit RGBA (see the constructor).
    bool rgba8() const { return rgba8_; }
    // The frame as rgba8FromImage(finish()) would give it; only once done() and rgba8().
    Rgba8Image finishRgba8();

    const Quality &quality() const { return request_.quality; }
    int gridWidth() const { return gridWidth_; }
    int gridHeight() const { return gridHeight_; }
    int passes() const { return passes_; }
    int units() const { return units_; }
    double renderMs() const { return renderMs_; }   // the units' sum
    int cellsPerPass() const { return int(order_.size()); }
    int cellsLeftInPass() const { return int(order_.size()) - next_; }
    int cellRays() const { return cellRays_; }      // rays of a whole cell
    int lastUnitCells() const { return lastUnitCells_; }
    // The cost per ray to plan the next unit with: the larger of the last unit's and this
    // frame's average (a unit of cheap rays must not make the next one large); 0 before the
    // first unit.
    double msPerRayEstimate() const;

  private:
    struct Cell {
        int x, y, width, height;
    };
    FrameRequest request_;
    int passes_;
    int gridWidth_, gridHeight_;  // rays cast (image_scale < 1: fewer than the view's pixels)
    int cellRays_;
    std::vector<Cell> order_;     // the cells of a pass, in the order they are rendered
    int pass_ = 0, next_ = 0;
    int units_ = 0;
    int lastUnitCells_ = 0;
    uint64_t raysDone_ = 0;
    double renderMs_ = 0;
    double lastUnitMsPerRay_ = 0;
    bool rgba8_ = false;
    Image sum_, current_;
    Rgba8Image bytes_;            // rgba8(): the pass's cells as 8-bit RGBA
};

// 0, ..., n-1 middle out and spread: n/2 first, then the other positions in bit-reversed
// order shifted by n/2, so that every prefix is spread over the whole range.
std::vector<int> middleOutOrder(int n);

// Cells of cellRays rays that fit budgetMs at msPerRay: at least one (a cell is the smallest
// unit), at most twice the previous unit's cells when there was one (a unit's rays may cost
// more than those measured so far; growing by at most 2 bounds the overrun when they do).
int cellsForBudget(double budgetMs, double msPerRay, int cellRays, int previousUnitCells);

} // namespace volcast::server
