#pragma once
// The native path's bricked copy of a narrow (8- or 16-bit) level: the samples in cubes of
// 9³, each the 8³ cells whose lowest corner lies in it plus one sample more on each axis, so
// that every tap of a trilinear cell is in the cell's own brick. A packet of rays crossing
// the volume slice after slice in the volume's own layout reads a new cache line for nearly
// every row of its footprint in every slice; in bricks, a 64-byte line holds 3½ rows of 9
// (16-bit) and a brick's 8 slices lie within 1.5 KiB, so the same footprint takes a few lines.
//
// Brick (bx, by, bz) holds samples (8·bx + i, 8·by + j, 8·bz + k), i, j, k in 0 … 8, each
// clamped to the last sample of its axis: past the last sample the copy repeats it, which is
// what the slice layout's sampler reads there (its upper tap on the last sample is the sample
// itself), so both layouts give the same floats bit for bit.

#include "renderer/common/narrow_samples.hpp"
#include "renderer/model/huge_pages.hpp"
#include "renderer/model/math.hpp"

#include <cstdint>
#include <vector>

namespace volcast::cpu {

inline constexpr int kLayoutEdge = 8;               // cells per brick edge
inline constexpr int kLayoutSide = kLayoutEdge + 1; // samples per brick edge
// 9³ = 729 samples, rounded up to a multiple of 64 so that every brick starts on a cache
// line at 1 and 2 bytes a sample. The pad also holds the 32-bit gathers' overreach past a
// brick's last sample (at most 3 bytes).
inline constexpr int kLayoutBrickSamples = 768;

struct BrickedSamples {
    Vec3i bricks{0, 0, 0}; // per axis: (n − 1) / 8 + 1, the bricks holding cells' corners
    int bytes = 0;         // per sample: 1 or 2, as the narrow level
    std::vector<unsigned char, HugePageAllocator<unsigned char>> store;

    // Bytes a copy of a level of `dims` at `bytes` a sample takes.
    static uint64_t plannedBytes(Vec3i dims, int bytes);
};

// Copies a narrow level into bricks (threads: 0 one per core). std::invalid_argument for a
// float grid.
BrickedSamples brickSamples(const SampleGrid &level, int threads);

} // namespace volcast::cpu
