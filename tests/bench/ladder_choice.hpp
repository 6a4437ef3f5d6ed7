#pragma once
// The `ladder` study: on the device it runs on, the level the server's quality ladder picks
// while dragging, with the server's own code (server/quality_ladder.hpp: automaticLadder,
// fitToLimits, predictedSamples, LevelTimer, chooseInteractiveLevel; server/tiled_frame.hpp
// renders each frame as the scheduler does; server/error_calibrator.hpp measures each level's
// error as the server does). See tests/bench/README.md.

#include "renderer/opencl/opencl_context.hpp"
#include "tests/bench/studies.hpp"

#include <algorithm>
#include <cstddef>
#include <memory>
#include <utility>
#include <vector>

namespace volcast::bench {

// Of the target frame time, the share the scheduler plans for rendering and encoding
// (kRenderShare in server/render_scheduler.cpp, which keeps it private; the rest is the send,
// the client's decoding and the scheduler's own time).
inline constexpr double kSchedulerRenderShare = 0.9;

// The render budget of one dragging session's interactive frame, as RenderScheduler::nextWork
// computes it: interactive frames are shared by count, so each of the n sessions dragging
// (at least 1: the one asking) gets its share of the target, less its frames' encoding and
// twice its frames' measured deviation from their prediction:
//
//   budget = kRenderShare · targetFrameMs / max(n, 1) − encodeMs − 2 · deviationMs
//
// The level chosen is then chooseInteractiveLevel(levels, budget).
inline double interactiveBudgetMs(double targetFrameMs, size_t sessionsDragging, double encodeMs, double deviationMs) {
    return kSchedulerRenderShare * targetFrameMs / double(std::max<size_t>(sessionsDragging, 1)) - encodeMs -
           2 * deviationMs;
}

// bonsai (options.data / "bonsai.nhdr", Figure 5's camera and the scans' transfer function)
// at each size, with the server's default final quality and ladder: every level timed
// (options.repeat, the first frame untimed) and its error measured against the final frame,
// then the level chosen for each number of sessions dragging. Writes ladder.json,
// ladder.csv (levels), ladder_choices.csv and ladder.md to options.out; prints the tables.
void ladderChoice(const std::shared_ptr<OpenClContext> &cl, const StudyOptions &options,
                  const std::vector<std::pair<int, int>> &sizes, const std::vector<int> &sessions);

} // namespace volcast::bench
