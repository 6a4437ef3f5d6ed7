#include "server/quality_ladder.hpp"

#include <algorithm>
#include <cmath>

namespace volcast::server {

namespace {
// The non-final levels, cheapest first, as server/README.md's table shows them. Each is
// derived from the final quality f: step max(stepAtLeast, stepTimesFinal · f.step), mip level
// at least mipAtLeast, image scale and early termination at most the given values; linear
// and unshaded-as-f, pre-integration only where keepsPreintegration, jittered where jittered
// (unless pre-integrated: the table already removes the rings jitter would hide).
struct LevelRule {
    double stepAtLeast;
    double stepTimesFinal;
    int mipAtLeast;
    double imageScaleAtMost;
    double earlyTerminationAtMost;
    bool keepsPreintegration;
    bool jittered;
    int jpegQuality;
};
constexpr double kNoLimit = 1e300;
constexpr LevelRule kLadder[] = {
    // 1/16 of the rays on the quarter-resolution mip, for big viewports on slow devices.
    {4, 8, 2, 0.25, 0.9, false, false, 50},
    {2, 4, 1, 0.5, 0.95, false, false, 60},
    {1, 2, 0, 0.5, 0.98, false, false, 70},
    // Full size at twice the final step; jitter hides its onion rings until the final replaces it.
    {0, 2, 0, kNoLimit, kNoLimit, true, true, 80},
};
constexpr int kFinalJpegQuality = 90;   // the final level's frames sent before it is final (the final itself is PNG)
} // namespace

std::vector<Level> automaticLadder(const Quality &f, int jitterPasses) {
    std::vector<Level> ladder;
    for (const LevelRule &r : kLadder) {
        Quality q = f;
        q.jitter = false;
        q.preintegrated = false;
        q.interpolation = Interpolation::Linear;
        q.step = std::max(r.stepAtLeast, r.stepTimesFinal * f.step);
        q.mipLevel = std::max(r.mipAtLeast, f.mipLevel);
        q.imageScale = std::min(r.imageScaleAtMost, f.imageScale);
        q.earlyTermination = std::min(r.earlyTerminationAtMost, f.earlyTermination);
        if (r.keepsPreintegration) q.preintegrated = f.preintegrated;
        if (r.jittered) q.jitter = !q.preintegrated;
        ladder.push_back({q, 1, r.jpegQuality});
    }
    ladder.push_back({f, f.jitter ? jitterPasses : 1, kFinalJpegQuality});

    // Leave out a level identical to the next one (a coarse final quality).
    std::vector<Level> unique;
    for (size_t i = 0; i < ladder.size(); ++i)
        if (i + 1 == ladder.size() || !(ladder[i].quality == ladder[i + 1].quality)) unique.push_back(ladder[i]);
    return unique;
}

size_t nextRefinementLevel(size_t sent, const std::vector<double> &predictedMs) {
    if (predictedMs.empty()) return 0;
    const size_t last = predictedMs.size() - 1;
    const size_t next = std::min(sent + 1, last);
    return next < last && 2 * predictedMs[next] > predictedMs[last] ? last : next;
}

std::vector<Level> explicitLadder(const Quality &quality, int jitterPasses) {
    return {{quality, quality.jitter ? jitterPasses : 1, 85}};
}

double predictedSamples(const Volume &volume, const Quality &q, int width, int height) {
    // The step is in level-0 voxels on every mip level (frameStep): a coarse level takes as
    // many samples per ray, each cheaper only by the cache it hits, which the timer measures.
    const Vec3d d = Vec3d(volume.dims);
    const double diagonalVoxels = std::sqrt(d.x * d.x + d.y * d.y + d.z * d.z);
    const double rays = double(width) * double(height) * q.imageScale * q.imageScale;
    double perSample = 1;
    if (q.interpolation == Interpolation::Cubic) perSample *= 4;   // 64 taps instead of 8
    if (q.shading) perSample *= 3;                                 // gradient: 6 more fetches
    return rays * diagonalVoxels / q.step * perSample;
}

void LevelTimer::record(size_t level, double ms, double samples) {
    if (level >= msPerSample_.size() || samples <= 0) return;
    const double measured = ms / samples;
    double &ema = msPerSample_[level];
    ema = ema == 0 ? measured : (1 - kSmoothing) * ema + kSmoothing * measured;
}

double LevelTimer::predictMs(size_t level, double samples) const {
    // The nearest measured level's cost, else the initial guess.
    for (size_t d = 0; d < msPerSample_.size(); ++d) {
        if (level >= d && msPerSample_[level - d] > 0) return msPerSample_[level - d] * samples;
        if (level + d < msPerSample_.size() && msPerSample_[level + d] > 0) return msPerSample_[level + d] * samples;
    }
    return kInitialMsPerSample * samples;
}

size_t LevelTimer::choose(size_t count, double targetMs, const std::vector<double> &samplesPerLevel) const {
    size_t best = 0;
    for (size_t l = 0; l < count && l < samplesPerLevel.size(); ++l)
        if (predictMs(l, samplesPerLevel[l]) <= targetMs) best = l;
    return best;
}

} // namespace volcast::server
