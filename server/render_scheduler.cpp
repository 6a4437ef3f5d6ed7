#include "server/render_scheduler.hpp"

#include "renderer/error_metrics.hpp"
#include "renderer/reference_renderer.hpp"
#include "server/frame_encoder.hpp"

#include <spdlog/spdlog.h>

#include <cmath>
#include <sstream>

namespace volcast::server {

namespace {
using Ms = std::chrono::duration<double, std::milli>;

nlohmann::json qualityToJson(const Quality &q) {
    Scene s;
    s.volume = "-";
    s.quality = q;
    return nlohmann::json::parse(sceneToJson(s)).at("quality");
}

// The calibration renders this small: the reference integrator is ~1000x slower than a frame.
constexpr int kCalibrationSide = 32;                         // pixels, the longer side
constexpr double kCalibrationTolerance = 1e-4;               // far below the levels' errors (~1e-2..1e-3)
constexpr size_t kMaxCalibratedVoxels = size_t(256) * 256 * 256;   // the cubic reference prefilters in double
constexpr size_t kMaxCalibrations = 256;                     // cached keys before the cache is cleared
} // namespace

RenderScheduler::RenderScheduler(Metrics &metrics, SchedulerOptions options) : metrics_(metrics), options_(options) {
    worker_ = std::thread([this] { workerLoop(); });
}

RenderScheduler::~RenderScheduler() { stop(); }

void RenderScheduler::stop() {
    {
        std::lock_guard lock(mutex_);
        stopping_ = true;
    }
    wake_.notify_all();
    if (worker_.joinable()) worker_.join();
}

RenderScheduler::SlotId RenderScheduler::addSession(Deliver deliver, Failed failed) {
    std::lock_guard lock(mutex_);
    const SlotId id = nextId_++;
    Slot &s = slots_[id];
    s.deliver = std::move(deliver);
    s.failed = std::move(failed);
    s.lastInput = Clock::now();
    return id;
}

void RenderScheduler::removeSession(SlotId slot) {
    std::lock_guard lock(mutex_);
    slots_.erase(slot);
}

void RenderScheduler::submit(SlotId slot, std::shared_ptr<const ViewJob> job) {
    {
        std::lock_guard lock(mutex_);
        auto it = slots_.find(slot);
        if (it == slots_.end()) return;
        Slot &s = it->second;
        s.job = std::move(job);
        ++s.generation;
        s.sentLevel = -1;
        s.finalSent = false;
        s.lastInput = Clock::now();
    }
    wake_.notify_all();
}

void RenderScheduler::setInteracting(SlotId slot, bool interacting) {
    {
        std::lock_guard lock(mutex_);
        auto it = slots_.find(slot);
        if (it == slots_.end()) return;
        Slot &s = it->second;
        const auto now = Clock::now();
        // interaction_end means the user let go: refine now rather than after the idle time.
        // interaction_start holds refinement back until the pointer rests for the idle time.
        if (s.interacting && !interacting)
            s.lastInput = now - std::chrono::duration_cast<Clock::duration>(Ms(options_.idleMs));
        else if (interacting)
            s.lastInput = now;
        s.interacting = interacting;
    }
    wake_.notify_all();
}

void RenderScheduler::frameDone(SlotId slot) {
    {
        std::lock_guard lock(mutex_);
        auto it = slots_.find(slot);
        if (it == slots_.end()) return;
        it->second.inFlight = false;
    }
    wake_.notify_all();
}

bool RenderScheduler::nextWork(SlotId id, Slot &s, Clock::time_point now, Work &work, Clock::time_point &wakeAt) {
    if (s.inFlight || !s.job || s.finalSent) return false;
    const ViewJob &job = *s.job;
    const int last = int(job.ladder.size()) - 1;
    work.slot = id;
    work.job = s.job;
    work.generation = s.generation;
    if (job.stillOnly) {
        work.level = last;
        work.final = true;
        return true;
    }
    const auto refineAt = s.lastInput + std::chrono::duration_cast<Clock::duration>(Ms(options_.idleMs));
    const bool still = now >= refineAt;
    if (s.sentLevel < 0) {
        if (last == 0 && still) {   // an explicit policy, already still: straight to the final frame
            work.level = 0;
            work.final = true;
            return true;
        }
        // The interactive level: the finest non-final one predicted to fit the target.
        if (s.timerLadderSize != job.ladder.size()) {
            s.timer.reset(job.ladder.size());
            s.timerLadderSize = job.ladder.size();
        }
        std::vector<double> samples;
        for (const Level &l : job.ladder)
            samples.push_back(predictedSamples(*job.volume->volume, l.quality, job.width, job.height));
        work.level = last == 0 ? 0 : int(s.timer.choose(size_t(last), job.targetFrameMs, samples));
        work.final = false;
        return true;
    }
    if (!still) {
        wakeAt = std::min(wakeAt, refineAt);
        return false;
    }
    std::vector<double> predictedMs;
    for (size_t i = 0; i < job.ladder.size(); ++i) {
        const Level &l = job.ladder[i];
        predictedMs.push_back(
            s.timer.predictMs(i, predictedSamples(*job.volume->volume, l.quality, job.width, job.height)) * l.passes);
    }
    work.level = int(nextRefinementLevel(size_t(std::max(s.sentLevel, 0)), predictedMs));
    work.final = work.level == last;
    return true;
}

void RenderScheduler::workerLoop() {
    std::unique_lock lock(mutex_);
    while (!stopping_) {
        const auto now = Clock::now();
        Work work;
        bool found = false;
        auto wakeAt = Clock::time_point::max();
        // Round robin: the sessions after the one served last, then from the start.
        for (auto it = slots_.upper_bound(lastServed_); !found && it != slots_.end(); ++it)
            found = nextWork(it->first, it->second, now, work, wakeAt);
        for (auto it = slots_.begin(); !found && it != slots_.end() && it->first <= lastServed_; ++it)
            found = nextWork(it->first, it->second, now, work, wakeAt);
        if (found) {
            lastServed_ = work.slot;
            slots_[work.slot].inFlight = true;
            lock.unlock();
            // The worker thread's one boundary: nothing thrown here may end the thread (every
            // session would wait for frames forever) or the process.
            try {
                render(work);
            } catch (const std::exception &e) {
                spdlog::error("render worker: {}", e.what());
                try {
                    renderFailed(work, std::string("internal error: ") + e.what());
                } catch (const std::exception &again) {
                    spdlog::error("render worker: telling the session failed too: {}", again.what());
                }
            }
            lock.lock();
            continue;
        }
        // Nothing to render now: calibrate the newest view's error estimates.
        if (toCalibrate_) {
            auto job = std::move(toCalibrate_);
            toCalibrate_.reset();
            lock.unlock();
            try {
                calibrate(*job, calibrationKey(*job));
            } catch (const std::exception &e) {
                spdlog::error("render worker: calibration: {}", e.what());
            }
            lock.lock();
            continue;
        }
        if (wakeAt == Clock::time_point::max())
            wake_.wait(lock);
        else
            wake_.wait_until(lock, wakeAt);
    }
}

bool RenderScheduler::stale(const Work &work) {
    std::lock_guard lock(mutex_);
    auto it = slots_.find(work.slot);
    return stopping_ || it == slots_.end() || it->second.generation != work.generation;
}

void RenderScheduler::render(const Work &work) {
    const ViewJob &job = *work.job;
    const Level &level = job.ladder[size_t(work.level)];
    FrameRenderer &renderer = *job.volume->renderer;
    const bool firstOfView = [&] {
        std::lock_guard lock(mutex_);
        auto it = slots_.find(work.slot);
        return it != slots_.end() && it->second.sentLevel < 0 && it->second.generation == work.generation;
    }();
    RenderStats stats;
    const auto t0 = Clock::now();
    Image image;
    bool cancelled = false;
    double kernelMs = 0;
    try {
        if (level.passes <= 1) {
            image = renderer.render(job.transferFunction, job.camera, job.width, job.height, level.quality,
                                    job.clipPlanes, &stats);
            kernelMs = stats.renderSeconds * 1e3;
        } else {
            // Several jittered passes, averaged: each pass moves the sample positions, so the
            // onion rings of one pass average out; new input cancels between passes.
            for (int k = 0; k < level.passes && !cancelled; ++k) {
                Quality q = level.quality;
                q.jitter = true;
                q.seed = level.quality.seed + uint64_t(k);
                Image pass = renderer.render(job.transferFunction, job.camera, job.width, job.height, q,
                                             job.clipPlanes, &stats);
                kernelMs += stats.renderSeconds * 1e3;
                if (k == 0)
                    image = std::move(pass);
                else
                    for (size_t i = 0; i < image.rgba.size(); ++i) image.rgba[i] += pass.rgba[i];
                cancelled = k + 1 < level.passes && stale(work);
            }
            for (float &v : image.rgba) v /= float(level.passes);
        }
    } catch (const std::exception &e) {
        spdlog::error("render failed: {}", e.what());
        renderFailed(work, e.what());
        return;
    }
    const double renderMs = Ms(Clock::now() - t0).count();

    RenderedFrame frame;
    if (!cancelled && !(stale(work) && !firstOfView)) {
        const auto t1 = Clock::now();
        try {
            frame.image = work.final ? encodePng(image) : encodeJpeg(image, level.jpegQuality);
        } catch (const std::exception &e) {
            // Like a render failure: tell the client once and stop, rather than re-render the
            // view forever with nothing to show for it.
            spdlog::error("encoding failed: {}", e.what());
            renderFailed(work, std::string("encoding the frame failed: ") + e.what());
            return;
        }
        const double encodeMs = Ms(Clock::now() - t1).count();
        protocol::FrameHeader &h = frame.header;
        h.request = job.request;
        h.level = work.level;
        h.quality = qualityToJson(level.quality);
        if (level.passes > 1) h.quality["jitter"] = true;
        h.width = image.width;
        h.height = image.height;
        h.codec = work.final ? protocol::Codec::Png : protocol::Codec::Jpeg;
        h.renderMs = renderMs;
        h.encodeMs = encodeMs;
        h.final = work.final;
        h.camera = job.cameraJson;
        if (auto it = calibrations_.find(calibrationKey(job));
            it != calibrations_.end() && size_t(work.level) < it->second.rmse.size())
            h.error = protocol::ErrorEstimate{it->second.rmse[size_t(work.level)], "calibrated_vs_reference"};
    }

    Deliver deliver;
    {
        std::lock_guard lock(mutex_);
        auto it = slots_.find(work.slot);
        if (it == slots_.end()) return;
        Slot &s = it->second;
        const bool isStale = s.generation != work.generation;
        // A refined frame made stale by newer input is dropped; the first (interactive) frame
        // of a view is delivered anyway: it is the newest picture the client can have.
        if (cancelled || (isStale && !firstOfView) || frame.image.empty()) {
            s.inFlight = false;
            if (isStale) metrics_.frameDroppedStale();
            wake_.notify_all();
            return;
        }
        if (!isStale) {
            s.sentLevel = std::max(s.sentLevel, work.level);
            s.finalSent = work.final;
        }
        if (size_t(work.level) < s.timerLadderSize)
            s.timer.record(size_t(work.level), kernelMs,
                           predictedSamples(*job.volume->volume, level.quality, job.width, job.height) *
                               double(level.passes));
        if (options_.errorCalibration && !frame.header.error && !job.stillOnly) toCalibrate_ = work.job;
        deliver = s.deliver;
    }
    deliver(std::move(frame));
}

void RenderScheduler::renderFailed(const Work &work, const std::string &message) {
    Failed failed;
    {
        std::lock_guard lock(mutex_);
        auto it = slots_.find(work.slot);
        if (it == slots_.end()) return;
        it->second.inFlight = false;
        it->second.finalSent = true;   // do not retry the same view in a loop
        failed = it->second.failed;
    }
    wake_.notify_all();
    failed(message, work.job->request);
}

std::string RenderScheduler::calibrationKey(const ViewJob &job) const {
    std::ostringstream key;
    key << static_cast<const void *>(job.volume.get()) << '|';
    Scene s;
    s.volume = "-";
    s.transferFunction = job.transferFunction;
    s.clipPlanes = job.clipPlanes;
    key << sceneToJson(s);
    for (const Level &l : job.ladder) key << '|' << qualityToJson(l.quality).dump();
    return key.str();
}

void RenderScheduler::calibrate(const ViewJob &job, const std::string &key) {
    if (calibrations_.count(key)) return;
    if (calibrations_.size() >= kMaxCalibrations) calibrations_.clear();
    Calibration &c = calibrations_[key];   // empty (no estimates) if it cannot be measured
    const Volume &volume = *job.volume->volume;
    if (volume.voxelCount() > kMaxCalibratedVoxels) return;
    try {
        const auto t0 = Clock::now();
        const int w = job.width >= job.height ? kCalibrationSide
                                              : std::max(4, int(std::lround(kCalibrationSide * double(job.width) / job.height)));
        const int h = job.width >= job.height ? std::max(4, int(std::lround(kCalibrationSide * double(job.height) / job.width)))
                                              : kCalibrationSide;
        const Quality &final = job.ladder.back().quality;
        ReferenceRenderer reference(volume, job.transferFunction,
                                    final.interpolation == Interpolation::Cubic ? Reconstruction::Cubic
                                                                                : Reconstruction::Linear);
        reference.setShading(final.shading);
        ReferenceOptions options;
        options.tolerance = kCalibrationTolerance;
        const Image exact = reference.render(job.camera, w, h, job.clipPlanes, options);
        std::vector<double> rmse;
        for (const Level &l : job.ladder) {
            const Image img = job.volume->renderer->render(job.transferFunction, job.camera, w, h, l.quality, job.clipPlanes);
            rmse.push_back(compareImages(img, exact).rmse);
        }
        c.rmse = std::move(rmse);
        spdlog::debug("calibrated {} levels of {} in {:.0f} ms", c.rmse.size(), job.volume->name,
                      Ms(Clock::now() - t0).count());
    } catch (const std::exception &e) {
        spdlog::warn("error calibration failed: {}", e.what());
    }
}

} // namespace volcast::server
