// volcast-prefilter-timer: the multithreaded B-spline prefilter on 256³ random floats, against
// three read+write passes over the same volume (its memory-bandwidth floor), median of 5.
// Small and quick so that two builds can be run interleaved (docs/performance.md, Table 2);
// `volcast-bench prefilter` is the full study.

#include "renderer/bspline_prefilter.hpp"

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <random>
#include <vector>

int main() {
    using Clock = std::chrono::steady_clock;
    const volcast::Vec3i dims{256, 256, 256};
    const size_t n = size_t(256) * 256 * 256;
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
        t = Clock::now();
        for (int p = 0; p < 3; ++p)
            for (float &v : work) v = v * 0.999f + 0.001f;
        passes.push_back(ms(t));
    }
    std::sort(filter.begin(), filter.end());
    std::sort(passes.begin(), passes.end());
    std::printf("prefilter median %.1f ms (min %.1f max %.1f); 3 passes median %.1f ms; checksum %.6f\n", filter[2],
                filter[0], filter[4], passes[2], double(work[12345]));
}
