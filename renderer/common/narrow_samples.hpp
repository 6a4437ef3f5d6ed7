#pragma once
// Samples held narrow. An 8- or 16-bit scan's values are integers: a volume whose samples are
// integers spanning at most 2^8 (2^16) values holds them as sample − offset in 1 (2) bytes
// (Volume::narrowVoxels), a quarter (half) of float32's bytes, and both back ends sample that
// store as it is. Widened back to float the values are exactly the same.

#include "renderer/model/math.hpp"

#include <cstddef>
#include <cstdint>
#include <vector>

namespace volcast {

struct NarrowWidth {
    int bytes = 4;     // 1, 2, or 4 (float: not narrow)
    float offset = 0;  // the lowest sample; stored value = sample − offset
};

// Bytes after a narrow store's last sample: the native path reads 32 bits at every sample's
// byte offset (the sample and its +x neighbour), up to 3 bytes past the last one.
constexpr size_t kNarrowSlack = 4;

// 1 or 2 bytes when every sample is an integer (not −0) of magnitude ≤ 2^24 and they span at
// most 2^8 or 2^16 values; else 4. Those are the samples float(u) + offset gives back exactly.
// T: float, or an 8- or 16-bit integer (a file's samples as read, never wider than 2 bytes).
template <class T>
NarrowWidth narrowWidth(const T *samples, size_t count);
inline NarrowWidth narrowWidth(const std::vector<float> &samples) {
    return narrowWidth(samples.data(), samples.size());
}

// count samples from src into dst as sample − w.offset, w.bytes (1 or 2) bytes each,
// little-endian: the layout a 1-D array of uint8 or uint16 has on the hosts and devices we
// run on. dst holds count · w.bytes bytes. T as for narrowWidth.
template <class T>
void packNarrow(const T *src, size_t count, NarrowWidth w, unsigned char *dst);

// One grid of samples (a volume's level 0, or a mip level) as it is held: float32, or narrow.
// A view: the store must outlive it.
struct SampleGrid {
    Vec3i dims{0, 0, 0};
    const float *floats = nullptr;         // width.bytes == 4
    const unsigned char *narrow = nullptr; // else: sample − width.offset, width.bytes each
    NarrowWidth width;

    static SampleGrid ofFloats(Vec3i dims, const float *floats) { return {dims, floats, nullptr, {}}; }

    size_t count() const { return size_t(dims.x) * size_t(dims.y) * size_t(dims.z); }
    bool isNarrow() const { return width.bytes < 4; }
    float operator[](size_t i) const {
        if (width.bytes == 4) return floats[i];
        const unsigned u = width.bytes == 1 ? narrow[i] : unsigned(narrow[2 * i]) | unsigned(narrow[2 * i + 1]) << 8;
        return float(u) + width.offset;
    }
    // count samples from `first` as float32 into out.
    void read(size_t first, size_t count, float *out) const;
    // Row j of slice k (dims.x samples), or slice k (dims.x · dims.y): a pointer into a float
    // grid, or the samples widened into `scratch`.
    const float *row(int64_t j, int64_t k, std::vector<float> &scratch) const;
    const float *slice(int64_t k, std::vector<float> &scratch) const;
    // Every sample as float32 (a copy).
    std::vector<float> toFloats() const;
};

} // namespace volcast
