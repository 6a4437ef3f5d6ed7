#pragma once
// Decides what each session's next frame is and renders it, in bounded units of work, on
// one render thread: the device is one PoCL CPU device, and one worker with a fair queue is
// the simplest thing that shares it fairly.
//
// Units: an interactive frame (its level is chosen to fit the frame-time target), or some
// cells of one pass of a refinement level (as many as fit unitMs at the cost measured;
// TiledFrame). Between units the worker picks again: any session's interactive frame
// first, then the next refinement unit; within each, the session that has had the fewest
// interactive frames, or the least render time for refinement (ties round-robin).
// So a session's interactive frame waits for at most one unit, whatever another session's
// final frame costs, and new input drops a refinement at the next unit boundary.
//
// Per session ("slot"): the newest view only (latest wins; an interactive frame under way
// is finished first, or input faster than a frame would starve the drag), at most one frame in flight
// (from its delivery until the session has written it), and a position on the view's
// ladder: one interactive frame, then after idleMs without input (or at interaction_end)
// refinement level by level to the final one. A slot's life is an explicit state machine
// (SlotState, below; the table in server/README.md, "A slot's life"): every change of state
// goes through one function that refuses a transition not in slotTransitions().
//
// Long preparation (B-spline coefficients, pre-integration tables, a new kernel variant)
// runs on the PreprocessWorker; until it is ready, the level is rendered without it
// (trilinear, no pre-integration, no shading: the frame's quality says so) and the session
// gets `progress` messages. Error estimates come from the ErrorCalibrator, off this thread.
//
// Frames, failures and progress go out through the slot's callbacks on the worker threads;
// the session's callbacks only post them to its strand.

#include "protocol/frame.hpp"
#include "protocol/server_messages.hpp"
#include "renderer/common/frame_renderer.hpp"
#include "renderer/model/scene.hpp"
#include "server/error_calibrator.hpp"
#include "server/metrics.hpp"
#include "server/preprocess_worker.hpp"
#include "server/quality_ladder.hpp"
#include "server/tiled_frame.hpp"
#include "server/volume_registry.hpp"

#include <chrono>
#include <condition_variable>
#include <cstdint>
#include <functional>
#include <map>
#include <memory>
#include <mutex>
#include <optional>
#include <set>
#include <span>
#include <string>
#include <thread>
#include <vector>

