#pragma once
// The ladder of quality levels a view is refined through, cheapest first, and the policy
// that picks the interactive level. Kept deliberately simple and explicit:
//
//   level 0  step max(4, 8·s_f), mip level 2, image scale 0.25, linear, ET ≤ 0.9   JPEG q50
//   level 1  step max(2, 4·s_f), mip level 1, image scale 0.5, linear, ET ≤ 0.95   JPEG q60
//   level 2  step max(1, 2·s_f), mip level 0, image scale 0.5, linear, ET ≤ 0.98   JPEG q70
//   level 3  step 2·s_f, full size, linear, pre-integration as final, jittered     JPEG q80
//   level 4  the final quality exactly; jittered → several passes accumulated      PNG
//
// (s_f is the final step; a level equal to the one after it is left out). An explicit
// policy has one level, its own quality. While interacting, the policy picks the finest
// non-final level whose predicted time fits the target; the prediction is
// rays × samples per ray × cost per sample, with the cost per sample an exponential moving
// average measured per level (unmeasured levels borrow the nearest measured one's cost,
// and a device-independent guess before any measurement).

#include "renderer/scene.hpp"
#include "renderer/volume.hpp"

#include <vector>

namespace volcast::server {

struct Level {
    Quality quality;
    int passes = 1;        // jittered passes accumulated (final level with jitter)
    int jpegQuality = 80;  // for non-final frames
};

std::vector<Level> automaticLadder(const Quality &finalQuality, int jitterPasses);

// The level to refine to after level `sent`, given each level's predicted ms: the next one,
// unless it is predicted to cost more than half the final one, which would then show little
// sooner than the final itself (bonsai at 512²: level 3 took 804 ms, the final 938).
size_t nextRefinementLevel(size_t sent, const std::vector<double> &predictedMs);
std::vector<Level> explicitLadder(const Quality &quality, int jitterPasses);

// Geometric samples of a level: rays × the volume's diagonal in level-0 voxels divided by
// the step (the step is in level-0 voxels on every mip level), × the taps' relative cost.
// A prediction, not a measurement (early termination and empty-space skipping make real
// rays shorter); the measured cost per sample absorbs the difference.
double predictedSamples(const Volume &volume, const Quality &q, int width, int height);

// Measured cost per sample, per level, for one session.
class LevelTimer {
  public:
    static constexpr double kInitialMsPerSample = 1.0 / 50e3;   // 50 M samples/s (docs/platform.md: 30-150 M)
    static constexpr double kSmoothing = 0.3;                   // weight of the newest frame in the EMA
    void reset(size_t levels) { msPerSample_.assign(levels, 0); }
    void forget(size_t level) {
        if (level < msPerSample_.size()) msPerSample_[level] = 0;
    }
    void record(size_t level, double ms, double samples);
    double predictMs(size_t level, double samples) const;
    // Whether this level itself was measured (not borrowed from another, not the guess).
    bool measured(size_t level) const { return level < msPerSample_.size() && msPerSample_[level] > 0; }
    // The finest of levels [0, count) whose predicted time fits targetMs; 0 if none does.
    size_t choose(size_t count, double targetMs, const std::vector<double> &samplesPerLevel) const;

  private:
    std::vector<double> msPerSample_;   // 0: not measured yet
};

} // namespace volcast::server
