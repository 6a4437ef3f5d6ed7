#pragma once
// The ladder of quality levels a view is shown at, cheapest first, the final one last, and
// the choice among them. Every level below the final is a candidate, both for the frame shown
// while interacting and for the one refinement step before the final:
//
//   image scale {1/4, 1/2, 1} × mip level {0, 1, 2} × step {1, 2, 4}·max(1, s_f): linear,
//     unjittered, shading as the final, early termination ≤ 0.98, JPEG q50 / q70 / q80 by
//     image scale; mip level m only with steps of at least 2^m level-0 voxels (a finer step
//     on a coarser level costs what level 0 costs and has more error);
//   full size at step 2·s_f, pre-integration as the final, jittered, JPEG q80;
//   the final quality exactly; jittered → several passes accumulated, PNG.
//
// (s_f is the final step; image scale, mip level and step never finer than the final's; a
// level equal to another is left out), ordered by predicted cost: rays ÷ step, then coarser
// mip level first. An explicit policy has one level, its own quality.
//
// The automatic ladder then stays within the server's admission limits (fitToLimits): a level
// predicted over --max-samples-per-frame or --max-request-mib for the view's size is lowered,
// image scale first (down to kMinFittedImageScale), then step (doubled, with the mip level that
// step allows), then image scale again; the level says so (Level::limited) and its frames'
// headers carry the words. An explicit policy is refused instead (too_large).
//
// The choice is made on the error-against-time front of the view: each level's error is its
// measured RMSE against the final frame of the same camera (ErrorCalibrator renders every
// level once in the background when a view of its kind first reaches its final frame, and
// adds each frame delivered afterwards), its time the prediction below (LevelTimer). While
// interacting: the level with the lowest error of those predicted to fit the target frame
// time. At rest: the level with the lowest error below the shown one's of those predicted to
// take at most half the final's time, then the final. Until the errors are measured, the
// costliest level stands for the lowest error. The prediction is rays × samples per ray ×
// cost per sample, with the cost per sample an exponential moving average measured per level
// (unmeasured levels take their background calibration render's cost, scaled by how the
// latest level measured both ways compares; else the nearest measured level's; else a
// device-independent guess).

#include "renderer/model/scene.hpp"
#include "renderer/model/volume.hpp"

#include <cstdint>
#include <optional>
#include <string>
#include <vector>

