#include "renderer/narrow_samples.hpp"

#include <algorithm>
#include <cmath>
#include <cstdint>

namespace volcast {

NarrowWidth narrowWidth(const std::vector<float> &samples) {
    if (samples.empty()) return {};
    float lo = samples[0], hi = samples[0];
    for (const float v : samples) {
        // An integer of magnitude ≤ 2^24 survives float(v − offset) + offset exactly; −0
        // would come back as +0, NaN and ±inf not at all.
        if (!(std::fabs(v) <= 16777216.0f) || v != std::trunc(v) || (v == 0 && std::signbit(v))) return {};
        lo = std::min(lo, v);
        hi = std::max(hi, v);
    }
    const double span = double(hi) - double(lo);
    if (span < 256) return {1, lo};
    if (span < 65536) return {2, lo};
    return {};
}

void packNarrow(const float *src, size_t count, NarrowWidth w, unsigned char *dst) {
    for (size_t i = 0; i < count; ++i) {
        const auto u = uint32_t(src[i] - w.offset);
        dst[i * size_t(w.bytes)] = uint8_t(u);
        if (w.bytes == 2) dst[i * 2 + 1] = uint8_t(u >> 8);
    }
}

std::vector<unsigned char> narrowSamples(const std::vector<float> &samples, NarrowWidth w) {
    std::vector<unsigned char> out(samples.size() * size_t(w.bytes));
    packNarrow(samples.data(), samples.size(), w, out.data());
    return out;
}

} // namespace volcast
