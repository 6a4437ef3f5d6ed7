#pragma once
// Samples held narrow: an 8- or 16-bit scan's values are integers, held as float32 in
// Volume::voxels. Where every sample of a level is an integer spanning at most 2^8 (2^16)
// values, both back ends sample a copy that stores sample − offset in 1 (2) bytes: a quarter
// (half) of the bytes, and, widened back to float, exactly the same values.

#include <cstddef>
#include <vector>

namespace volcast {

struct NarrowWidth {
    int bytes = 4;     // 1, 2, or 4 (float: not narrow)
    float offset = 0;  // the lowest sample; stored value = sample − offset
};

// 1 or 2 bytes when every sample is an integer (not −0) of magnitude ≤ 2^24 and they span at
// most 2^8 or 2^16 values; else 4. Those are the samples float(u) + offset gives back exactly.
NarrowWidth narrowWidth(const std::vector<float> &samples);

// count samples from src into dst as sample − w.offset, w.bytes (1 or 2) bytes each,
// little-endian: the layout a 1-D array of uint8 or uint16 has on the hosts and devices we
// run on. dst holds count · w.bytes bytes.
void packNarrow(const float *src, size_t count, NarrowWidth w, unsigned char *dst);

// All the samples, packed.
std::vector<unsigned char> narrowSamples(const std::vector<float> &samples, NarrowWidth w);

} // namespace volcast
