#include "server/quality_ladder.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>

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
        candidates.push_back({q, 1, jpegQuality, {}});
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
    candidates.push_back({f, f.jitter ? jitterPasses : 1, kFinalJpegQuality, {}});
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

size_t nextRefinementLevel(size_t sent, const std::vector<LevelOutlook> &levels, const std::vector<bool> &shown) {
    if (levels.empty()) return 0;
    const size_t last = levels.size() - 1;
    if (sent >= last) return last;
    std::vector<size_t> better;
    for (size_t i = 0; i < last; ++i) {
        if (i == sent || (i < shown.size() && shown[i]) || 2 * levels[i].predictedMs > levels[last].predictedMs)
            continue;
        const bool measured = levels[i].error && levels[sent].error;
        if (measured ? *levels[i].error < *levels[sent].error : i > sent) better.push_back(i);
    }
    return bestOf(levels, better).value_or(last);
}

std::vector<Level> explicitLadder(const Quality &quality, int jitterPasses) {
    return {{quality, quality.jitter ? jitterPasses : 1, 85, {}}};
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

double requestBytes(const Level &level, int width, int height) {
    const double scale = level.quality.imageScale;
    return double(width) * double(height) * scale * scale * 16.0 * double(level.passes);
}

namespace {
// A number for the user: up to three significant digits ("0.25", "4", "1.5").
std::string shortNumber(double x) {
    char buffer[32];
    std::snprintf(buffer, sizeof buffer, "%.3g", x);
    return buffer;
}

// The largest image scale, in hundredths, at or below `scale`: a readable number whose
// prediction is at or under what `scale` was computed to allow.
double hundredthsBelow(double scale) { return std::max(0.01, std::floor(scale * 100 + 1e-9) / 100); }
} // namespace

std::vector<Level> fitToLimits(std::vector<Level> ladder, const Volume *volume, int width, int height,
                               const AdmissionLimits &limits) {
    const auto samplesOf = [&](const Quality &q) {
        return volume ? predictedSamples(*volume, q, width, height) : 0.0;
    };
    const auto bytesFit = [&](const Level &l) { return requestBytes(l, width, height) <= limits.maxRequestBytes; };
    const auto samplesFit = [&](const Quality &q) { return samplesOf(q) <= limits.maxSamplesPerFrame; };
    // The largest scale at or below q's that both limits allow at q's step (prediction ∝ scale²).
    const auto scaleAllowed = [&](const Level &l) {
        double s = l.quality.imageScale;
        const double bytes = requestBytes(l, width, height);
        if (bytes > limits.maxRequestBytes) s = std::min(s, l.quality.imageScale * std::sqrt(limits.maxRequestBytes / bytes));
        const double samples = samplesOf(l.quality);
        if (samples > limits.maxSamplesPerFrame)
            s = std::min(s, l.quality.imageScale * std::sqrt(limits.maxSamplesPerFrame / samples));
        return s;
    };
    for (Level &level : ladder) {
        if (bytesFit(level) && samplesFit(level.quality)) continue;
        const Quality own = level.quality;
        const bool memory = !bytesFit(level);
        Level l = level;
        const double scale = scaleAllowed(l);
        if (scale >= kMinFittedImageScale || scale >= own.imageScale) {
            l.quality.imageScale = hundredthsBelow(scale);
        } else {
            // A quarter of the pixels at most is taken from the picture; then a coarser step.
            l.quality.imageScale = std::min(own.imageScale, kMinFittedImageScale);
            while (bytesFit(l) && !samplesFit(l.quality) && l.quality.step < own.step * kMaxFittedStepFactor) {
                l.quality.step *= 2;
                // The mip level a step of 2^m level-0 voxels allows (the ladder's rule), at most its coarsest.
                while (l.quality.mipLevel < 2 && l.quality.step >= double(2 << l.quality.mipLevel)) ++l.quality.mipLevel;
            }
            if (!(bytesFit(l) && samplesFit(l.quality))) l.quality.imageScale = hundredthsBelow(scaleAllowed(l));
        }
        std::string what = "image scale " + shortNumber(l.quality.imageScale);
        if (l.quality.step != own.step) what += ", step " + shortNumber(l.quality.step);
        if (l.quality.mipLevel != own.mipLevel) what += ", mip level " + std::to_string(l.quality.mipLevel);
        const bool both = memory && volume && samplesOf(own) > limits.maxSamplesPerFrame;
        l.limited = what + " to stay within the server's " +
                    (both ? "per-frame and image-memory limits" : memory ? "image-memory limit" : "per-frame limit");
        level = std::move(l);
    }
    // A lowered level may now equal a cheaper one: one of them is enough.
    std::vector<Level> out;
    for (size_t i = 0; i < ladder.size(); ++i) {
        const bool last = i + 1 == ladder.size();
        bool repeated = false;
        for (const Level &kept : out) repeated = repeated || (kept.quality == ladder[i].quality && kept.passes == ladder[i].passes);
        if (!last && (repeated || (ladder[i].quality == ladder.back().quality && ladder[i].passes == ladder.back().passes)))
            continue;
        out.push_back(std::move(ladder[i]));
    }
    return out;
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
