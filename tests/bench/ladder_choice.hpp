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

// The render budget of one dragging session's interactive frame is the scheduler's own
// (server::interactiveBudgetMs, server/quality_ladder.hpp); the level chosen is then
// chooseInteractiveLevel(levels, budget).

// bonsai (options.data / "bonsai.nhdr", Figure 5's camera and the scans' transfer function)
// at each size, with the server's default final quality and ladder: every level timed
// (options.repeat, the first frame untimed) and its error measured against the final frame,
// then the level chosen for each number of sessions dragging. Writes ladder.json,
// ladder.csv (levels), ladder_choices.csv and ladder.md to options.out; prints the tables.
void ladderChoice(const std::shared_ptr<OpenClContext> &cl, const StudyOptions &options,
                  const std::vector<std::pair<int, int>> &sizes, const std::vector<int> &sessions);

} // namespace volcast::bench
