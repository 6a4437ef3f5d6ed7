// volcast-prefilter-timer [side]: the multithreaded B-spline prefilter on side³ random floats
// (default 256), against three read+write passes over the same volume on every hardware thread
// (its memory-bandwidth floor), median of 5. Small and quick so that two builds can be run
// interleaved (docs/performance.md, Table 2); `volcast-bench prefilter` is the full study.

#include "renderer/common/bspline_prefilter.hpp"

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <random>
#include <thread>
#include <vector>

namespace {

// One read-and-write pass on every hardware thread (x ← x·a + b, which the compiler cannot
// drop): the memory traffic of one prefilter axis with no arithmetic cost.
void readWritePass(std::vector<float> &data, float a, float b) {
    const size_t threads = std::max(1u, std::thread::hardware_concurrency());
    std::vector<std::thread> pool;
    for (size_t t = 0; t < threads; ++t)
        pool.emplace_back([&, t] {
            const size_t begin = data.size() * t / threads, end = data.size() * (t + 1) / threads;
            for (size_t i = begin; i < end; ++i) data[i] = data[i] * a + b;
        });
    for (std::thread &th : pool) th.join();
}

} // namespace

int main(int argc, char **argv) {
    using Clock = std::chrono::steady_clock;
    const long side = argc > 1 ? std::atol(argv[1]) : 256;
    if (side < 1 || side > 2048) {
        std::fprintf(stderr, "usage: %s [side in 1..2048]\n", argv[0]);
        return 2;
    }
    const volcast::Vec3i dims{side, side, side};
    const size_t n = size_t(side) * size_t(side) * size_t(side);
    std::vector<float> input(n), work(n);
    std::mt19937 rng(1);
    std::uniform_real_distribution<float> uniform(0, 255);
    for (float &v : input) v = uniform(rng);
    std::vector<double> filter, passes;
    const auto ms = [](Clock::time_point since) {
        return std::chrono::duration<double, std::milli>(Clock::now() - since).count();
    };
    for (int r = 0; r < 5; ++r) {
        work = input;
        auto t = Clock::now();
        volcast::bsplinePrefilterMultithreaded(work.data(), dims, 0);
        filter.push_back(ms(t));
        const float checked = work[n / 2 + 12345 % n];
        t = Clock::now();
        for (int p = 0; p < 3; ++p) readWritePass(work, 0.999f, 0.001f);
        passes.push_back(ms(t));
        if (r == 4) std::printf("side %ld: coefficient[n/2 + 12345] %.6f; ", side, double(checked));
    }
    std::sort(filter.begin(), filter.end());
    std::sort(passes.begin(), passes.end());
    std::printf("prefilter median %.1f ms (min %.1f max %.1f); 3 passes median %.1f ms (min %.1f); ratio %.2f\n",
                filter[2], filter[0], filter[4], passes[2], passes[0], filter[2] / passes[2]);
}
