#pragma once
// A scalar volume on a regular grid, in the coordinates of docs/design.md: voxel (i, j, k) is a
// sample at world = origin + D·(i·sx, j·sy, k·sz), and owns the cell of size s around it.

#include "renderer/math.hpp"

#include <cstddef>
#include <cstdint>
#include <string>
#include <string_view>
#include <vector>

namespace volcast {

// The type the voxels had in their file; in memory every volume is float32.
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
    std::vector<float> voxels;      // dims.x * dims.y * dims.z samples
    ValueRange range;               // of the finite voxels
    Histogram histogram;
    size_t nonFiniteReplaced = 0;   // NaN/Inf voxels replaced under the loader's policy
    // Whether the file names its patient space (DICOM image orientation, NRRD `space`, NIfTI
    // qform/sform code > 0): only then are the world axes L, P, S. Otherwise the starting
    // view is a guess the client must say it is.
    bool orientationKnown = false;
    std::string modality;           // the file's own (DICOM 0008,0060: "CT", "MR", ...); empty if none

    size_t voxelCount() const { return size_t(dims.x) * size_t(dims.y) * size_t(dims.z); }
    size_t index(int64_t i, int64_t j, int64_t k) const {
        return size_t((k * dims.y + j) * dims.x + i);
    }
    float at(int64_t i, int64_t j, int64_t k) const { return voxels[index(i, j, k)]; }

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

// Recompute range and histogram from the voxels (finite values only).
void computeStatistics(Volume &v);

} // namespace volcast
