#include "server/work_lane.hpp"

#include <spdlog/spdlog.h>

#include <algorithm>
#include <exception>

namespace volcast::server {

WorkLane::WorkLane(std::string name, int workers, size_t maxWaiting)
    : name_(std::move(name)), maxWaiting_(maxWaiting) {
    for (int i = 0; i < std::max(workers, 1); ++i) threads_.emplace_back([this] { work(); });
}

WorkLane::~WorkLane() { stop(); }

bool WorkLane::post(Job job) {
    {
        std::lock_guard lock(mutex_);
        if (stopping_ || waitingCount_ >= maxWaiting_) return false;
        auto &queue = waiting_[job.owner];
        if (queue.empty()) turns_.push_back(job.owner);
        queue.push_back(std::move(job));
        ++waitingCount_;
    }
    wake_.notify_one();
    return true;
}

void WorkLane::stop() {
    std::vector<Job> dropped;
    std::vector<std::thread> threads;   // joined by the first call only
    {
        std::lock_guard lock(mutex_);
        stopping_ = true;
        for (auto &[owner, queue] : waiting_)
            for (auto &job : queue) dropped.push_back(std::move(job));
        waiting_.clear();
        turns_.clear();
        waitingCount_ = 0;
        threads.swap(threads_);
    }
    wake_.notify_all();
    for (auto &job : dropped)
        if (job.dropped) job.dropped();
    for (auto &t : threads) t.join();
}

void WorkLane::work() {
    for (;;) {
        Job job;
        {
            std::unique_lock lock(mutex_);
            wake_.wait(lock, [&] { return stopping_ || !turns_.empty(); });
            if (stopping_) return;
            const uint64_t owner = turns_.front();
            turns_.pop_front();
            auto it = waiting_.find(owner);
            job = std::move(it->second.front());
            it->second.pop_front();
            if (it->second.empty()) waiting_.erase(it);
            else turns_.push_back(owner);   // the owner's next job waits for the others' turns
            --waitingCount_;
        }
        try {
            job.run();
        } catch (const std::exception &e) {
            // A job answers its own failures; one that escapes must not end the worker.
            spdlog::error("{} lane: {}", name_, e.what());
        }
    }
}

} // namespace volcast::server
