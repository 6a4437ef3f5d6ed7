// Exceptions at the render worker's asynchronous boundary (server/render_scheduler.cpp,
// workerLoop): a renderer that throws, the way a driver error or a failed allocation inside
// a real one would. The scheduler, its worker thread and the other sessions are the real
// ones; only the failing renderer is a test double (it renders real frames through
// SlowRenderer until told to throw). What must hold: the session whose frame failed is told,
// with the request the frame was for; the other session keeps getting frames up to its
// final one; the worker survives, so the failed session renders again on its next view.
// Without the worker's catch the exception ends the process (std::terminate), so each test
// here fails by crashing the test binary.

#include "renderer/model/synthetic.hpp"
#include "server/render_scheduler.hpp"
#include "slow_renderer.hpp"

#include <gtest/gtest.h>

#include <atomic>
#include <chrono>
#include <cmath>
#include <condition_variable>
#include <mutex>
#include <new>
#include <stdexcept>
#include <string>
#include <thread>
#include <vector>

namespace {

using namespace volcast;
using namespace volcast::server;
using Clock = std::chrono::steady_clock;
using Ms = std::chrono::duration<double, std::milli>;

std::shared_ptr<const Volume> blob() {
    static const auto volume = std::make_shared<const Volume>(makeGaussianBlob({16, 16, 16}, {1, 1, 1}, 4, 200).volume);
    return volume;
}

// Renders like SlowRenderer; while `failing` is set, every render throws what `thrower` throws.
class FailingRenderer : public FrameRenderer {
  public:
    explicit FailingRenderer(std::function<void()> thrower)
        : inner_(blob(), 0.02), thrower_(std::move(thrower)) {}

    Image render(const FrameRequest &request, RenderStats *stats = nullptr) override {
        maybeThrow();
        return inner_.render(request, stats);
    }
    bool rendersWindowsCheaply() const override { return true; }
    std::string description() const override { return "failing test renderer"; }
    PreprocessCounts preprocessCounts() const override { return inner_.preprocessCounts(); }
    const Volume &volume() const override { return inner_.volume(); }

    std::atomic<bool> failing{true};
    std::atomic<int> thrown{0};

  private:
    void maybeThrow() {
        if (!failing) return;
        ++thrown;
        thrower_();
    }
    slow::SlowRenderer inner_;
    std::function<void()> thrower_;
};

// One session: its frames and the failures it was told of.
struct Session {
    RenderScheduler &scheduler;
    std::shared_ptr<FrameRenderer> renderer;
    RenderScheduler::SlotId slot = 0;
    std::mutex mutex;
    std::condition_variable changed;
    std::vector<protocol::FrameHeader> frames;
    std::vector<std::pair<std::string, nlohmann::json>> failures;

    Session(RenderScheduler &s, std::shared_ptr<FrameRenderer> r) : scheduler(s), renderer(std::move(r)) {
        slot = scheduler.addSession(
            [this](RenderedFrame f) {
                {
                    std::lock_guard lock(mutex);
                    frames.push_back(f.header);
                }
                changed.notify_all();
                scheduler.frameDone(slot);
            },
            [this](const std::string &message, const nlohmann::json &request) {
                {
                    std::lock_guard lock(mutex);
                    failures.emplace_back(message, request);
                }
                changed.notify_all();
            });
    }
    // The worker delivers outside its lock: stop it before this Session goes.
    ~Session() {
        scheduler.stop();
        scheduler.removeSession(slot);
    }

    void view(int request, double angle) {
        auto job = std::make_shared<ViewJob>();
        job->renderer = renderer;
        job->volumeId = 1;
        job->volumeName = "blob";
        job->transferFunction.points = {{0, 0, 0, 0, 0}, {50, 0.8, 0.5, 0.3, 0.05}, {200, 1, 1, 1, 0.5}};
        job->camera.target = {7.5, 7.5, 7.5};
        job->camera.eye = job->camera.target + Vec3d{40 * std::cos(angle), 12, 40 * std::sin(angle)};
        job->width = job->height = 64;
        Quality final;
        final.step = 1;
        job->ladder = automaticLadder(final, 1);
        job->request = request;
        scheduler.submit(slot, job);
    }
    template <class Pred>
    bool waitUntil(Pred pred, double timeoutMs) {
        std::unique_lock lock(mutex);
        return changed.wait_for(lock, Ms(timeoutMs), [&] { return pred(); });
    }
    bool finalFrameOf(int request) {
        for (const auto &h : frames)
            if (h.final && h.request == request) return true;
        return false;
    }
};

SchedulerOptions options() {
    SchedulerOptions o;
    o.idleMs = 30;
    o.errorCalibration = false;
    o.unitMs = 20;
    return o;
}

// The whole story for one kind of exception. Timeouts: a 64² frame at 0.02 ms a ray is
// ~80 ms of the final level; 20 s leaves room for a machine loaded many times over.
void failingRendererIsReportedAndNothingElseStops(std::function<void()> thrower, const std::string &what) {
    Metrics metrics;
    RenderScheduler scheduler(metrics, options());
    auto failing = std::make_shared<FailingRenderer>(std::move(thrower));
    Session a(scheduler, failing);
    Session b(scheduler, std::make_shared<slow::SlowRenderer>(blob(), 0.02));

    a.view(7, 0.0);
    b.view(1, 0.5);
    ASSERT_TRUE(a.waitUntil([&] { return !a.failures.empty(); }, 20000))
        << "session A was never told its frame failed (renderer threw " << failing->thrown << " times)";
    {
        std::lock_guard lock(a.mutex);
        EXPECT_EQ(a.failures.front().second, nlohmann::json(7)) << "the failure must name the request it was for";
        EXPECT_NE(a.failures.front().first.find(what), std::string::npos)
            << "the failure should carry the exception's message; got: " << a.failures.front().first;
        EXPECT_TRUE(a.frames.empty()) << "no frame can come from a renderer that only throws";
    }
    EXPECT_TRUE(b.waitUntil([&] { return b.finalFrameOf(1); }, 20000))
        << "session B got no final frame while A's renderer threw: the worker stopped";

    // The worker survived: B's next view renders, and A renders again once its renderer does.
    b.view(2, 1.0);
    EXPECT_TRUE(b.waitUntil([&] { return b.finalFrameOf(2); }, 20000)) << "session B's second view never finished";
    failing->failing = false;
    a.view(8, 0.3);
    EXPECT_TRUE(a.waitUntil([&] { return a.finalFrameOf(8); }, 20000))
        << "session A's next view after the failure never finished";
}

TEST(AsyncFailures, RendererThrowingRuntimeErrorFailsOnlyItsOwnRequest) {
    failingRendererIsReportedAndNothingElseStops([] { throw std::runtime_error("device lost (test)"); },
                                                 "device lost (test)");
}

TEST(AsyncFailures, RendererThrowingBadAllocFailsOnlyItsOwnRequest) {
    // What a render that cannot get its memory throws; its what() is the library's own text.
    failingRendererIsReportedAndNothingElseStops([] { throw std::bad_alloc(); }, "");
}

} // namespace
