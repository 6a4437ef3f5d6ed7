#pragma once
// Decides what each session's next frame is and renders it: one worker thread, round-robin
// over the sessions, so the one (PoCL CPU) device is shared fairly and no session's slow
// client holds up another's frames.
//
// Per session ("slot"): the newest view only (latest request wins: a view submitted before
// the previous one was rendered replaces it), at most one frame in flight (from the start
// of its render until the session has written it to the socket), and a position on the
// view's ladder of levels:
//   - a new view first gets one frame at the interactive level (the policy's choice);
//   - once no input has come for idleMs (or at interaction_end), it is refined level by
//     level to the final one, each frame delivered as soon as it is encoded;
//   - new input cancels refinement between levels and between jittered passes; a refined
//     frame that finishes after newer input arrived is dropped as stale (an interactive
//     one is still delivered: it is the newest picture there is).
// Frames are delivered through the slot's callback on the worker thread; the session's
// callback only posts them to its strand (no socket is touched here).

#include "protocol/frame.hpp"
#include "renderer/scene.hpp"
#include "server/metrics.hpp"
#include "server/quality_ladder.hpp"
#include "server/volume_registry.hpp"

#include <chrono>
#include <condition_variable>
#include <cstdint>
#include <functional>
#include <map>
#include <memory>
#include <mutex>
#include <thread>
#include <vector>

namespace volcast::server {

// One view to render, complete and immutable once submitted.
struct ViewJob {
    std::shared_ptr<VolumeEntry> volume;
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

// A rendered, encoded frame; the session gives it its sequence number.
struct RenderedFrame {
    protocol::FrameHeader header;
    std::vector<uint8_t> image;
};

struct SchedulerOptions {
    double idleMs = 150;             // ms without input before refinement starts
    bool errorCalibration = true;    // calibrate error estimates against the reference
};

class RenderScheduler {
  public:
    using SlotId = uint64_t;
    using Deliver = std::function<void(RenderedFrame)>;                 // must only post
    // render_failed for the request whose frame failed; must only post.
    using Failed = std::function<void(const std::string &message, const nlohmann::json &request)>;

    RenderScheduler(Metrics &metrics, SchedulerOptions options);
    ~RenderScheduler();   // stop()

    SlotId addSession(Deliver deliver, Failed failed);
    void removeSession(SlotId slot);
    // A new view for the slot: replaces any not yet rendered and cancels refinement.
    void submit(SlotId slot, std::shared_ptr<const ViewJob> job);
    void setInteracting(SlotId slot, bool interacting);
    // The session has written (or discarded) the frame it was delivered: the slot may render again.
    void frameDone(SlotId slot);
    void stop();

  private:
    using Clock = std::chrono::steady_clock;
    struct Slot {
        Deliver deliver;
        Failed failed;
        std::shared_ptr<const ViewJob> job;
        uint64_t generation = 0;      // bumps with every submit
        bool interacting = false;
        Clock::time_point lastInput;
        bool inFlight = false;
        int sentLevel = -1;           // highest level delivered for this generation
        bool finalSent = false;
        LevelTimer timer;
        size_t timerLadderSize = 0;
    };
    struct Work {
        SlotId slot = 0;
        std::shared_ptr<const ViewJob> job;
        uint64_t generation = 0;
        int level = 0;
        bool final = false;
    };
    // Calibrated RMSE per level against the reference, by what the error depends on.
    struct Calibration {
        std::vector<double> rmse;
    };

    void workerLoop();
    // What slot s should render now; false with wakeAt set when it waits for its idle time.
    bool nextWork(SlotId id, Slot &s, Clock::time_point now, Work &work, Clock::time_point &wakeAt);
    void render(const Work &work);
    // The view of `work` cannot be rendered: tell the session once and stop trying it.
    void renderFailed(const Work &work, const std::string &message);
    bool stale(const Work &work);
    std::string calibrationKey(const ViewJob &job) const;
    void calibrate(const ViewJob &job, const std::string &key);

    Metrics &metrics_;
    SchedulerOptions options_;
    std::mutex mutex_;
    std::condition_variable wake_;
    std::map<SlotId, Slot> slots_;
    SlotId nextId_ = 1;
    SlotId lastServed_ = 0;
    bool stopping_ = false;
    std::map<std::string, Calibration> calibrations_;   // worker thread only
    std::shared_ptr<const ViewJob> toCalibrate_;        // the newest view without a calibration
    std::thread worker_;
};

} // namespace volcast::server