namespace volcast::server {

struct Level {
    Quality quality;
    int passes = 1;        // jittered passes accumulated (final level with jitter)
    int jpegQuality = 80;  // for non-final frames
    std::string limited;   // what fitToLimits lowered, for the user; empty when nothing
};

// The admission limits a view is judged by (ServerConfig's, protocol/README.md "Admission").
struct AdmissionLimits {
    double maxSamplesPerFrame = 0;   // predicted samples of one frame (predictedSamples)
    double maxRequestBytes = 0;      // image buffers of one view (requestBytes)
};

// Image scale a fitted level keeps before its step is made coarser: below a quarter of the
// window's pixels a picture loses more than a doubled step costs it.
inline constexpr double kMinFittedImageScale = 0.25;
// Steps a fitted level may take, as a multiple of its own, before the scale drops further.
inline constexpr double kMaxFittedStepFactor = 8;

std::vector<Level> automaticLadder(const Quality &finalQuality, int jitterPasses);
std::vector<Level> explicitLadder(const Quality &quality, int jitterPasses);

// What is known of a level when one is chosen: its predicted time (ms, all passes) and its
// measured error against the final frame (RMSE, 8-bit RGB in [0, 1]; none until measured).
struct LevelOutlook {
    double predictedMs = 0;
    std::optional<double> error;
};

// Of the target frame time, the share planned for rendering and encoding; the rest is the
// send, the client's decoding and the scheduler's own time (one session dragging the demo in
// a closed loop, tests/server/fairness_bench.py: frames planned to the whole target arrived
// after 57–62 ms at p95, to 0.9 of it after 43–46 ms, to 0.8 after 20 ms; bonsai at 512²,
// tests/bench/drag_quality.py: 43.7, 43 and 36 dB, docs/service.md).
inline constexpr double kRenderShare = 0.9;

// The render budget of one dragging session's interactive frame. Interactive frames are
// shared by count, so a dragging session's next frame waits for one frame of every other
// dragging session: each of the n (at least 1: the one asking) gets its share of the target,
// less the encoding its frames take and twice their measured deviation from their prediction.
inline double interactiveBudgetMs(double targetFrameMs, size_t sessionsDragging, double encodeMs, double deviationMs) {
    return kRenderShare * targetFrameMs / double(sessionsDragging > 0 ? sessionsDragging : 1) - encodeMs - 2 * deviationMs;
}

// The level to show while interacting: of the non-final levels predicted to fit targetMs,
// the one with the lowest error (the cheaper on a tie), or the costliest while any of them
// has no measured error; 0 (the cheapest) if none fits.
size_t chooseInteractiveLevel(const std::vector<LevelOutlook> &levels, double targetMs);

// The level to refine to after level `sent`: of the non-final levels with a lower error than
// `sent` (while either is unmeasured: a costlier one) predicted to take at most half the
// final's time, the one with the lowest error (the costliest while any is unmeasured); else
// the final. A level costing more than half the final would show little sooner than the
// final itself (bonsai at 512² on PoCL: the jittered level took 804 ms, the final 938).
// `sent` is the level shown last; a level in `shown` (true: shown already in this view) is
// never chosen again, so a view reaches its final within as many refinements as it has
// levels, even where measured errors do not fall with cost (a cheaper level with a lower
// error is taken, and from there the costlier one must not come back).
size_t nextRefinementLevel(size_t sent, const std::vector<LevelOutlook> &levels, const std::vector<bool> &shown = {});

// Geometric samples of a level: rays × the volume's diagonal in level-0 voxels divided by
// the step (the step is in level-0 voxels on every mip level), × the taps' relative cost.
// A prediction, not a measurement (early termination and empty-space skipping make real
// rays shorter); the measured cost per sample absorbs the difference.
double predictedSamples(const Volume &volume, const Quality &q, int width, int height);

// The image memory a level of a width × height view allocates: the float RGBA image of each
// jittered pass (a conservative bound of what one view holds).
double requestBytes(const Level &level, int width, int height);

// The ladder with every level lowered until it fits `limits` at width × height (see the top
// of this file); `volume` null: only the image memory is judged (no volume open yet). Levels
// that become equal to a cheaper one are left out; the final stays last.
std::vector<Level> fitToLimits(std::vector<Level> ladder, const Volume *volume, int width, int height,
                               const AdmissionLimits &limits);

// Measured cost per sample, per level, for one session.
class LevelTimer {
  public:
    static constexpr double kInitialMsPerSample = 1.0 / 50e3;   // 50 M samples/s (docs/platform.md: 30-150 M)
    static constexpr double kSmoothing = 0.3;                   // weight of the newest frame in the EMA
    void reset(size_t levels) {
        msPerSample_.assign(levels, 0);
        recordedAt_.assign(levels, 0);
        records_ = 0;
        deviationMs_ = 0;
    }
    void forget(size_t level) {
        if (level < msPerSample_.size()) msPerSample_[level] = 0;
    }
    void record(size_t level, double ms, double samples);
    // Each level's cost per sample as its background calibration render measured it (0: not
    // rendered there); it stands in for a level not measured here, scaled by how the latest
    // level measured both ways compares (1 before there is one): the calibration renders ran
    // at a lower priority beside other work, this session's frames on the render thread, and
    // the latest frame was measured at the machine's load of the moment.
    void setBackgroundCosts(std::vector<double> msPerSample) { backgroundMsPerSample_ = std::move(msPerSample); }
    double predictMs(size_t level, double samples) const;
    // Whether this level itself was measured (not borrowed from another, not the guess).
    bool measured(size_t level) const { return level < msPerSample_.size() && msPerSample_[level] > 0; }
    // How far frames of a measured level come from its prediction (EMA of |ms − predicted|):
    // frames vary with the camera (how much of the volume the view crosses), so a level
    // planned at its mean would overrun the target on every other frame.
    double deviationMs() const { return deviationMs_; }
    // Whether this level's cost is known from a measurement of it, here or in the background.
    bool known(size_t level) const {
        return measured(level) || (level < backgroundMsPerSample_.size() && backgroundMsPerSample_[level] > 0);
    }

  private:
    std::vector<double> msPerSample_;   // 0: not measured yet
    std::vector<double> backgroundMsPerSample_;
    std::vector<uint64_t> recordedAt_;   // the record() count when each level was last measured
    uint64_t records_ = 0;
    double deviationMs_ = 0;
};

} // namespace volcast::server