namespace volcast::server {

// One view to render, complete and immutable once submitted.
struct ViewJob {
    std::shared_ptr<FrameRenderer> renderer;   // keeps its volume alive (aliases the registry entry)
    uint64_t volumeId = 0;                     // the registry's id of the volume: never reused
    std::string volumeName;                    // for progress messages
    TransferFunction transferFunction;   // resolved (presets placed on the value range)
    Camera camera;
    nlohmann::json cameraJson;           // scene-file form, echoed in frame headers
    int width = 0, height = 0;           // the viewport, or a still's own size
    std::vector<ClipPlane> clipPlanes;
    std::vector<Level> ladder;           // cheapest first; the last one is final
    double targetFrameMs = 40;
    bool stillOnly = false;              // a `still` request: the final level only
    nlohmann::json request;              // id of the request this view reflects
};

// The job for a registry entry's renderer, sharing the entry's lifetime.
std::shared_ptr<FrameRenderer> rendererOf(const std::shared_ptr<VolumeEntry> &entry);

// A rendered, encoded frame; the session gives it its sequence number.
struct RenderedFrame {
    protocol::FrameHeader header;
    std::vector<uint8_t> image;
};

struct SchedulerOptions {
    double idleMs = 150;             // ms without input before refinement starts
    bool errorCalibration = true;    // measure error estimates (background)
    double unitMs = 40;              // the longest a refinement unit is planned to take
    // Refinement at rest: after a view's final frame, while the server has nothing else to
    // render, passes toward the exact integral (the final's step halved per pass), each sent
    // only when its 8-bit image changes, until its estimated error is ≤ kRestTargetError or
    // the view has had this much render time at rest. 0: none.
    double restRefinementMs = 0;
    // A view still for this long without its final frame is overdue: overdue refinement gets
    // kOverdueShare of the render time ahead of interactive frames, the oldest overdue view
    // first, so a resting view's wait is bounded however many others drag (docs/service.md,
    // "Scheduling").
    double refineWaitMs = 1000;
};

// The share of render time overdue refinement takes ahead of interactive frames; dragging
// sessions choose their levels from the rest of the frame-time target meanwhile.
inline constexpr double kOverdueShare = 0.5;

// Refinement at rest stops at this estimated error (RMSE, RGB in [0, 1]): half a grey level.
inline constexpr double kRestTargetError = 0.5 / 255;
// and after this many passes (the final's step / 64).
inline constexpr int kMaxRestPasses = 6;
// Early termination of a pass at rest: what it leaves out (≤ 1 − this of the colour) stays
// below a quarter of the target.
inline constexpr double kRestEarlyTermination = 1 - 0.25 / 255;

// Where a session's slot is in the life of its views. One frame at most is under way or with
// the session at a time, so these are exclusive.
enum class SlotState {
    NoView,               // no view submitted yet
    ViewWaiting,          // a view none of which is shown or under way: its first frame comes next
    InteractiveUnderWay,  // the view's interactive frame, unit by unit (possibly of an older view)
    LevelUnderWay,        // a refinement level, a still's or a one-level ladder's final, unit by unit
    WithSession,          // a frame delivered, until the session has written it (frameDone)
    LevelShown,           // a level below the final shown: refinement waits for the idle time
    FinalShown,           // the view's final frame shown: refined at rest while the server is idle
    RestUnderWay,         // a pass of refinement at rest, unit by unit
    Failed,               // rendering the view failed (told once): nothing until a new view
};
// What happens to a slot.
enum class SlotEvent {
    NewView,           // submit(), not a still
    NewStill,          // submit() of a still (`still`: the final level only)
    StartInteractive,  // the worker starts the view's interactive frame
    StartLevel,        // the worker starts a level that is not interactive
    FrameRendered,     // a frame's last unit is done and encoded: it goes to the session
    RenderFailed,      // rendering, encoding or delivering a frame threw
    FrameWritten,      // frameDone(): the session has written the frame
    StartRest,         // the worker starts a pass of refinement at rest
    RestUnchanged,     // a pass at rest changed no 8-bit pixel: nothing is sent
};
struct SlotTransition {
    SlotState from;
    SlotEvent event;
    SlotState to;
    const char *action;   // what goes with it, as server/README.md says
};
// Every transition a slot may take, in the order of server/README.md's table; any other is refused.
std::span<const SlotTransition> slotTransitions();
// The row of (from, event, to) in slotTransitions(), or -1 where it is not there.
int slotTransitionRow(SlotState from, SlotEvent event, SlotState to);
const char *toString(SlotState state);
const char *toString(SlotEvent event);

class RenderScheduler {
  public:
    using SlotId = uint64_t;
    using Deliver = std::function<void(RenderedFrame)>;   // must only post
    // render_failed for the request the failed frame was rendered for; must only post.
    using Failed = std::function<void(const std::string &message, const nlohmann::json &request)>;
    using Progress = std::function<void(const protocol::ProgressMessage &)>;   // must only post

    RenderScheduler(Metrics &metrics, SchedulerOptions options);
    ~RenderScheduler();   // stop()

    SlotId addSession(Deliver deliver, Failed failed, Progress progress = {});
    void removeSession(SlotId slot);
    // A new view for the slot: replaces any not yet rendered and cancels refinement.
    void submit(SlotId slot, std::shared_ptr<const ViewJob> job);
    void setInteracting(SlotId slot, bool interacting);
    // The session has written (or discarded) the frame it was delivered: the slot may render again.
    void frameDone(SlotId slot);
    // Stops the render worker after its current unit and the preprocess worker after its
    // current task (both cancel what is queued).
    void stop();

