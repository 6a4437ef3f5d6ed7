#include "renderer/cpu/bricked_samples.hpp"

#include "renderer/common/parallel_for.hpp"

#include <algorithm>
#include <cstring>
#include <stdexcept>

namespace volcast::cpu {

namespace {

int64_t bricksAlong(int64_t n) { return (n - 1) / kLayoutEdge + 1; }

} // namespace

uint64_t BrickedSamples::plannedBytes(Vec3i dims, int bytes) {
    return uint64_t(bricksAlong(dims.x)) * uint64_t(bricksAlong(dims.y)) * uint64_t(bricksAlong(dims.z)) *
           uint64_t(kLayoutBrickSamples) * uint64_t(bytes);
}

BrickedSamples brickSamples(const SampleGrid &level, int threads) {
    if (!level.isNarrow()) throw std::invalid_argument("brickSamples: a bricked copy is made of 8- and 16-bit levels only");
    const Vec3i n = level.dims;
    BrickedSamples out;
    out.bricks = {bricksAlong(n.x), bricksAlong(n.y), bricksAlong(n.z)};
    out.bytes = level.width.bytes;
    out.store.resize(BrickedSamples::plannedBytes(n, out.bytes));
    const size_t bytes = size_t(out.bytes), brickBytes = size_t(kLayoutBrickSamples) * bytes;
    // One layer of bricks per task (the pads stay as resize zeroed them).
    parallelFor(out.bricks.z, threads, [&](int64_t bz) {
        for (int64_t by = 0; by < out.bricks.y; ++by)
            for (int64_t bx = 0; bx < out.bricks.x; ++bx) {
                unsigned char *brick = out.store.data() + size_t((bz * out.bricks.y + by) * out.bricks.x + bx) * brickBytes;
                const int64_t x0 = bx * kLayoutEdge;
                const int64_t whole = std::min<int64_t>(kLayoutSide, n.x - x0); // samples before the clamp
                for (int k = 0; k < kLayoutSide; ++k)
                    for (int j = 0; j < kLayoutSide; ++j) {
                        const int64_t y = std::min<int64_t>(by * kLayoutEdge + j, n.y - 1);
                        const int64_t z = std::min<int64_t>(bz * kLayoutEdge + k, n.z - 1);
                        const unsigned char *row = level.narrow + size_t((z * n.y + y) * n.x) * bytes;
                        unsigned char *to = brick + size_t((k * kLayoutSide + j) * kLayoutSide) * bytes;
                        std::memcpy(to, row + size_t(x0) * bytes, size_t(whole) * bytes);
                        for (int64_t i = whole; i < kLayoutSide; ++i)
                            std::memcpy(to + size_t(i) * bytes, row + size_t(n.x - 1) * bytes, bytes);
                    }
            }
    });
    return out;
}

} // namespace volcast::cpu
