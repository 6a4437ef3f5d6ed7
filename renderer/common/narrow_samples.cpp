#include "renderer/common/narrow_samples.hpp"

#include <algorithm>
#include <cmath>
#include <cstdint>

namespace volcast {

template <class T>
NarrowWidth narrowWidth(const T *samples, size_t count) {
    if (count == 0) return {};
    float lo = float(samples[0]), hi = float(samples[0]);
    for (size_t i = 0; i < count; ++i) {
        const float v = float(samples[i]);
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

template <class T>
void packNarrow(const T *src, size_t count, NarrowWidth w, unsigned char *dst) {
    for (size_t i = 0; i < count; ++i) {
        const auto u = uint32_t(float(src[i]) - w.offset);
        dst[i * size_t(w.bytes)] = uint8_t(u);
        if (w.bytes == 2) dst[i * 2 + 1] = uint8_t(u >> 8);
    }
}

template NarrowWidth narrowWidth(const float *, size_t);
template NarrowWidth narrowWidth(const int8_t *, size_t);
template NarrowWidth narrowWidth(const uint8_t *, size_t);
template NarrowWidth narrowWidth(const int16_t *, size_t);
template NarrowWidth narrowWidth(const uint16_t *, size_t);
template void packNarrow(const float *, size_t, NarrowWidth, unsigned char *);
template void packNarrow(const int8_t *, size_t, NarrowWidth, unsigned char *);
template void packNarrow(const uint8_t *, size_t, NarrowWidth, unsigned char *);
template void packNarrow(const int16_t *, size_t, NarrowWidth, unsigned char *);
template void packNarrow(const uint16_t *, size_t, NarrowWidth, unsigned char *);

void SampleGrid::read(size_t first, size_t n, float *out) const {
    if (width.bytes == 4) {
        std::copy(floats + first, floats + first + n, out);
    } else if (width.bytes == 1) {
        const unsigned char *p = narrow + first;
        for (size_t i = 0; i < n; ++i) out[i] = float(p[i]) + width.offset;
    } else {
        const unsigned char *p = narrow + 2 * first;
        for (size_t i = 0; i < n; ++i) out[i] = float(unsigned(p[2 * i]) | unsigned(p[2 * i + 1]) << 8) + width.offset;
    }
}

const float *SampleGrid::row(int64_t j, int64_t k, std::vector<float> &scratch) const {
    const size_t first = (size_t(k) * size_t(dims.y) + size_t(j)) * size_t(dims.x);
    if (width.bytes == 4) return floats + first;
    scratch.resize(size_t(dims.x));
    read(first, size_t(dims.x), scratch.data());
    return scratch.data();
}

const float *SampleGrid::slice(int64_t k, std::vector<float> &scratch) const {
    const size_t n = size_t(dims.x) * size_t(dims.y), first = size_t(k) * n;
    if (width.bytes == 4) return floats + first;
    scratch.resize(n);
    read(first, n, scratch.data());
    return scratch.data();
}

std::vector<float> SampleGrid::toFloats() const {
    std::vector<float> out(count());
    read(0, out.size(), out.data());
    return out;
}

} // namespace volcast
