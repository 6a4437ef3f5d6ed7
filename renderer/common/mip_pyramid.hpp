#pragma once
// Mip pyramid of a volume (docs/design.md `mip_level`): coarser data for interactive frames,
// each level built on first request and cached.
//
// Level L + 1 averages 2×2×2 blocks of level L; on an odd axis the last block repeats the
// edge sample (clamp), so level dims are ceil(n / 2), never below 1. A level-L voxel j covers
// level-0 voxels [j·2^L, (j+1)·2^L), so level-L index coordinate q and level-0 index
// coordinate p are related by q = (p + 1/2) / 2^L − 1/2 (mipIndexFromIndex). The ray caster
// keeps clipping rays against the level-0 box [−1/2, n − 1/2] and only samples the coarser
// data through this map: where n is not a multiple of 2^L, the level-L box reaches past the
// level-0 box, and that overhang is never sampled.

#include "renderer/model/huge_pages.hpp"
#include "renderer/model/math.hpp"
#include "renderer/model/volume.hpp"

#include <cmath>
#include <mutex>
#include <vector>

namespace volcast {

// Level-L index coordinate of level-0 index coordinate p: (p + 1/2) / 2^L − 1/2.
inline Vec3d mipIndexFromIndex(const Vec3d &p, int level) {
    const double scale = std::ldexp(1.0, -level);
    return (p + Vec3d{0.5, 0.5, 0.5}) * scale - Vec3d{0.5, 0.5, 0.5};
}

// Samples per axis at level L: ceil(n / 2) applied L times, never below 1.
Vec3i mipLevelDims(Vec3i dims0, int level);

// A coarser level's samples: in 2 MiB pages where large, as level 0's narrow store (on this
// project's VM a fresh 4 KiB page costs ~16 µs at first touch, a 2 MiB one far less: the 39 MB
// of a 512x512x300 scan's first level took 0.16-0.2 s to allocate in small pages).
using MipSamples = std::vector<float, HugePageAllocator<float>>;

// One averaging step: level L + 1 from level L's samples (dims x fastest).
MipSamples downsampleMip(const SampleGrid &fine);
inline MipSamples downsampleMip(const std::vector<float> &fine, Vec3i fineDims) {
    return downsampleMip(SampleGrid::ofFloats(fineDims, fine.data()));
}

class MipPyramid {
  public:
    // Level 0 is `level0`'s samples as it holds them (float or narrow), not copied: the
    // volume must outlive the pyramid. Coarser levels are averages, held as float.
    // Throws std::invalid_argument for a volume without samples or with mismatched dims.
    explicit MipPyramid(const Volume &level0);

    // Samples of level L (dims(L) x fastest), building any missing levels up to L once.
    // Thread-safe; what the view points at stays valid for the pyramid's lifetime.
    // Throws std::out_of_range for L < 0 or L > maxLevel().
    SampleGrid level(int L);
    Vec3i dims(int L) const;
    // Coarser levels built so far (level 0 is not counted: it is the volume's own voxels).
    int levelsBuilt() const;
    // The first level where every axis has one sample.
    int maxLevel() const { return maxLevel_; }
    // Level L as a Volume in the same world space (a copy): spacing · 2^L, and voxel 0 at
    // level-0 index (2^L − 1)/2, so worldFromIndex agrees with mipIndexFromIndex.
    Volume levelVolume(int L);

  private:
    void check(int L) const;

    const Volume &volume_;
    int maxLevel_ = 0;
    std::vector<MipSamples> levels_;         // [0] unused: level 0 is the volume's samples
    int built_ = 0;                          // levels 1 … built_ are in levels_
    mutable std::mutex mutex_;
};

} // namespace volcast
