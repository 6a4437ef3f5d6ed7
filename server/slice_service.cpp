#include "server/slice_service.hpp"

#include <chrono>
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
    return p;
}

std::vector<uint8_t> SliceService::render(const Volume &volume, const Prepared &p, const protocol::RequestId &request) {
    const auto start = std::chrono::steady_clock::now();
    const SliceImage image = sampleSlice(volume, p.plane, p.correction);
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
    }
    job.session = session;
    job.volume = std::move(volume);
    job.id = request.id;
    job.reply = std::move(reply);
    {
        std::lock_guard lock(mutex_);
        if (stopping_) return refuse(ErrorCode::Busy, "the server is stopping");
        size_t &queued = queuedPerSession_[session];
        if (queued >= kMaxQueuedPerSession)
            return refuse(ErrorCode::Busy, std::to_string(queued) + " slices of this session are waiting (at most " +
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
        try {
            answer = render(*job.volume, job.prepared, job.id);
        } catch (const std::exception &e) {
            // Out of memory for a large slice, or a bug: an answer all the same.
            answer = ProtocolError{ErrorCode::RenderFailed, std::string("slice failed: ") + e.what(), job.id,
                                   std::string(kType)};
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
