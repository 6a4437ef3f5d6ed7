#include "server/quality_ladder.hpp"

#include <algorithm>
#include <cmath>

namespace volcast::server {

namespace {
constexpr double kImageScales[] = {0.25, 0.5, 1};
constexpr int kMipLevels[] = {0, 1, 2};
constexpr double kStepFactors[] = {1, 2, 4};
constexpr double kInteractiveEarlyTermination = 0.98; // leaves at most 2 % of the light behind
constexpr int kFinalJpegQuality = 90;   // the final level's frames sent before it is final (the final itself is PNG)

int jpegQualityFor(double imageScale) { return imageScale <= 0.25 ? 50 : imageScale <= 0.5 ? 70 : 80; }

// Rays ÷ step: a level's predicted samples up to the volume's diagonal, the same for every mip level.
double relativeCost(const Quality &q) { return q.imageScale * q.imageScale / q.step; }
} // namespace

std::vector<Level> automaticLadder(const Quality &f, int jitterPasses) {
    std::vector<Level> candidates;
    const auto add = [&](const Quality &q, int jpegQuality) {
        for (const Level &c : candidates)
            if (c.quality == q) return;
        if (q == f) return;
        candidates.push_back({q, 1, jpegQuality});
    };
    Quality plain = f;
    plain.jitter = false;
    plain.preintegrated = false;
    plain.interpolation = Interpolation::Linear;
    plain.earlyTermination = std::min(kInteractiveEarlyTermination, f.earlyTermination);
    for (double scale : kImageScales)
        for (int mip : kMipLevels)
            for (double factor : kStepFactors) {
                Quality q = plain;
                q.imageScale = std::min(scale, f.imageScale);
                q.mipLevel = std::max(mip, f.mipLevel);
                q.step = factor * std::max(1.0, f.step);
                if (q.mipLevel > f.mipLevel && q.step < double(1 << q.mipLevel)) continue;
                add(q, jpegQualityFor(q.imageScale));
            }
    // Full size at twice the final step; jitter hides its onion rings until the final replaces it.
    Quality jittered = f;
    jittered.interpolation = Interpolation::Linear;
    jittered.step = 2 * f.step;
    jittered.jitter = !f.preintegrated;   // the table already removes the rings jitter would hide
    add(jittered, 80);

    std::stable_sort(candidates.begin(), candidates.end(), [](const Level &a, const Level &b) {
        const double ca = relativeCost(a.quality), cb = relativeCost(b.quality);
        if (ca != cb) return ca < cb;
        return a.quality.mipLevel > b.quality.mipLevel;
    });
    candidates.push_back({f, f.jitter ? jitterPasses : 1, kFinalJpegQuality});
    return candidates;
}

namespace {
// The best of `levels` (indices, ascending): the lowest measured error, the cheaper on a tie;
// the costliest while any of them is unmeasured.
std::optional<size_t> bestOf(const std::vector<LevelOutlook> &outlook, const std::vector<size_t> &levels) {
    if (levels.empty()) return std::nullopt;
    for (size_t i : levels)
        if (!outlook[i].error) return levels.back();
    size_t best = levels.front();
    for (size_t i : levels)
        if (*outlook[i].error < *outlook[best].error) best = i;
    return best;
}
} // namespace

size_t chooseInteractiveLevel(const std::vector<LevelOutlook> &levels, double targetMs) {
    std::vector<size_t> fitting;
    for (size_t i = 0; i + 1 < levels.size(); ++i)
        if (levels[i].predictedMs <= targetMs) fitting.push_back(i);
    return bestOf(levels, fitting).value_or(0);
}

size_t nextRefinementLevel(size_t sent, const std::vector<LevelOutlook> &levels) {
    if (levels.empty()) return 0;
    const size_t last = levels.size() - 1;
    if (sent >= last) return last;
    std::vector<size_t> better;
    for (size_t i = 0; i < last; ++i) {
        if (i == sent || 2 * levels[i].predictedMs > levels[last].predictedMs) continue;
        const bool measured = levels[i].error && levels[sent].error;
        if (measured ? *levels[i].error < *levels[sent].error : i > sent) better.push_back(i);
    }
    return bestOf(levels, better).value_or(last);
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
    if (msPerSample_[level] > 0) {
        const double miss = std::fabs(ms - msPerSample_[level] * samples);
        deviationMs_ = deviationMs_ == 0 ? miss : (1 - kSmoothing) * deviationMs_ + kSmoothing * miss;
    }
    double &ema = msPerSample_[level];
    ema = ema == 0 ? measured : (1 - kSmoothing) * ema + kSmoothing * measured;
    recordedAt_[level] = ++records_;
}

double LevelTimer::predictMs(size_t level, double samples) const {
    if (measured(level)) return msPerSample_[level] * samples;
    // Its background render's cost, scaled by the latest level measured both ways.
    if (level < backgroundMsPerSample_.size() && backgroundMsPerSample_[level] > 0) {
        double ratio = 1;
        uint64_t latest = 0;
        for (size_t i = 0; i < msPerSample_.size() && i < backgroundMsPerSample_.size(); ++i)
            if (msPerSample_[i] > 0 && backgroundMsPerSample_[i] > 0 && recordedAt_[i] > latest) {
                latest = recordedAt_[i];
                ratio = msPerSample_[i] / backgroundMsPerSample_[i];
            }
        return backgroundMsPerSample_[level] * ratio * samples;
    }
    // The nearest measured level's cost, else the initial guess.
    for (size_t d = 0; d < msPerSample_.size(); ++d) {
        if (level >= d && msPerSample_[level - d] > 0) return msPerSample_[level - d] * samples;
        if (level + d < msPerSample_.size() && msPerSample_[level + d] > 0) return msPerSample_[level + d] * samples;
    }
    return kInitialMsPerSample * samples;
}

} // namespace volcast::server
