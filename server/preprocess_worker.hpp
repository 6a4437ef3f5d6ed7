#pragma once
// Long preparation off the frame path: one background thread, below the render worker in
// priority (a nice value of 10 and one core at most for work it does itself), running keyed
// tasks once each: a scene's B-spline coefficients, pre-integration table and kernel build
// (by a one-ray render that makes the renderer build and cache them), and error
// calibrations. Tasks see a cancel flag that stop() raises; queued tasks are dropped.
//
// The render worker asks ready(key) before it renders a quality that needs preparation;
// until then it renders what is ready and says so in the frame.

#include <atomic>
#include <condition_variable>
#include <cstddef>
#include <deque>
#include <functional>
#include <mutex>
#include <set>
#include <string>
#include <thread>

namespace volcast::server {

class PreprocessWorker {
  public:
    using Task = std::function<void(const std::atomic<bool> &cancelled)>;
    using Done = std::function<void(const std::string &key, bool ok)>;   // on the worker thread

    enum class Priority { Preparation, Calibration };   // preparation runs first

    PreprocessWorker();
    ~PreprocessWorker();   // stop()

    // Queue task under key unless that key is queued, running or done; false if it was.
    bool request(const std::string &key, Priority priority, Task task, Done done = {});
    bool ready(const std::string &key) const;
    // Marks a key done without a task (the render worker prepared it on its own way).
    void markReady(const std::string &key);
    bool busy() const;   // a task queued or running (tests)
    // Cancels the running task's flag, drops the queue and joins the thread.
    void stop();

    static constexpr size_t kMaxRemembered = 4096;   // done keys before the record is cleared

  private:
    struct Item {
        std::string key;
        Priority priority;
        Task task;
        Done done;
    };
    void loop();

    mutable std::mutex mutex_;
    std::condition_variable wake_;
    std::deque<Item> queue_;
    std::set<std::string> queued_, done_;
    std::string running_;
    bool stopping_ = false;
    std::atomic<bool> cancelled_{false};
    std::thread thread_;
};

} // namespace volcast::server
