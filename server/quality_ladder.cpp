#include "server/quality_ladder.hpp"

#include <algorithm>
#include <cmath>

namespace volcast::server {

std::vector<Level> automaticLadder(const Quality &f, int jitterPasses) {
    std::vector<Level> ladder;
    Quality q = f;
    q.jitter = false;
    q.preintegrated = false;
    q.interpolation = Interpolation::Linear;
    q.shading = f.shading;

    // The cheapest: 1/16 of the rays on the quarter-resolution mip, for big viewports on slow devices.
    Quality lq = q;
    lq.step = std::max(4.0, 8 * f.step);
    lq.mipLevel = std::max(2, f.mipLevel);
    lq.imageScale = std::min(0.25, f.imageScale);
    lq.earlyTermination = std::min(0.9, f.earlyTermination);
    ladder.push_back({lq, 1, 50});

    Quality l0 = q;
    l0.step = std::max(2.0, 4 * f.step);
    l0.mipLevel = std::max(1, f.mipLevel);
    l0.imageScale = std::min(0.5, f.imageScale);
    l0.earlyTermination = std::min(0.95, f.earlyTermination);
    ladder.push_back({l0, 1, 60});

    Quality l1 = q;
    l1.step = std::max(1.0, 2 * f.step);
    l1.imageScale = std::min(0.5, f.imageScale);
    l1.earlyTermination = std::min(0.98, f.earlyTermination);
    ladder.push_back({l1, 1, 70});

    // Jitter hides the onion rings of the coarser step until the final level replaces it.
    Quality l2 = q;
    l2.step = 2 * f.step;
    l2.preintegrated = f.preintegrated;
    l2.jitter = !f.preintegrated;
    ladder.push_back({l2, 1, 80});

    ladder.push_back({f, f.jitter ? jitterPasses : 1, 90});

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
    const double scale = double(1 << std::min(q.mipLevel, 16));
    const Vec3d d = Vec3d(volume.dims);
    const double diagonalVoxels = std::sqrt(d.x * d.x + d.y * d.y + d.z * d.z) / scale;
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