    // For tests and metrics: the longest unit rendered so far, in ms.
    double longestUnitMs() const;
    // For tests: a slot's state (NoView for one not there); how often each row of
    // slotTransitions() was taken; transitions refused (each a bug, logged).
    SlotState slotState(SlotId slot) const;
    std::vector<uint64_t> transitionCounts() const;
    uint64_t refusedTransitions() const;
    // For tests: called on the render worker after each unit, with its time in ms.
    void setUnitObserver(std::function<void(double unitMs)> observer);
    bool preparing() const { return preprocess_.busy(); }

  private:
    using Clock = std::chrono::steady_clock;
    // The frame a slot has under way, owned by the states InteractiveUnderWay and
    // LevelUnderWay: it may belong to an older view than the slot's (an interactive frame is
    // finished when newer input comes). Let go with its state: its view may hold a volume
    // the registry has evicted.
    struct FrameUnderWay {
        std::shared_ptr<TiledFrame> frame;
        std::shared_ptr<const ViewJob> job;   // the view it belongs to
        uint64_t generation = 0;              // of that view
        int level = -1;
        bool final = false;
        bool substitute = false;              // rendered without its pending preparation
    };
    // The frame with the session (WithSession).
    struct Delivery {
        const TiledFrame *frame = nullptr;    // which one (identity only)
        uint64_t generation = 0;              // of the view it belongs to
        bool final = false;                   // that view's final frame
    };
    // Refinement at rest of the slot's view (SchedulerOptions::restRefinementMs).
    struct Rest {
        int passes = 0;                  // passes rendered at rest
        double spentMs = 0;              // their render time
        bool done = false;               // target reached, time or passes used up, or failed
        Image previous;                  // the float image rendered last (the final's, then each pass's)
        PixelVector<uint8_t> shown;     // the 8-bit RGBA of the frame shown last
    };
    struct Slot {
        Deliver deliver;
        Failed failed;
        Progress progress;
        SlotState state = SlotState::NoView;
        std::optional<FrameUnderWay> underWay;   // in InteractiveUnderWay and LevelUnderWay only
        Delivery delivery;                       // meaningful in WithSession only
        std::shared_ptr<const ViewJob> job;
        std::shared_ptr<const CalibrationView> calibration;   // the job's, with its key
        uint64_t generation = 0;      // bumps with every submit
        bool interacting = false;
        Clock::time_point lastInput;
        // What of this generation's view has been delivered (its progress on the ladder).
        int sentLevel = -1;           // level delivered last
        std::vector<bool> levelsShown;  // of its ladder: delivered (not as a substitute)
        int substituteSent = -1;      // highest level delivered with its preparation pending
        double serviceMs = 0;         // render time received: the least served refines next
        double interactiveFrames = 0; // interactive frames received: the fewest goes next
        LevelTimer timer;
        double encodeMs = 0;          // JPEG coding of this session's frames (EMA; 0: none yet)
        std::vector<Quality> timerLadder;   // the qualities the timer's levels were measured at
        uint64_t timerVolumeId = 0;
        std::vector<std::pair<int, std::vector<uint8_t>>> levelImages;   // this generation's JPEGs, for calibration
        std::map<std::string, std::string> announced;   // preparations this slot was told of: key, task
        Rest rest;                    // of this generation's view
    };
    // Interactive frames first, then refinement to the final, then refinement at rest.
    enum class Kind { Interactive, Refine, Rest };
    struct Work {
        Kind kind = Kind::Interactive;
        SlotId slot = 0;
        std::shared_ptr<const ViewJob> job;
        uint64_t generation = 0;
        int level = 0;
        bool final = false;
        Quality quality;              // what is rendered: the level's, or its substitute
        bool substitute = false;
        std::shared_ptr<TiledFrame> frame;   // Refine: the frame the unit belongs to
        bool aheadOfInteractive = false;     // an overdue refinement's unit, taken before interactive frames
        int cells = 0;                       // the unit's cells (TiledFrame)
    };

