#pragma once
// A scalar volume on a regular grid, in the coordinates of docs/design.md: voxel (i, j, k) is a
// sample at world = origin + D·(i·sx, j·sy, k·sz), and owns the cell of size s around it.

#include "renderer/model/huge_pages.hpp"
#include "renderer/model/math.hpp"
#include "renderer/common/narrow_samples.hpp"

#include <cstddef>
#include <cstdint>
#include <string>
#include <string_view>
#include <vector>

namespace volcast {

// The type the voxels had in their file. In memory a volume holds float32, or the narrow
// store an 8- or 16-bit scan's integer samples fit (narrow_samples.hpp).
enum class VoxelType { UInt8, Int8, UInt16, Int16, UInt32, Int32, Float32, Float64 };

std::string_view voxelTypeName(VoxelType t);
size_t voxelTypeSize(VoxelType t);

struct ValueRange {
    float min = 0;
    float max = 0;
};

struct Histogram {
    static constexpr int kBins = 256;
    ValueRange range;               // bins span [range.min, range.max]
    std::vector<uint64_t> counts;   // kBins entries
};

struct Volume {
    std::string name;               // file name or built-in name, for messages
    Vec3i dims{0, 0, 0};            // samples per axis, x fastest in memory
    Vec3d spacing{1, 1, 1};         // world units between samples
    Vec3d origin{0, 0, 0};          // world position of voxel (0, 0, 0)
    Mat3d direction;                // unit index axes in world space (columns)
    VoxelType sourceType = VoxelType::Float32;
    // The samples, x fastest, held in one of two stores: float32 in `voxels`, or (holdNarrow)
    // sample − narrow.offset in narrow.bytes (1 or 2) bytes each in `narrowVoxels`, followed by
    // kNarrowSlack bytes, with `voxels` empty. Read them through samples() or at().
    std::vector<float> voxels;
    NarrowWidth narrow;                     // bytes 4: the samples are in `voxels`
    std::vector<unsigned char, HugePageAllocator<unsigned char>> narrowVoxels;
    ValueRange range;               // of the finite voxels
    Histogram histogram;
    size_t nonFiniteReplaced = 0;   // NaN/Inf voxels replaced under the loader's policy
    // Whether the file names its patient space (DICOM image orientation, NRRD `space`, NIfTI
    // qform/sform code > 0): only then are the world axes L, P, S. Otherwise the starting
    // view is a guess the client must say it is.
    bool orientationKnown = false;
    // What the file's header says the data is, and where: a modality code (DICOM Modality
    // (0008,0060), an NRRD key `modality:=CT`) or a description whose words may name one (NRRD
    // `content`, NIfTI `descrip`); renderer/model/presets.cpp reads it. Both empty if none.
    std::string modality;
    std::string modalityField;      // "DICOM", "NRRD key", "NRRD content", "NIfTI descrip"; empty: a code

    size_t voxelCount() const { return size_t(dims.x) * size_t(dims.y) * size_t(dims.z); }
    size_t index(int64_t i, int64_t j, int64_t k) const {
        return size_t((k * dims.y + j) * dims.x + i);
    }
    SampleGrid samples() const { return {dims, voxels.data(), narrowVoxels.data(), narrow}; }
    float at(int64_t i, int64_t j, int64_t k) const { return samples()[index(i, j, k)]; }
    // Whether the store holds one sample per voxel (loaders and tests build `voxels` by hand).
    bool hasSamples() const {
        return narrow.bytes == 4 ? voxels.size() == voxelCount()
                                 : narrowVoxels.size() == voxelCount() * size_t(narrow.bytes) + kNarrowSlack;
    }
    // Bytes the samples take in memory.
    size_t sampleBytes() const { return voxels.size() * sizeof(float) + narrowVoxels.size(); }

    // Index space: continuous voxel coordinates; the volume is [-1/2, n - 1/2] on each axis.
    Vec3d indexFromWorld(const Vec3d &p) const {
        return div(direction.transposed() * (p - origin), spacing);
    }
    Vec3d worldFromIndex(const Vec3d &p) const { return origin + direction * mul(p, spacing); }
    // Index-space direction of a world-space direction (not normalized).
    Vec3d indexFromWorldDir(const Vec3d &d) const { return div(direction.transposed() * d, spacing); }

    Vec3d worldBoundsMin() const { return worldFromIndex({-0.5, -0.5, -0.5}); }
    Vec3d center() const {
        return worldFromIndex(Vec3d(dims - Vec3i{1, 1, 1}) * 0.5);
    }
    // World-space extent of the cell-extent box along each index axis.
    Vec3d extent() const { return mul(Vec3d(dims), spacing); }
    double smallestSpacing() const { return minComponent(spacing); }
};

// Recompute range and histogram from the samples (finite values only).
void computeStatistics(Volume &v);

// Moves float samples into the narrow store when every one fits it (narrowWidth); returns
// whether the volume is held narrow now. Loaders call it; so may anyone building a volume.
bool holdNarrow(Volume &v);

// Stores v.voxelCount() samples held elsewhere (a reader's buffer) in v: narrow when every one
// fits the narrow store (as holdNarrow would keep them), else as float32. T as for narrowWidth.
template <class T>
void storeSamples(Volume &v, const T *samples);

} // namespace volcast
