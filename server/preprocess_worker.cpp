#include "server/preprocess_worker.hpp"

#include <spdlog/spdlog.h>

#include <algorithm>

#include <sys/resource.h>
#include <sys/syscall.h>
#include <unistd.h>

namespace volcast::server {

PreprocessWorker::PreprocessWorker() {
    thread_ = std::thread([this] {
        // Below the render worker: on Linux a nice value applies to the calling thread alone.
        if (setpriority(PRIO_PROCESS, static_cast<id_t>(syscall(SYS_gettid)), 10) != 0)
            spdlog::debug("preprocess worker: could not lower its priority");
        loop();
    });
}

PreprocessWorker::~PreprocessWorker() { stop(); }

bool PreprocessWorker::request(const std::string &key, Priority priority, Task task, Done done) {
    {
        std::lock_guard lock(mutex_);
        if (stopping_ || queued_.count(key) || done_.count(key) || running_ == key) return false;
        queued_.insert(key);
        Item item{key, priority, std::move(task), std::move(done)};
        // Preparation ahead of calibration; first come first served within a priority.
        auto at = queue_.end();
        if (priority == Priority::Preparation)
            at = std::find_if(queue_.begin(), queue_.end(),
                              [](const Item &i) { return i.priority != Priority::Preparation; });
        queue_.insert(at, std::move(item));
    }
    wake_.notify_all();
    return true;
}

bool PreprocessWorker::ready(const std::string &key) const {
    std::lock_guard lock(mutex_);
    return done_.count(key) > 0;
}

void PreprocessWorker::markReady(const std::string &key) {
    std::lock_guard lock(mutex_);
    if (done_.size() >= kMaxRemembered) done_.clear();   // forgotten keys are prepared again, cheaply (cached)
    done_.insert(key);
}

bool PreprocessWorker::busy() const {
    std::lock_guard lock(mutex_);
    return !queue_.empty() || !running_.empty();
}

void PreprocessWorker::stop() {
    {
        std::lock_guard lock(mutex_);
        stopping_ = true;
        queue_.clear();
        queued_.clear();
    }
    cancelled_ = true;
    wake_.notify_all();
    if (thread_.joinable()) thread_.join();
}

void PreprocessWorker::loop() {
    std::unique_lock lock(mutex_);
    while (!stopping_) {
        if (queue_.empty()) {
            wake_.wait(lock);
            continue;
        }
        Item item = std::move(queue_.front());
        queue_.pop_front();
        queued_.erase(item.key);
        running_ = item.key;
        lock.unlock();
        bool ok = true;
        try {
            item.task(cancelled_);
        } catch (const std::exception &e) {
            ok = false;
            spdlog::warn("preparing {} failed: {}", item.key, e.what());
        }
        lock.lock();
        running_.clear();
        if (cancelled_) break;
        if (done_.size() >= kMaxRemembered) done_.clear();
        // A failed task is remembered too: the renderer would fail the same way on the
        // frame path, and the frame's own error then reaches the client.
        done_.insert(item.key);
        lock.unlock();
        if (item.done) item.done(item.key, ok);
        lock.lock();
    }
}

} // namespace volcast::server