    void workerLoop();
    double leastServiceMs() const;   // over sessions with a view; under the lock
    double leastInteractiveFrames() const;
    size_t draggingCount() const;      // sessions interacting or awaiting an interactive frame; under the lock
    size_t sessionsDragging() const;   // the same, at least 1
    // Some session dragging or with input within the idle time (then wakeAt is when that
    // time ends): refinement at rest waits. Under the lock.
    bool anyoneActive(Clock::time_point now, Clock::time_point &wakeAt) const;
    // The next unit of this kind: the least served session's (ties round-robin); for
    // refinement, overdue views first, the one still the longest first. overdueOnly: only an
    // overdue view's refinement.
    bool pickWork(Kind kind, Clock::time_point now, Work &work, Clock::time_point &wakeAt, bool overdueOnly = false);
    // When the slot's view could start refining (its last input + the idle time).
    Clock::time_point stillSince(const Slot &s) const;
    // The slot's view waits for refinement (a level or the final) and has been still for
    // SchedulerOptions::refineWaitMs. Under the lock.
    bool overdue(const Slot &s, Clock::time_point now) const;
    // What slot s should do now of this kind; false with wakeAt set when it waits for its idle time.
    bool nextWork(Kind kind, SlotId id, Slot &s, Clock::time_point now, Work &work, Clock::time_point &wakeAt);
    // A pass of refinement at rest for slot s, or its next unit; false when it has none.
    bool nextRestWork(SlotId id, Slot &s, Work &work);
    // The cells of the frame under way that the unit renders (into work). Under the lock.
    void planCells(Slot &s, Work &work);
    // Finishes a pass at rest: its estimate, and delivery when its 8-bit image changed.
    void finishRest(Work &work);
    // The quality to render for a level now: the level's if prepared, else a substitute
    // (and the preparation asked for). Under the lock.
    Quality renderable(SlotId id, Slot &s, const Quality &q, bool &substitute);
    // Renders one unit; when it completes its frame, encodes and delivers it.
    void runUnit(Work &work);
    void fail(const Work &work, const std::string &message);
    // The one way a slot changes state: refused (logged, counted, the state kept) unless
    // (s.state, event, to) is a row of slotTransitions(). Leaving the under-way states lets
    // the frame under way go. Under the lock.
    bool moveTo(Slot &s, SlotEvent event, SlotState to);
    // The slot's view is done with: its final frame is out or it failed. Under the lock.
    static bool viewDone(const Slot &s);

    Metrics &metrics_;
    SchedulerOptions options_;
    PreprocessWorker preprocess_;
    ErrorCalibrator calibrator_;
    mutable std::mutex mutex_;
    std::condition_variable wake_;
    std::map<SlotId, Slot> slots_;
    SlotId nextId_ = 1;
    SlotId lastServed_ = 0;
    uint64_t viewSerial_ = 0;
    // Render time overdue refinement may still take ahead of interactive frames: interactive
    // units add to it while a view is overdue (at most one unit's worth), those it takes spend it.
    double overdueCreditMs_ = 0;
    bool overdueWaiting_ = false;   // some view overdue, as of the worker's last pick
    bool stopping_ = false;
    double longestUnitMs_ = 0;
    std::vector<uint64_t> transitionCounts_;
    std::function<void(double)> unitObserver_;
    uint64_t refusedTransitions_ = 0;
    // A renderer is used by one thread at a time without the render worker ever waiting:
    // the worker skips sessions whose renderer is being prepared, and a preparation waits
    // for the worker's current unit on its renderer.
    const FrameRenderer *rendering_ = nullptr;
    std::set<const FrameRenderer *> preparing_;
    std::thread worker_;
};

// The key of a quality's slow preparation for a volume, or "" when it needs none (a plain
// trilinear quality without pre-integration or shading is prepared on the frame path).
std::string preparationKey(uint64_t volumeId, const TransferFunction &tf, const Quality &q);
// A quality with what needs slow preparation taken out: trilinear, no pre-integration, no shading.
Quality plainQuality(const Quality &q);

} // namespace volcast::server
