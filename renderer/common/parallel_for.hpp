#pragma once
// One way to fan work out over threads: parallelFor(count, threads, body).
//
//   body(begin, end)  contiguous shares of [0, count): with n = min(threads, count) shares,
//                     share t is [count·t/n, count·(t+1)/n) and the calling thread runs share 0.
//                     The split depends only on (count, threads), so a result that depends on
//                     it (a per-share scratch, a per-share sum) is the same on every run.
//   body(i)           every index once, handed out one at a time to min(threads, count)
//                     workers, the calling thread one of them: balances work whose cost varies
//                     from index to index (rows of an image). Which worker runs i varies.
//
// threads ≤ 0 means one per hardware thread; one thread (or count ≤ 1) runs everything inline on
// the caller, starting no thread. An exception thrown by body on any worker stops the handing
// out of further indices, waits for the other workers, and is rethrown on the caller (the first
// one caught; the others are dropped).

#include <algorithm>
#include <atomic>
#include <concepts>
#include <exception>
#include <mutex>
#include <thread>
#include <vector>

namespace volcast {

// threads ≤ 0: one per hardware thread (at least one).
inline int resolveThreadCount(int threads) {
    return threads > 0 ? threads : int(std::max(1u, std::thread::hardware_concurrency()));
}

template <std::integral Index, typename Body>
    requires std::invocable<const Body &, Index, Index> || std::invocable<const Body &, Index>
void parallelFor(Index count, int threads, const Body &body) {
    if (count <= 0) return;
    const Index workers = std::min(Index(resolveThreadCount(threads)), count);
    constexpr bool ranges = std::invocable<const Body &, Index, Index>;

    std::atomic<Index> next{0};
    std::mutex failureMutex;
    std::exception_ptr failure;
    auto run = [&](Index worker) {
        try {
            if constexpr (ranges) {
                // In 64 bits: count · share number overflows an int long before count does.
                using Wide = unsigned long long;
                const auto share = [&](Index w) { return Index(Wide(count) * Wide(w) / Wide(workers)); };
                body(share(worker), share(worker + 1));
            } else {
                for (Index i; (i = next.fetch_add(1)) < count;) body(i);
            }
        } catch (...) {
            next.store(count); // no further indices
            const std::lock_guard lock(failureMutex);
            if (!failure) failure = std::current_exception();
        }
    };
    if (workers == 1) {
        // Inline: the body's exception reaches the caller as it is.
        if constexpr (ranges) body(Index(0), count);
        else
            for (Index i = 0; i < count; ++i) body(i);
        return;
    }
    {
        // Declared before the caller's share so that a failure to start a thread still joins
        // the ones started (jthread joins in its destructor).
        std::vector<std::jthread> pool;
        pool.reserve(size_t(workers - 1));
        for (Index w = 1; w < workers; ++w) pool.emplace_back(run, w);
        run(Index(0));
    }
    if (failure) std::rethrow_exception(failure);
}

} // namespace volcast
