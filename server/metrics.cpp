#include "server/metrics.hpp"

#include <sstream>

namespace volcast::server {

void Histogram::observe(double v) {
    size_t i = 0;
    while (i < bounds.size() && v > bounds[i]) ++i;
    ++counts[i];
    sum += v;
    ++count;
}

namespace {
// Frame times from 1 ms (a tiny interactive frame) to 10 s (a huge still).
std::vector<double> timeBuckets() { return {0.001, 0.0025, 0.005, 0.01, 0.02, 0.04, 0.08, 0.16, 0.32, 0.64, 1.28, 2.56, 10}; }

void writeHistogram(std::ostringstream &o, const std::string &name, const std::string &help, const Histogram &h) {
    o << "# HELP " << name << ' ' << help << "\n# TYPE " << name << " histogram\n";
    uint64_t cumulative = 0;
    for (size_t i = 0; i < h.bounds.size(); ++i) {
        cumulative += h.counts[i];
        o << name << "_bucket{le=\"" << h.bounds[i] << "\"} " << cumulative << '\n';
    }
    cumulative += h.counts.back();
    o << name << "_bucket{le=\"+Inf\"} " << cumulative << '\n';
    o << name << "_sum " << h.sum << '\n' << name << "_count " << h.count << '\n';
}

void writeScalar(std::ostringstream &o, const std::string &name, const char *type, const std::string &help,
                 double value) {
    o << "# HELP " << name << ' ' << help << "\n# TYPE " << name << ' ' << type << '\n' << name << ' ' << value << '\n';
}
} // namespace

Metrics::Metrics() : renderSeconds_(timeBuckets()), encodeSeconds_(timeBuckets()) {}

void Metrics::sessionOpened() {
    std::lock_guard lock(mutex_);
    ++sessions_;
    ++sessionsTotal_;
}
void Metrics::sessionClosed() {
    std::lock_guard lock(mutex_);
    --sessions_;
}
void Metrics::sessionRefused() {
    std::lock_guard lock(mutex_);
    ++sessionsRefused_;
}
void Metrics::frameSent(int level, bool final, double renderSeconds, double encodeSeconds, size_t bytes) {
    std::lock_guard lock(mutex_);
    ++frames_[{level, final}];
    frameBytes_ += bytes;
    renderSeconds_.observe(renderSeconds);
    encodeSeconds_.observe(encodeSeconds);
}
void Metrics::frameDroppedStale() {
    std::lock_guard lock(mutex_);
    ++framesDroppedStale_;
}
void Metrics::error(const std::string &code) {
    std::lock_guard lock(mutex_);
    ++errors_[code];
}
void Metrics::volumeLoaded(uint64_t) {
    std::lock_guard lock(mutex_);
    ++volumeLoads_;
}
void Metrics::volumeEvicted(uint64_t) {
    std::lock_guard lock(mutex_);
    ++volumeEvictions_;
}
void Metrics::setVolumeMemory(uint64_t bytes, int loaded) {
    std::lock_guard lock(mutex_);
    volumeMemory_ = bytes;
    volumesLoaded_ = loaded;
}
void Metrics::setQueuedBytes(int64_t delta) {
    std::lock_guard lock(mutex_);
    queuedBytes_ += delta;
}
int Metrics::sessions() const {
    std::lock_guard lock(mutex_);
    return sessions_;
}
uint64_t Metrics::volumeLoads() const {
    std::lock_guard lock(mutex_);
    return volumeLoads_;
}

void Metrics::setBackEnd(const std::string &description, const std::string &type) {
    std::lock_guard lock(mutex_);
    backEnd_ = description;
    backEndType_ = type;
}

namespace {
// A Prometheus label value: backslash, quote and newline escaped.
std::string labelValue(const std::string &s) {
    std::string o;
    for (char c : s) {
        if (c == '\\' || c == '"') o += '\\';
        if (c == '\n') o += "\\n";
        else o += c;
    }
    return o;
}
} // namespace

std::string Metrics::prometheusText() const {
    std::lock_guard lock(mutex_);
    std::ostringstream o;
    writeScalar(o, "volcast_sessions", "gauge", "WebSocket sessions open now", sessions_);
    writeScalar(o, "volcast_sessions_total", "counter", "WebSocket sessions opened", double(sessionsTotal_));
    writeScalar(o, "volcast_sessions_refused_total", "counter", "Sessions refused (max sessions, origin)",
                double(sessionsRefused_));
    o << "# HELP volcast_frames_total Frames sent, by level and whether final\n# TYPE volcast_frames_total counter\n";
    for (const auto &[key, n] : frames_)
        o << "volcast_frames_total{level=\"" << key.first << "\",final=\"" << (key.second ? "true" : "false")
          << "\"} " << n << '\n';
    writeScalar(o, "volcast_frame_bytes_total", "counter", "Encoded frame bytes sent", double(frameBytes_));
    writeScalar(o, "volcast_frames_dropped_stale_total", "counter",
                "Rendered frames dropped because newer input made them stale", double(framesDroppedStale_));
    writeHistogram(o, "volcast_render_seconds", "Render time per frame (kernel, read-back, upsampling)", renderSeconds_);
    writeHistogram(o, "volcast_encode_seconds", "Encode time per frame (JPEG or PNG)", encodeSeconds_);
    o << "# HELP volcast_errors_total Error messages sent, by code\n# TYPE volcast_errors_total counter\n";
    for (const auto &[code, n] : errors_) o << "volcast_errors_total{code=\"" << code << "\"} " << n << '\n';
    writeScalar(o, "volcast_volume_loads_total", "counter", "Volumes loaded from disk or generated", double(volumeLoads_));
    writeScalar(o, "volcast_volume_evictions_total", "counter", "Unused volumes evicted for the memory budget",
                double(volumeEvictions_));
    writeScalar(o, "volcast_volume_memory_bytes", "gauge", "Host memory held by loaded volumes", double(volumeMemory_));
    writeScalar(o, "volcast_volumes_loaded", "gauge", "Volumes in memory", volumesLoaded_);
    writeScalar(o, "volcast_outgoing_queue_bytes", "gauge", "Bytes waiting to be written to clients, all sessions",
                double(queuedBytes_));
    if (!backEnd_.empty())
        o << "# HELP volcast_back_end_info The back end drawing frames (--device)\n# TYPE volcast_back_end_info gauge\n"
          << "volcast_back_end_info{back_end=\"" << labelValue(backEnd_) << "\",type=\"" << labelValue(backEndType_)
          << "\"} 1\n";
    return o.str();
}

} // namespace volcast::server
