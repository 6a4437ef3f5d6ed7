#pragma once
// Answers `slice` requests (protocol/README.md): resamples a plane of a session's volume
// (renderer/model/slice.hpp), windows it to 8-bit grey and encodes the VCS1 slice message.
//
// Where it runs: on its own worker thread, one slice at a time, not through the render
// scheduler nor the preprocessing worker. A slice is a few milliseconds of host work
// (trilinear on the host copy of the volume, no device); the scheduler's units are device
// frames with the one-frame-in-flight flow control of a view, and the preprocessing worker
// runs keyed once-only tasks at nice 10 behind B-spline prefilters that take seconds. Its
// own thread means a slice never waits behind a 3D refinement ladder, and a 3D frame never
// waits behind slices: the render worker and this thread are separate, and a session may
// have at most kMaxQueuedPerSession slices queued (more get `busy`), so no session can fill
// the queue for the others. Checks that need no work (the fields, the pixel limit) happen
// on the caller's thread, so a bad request is refused at once.
//
// The same thread answers the session's other measurements that read the volume on the host
// (roi_stats, pick: submitTask): like a slice they take milliseconds to a second, must not
// hold up the session's strand, and share the per-session bound.

#include "protocol/errors.hpp"
#include "protocol/slice.hpp"
#include "renderer/model/slice.hpp"
#include "renderer/model/volume.hpp"

#include <condition_variable>
#include <cstdint>
#include <deque>
#include <functional>
#include <map>
#include <memory>
#include <mutex>
#include <optional>
#include <thread>
#include <variant>
#include <vector>

namespace volcast::server {

class SliceService {
  public:
    static constexpr size_t kMaxQueuedPerSession = 6;   // three panes, twice over
    // The slice message, or the error answering the request. Runs on the worker thread
    // (or, for a request dropped by stop(), not at all); must only post.
    // A slice message (binary), an error, or a JSON text message (the answer of a task).
    using Answer = std::variant<std::vector<uint8_t>, protocol::ProtocolError, std::string>;
    using Reply = std::function<void(Answer)>;

    // maxPixels: the most width x height of one slice (the server's --max-still-pixels).
    explicit SliceService(int64_t maxPixels);
    ~SliceService();   // stop()
    SliceService(const SliceService &) = delete;
    SliceService &operator=(const SliceService &) = delete;

    // Checks the request against the volume and the limits and queues it; reply then runs
    // once with the answer. A refusal is returned instead (reply never runs): bad_field
    // naming the field, too_large over maxPixels, busy with kMaxQueuedPerSession queued for
    // this session or after stop(). `correction` is the session's orientation correction
    // (quality.orientation_correction): its slices show the volume where its frames do.
    std::optional<protocol::ProtocolError> submit(uint64_t session, std::shared_ptr<const Volume> volume,
                                                  const protocol::SliceRequest &request, Reply reply,
                                                  const OrientationCorrection &correction = {});
    // Queues `work` for the worker; reply then runs once with what it returns (an exception it
    // throws becomes render_failed naming `type`). Refused with busy like a slice.
    std::optional<protocol::ProtocolError> submitTask(uint64_t session, const protocol::RequestId &id,
                                                      std::string_view type, std::function<Answer()> work,
                                                      Reply reply);
    // Drops the queued requests (unanswered: their sessions are going) and joins the worker.
    void stop();

    // The plane and window/level a request asks for, with the defaults filled in. Throws
    // std::invalid_argument naming the field.
    struct Prepared {
        SlicePlane plane;
        double window = 1;
        double level = 0;
        Vec3d point;
        OrientationCorrection correction;
        std::optional<protocol::SliceSlab> slab;   // as asked; the planes below
        Slab samplingSlab;
        int slabPlanes = 1;
    };
    // A slab over the limits throws std::length_error (too_large).
    static Prepared prepare(const Volume &volume, const protocol::SliceRequest &request,
                            const OrientationCorrection &correction = {});
    // The whole answer on the calling thread: the slice message's bytes.
    static std::vector<uint8_t> render(const Volume &volume, const Prepared &prepared,
                                       const protocol::RequestId &request);

  private:
    struct Job {
        uint64_t session = 0;
        std::shared_ptr<const Volume> volume;
        Prepared prepared;
        protocol::RequestId id;
        Reply reply;
        std::function<Answer()> work;   // a task instead of a slice
        std::string type;
    };
    std::optional<protocol::ProtocolError> enqueue(Job job, std::string_view type);
    void loop();

    int64_t maxPixels_;
    std::mutex mutex_;
    std::condition_variable wake_;
    std::deque<Job> queue_;
    std::map<uint64_t, size_t> queuedPerSession_;   // queued and running
    bool stopping_ = false;
    std::thread thread_;
};

} // namespace volcast::server
