#include "server/render_scheduler.hpp"

#include "server/frame_encoder.hpp"

#include <spdlog/spdlog.h>

#include <algorithm>
#include <cmath>
#include <sstream>
#include <stdexcept>

namespace volcast::server {

namespace {
using Ms = std::chrono::duration<double, std::milli>;

// Everything a level's error depends on besides the camera: volume, transfer function,
// clip planes, the ladder and the frame size. The volume by its registry id, which is never
// reused (an address would be, by the next volume loaded after an eviction).
std::string calibrationKey(const ViewJob &job) {
    std::ostringstream key;
    key << job.volumeId << '|' << job.width << 'x' << job.height << '|';
    Scene tf;
    tf.transferFunction = job.transferFunction;
    key << transferFunctionToJson(tf).dump() << '|' << clipPlanesToJson(job.clipPlanes).dump();
    for (const Level &l : job.ladder) key << '|' << qualityToJson(l.quality).dump() << 'x' << l.passes;
    return key.str();
}

std::string preparationTask(const Quality &q) {
    std::string task;
    const auto add = [&](const char *what) {
        if (!task.empty()) task += ',';
        task += what;
    };
    if (q.interpolation == Interpolation::Cubic) add("bspline_coefficients");
    if (q.preintegrated) add("preintegration_table");
    if (q.shading) add("shading_kernel");
    return task;
}
} // namespace

// ---- A slot's life ------------------------------------------------------------------------

namespace {
using S = SlotState;
using E = SlotEvent;
// The same rows as server/README.md's table "A slot's life" (the test walks both).
constexpr SlotTransition kSlotTransitions[] = {
    {S::NoView, E::NewView, S::ViewWaiting, "keep the view"},
    {S::NoView, E::NewStill, S::ViewWaiting, "keep the view"},
    {S::ViewWaiting, E::NewView, S::ViewWaiting, "the newer view replaces the waiting one"},
    {S::ViewWaiting, E::NewStill, S::ViewWaiting, "the newer view replaces the waiting one"},
    {S::ViewWaiting, E::StartInteractive, S::InteractiveUnderWay, "plan the interactive level's frame"},
    {S::ViewWaiting, E::StartLevel, S::LevelUnderWay, "plan the final frame (a still, or a one-level ladder at rest)"},
    {S::ViewWaiting, E::FrameRendered, S::WithSession,
     "deliver a first frame whose last unit ran while a newer view dropped it: the newest picture there is"},
    {S::InteractiveUnderWay, E::NewView, S::InteractiveUnderWay,
     "keep rendering the frame (of the older view): input faster than a frame must not starve the drag"},
    {S::InteractiveUnderWay, E::NewStill, S::ViewWaiting, "drop the frame"},
    {S::InteractiveUnderWay, E::FrameRendered, S::WithSession, "deliver it (stale or not), count an interactive frame"},
    {S::InteractiveUnderWay, E::RenderFailed, S::Failed, "tell the session (render_failed)"},
    {S::InteractiveUnderWay, E::RenderFailed, S::ViewWaiting,
     "the failed frame was an older view's: the new view's frame comes next, nothing told"},
    {S::LevelUnderWay, E::NewView, S::ViewWaiting, "drop the frame at the end of its unit (cancellation)"},
    {S::LevelUnderWay, E::NewStill, S::ViewWaiting, "drop the frame at the end of its unit (cancellation)"},
    {S::LevelUnderWay, E::FrameRendered, S::WithSession, "deliver it"},
    {S::LevelUnderWay, E::RenderFailed, S::Failed, "tell the session (render_failed)"},
    {S::WithSession, E::NewView, S::WithSession, "keep the view; its frame waits for the write"},
    {S::WithSession, E::NewStill, S::WithSession, "keep the view; its frame waits for the write"},
    {S::WithSession, E::FrameWritten, S::ViewWaiting, "a newer view came meanwhile: its first frame next"},
    {S::WithSession, E::FrameWritten, S::LevelShown, "a level below the final was written: refine after the idle time"},
    {S::WithSession, E::FrameWritten, S::FinalShown, "the final frame was written: calibrate, rest"},
    {S::WithSession, E::RenderFailed, S::Failed, "the frame never reached the session: tell it (render_failed)"},
    {S::WithSession, E::RenderFailed, S::ViewWaiting,
     "the frame never reached the session, but a newer view came: its first frame next"},
    {S::LevelShown, E::NewView, S::ViewWaiting, "keep the view"},
    {S::LevelShown, E::NewStill, S::ViewWaiting, "keep the view"},
    {S::LevelShown, E::StartLevel, S::LevelUnderWay, "plan the next refinement level's frame"},
    {S::FinalShown, E::NewView, S::ViewWaiting, "keep the view; no render-time credit for the rest"},
    {S::FinalShown, E::NewStill, S::ViewWaiting, "keep the view; no render-time credit for the rest"},
    {S::FinalShown, E::StartRest, S::RestUnderWay,
     "plan a pass at rest: the final's step halved once more, when the server has nothing else to render"},
    {S::RestUnderWay, E::NewView, S::ViewWaiting, "drop the pass at the end of its unit (cancellation)"},
    {S::RestUnderWay, E::NewStill, S::ViewWaiting, "drop the pass at the end of its unit (cancellation)"},
    {S::RestUnderWay, E::FrameRendered, S::WithSession, "deliver it: its 8-bit image differs from the frame shown"},
    {S::RestUnderWay, E::RestUnchanged, S::FinalShown, "no 8-bit pixel changed: nothing sent, refine on"},
    {S::RestUnderWay, E::RenderFailed, S::FinalShown, "stop refining at rest: the final frame stays shown"},
    {S::Failed, E::NewView, S::ViewWaiting, "keep the view; no render-time credit for the rest"},
    {S::Failed, E::NewStill, S::ViewWaiting, "keep the view; no render-time credit for the rest"},
};

bool underWayState(SlotState s) {
    return s == S::InteractiveUnderWay || s == S::LevelUnderWay || s == S::RestUnderWay;
}
} // namespace

std::span<const SlotTransition> slotTransitions() { return kSlotTransitions; }

int slotTransitionRow(SlotState from, SlotEvent event, SlotState to) {
    for (size_t i = 0; i < std::size(kSlotTransitions); ++i) {
        const SlotTransition &t = kSlotTransitions[i];
        if (t.from == from && t.event == event && t.to == to) return int(i);
    }
    return -1;
}

const char *toString(SlotState state) {
    switch (state) {
    case S::NoView: return "NoView";
    case S::ViewWaiting: return "ViewWaiting";
    case S::InteractiveUnderWay: return "InteractiveUnderWay";
    case S::LevelUnderWay: return "LevelUnderWay";
    case S::WithSession: return "WithSession";
    case S::LevelShown: return "LevelShown";
    case S::FinalShown: return "FinalShown";
    case S::RestUnderWay: return "RestUnderWay";
    case S::Failed: return "Failed";
    }
    return "?";
}

const char *toString(SlotEvent event) {
    switch (event) {
    case E::NewView: return "NewView";
    case E::NewStill: return "NewStill";
    case E::StartInteractive: return "StartInteractive";
    case E::StartLevel: return "StartLevel";
    case E::FrameRendered: return "FrameRendered";
    case E::RenderFailed: return "RenderFailed";
    case E::FrameWritten: return "FrameWritten";
    case E::StartRest: return "StartRest";
    case E::RestUnchanged: return "RestUnchanged";
    }
    return "?";
}

bool RenderScheduler::moveTo(Slot &s, SlotEvent event, SlotState to) {
    const int row = slotTransitionRow(s.state, event, to);
    if (row < 0) {
        // A bug: the slot would reach a state nobody designed. Keep the one it has.
        spdlog::error("render scheduler: refused slot transition {} --{}--> {}", toString(s.state), toString(event),
                      toString(to));
        ++refusedTransitions_;   // the tests check that it stays 0
        return false;
    }
    ++transitionCounts_[size_t(row)];
    if (!underWayState(to)) s.underWay.reset();
    s.state = to;
    return true;
}

bool RenderScheduler::viewDone(const Slot &s) {
    return s.state == S::FinalShown || s.state == S::RestUnderWay || s.state == S::Failed ||
           (s.state == S::WithSession && s.delivery.final && s.delivery.generation == s.generation);
}

SlotState RenderScheduler::slotState(SlotId slot) const {
    std::lock_guard lock(mutex_);
    const auto it = slots_.find(slot);
    return it == slots_.end() ? S::NoView : it->second.state;
}

std::vector<uint64_t> RenderScheduler::transitionCounts() const {
    std::lock_guard lock(mutex_);
    return transitionCounts_;
}

uint64_t RenderScheduler::refusedTransitions() const {
    std::lock_guard lock(mutex_);
    return refusedTransitions_;
}

void RenderScheduler::setUnitObserver(std::function<void(double)> observer) {
    std::lock_guard lock(mutex_);
    unitObserver_ = std::move(observer);
}

// ---- Preparation keys -----------------------------------------------------------------------

std::string preparationKey(uint64_t volumeId, const TransferFunction &tf, const Quality &q) {
    if (q.interpolation != Interpolation::Cubic && !q.preintegrated && !q.shading) return "";
    std::ostringstream key;
    key << "prepare " << volumeId << " mip" << q.mipLevel << (q.interpolation == Interpolation::Cubic ? " cubic" : "")
        << (q.shading ? " shading" : "");
    if (q.preintegrated) {
        // The table depends on the transfer function and the step.
        Scene s;
        s.transferFunction = tf;
        key << " preintegrated step " << q.step << ' ' << transferFunctionToJson(s).dump();
    }
    return key.str();
}

Quality plainQuality(const Quality &q) {
    Quality p = q;
    p.interpolation = Interpolation::Linear;
    p.preintegrated = false;
    p.shading = false;
    return p;
}

std::shared_ptr<FrameRenderer> rendererOf(const std::shared_ptr<VolumeEntry> &entry) {
    return std::shared_ptr<FrameRenderer>(entry, entry->renderer.get());
}

RenderScheduler::RenderScheduler(Metrics &metrics, SchedulerOptions options)
    : metrics_(metrics), options_(options),
      calibrator_(preprocess_, options.errorCalibration, [this] {
          std::lock_guard lock(mutex_);
          return draggingCount() > 0;
      }),
      transitionCounts_(std::size(kSlotTransitions), 0) {
    worker_ = std::thread([this] { workerLoop(); });
}

RenderScheduler::~RenderScheduler() { stop(); }

void RenderScheduler::stop() {
    {
        std::lock_guard lock(mutex_);
        stopping_ = true;
    }
    wake_.notify_all();
    preprocess_.stop();
    if (worker_.joinable()) worker_.join();
}

double RenderScheduler::longestUnitMs() const {
    std::lock_guard lock(mutex_);
    return longestUnitMs_;
}

RenderScheduler::SlotId RenderScheduler::addSession(Deliver deliver, Failed failed, Progress progress) {
    std::lock_guard lock(mutex_);
    const SlotId id = nextId_++;
    const double least = leastServiceMs();
    const double leastFrames = leastInteractiveFrames();
    Slot &s = slots_[id];
    s.serviceMs = least;   // no head start over the sessions already there
    s.interactiveFrames = leastFrames;
    s.deliver = std::move(deliver);
    s.failed = std::move(failed);
    s.progress = std::move(progress);
    s.lastInput = Clock::now();
    return id;
}

void RenderScheduler::removeSession(SlotId slot) {
    std::lock_guard lock(mutex_);
    slots_.erase(slot);
}

void RenderScheduler::submit(SlotId slot, std::shared_ptr<const ViewJob> job) {
    auto calibration = std::make_shared<CalibrationView>();
    calibration->key = calibrationKey(*job);
    calibration->renderer = job->renderer;
    calibration->transferFunction = job->transferFunction;
    calibration->camera = job->camera;
    calibration->clipPlanes = job->clipPlanes;
    calibration->ladder = job->ladder;
    calibration->width = job->width;
    calibration->height = job->height;
    {
        std::lock_guard lock(mutex_);
        auto it = slots_.find(slot);
        if (it == slots_.end()) return;
        Slot &s = it->second;
        // Time without work is not credit to spend later at the others' expense.
        if (!s.job || viewDone(s)) {
            s.serviceMs = std::max(s.serviceMs, leastServiceMs());
            s.interactiveFrames = std::max(s.interactiveFrames, leastInteractiveFrames());
        }
        // An interactive frame under way is finished and delivered, stale or not: dropping
        // it would leave a client whose input comes faster than one frame renders (a loaded
        // server, a slow level) with no frame at all for as long as it drags. A refinement
        // or a final frame is dropped, and for a still the interactive frame too: the new
        // view's first frame comes next. A frame with the session waits for its write.
        const bool still = job->stillOnly;
        SlotState next = SlotState::ViewWaiting;
        if (s.state == SlotState::InteractiveUnderWay && !still) next = SlotState::InteractiveUnderWay;
        if (s.state == SlotState::WithSession) next = SlotState::WithSession;
        moveTo(s, still ? SlotEvent::NewStill : SlotEvent::NewView, next);
        s.job = std::move(job);
        s.calibration = std::move(calibration);
        ++s.generation;
        s.sentLevel = -1;
        s.levelsShown.clear();
        s.substituteSent = -1;
        s.levelImages.clear();
        s.rest = Rest();
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
        Slot &s = it->second;
        // Rest after the final frame, refine after a lower level, or start a view that came meanwhile.
        SlotState next = SlotState::ViewWaiting;
        if (s.delivery.generation == s.generation) next = s.delivery.final ? SlotState::FinalShown : SlotState::LevelShown;
        moveTo(s, SlotEvent::FrameWritten, next);
    }
    wake_.notify_all();
}

Quality RenderScheduler::renderable(SlotId id, Slot &s, const Quality &q, bool &substitute) {
    const ViewJob &job = *s.job;
    const std::string key = preparationKey(job.volumeId, job.transferFunction, q);
    substitute = !key.empty() && !preprocess_.ready(key);
    if (!substitute) return q;
    // Prepare it in the background with a one-ray render: the renderer builds and caches
    // what the quality needs (coefficients, table, kernel), then the level renders for real.
    Quality warm = q;
    warm.imageScale = 1;
    const bool queued = preprocess_.request(
        key, PreprocessWorker::Priority::Preparation,
        [this, renderer = job.renderer, tf = job.transferFunction, camera = job.camera, clip = job.clipPlanes,
         warm](const std::atomic<bool> &) {
            // The renderer is ours alone meanwhile: the render worker skips its sessions
            // rather than wait on its lock (which would hold every session's frames).
            const FrameRenderer *r = renderer.get();
            {
                std::unique_lock lock(mutex_);
                wake_.wait(lock, [&] { return rendering_ != r || stopping_; });
                if (stopping_) return;
                preparing_.insert(r);
            }
            struct Release {
                RenderScheduler &self;
                const FrameRenderer *r;
                ~Release() {
                    {
                        std::lock_guard lock(self.mutex_);
                        self.preparing_.erase(r);
                    }
                    self.wake_.notify_all();
                }
            } release{*this, r};
            renderer->render({tf, camera, 1, 1, warm, clip});
        },
        [this](const std::string &doneKey, bool) {
            std::vector<std::pair<Progress, protocol::ProgressMessage>> told;
            {
                std::lock_guard lock(mutex_);
                for (auto &[slotId, slot] : slots_)
                    if (auto a = slot.announced.find(doneKey); a != slot.announced.end()) {
                        const std::string task = a->second;
                        slot.announced.erase(a);
                        if (!slot.progress || !slot.job) continue;
                        protocol::ProgressMessage p;
                        p.id = slot.job->request;
                        p.volume = slot.job->volumeName;
                        p.stage = protocol::ProgressStage::Preprocessing;
                        p.task = task;
                        p.fraction = 1;
                        told.emplace_back(slot.progress, p);
                    }
            }
            wake_.notify_all();
            for (auto &[progress, message] : told) progress(message);
        });
    (void)queued;
    if (!s.announced.count(key) && s.progress) {
        s.announced[key] = preparationTask(q);
        protocol::ProgressMessage p;
        p.id = job.request;
        p.volume = job.volumeName;
        p.stage = protocol::ProgressStage::Preprocessing;
        p.task = preparationTask(q);
        p.fraction = 0;
        s.progress(p);   // only posts
    }
    (void)id;
    return plainQuality(q);
}

bool RenderScheduler::nextWork(Kind kind, SlotId id, Slot &s, Clock::time_point now, Work &work,
                               Clock::time_point &wakeAt) {
    // Only a slot waiting for its view's first frame, resting between levels or with a frame
    // under way has work; a frame with the session, a final frame shown or a failure has none.
    if (s.state != SlotState::ViewWaiting && s.state != SlotState::LevelShown && !underWayState(s.state)) return false;
    if (s.state == SlotState::RestUnderWay) return false;   // nextRestWork's
    const ViewJob &job = *s.job;
    // The renderer of the frame under way: an older view's while its interactive frame finishes.
    const ViewJob &underWay = s.underWay ? *s.underWay->job : job;
    if (preparing_.count(underWay.renderer.get())) return false;   // its preparation's end wakes us
    const int last = int(job.ladder.size()) - 1;
    const bool firstOfView = !job.stillOnly && s.sentLevel < 0 && s.substituteSent < 0;
    if ((kind == Kind::Interactive) != firstOfView) return false;
    work.kind = kind;
    work.slot = id;

    // A level's measured cost holds for its quality on this volume only: a level whose
    // quality changed (tricubic or shading ticked) forgets it, or its first frame is planned
    // at the old cost (a linear level's cost predicted a cubic, shaded one at a fifth).
    if (s.timerLadder.size() != job.ladder.size() || s.timerVolumeId != job.volumeId) {
        s.timer.reset(job.ladder.size());
        s.timerLadder.clear();
        for (const Level &l : job.ladder) s.timerLadder.push_back(l.quality);
        s.timerVolumeId = job.volumeId;
    }
    for (size_t i = 0; i < job.ladder.size(); ++i)
        if (!(s.timerLadder[i] == job.ladder[i].quality)) {
            s.timer.forget(i);
            s.timerLadder[i] = job.ladder[i].quality;
        }
    const auto samplesOf = [&](const Quality &q) { return predictedSamples(job.renderer->volume(), q, job.width, job.height); };

    if (!s.underWay) {
        // The view's error-against-time front: each level's measured error and predicted time
        // (the timer also plans this frame's cells from the background costs, below).
        ErrorCalibrator::LevelsMeasured measured;
        if (s.calibration) measured = calibrator_.levels(s.calibration->key, job.ladder.size());
        s.timer.setBackgroundCosts(measured.backgroundMsPerSample);
        const auto outlook = [&] {
            std::vector<LevelOutlook> levels(job.ladder.size());
            for (size_t i = 0; i < job.ladder.size(); ++i) {
                levels[i].predictedMs = s.timer.predictMs(i, samplesOf(job.ladder[i].quality)) * job.ladder[i].passes;
                if (i < measured.errors.size()) levels[i].error = measured.errors[i];
            }
            return levels;
        };
        const auto refineAt = stillSince(s);
        const bool still = now >= refineAt;
        int level = 0;
        if (job.stillOnly) {
            level = last;
        } else if (firstOfView) {
            if (last == 0 && still) {
                level = 0;   // an explicit policy, already still: straight to the final frame
            } else {
                // The interactive level: the lowest error predicted to fit the render budget
                // (interactiveBudgetMs, quality_ladder.hpp).
                // While a view is overdue, refinement takes kOverdueShare of the render time.
                const double targetMs = job.targetFrameMs * (overdueWaiting_ ? 1 - kOverdueShare : 1.0);
                const double renderBudgetMs =
                    interactiveBudgetMs(targetMs, sessionsDragging(), s.encodeMs, s.timer.deviationMs());
                level = last == 0 ? 0 : int(chooseInteractiveLevel(outlook(), renderBudgetMs));
            }
        } else {
            if (!still) {
                wakeAt = std::min(wakeAt, refineAt);
                return false;
            }
            level = int(nextRefinementLevel(size_t(std::max({s.sentLevel, s.substituteSent, 0})), outlook(),
                                            s.levelsShown));
            if (s.substituteSent >= level) {
                // Shown already without its preparation: wait for it (its completion wakes us).
                const std::string key = preparationKey(job.volumeId, job.transferFunction, job.ladder[size_t(level)].quality);
                if (!key.empty() && !preprocess_.ready(key)) return false;
            }
        }
        const Level &l = job.ladder[size_t(level)];
        const bool final = level == last && (job.stillOnly || !firstOfView || (last == 0 && still));
        bool substitute = false;
        const Quality q = renderable(id, s, l.quality, substitute);
        FrameUnderWay f;
        // A frame sent as a JPEG (all but the final PNG, whose floats the error calibration
        // reads) needs only its 8-bit bytes: TiledFrame renders them so when it can.
        const bool jpeg = !(final && !substitute);
        f.frame = std::make_shared<TiledFrame>(FrameRequest{job.transferFunction, job.camera, job.width, job.height, q,
                                               job.clipPlanes},
                                               substitute ? 1 : l.passes, job.renderer->bandRows(), jpeg);
        f.job = s.job;
        f.generation = s.generation;
        f.level = level;
        f.final = final;
        f.substitute = substitute;
        const bool interactive = firstOfView && !final;
        if (!moveTo(s, interactive ? SlotEvent::StartInteractive : SlotEvent::StartLevel,
                    interactive ? SlotState::InteractiveUnderWay : SlotState::LevelUnderWay))
            return false;
        s.underWay = std::move(f);
    }
    planCells(s, work);
    return true;
}

namespace {
constexpr double kRestUnitShare = 0.25;
} // namespace

void RenderScheduler::planCells(Slot &s, Work &work) {
    const FrameUnderWay &u = *s.underWay;
    const ViewJob &underWay = *u.job;
    work.job = u.job;
    work.generation = u.generation;
    const TiledFrame &frame = *u.frame;
    work.level = u.level;
    work.final = u.final && !u.substitute;
    work.substitute = u.substitute;
    work.quality = frame.quality();
    work.frame = u.frame;
    // As many cells as fit the unit at the cost measured by this frame's own units, else by
    // this level's earlier frames or its background calibration render; a level never
    // measured starts with one cell (a guess of the cost could be off a hundredfold, and a
    // unit must not overrun). A frame planned from
    // earlier frames' average that will not fit one unit starts with half the unit: its first
    // cells are the centre's, which cost more than the average. A renderer that cannot render
    // part of a frame cheaply renders each pass whole.
    const double rays = double(frame.gridWidth()) * frame.gridHeight();
    double msPerRay = frame.msPerRayEstimate();
    // A pass at rest is the server's spare time: its units are a quarter of the others', so
    // that another session's interactive frame waits for less of one.
    double budgetMs = work.kind == Kind::Rest ? options_.unitMs * kRestUnitShare : options_.unitMs;
    if (msPerRay == 0 && s.timer.known(size_t(work.level)) && !work.substitute) {
        msPerRay = s.timer.predictMs(size_t(work.level), predictedSamples(underWay.renderer->volume(), frame.quality(),
                                                                           underWay.width, underWay.height)) /
                   std::max(rays, 1.0);
        if (msPerRay * rays > budgetMs) budgetMs /= 2;
    }
    if (!underWay.renderer->rendersWindowsCheaply())
        work.cells = frame.cellsLeftInPass();
    else
        work.cells = std::min(frame.cellsLeftInPass(),
                              cellsForBudget(budgetMs, msPerRay, frame.cellRays(), frame.lastUnitCells()));
}

bool RenderScheduler::nextRestWork(SlotId id, Slot &s, Work &work) {
    if (options_.restRefinementMs <= 0 || !s.job) return false;
    if (s.state == SlotState::FinalShown) {
        const ViewJob &job = *s.job;
        if (s.rest.done || s.interacting || s.rest.previous.rgba.empty() || preparing_.count(job.renderer.get()))
            return false;
        // The final's quality with its step halved once more per pass, and early termination
        // moved to where what it leaves out is below the target.
        const Level &l = job.ladder.back();
        Quality q = l.quality;
        q.step = std::ldexp(l.quality.step, -(s.rest.passes + 1));
        q.earlyTermination = std::max(q.earlyTermination, kRestEarlyTermination);
        bool substitute = false;
        renderable(id, s, q, substitute);
        if (substitute) return false;   // its preparation runs first (a pre-integration table per step); it wakes us
        FrameUnderWay f;
        f.frame = std::make_shared<TiledFrame>(FrameRequest{job.transferFunction, job.camera, job.width, job.height, q,
                                                            job.clipPlanes},
                                               l.passes, job.renderer->bandRows(), false);
        f.job = s.job;
        f.generation = s.generation;
        f.level = int(job.ladder.size()) - 1;
        f.final = true;
        if (!moveTo(s, SlotEvent::StartRest, SlotState::RestUnderWay)) return false;
        s.underWay = std::move(f);
    } else if (s.state != SlotState::RestUnderWay) {
        return false;
    }
    work.kind = Kind::Rest;
    work.slot = id;
    planCells(s, work);
    return true;
}

bool RenderScheduler::anyoneActive(Clock::time_point now, Clock::time_point &wakeAt) const {
    const auto idle = std::chrono::duration_cast<Clock::duration>(Ms(options_.idleMs));
    bool active = draggingCount() > 0;
    for (const auto &[id, s] : slots_)
        if (s.job && now < s.lastInput + idle) {
            active = true;
            wakeAt = std::min(wakeAt, s.lastInput + idle);
        }
    return active;
}

size_t RenderScheduler::sessionsDragging() const { return std::max<size_t>(draggingCount(), 1); }

size_t RenderScheduler::draggingCount() const {
    size_t n = 0;
    for (const auto &[id, s] : slots_) {
        const bool awaitingInteractive = s.job && !s.job->stillOnly && s.sentLevel < 0 && s.substituteSent < 0 &&
                                         !viewDone(s);
        if (s.interacting || awaitingInteractive) ++n;
    }
    return n;
}

bool RenderScheduler::pickWork(Kind kind, Clock::time_point now, Work &work, Clock::time_point &wakeAt,
                               bool overdueOnly) {
    // The session with work that has had the least render time; ties in round-robin order
    // (the sessions after the one served last, then from the start). Least service rather
    // than plain turns: a session whose client answered a moment late gets the next unit
    // instead of losing its turn for a round.
    // Interactive frames are shared by count (dragging sessions get as many frames each,
    // whatever level each one's measured cost allows), refinement by render time, except that
    // overdue views come first, the one still the longest first: under load, least service
    // alone let views that came to rest later go ahead of an older one again and again (a
    // rest's final frame came after up to 3.9 s with 32 sessions, tests/soak/load.py).
    bool found = false;
    std::pair<int, double> least{0, 0.0};
    const auto consider = [&](SlotId id, Slot &s) {
        const bool overdue = kind == Kind::Refine && this->overdue(s, now);
        if (overdueOnly && !overdue) return;
        Work candidate;
        if (kind == Kind::Rest ? !nextRestWork(id, s, candidate) : !nextWork(kind, id, s, now, candidate, wakeAt)) return;
        const std::pair<int, double> key =
            overdue ? std::pair{0, Ms(stillSince(s).time_since_epoch()).count()}
                    : std::pair{1, kind == Kind::Interactive ? s.interactiveFrames
                                   : kind == Kind::Rest      ? s.rest.spentMs
                                                             : s.serviceMs};
        if (found && key >= least) return;
        found = true;
        least = key;
        work = std::move(candidate);
    };
    for (auto it = slots_.upper_bound(lastServed_); it != slots_.end(); ++it) consider(it->first, it->second);
    for (auto it = slots_.begin(); it != slots_.end() && it->first <= lastServed_; ++it) consider(it->first, it->second);
    return found;
}

RenderScheduler::Clock::time_point RenderScheduler::stillSince(const Slot &s) const {
    return s.lastInput + std::chrono::duration_cast<Clock::duration>(Ms(options_.idleMs));
}

bool RenderScheduler::overdue(const Slot &s, Clock::time_point now) const {
    const bool refining = s.state == SlotState::LevelShown || s.state == SlotState::LevelUnderWay ||
                          (s.state == SlotState::ViewWaiting && s.job && s.job->stillOnly);
    return refining && now >= stillSince(s) + std::chrono::duration_cast<Clock::duration>(Ms(options_.refineWaitMs));
}

double RenderScheduler::leastServiceMs() const {
    double least = -1;
    for (const auto &[id, s] : slots_)
        if (s.job && (least < 0 || s.serviceMs < least)) least = s.serviceMs;
    return std::max(least, 0.0);
}

double RenderScheduler::leastInteractiveFrames() const {
    double least = -1;
    for (const auto &[id, s] : slots_)
        if (s.job && (least < 0 || s.interactiveFrames < least)) least = s.interactiveFrames;
    return std::max(least, 0.0);
}

void RenderScheduler::workerLoop() {
    std::unique_lock lock(mutex_);
    while (!stopping_) {
        const auto now = Clock::now();
        Work work;
        auto wakeAt = Clock::time_point::max();
        // Every session's interactive frame before anyone's refinement, except that overdue
        // refinement takes kOverdueShare of the render time ahead of them: with others dragging
        // an interactive frame nearly always waits, and a resting view would stay blurry for as
        // long as they drag. A dragging frame then waits for at most one refinement unit, as it
        // may for a still's. Refinement at rest only when there is nothing else and no session
        // has had input within the idle time.
        overdueWaiting_ = std::any_of(slots_.begin(), slots_.end(), [&](const auto &e) { return overdue(e.second, now); });
        if (!overdueWaiting_) overdueCreditMs_ = 0;
        const bool overdueFirst = overdueCreditMs_ > 0 && pickWork(Kind::Refine, now, work, wakeAt, true);
        work.aheadOfInteractive = overdueFirst;
        const bool found = overdueFirst || pickWork(Kind::Interactive, now, work, wakeAt) ||
                           pickWork(Kind::Refine, now, work, wakeAt) ||
                           (!anyoneActive(now, wakeAt) && pickWork(Kind::Rest, now, work, wakeAt));
        if (found) {
            lastServed_ = work.slot;
            rendering_ = work.job->renderer.get();
            lock.unlock();
            // The worker thread's one boundary: nothing thrown may end the thread (every
            // session would wait for frames forever) or the process.
            try {
                runUnit(work);
            } catch (const std::exception &e) {
                spdlog::error("render failed: {}", e.what());
                try {
                    fail(work, e.what());
                } catch (const std::exception &again) {
                    spdlog::error("render worker: telling the session failed too: {}", again.what());
                }
            }
            lock.lock();
            rendering_ = nullptr;
            wake_.notify_all();   // a preparation may wait for this renderer
            continue;
        }
        if (wakeAt == Clock::time_point::max())
            wake_.wait(lock);
        else
            wake_.wait_until(lock, wakeAt);
    }
}

namespace {
// What every frame of a view's tiled frame says of itself.
protocol::FrameHeader headerOf(const ViewJob &job, int level, const TiledFrame &frame, int width, int height,
                               protocol::Codec codec, double encodeMs) {
    protocol::FrameHeader h;
    h.request = job.request;
    h.level = level;
    h.quality = qualityToJson(frame.quality());
    if (frame.passes() > 1) h.quality["jitter"] = true;
    h.width = width;
    h.height = height;
    h.viewWidth = job.width;
    h.viewHeight = job.height;
    h.codec = codec;
    h.renderMs = frame.renderMs();
    h.encodeMs = encodeMs;
    h.camera = job.cameraJson;
    return h;
}

// RMSE over RGB (premultiplied, clamped to [0, 1], as the frames show it over black) between
// two images of one size.
double rgbRmse(const Image &a, const Image &b) {
    double sum = 0;
    for (size_t i = 0; i < a.rgba.size(); i += 4)
        for (size_t c = 0; c < 3; ++c) {
            const double d = double(clampUnit(a.rgba[i + c])) - double(clampUnit(b.rgba[i + c]));
            sum += d * d;
        }
    return std::sqrt(sum / double(std::max<size_t>(a.rgba.size() / 4 * 3, 1)));
}
} // namespace

void RenderScheduler::runUnit(Work &work) {
    const ViewJob &job = *work.job;
    TiledFrame &frame = *work.frame;
    const double ms = frame.renderUnit(*job.renderer, work.cells);
    std::function<void(double)> observer;
    {
        std::lock_guard lock(mutex_);
        longestUnitMs_ = std::max(longestUnitMs_, ms);
        if (work.aheadOfInteractive)
            overdueCreditMs_ -= ms;
        else if (work.kind == Kind::Interactive && overdueWaiting_)
            overdueCreditMs_ = std::min(overdueCreditMs_ + ms * kOverdueShare / (1 - kOverdueShare), options_.unitMs);
        // Time at rest is the server's spare time: no debt against the session's next views.
        if (auto it = slots_.find(work.slot); it != slots_.end())
            (work.kind == Kind::Rest ? it->second.rest.spentMs : it->second.serviceMs) += ms;
        observer = unitObserver_;
    }
    if (observer) observer(ms);
    if (!frame.done()) return;
    if (work.kind == Kind::Rest) return finishRest(work);

    const Level &level = job.ladder[size_t(work.level)];
    const double samples = predictedSamples(job.renderer->volume(), frame.quality(), job.width, job.height);
    // Floats, or (a JPEG frame rendered as bytes: TiledFrame::rgba8) the bytes it encodes.
    Image image;
    Rgba8Image bytes;
    if (frame.rgba8())
        bytes = frame.finishRgba8();
    else
        image = frame.finish();
    {
        std::lock_guard lock(mutex_);
        auto it = slots_.find(work.slot);
        if (it == slots_.end()) return;
        Slot &s = it->second;
        // The first (interactive) frame of a view is delivered even if newer input came: it
        // is the newest picture the client can have. A refined one is dropped (a newer view
        // took the slot out of its under-way state already).
        if (s.generation != work.generation && work.kind != Kind::Interactive) {
            metrics_.frameDroppedStale();
            return;
        }
        // Timed at the quality it was rendered at: not onto a level whose quality changed meanwhile.
        if (!work.substitute && size_t(work.level) < s.timerLadder.size() &&
            s.timerLadder[size_t(work.level)] == frame.quality())
            s.timer.record(size_t(work.level), frame.renderMs(), samples * double(frame.passes()));
        if (work.kind == Kind::Interactive) ++s.interactiveFrames;
    }
    if (!work.substitute) {
        const std::string key = preparationKey(job.volumeId, job.transferFunction, frame.quality());
        if (!key.empty()) preprocess_.markReady(key);
    }

    RenderedFrame out;
    const auto t1 = Clock::now();
    try {
        if (work.final && frame.rgba8()) throw std::logic_error("a final frame rendered without its floats");
        out.image = work.final      ? encodePng(image)
                    : frame.rgba8() ? encodeJpeg(bytes, level.jpegQuality)
                                    : encodeJpeg(image, level.jpegQuality);
    } catch (const std::exception &e) {
        spdlog::error("encoding failed: {}", e.what());
        fail(work, std::string("encoding the frame failed: ") + e.what());
        return;
    }
    out.header = headerOf(job, work.level, frame, frame.rgba8() ? bytes.width : image.width,
                          frame.rgba8() ? bytes.height : image.height,
                          work.final ? protocol::Codec::Png : protocol::Codec::Jpeg, Ms(Clock::now() - t1).count());
    protocol::FrameHeader &h = out.header;
    h.final = work.final;
    h.limited = level.limited;

    // The final frame's image and bytes, which refinement at rest starts from: copied and
    // converted here, not under the lock.
    std::optional<Image> restBase;
    PixelVector<uint8_t> restShown;
    if (work.final && !work.substitute && options_.restRefinementMs > 0) {
        restBase = image;
        restShown = rgba8FromImage(image).rgba;
    }
    Deliver deliver;
    std::shared_ptr<const CalibrationView> calibration;
    std::vector<std::pair<int, std::vector<uint8_t>>> levelImages;
    uint64_t serial = 0;
    {
        std::lock_guard lock(mutex_);
        auto it = slots_.find(work.slot);
        if (it == slots_.end()) return;
        Slot &s = it->second;
        // The frame goes to the session: from its under-way state, or from ViewWaiting when a
        // newer view dropped it after its last unit began.
        if (!moveTo(s, SlotEvent::FrameRendered, SlotState::WithSession)) return;
        s.delivery = {work.frame.get(), work.generation, work.final};
        if (!work.substitute && s.calibration) h.error = calibrator_.estimate(s.calibration->key, work.level, work.final);
        if (!work.final) s.encodeMs = s.encodeMs == 0 ? h.encodeMs : 0.7 * s.encodeMs + 0.3 * h.encodeMs;
        if (s.generation == work.generation) {
            if (work.substitute)
                s.substituteSent = std::max(s.substituteSent, work.level);
            else {
                // The level shown last, not the highest: refinement may step to a cheaper
                // level with a lower measured error, and goes on from there.
                s.sentLevel = work.level;
                if (s.levelsShown.size() <= size_t(work.level)) s.levelsShown.resize(size_t(work.level) + 1);
                s.levelsShown[size_t(work.level)] = true;
            }
            if (restBase) {
                s.rest.previous = std::move(*restBase);   // what the first pass at rest is compared with
                s.rest.shown = std::move(restShown);
            }
            if (options_.errorCalibration && !work.substitute) {
                if (work.final) {
                    calibration = s.calibration;
                    levelImages = std::move(s.levelImages);
                    s.levelImages.clear();
                    serial = ++viewSerial_;
                } else {
                    s.levelImages.emplace_back(work.level, out.image);   // as the client sees it
                }
            }
        }
        deliver = s.deliver;
    }
    if (calibration) calibrator_.finalRendered(calibration, std::move(levelImages), toRgb8(image), serial);
    deliver(std::move(out));
}


void RenderScheduler::finishRest(Work &work) {
    const ViewJob &job = *work.job;
    TiledFrame &frame = *work.frame;
    Image image = frame.finish();
    protocol::ErrorEstimate estimate;
    int restPass = 0;
    PixelVector<uint8_t> bytes = rgba8FromImage(image).rgba;
    {
        std::lock_guard lock(mutex_);
        auto it = slots_.find(work.slot);
        if (it == slots_.end()) return;
        Slot &s = it->second;
        if (s.generation != work.generation || s.state != SlotState::RestUnderWay) {
            metrics_.frameDroppedStale();   // a new view took the slot
            return;
        }
        // The midpoint rule is second order: the error of a pass at half the step is a quarter
        // of the last one's, so the difference of the two is three times the new error
        // (Richardson). Its RMSE / 3 is the new frame's estimate.
        estimate.value = rgbRmse(image, s.rest.previous) / 3;
        estimate.method = "rmse_vs_previous_pass_over_3";
        restPass = ++s.rest.passes;
        s.rest.previous = image;
        s.rest.done = estimate.value <= kRestTargetError || s.rest.spentMs >= options_.restRefinementMs ||
                      s.rest.passes >= kMaxRestPasses;
        if (bytes == s.rest.shown) {
            moveTo(s, SlotEvent::RestUnchanged, SlotState::FinalShown);
            return;
        }
        s.rest.shown = bytes;
    }
    RenderedFrame out;
    const auto t1 = Clock::now();
    try {
        out.image = encodePng(image);
    } catch (const std::exception &e) {
        spdlog::error("encoding a frame at rest failed: {}", e.what());
        fail(work, std::string("encoding the frame failed: ") + e.what());
        return;
    }
    out.header = headerOf(job, work.level, frame, image.width, image.height, protocol::Codec::Png,
                          Ms(Clock::now() - t1).count());
    protocol::FrameHeader &h = out.header;
    h.final = false;   // the final level's frame came before; clients waiting for it are not fooled
    h.restPass = restPass;
    h.error = estimate;
    Deliver deliver;
    {
        std::lock_guard lock(mutex_);
        auto it = slots_.find(work.slot);
        if (it == slots_.end()) return;
        Slot &s = it->second;
        if (!moveTo(s, SlotEvent::FrameRendered, SlotState::WithSession)) return;
        s.delivery = {work.frame.get(), work.generation, true};
        deliver = s.deliver;
    }
    deliver(std::move(out));
}

void RenderScheduler::fail(const Work &work, const std::string &message) {
    Failed failed;
    {
        std::lock_guard lock(mutex_);
        auto it = slots_.find(work.slot);
        if (it == slots_.end()) return;
        Slot &s = it->second;
        // Only the slot's own frame, under way or with the session, fails the slot; one a newer
        // view dropped is forgotten.
        const bool underWay = s.underWay && s.underWay->frame == work.frame;
        const bool withSession = s.state == SlotState::WithSession && s.delivery.frame == work.frame.get();
        if (!underWay && !withSession) return;
        // A pass at rest that fails ends refinement at rest; the final frame stays shown.
        if (work.kind == Kind::Rest && s.state == SlotState::RestUnderWay) {
            s.rest.done = true;
            moveTo(s, SlotEvent::RenderFailed, SlotState::FinalShown);
            return;
        }
        // A newer view replaced it: no use telling, its first frame comes next. Else do not
        // retry the same view in a loop.
        const bool current = s.generation == work.generation;
        if (!moveTo(s, SlotEvent::RenderFailed, current ? SlotState::Failed : SlotState::ViewWaiting) || !current)
            return;
        failed = s.failed;
    }
    wake_.notify_all();
    if (failed) failed(message, work.job->request);
}

} // namespace volcast::server
