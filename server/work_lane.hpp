#pragma once
// A lane: a few worker threads and a bounded queue, for work that must not wait behind
// unrelated work. The registry gives each remote source its own lane of retrievals and the
// local loads one of their own; the DICOMweb provider gives each source a lane of searches.
// A slow source then fills only its own lane. Waiting jobs are taken in turn by owner (a
// session), so one owner with many jobs cannot hold a lane's every turn while another waits.

#include <condition_variable>
#include <cstdint>
#include <deque>
#include <functional>
#include <map>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

namespace volcast::server {

class WorkLane {
  public:
    struct Job {
        uint64_t owner = 0;              // jobs of one owner start in order; owners take turns
        std::function<void()> run;       // on a worker thread
        std::function<void()> dropped;   // instead of run, on the thread calling stop(), if the lane stops first
    };

    // workers >= 1 threads, started now and named after `name` in the log; maxWaiting: jobs
    // that may wait for a worker, beyond which post() refuses.
    WorkLane(std::string name, int workers, size_t maxWaiting);
    ~WorkLane();   // stop()
    WorkLane(const WorkLane &) = delete;
    WorkLane &operator=(const WorkLane &) = delete;

    // false, and neither function called, when maxWaiting jobs wait already or the lane stops.
    bool post(Job job);
    // Waiting jobs get `dropped`; running ones finish (they watch a stop signal of their own,
    // e.g. the registry's); then the workers are joined. Idempotent.
    void stop();

  private:
    void work();

    const std::string name_;
    const size_t maxWaiting_;
    std::mutex mutex_;
    std::condition_variable wake_;
    std::map<uint64_t, std::deque<Job>> waiting_;   // by owner
    std::deque<uint64_t> turns_;                    // owners with waiting jobs, the next first
    size_t waitingCount_ = 0;
    bool stopping_ = false;
    std::vector<std::thread> threads_;
};

} // namespace volcast::server
