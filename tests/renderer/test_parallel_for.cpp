#include "renderer/common/parallel_for.hpp"

#include <gtest/gtest.h>

#include <atomic>
#include <chrono>
#include <algorithm>
#include <cstddef>
#include <mutex>
#include <set>
#include <stdexcept>
#include <thread>
#include <utility>
#include <vector>

namespace volcast {
namespace {

// Every index of [0, count) is run exactly once, for counts below, at and above the thread count.
TEST(ParallelFor, RunsEveryIndexOnce) {
    for (const int threads : {1, 2, 3, 8})
        for (const int count : {0, 1, 2, 7, 64, 1000}) {
            std::vector<std::atomic<int>> runs(static_cast<size_t>(count));
            parallelFor(count, threads, [&](int i) { runs[size_t(i)].fetch_add(1); });
            for (int i = 0; i < count; ++i)
                EXPECT_EQ(runs[size_t(i)].load(), 1) << "index " << i << " of " << count << ", threads " << threads;
        }
}

// The shares tile [0, count) without gap or overlap, and are the documented ones:
// share t of n = min(threads, count) is [count·t/n, count·(t+1)/n).
TEST(ParallelFor, RangesAreTheDocumentedContiguousShares) {
    for (const int threads : {1, 2, 3, 8})
        for (const size_t count : {size_t(0), size_t(1), size_t(2), size_t(7), size_t(1000)}) {
            std::mutex m;
            std::set<std::pair<size_t, size_t>> shares;
            parallelFor(count, threads, [&](size_t begin, size_t end) {
                const std::lock_guard lock(m);
                shares.emplace(begin, end);
            });
            const size_t n = std::min(size_t(threads), count);
            std::set<std::pair<size_t, size_t>> expected;
            for (size_t t = 0; t < n; ++t) expected.emplace(count * t / n, count * (t + 1) / n);
            EXPECT_EQ(shares, expected) << "count " << count << ", threads " << threads;
        }
}

// A count whose product with the share number overflows an int still splits right.
TEST(ParallelFor, SharesOfALargeIntCountDoNotOverflow) {
    const int count = 2'000'000'000;
    std::mutex m;
    std::set<std::pair<int, int>> shares;
    parallelFor(count, 3, [&](int begin, int end) {
        const std::lock_guard lock(m);
        shares.emplace(begin, end);
    });
    const std::set<std::pair<int, int>> expected = {
        {0, 666'666'666}, {666'666'666, 1'333'333'333}, {1'333'333'333, count}};
    EXPECT_EQ(shares, expected);
}

// An exception thrown on a worker other than the caller reaches the caller, and only after
// every worker has left the body (its captures must outlive every call).
TEST(ParallelFor, RethrowsAWorkersExceptionOnTheCaller) {
    const auto caller = std::this_thread::get_id();
    std::atomic<int> inside{0};
    EXPECT_THROW(parallelFor(64, 4,
                             [&](int) {
                                 ++inside;
                                 std::this_thread::sleep_for(std::chrono::milliseconds(2));
                                 --inside;
                                 if (std::this_thread::get_id() != caller) throw std::runtime_error("worker failed");
                             }),
                 std::runtime_error);
    EXPECT_EQ(inside.load(), 0);
    // The ranges form too, whether a worker's share or the caller's own throws.
    EXPECT_THROW(parallelFor(size_t(8), 4,
                             [](size_t begin, size_t) {
                                 if (begin >= 4) throw std::out_of_range("late share");
                             }),
                 std::out_of_range);
    EXPECT_THROW(parallelFor(size_t(8), 4,
                             [](size_t begin, size_t) {
                                 if (begin == 0) throw std::out_of_range("caller's share");
                             }),
                 std::out_of_range);
}

// After a failure no further indices are handed out.
TEST(ParallelFor, StopsHandingOutIndicesAfterAFailure) {
    std::atomic<int> ran{0};
    const int count = 1000;
    EXPECT_THROW(parallelFor(count, 2,
                             [&](int i) {
                                 ++ran;
                                 if (i == 0) throw std::runtime_error("first index");
                                 std::this_thread::sleep_for(std::chrono::milliseconds(1));
                             }),
                 std::runtime_error);
    // Index 0 is the first handed out and throws at once; the other worker, at ≥ 1 ms an index,
    // would need ≥ 1 s to run the rest alone, so only a stop leaves some of them unrun.
    EXPECT_LT(ran.load(), count);
}

// One thread (or a single index) runs everything on the caller, in order, starting no thread.
TEST(ParallelFor, OneThreadRunsInlineInOrder) {
    const auto caller = std::this_thread::get_id();
    std::vector<int> order;
    parallelFor(5, 1, [&](int i) {
        EXPECT_EQ(std::this_thread::get_id(), caller);
        order.push_back(i);
    });
    EXPECT_EQ(order, (std::vector<int>{0, 1, 2, 3, 4}));
    parallelFor(1, 8, [&](int) { EXPECT_EQ(std::this_thread::get_id(), caller); });
    parallelFor(size_t(9), 1, [&](size_t begin, size_t end) {
        EXPECT_EQ(std::this_thread::get_id(), caller);
        EXPECT_EQ(begin, 0u);
        EXPECT_EQ(end, 9u);
    });
    // Inline, the body's exception reaches the caller unchanged.
    EXPECT_THROW(parallelFor(3, 1, [](int i) {
                     if (i == 2) throw std::logic_error("inline");
                 }),
                 std::logic_error);
}

// threads ≤ 0 means one per hardware thread.
TEST(ParallelFor, ZeroThreadsMeansOnePerHardwareThread) {
    EXPECT_EQ(resolveThreadCount(0), int(std::max(1u, std::thread::hardware_concurrency())));
    EXPECT_EQ(resolveThreadCount(-3), resolveThreadCount(0));
    EXPECT_EQ(resolveThreadCount(5), 5);
    std::mutex m;
    std::set<std::thread::id> seen;
    parallelFor(size_t(1000), 0, [&](size_t, size_t) {
        const std::lock_guard lock(m);
        seen.insert(std::this_thread::get_id());
    });
    EXPECT_EQ(int(seen.size()), resolveThreadCount(0));
}

} // namespace
} // namespace volcast
