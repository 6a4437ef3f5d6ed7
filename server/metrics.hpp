#pragma once
// The server's counters, gauges and histograms, written out in Prometheus' text format by
// GET /metrics. One mutex guards everything: updates are a few per frame, far below contention.

#include <array>
#include <cstdint>
#include <map>
#include <mutex>
#include <string>
#include <vector>

namespace volcast::server {

// Cumulative histogram with fixed upper bounds (seconds).
struct Histogram {
    std::vector<double> bounds;
    std::vector<uint64_t> counts;   // one per bound, plus +Inf
    double sum = 0;
    uint64_t count = 0;
    explicit Histogram(std::vector<double> b) : bounds(std::move(b)), counts(bounds.size() + 1, 0) {}
    void observe(double v);
};

class Metrics {
  public:
    Metrics();
    void sessionOpened();
    void sessionClosed();
    void sessionRefused();
    void frameSent(int level, bool final, double renderSeconds, double encodeSeconds, size_t bytes);
    void frameDroppedStale();
    void error(const std::string &code);
    void volumeLoaded(uint64_t bytes);
    void volumeEvicted(uint64_t bytes);
    void setVolumeMemory(uint64_t bytes, int loaded);
    void setQueuedBytes(int64_t delta);   // bytes waiting to be written to clients, all sessions
    // The back end drawing frames ("cpu: …" or "opencl: …") and its device type: volcast_back_end_info.
    void setBackEnd(const std::string &description, const std::string &type);

    int sessions() const;
    uint64_t volumeLoads() const;
    std::string prometheusText() const;

  private:
    mutable std::mutex mutex_;
    int sessions_ = 0;
    uint64_t sessionsTotal_ = 0, sessionsRefused_ = 0;
    std::map<std::pair<int, bool>, uint64_t> frames_;   // by (level, final)
    uint64_t framesDroppedStale_ = 0;
    uint64_t frameBytes_ = 0;
    Histogram renderSeconds_, encodeSeconds_;
    std::map<std::string, uint64_t> errors_;
    uint64_t volumeLoads_ = 0, volumeEvictions_ = 0;
    uint64_t volumeMemory_ = 0;
    int volumesLoaded_ = 0;
    int64_t queuedBytes_ = 0;
    std::string backEnd_, backEndType_;
};

} // namespace volcast::server
