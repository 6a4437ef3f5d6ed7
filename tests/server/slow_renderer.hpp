#pragma once
// A renderer that is slow on purpose, for scheduler tests that must not depend on how fast
// PoCL is on the machine: it computes real frames (every ray through the double-precision
// reference integrator, trilinear, at a loose tolerance) and then waits until each frame or
// window has taken exactly `msPerRay` per ray cast. A quality that needs preparation (cubic,
// pre-integration or shading, as in OpenClRenderer) first costs `prepareMs` once, under the
// renderer's lock, like the real renderer's B-spline prefilter.

#include "renderer/common/frame_renderer.hpp"
#include "renderer/reference/reference_renderer.hpp"

#include <atomic>
#include <memory>
#include <mutex>
#include <set>

namespace volcast::server::slow {

class SlowRenderer : public FrameRenderer {
  public:
    SlowRenderer(std::shared_ptr<const Volume> volume, double msPerRay, double prepareMs = 0);

    Image render(const FrameRequest &request, RenderStats *stats = nullptr) override;
    bool rendersWindowsCheaply() const override { return true; }
    std::string description() const override { return "slow test renderer"; }
    PreprocessCounts preprocessCounts() const override;
    const Volume &volume() const override { return *volume_; }

    int preparations() const { return preparations_; }
    // Rays cast by renders that overlapped in time (must stay 0: frames are one at a time).
    int overlaps() const { return overlaps_; }

  private:
    std::shared_ptr<const Volume> volume_;
    double msPerRay_, prepareMs_;
    std::mutex mutex_;
    std::set<std::tuple<int, bool, bool, bool>> prepared_;   // (mip, cubic, preintegrated, shading)
    std::atomic<int> preparations_{0}, overlaps_{0}, active_{0};
};

} // namespace volcast::server::slow
