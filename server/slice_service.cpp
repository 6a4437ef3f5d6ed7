#include "server/slice_service.hpp"

#include <chrono>
#include <cstdio>
#include <cmath>
#include <stdexcept>
#include <string>
#include <utility>

namespace volcast::server {

using protocol::ErrorCode;
using protocol::ProtocolError;

namespace {
constexpr std::string_view kType = protocol::SliceRequest::kType;

Vec3d vec(const std::array<double, 3> &a) { return {a[0], a[1], a[2]}; }
std::array<double, 3> arr(const Vec3d &v) { return {v.x, v.y, v.z}; }
std::string num(double v) {
    char buf[32];
    std::snprintf(buf, sizeof buf, "%.6g", v);
    return buf;
}
} // namespace

SliceService::SliceService(int64_t maxPixels) : maxPixels_(maxPixels), thread_([this] { loop(); }) {}

SliceService::~SliceService() { stop(); }

void SliceService::stop() {
    {
        std::lock_guard lock(mutex_);
        stopping_ = true;
        queue_.clear();
    }
    wake_.notify_all();
    if (thread_.joinable()) thread_.join();
}

SliceService::Prepared SliceService::prepare(const Volume &volume, const protocol::SliceRequest &request,
                                             const OrientationCorrection &correction) {
    const auto axis = parseSliceAxis(request.axis);
    if (!axis) throw std::invalid_argument("axis: must be \"axial\", \"coronal\" or \"sagittal\"");
    SliceRequestGeometry g;
    g.axis = *axis;
    g.point = request.point ? vec(*request.point) : volume.center();
    g.width = request.width;
    g.height = request.height;
    g.pixelSpacing = request.pixelSpacing;
    if (request.center) g.center = vec(*request.center);
    Prepared p;
    p.plane = slicePlane(volume, g, correction);
    p.correction = correction;
    p.point = g.point;
    const WindowLevel wl = defaultWindowLevel(volume);
    p.window = request.window.value_or(wl.window);
    p.level = request.level.value_or(wl.level);
    if (!(std::isfinite(p.window) && p.window > 0)) throw std::invalid_argument("window: must be a finite number > 0");
    if (!std::isfinite(p.level)) throw std::invalid_argument("level: must be a finite number");
    if (request.slab) {
        p.slab = request.slab;
        const auto mode = parseSlabMode(request.slab->mode);
        if (!mode) throw std::invalid_argument("slab.mode: must be \"mip\", \"minip\" or \"mean\"");
        p.samplingSlab = Slab{request.slab->thickness, *mode};
        p.slabPlanes = slabPlaneCount(volume, request.slab->thickness);
        // The limits are checked here, on the caller's thread, so that too_large comes at once:
        // a zero-pixel probe of sampleSlab's checks without sampling anything.
        const double smallest = volume.smallestSpacing();
        if (p.slabPlanes > kMaxSlabPlanes)
            throw std::length_error("slab.thickness: " + num(request.slab->thickness) + " mm needs more than " +
                                    std::to_string(kMaxSlabPlanes) + " planes " + num(smallest / 2) +
                                    " mm apart (half the smallest voxel spacing); the most is " +
                                    num((kMaxSlabPlanes - 1) * smallest / 2) + " mm");
        const int64_t samples = int64_t(p.plane.width) * p.plane.height * p.slabPlanes;
        if (samples > kMaxSlabSamples)
            throw std::length_error("slab: " + std::to_string(p.slabPlanes) + " planes of " +
                                    std::to_string(p.plane.width) + " x " + std::to_string(p.plane.height) +
                                    " pixels are " + std::to_string(samples) + " samples, over the limit of " +
                                    std::to_string(kMaxSlabSamples) + "; ask for a smaller image or a thinner slab");
    }
    return p;
}

std::vector<uint8_t> SliceService::render(const Volume &volume, const Prepared &p, const protocol::RequestId &request) {
    const auto start = std::chrono::steady_clock::now();
    const SliceImage image = p.slab ? sampleSlab(volume, p.plane, p.samplingSlab, p.correction)
                                    : sampleSlice(volume, p.plane, p.correction);
    const std::vector<uint8_t> grey = windowToGray8(image, p.window, p.level);
    protocol::SliceHeader h;
    h.request = request;
    h.axis = std::string(sliceAxisName(p.plane.axis));
    h.width = p.plane.width;
    h.height = p.plane.height;
    h.pixelSpacing = p.plane.pixelSpacing;
    h.origin = arr(p.plane.origin);
    h.column = arr(p.plane.column);
    h.row = arr(p.plane.row);
    h.point = arr(p.point);
    h.window = p.window;
    h.level = p.level;
    h.slab = p.slab;
    h.slabPlanes = p.slabPlanes;
    h.renderMs = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count();
    return protocol::encodeSlice(h, grey);
}

std::optional<ProtocolError> SliceService::submit(uint64_t session, std::shared_ptr<const Volume> volume,
                                                  const protocol::SliceRequest &request, Reply reply,
                                                  const OrientationCorrection &correction) {
    const auto refuse = [&](ErrorCode code, std::string message) {
        return ProtocolError{code, std::move(message), request.id, std::string(kType)};
    };
    const int64_t pixels = int64_t(request.width) * int64_t(request.height);
    if (pixels > maxPixels_)
        return refuse(ErrorCode::TooLarge, "slice of " + std::to_string(request.width) + " x " +
                                               std::to_string(request.height) + " = " + std::to_string(pixels) +
                                               " pixels, over the server's limit of " + std::to_string(maxPixels_) +
                                               " (--max-still-pixels)");
    Job job;
    try {
        job.prepared = prepare(*volume, request, correction);
    } catch (const std::invalid_argument &e) {
        return refuse(ErrorCode::BadField, e.what());
    } catch (const std::length_error &e) {
        return refuse(ErrorCode::TooLarge, e.what());
    }
    job.session = session;
    job.volume = std::move(volume);
    job.id = request.id;
    job.reply = std::move(reply);
    return enqueue(std::move(job), kType);
}

std::optional<ProtocolError> SliceService::submitTask(uint64_t session, const protocol::RequestId &id,
                                                      std::string_view type, std::function<Answer()> work,
                                                      Reply reply) {
    Job job;
    job.session = session;
    job.id = id;
    job.reply = std::move(reply);
    job.work = std::move(work);
    job.type = std::string(type);
    return enqueue(std::move(job), type);
}

std::optional<ProtocolError> SliceService::enqueue(Job job, std::string_view type) {
    const auto refuse = [&](ErrorCode code, std::string message) {
        return ProtocolError{code, std::move(message), job.id, std::string(type)};
    };
    {
        std::lock_guard lock(mutex_);
        if (stopping_) return refuse(ErrorCode::Busy, "the server is stopping");
        size_t &queued = queuedPerSession_[job.session];
        if (queued >= kMaxQueuedPerSession)
            return refuse(ErrorCode::Busy, std::to_string(queued) + " slices and measurements of this session are waiting (at most " +
                                               std::to_string(kMaxQueuedPerSession) +
                                               "); wait for their answers before asking for more");
        ++queued;
        queue_.push_back(std::move(job));
    }
    wake_.notify_one();
    return std::nullopt;
}

void SliceService::loop() {
    for (;;) {
        Job job;
        {
            std::unique_lock lock(mutex_);
            wake_.wait(lock, [&] { return stopping_ || !queue_.empty(); });
            if (stopping_) return;
            job = std::move(queue_.front());
            queue_.pop_front();
        }
        Answer answer;
        const std::string type = job.work ? job.type : std::string(kType);
        try {
            answer = job.work ? job.work() : render(*job.volume, job.prepared, job.id);
        } catch (const std::exception &e) {
            // Out of memory for a large slice, or a bug: an answer all the same.
            answer = ProtocolError{ErrorCode::RenderFailed, type + " failed: " + e.what(), job.id, type};
        }
        {
            std::lock_guard lock(mutex_);
            if (auto it = queuedPerSession_.find(job.session); it != queuedPerSession_.end() && --it->second == 0)
                queuedPerSession_.erase(it);
        }
        try {
            job.reply(std::move(answer));
        } catch (...) {
            // Reply only posts; a failure there (out of memory) loses one answer, not the thread.
        }
    }
}

} // namespace volcast::server
