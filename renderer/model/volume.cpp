#include "renderer/model/volume.hpp"

#include <algorithm>
#include <cmath>
#include <limits>

namespace volcast {

std::string_view voxelTypeName(VoxelType t) {
    switch (t) {
    case VoxelType::UInt8: return "uint8";
    case VoxelType::Int8: return "int8";
    case VoxelType::UInt16: return "uint16";
    case VoxelType::Int16: return "int16";
    case VoxelType::UInt32: return "uint32";
    case VoxelType::Int32: return "int32";
    case VoxelType::Float32: return "float32";
    case VoxelType::Float64: return "float64";
    }
    return "unknown";
}

size_t voxelTypeSize(VoxelType t) {
    switch (t) {
    case VoxelType::UInt8:
    case VoxelType::Int8: return 1;
    case VoxelType::UInt16:
    case VoxelType::Int16: return 2;
    case VoxelType::UInt32:
    case VoxelType::Int32:
    case VoxelType::Float32: return 4;
    case VoxelType::Float64: return 8;
    }
    return 0;
}

void computeStatistics(Volume &v) {
    const SampleGrid g = v.samples();
    std::vector<float> scratch;
    float lo = std::numeric_limits<float>::max();
    float hi = std::numeric_limits<float>::lowest();
    for (int64_t k = 0; k < v.dims.z; ++k) {
        const float *slice = g.slice(k, scratch);
        for (size_t i = 0, n = size_t(v.dims.x) * size_t(v.dims.y); i < n; ++i) {
            const float x = slice[i];
            if (!std::isfinite(x)) continue;
            lo = std::min(lo, x);
            hi = std::max(hi, x);
        }
    }
    if (lo > hi) lo = hi = 0; // no finite voxel (callers reject such volumes)
    v.range = {lo, hi};

    v.histogram.range = v.range;
    v.histogram.counts.assign(Histogram::kBins, 0);
    const double width = double(hi) - double(lo);
    for (int64_t k = 0; k < v.dims.z; ++k) {
        const float *slice = g.slice(k, scratch);
        for (size_t i = 0, n = size_t(v.dims.x) * size_t(v.dims.y); i < n; ++i) {
            const float x = slice[i];
            if (!std::isfinite(x)) continue;
            int bin = width > 0 ? int((double(x) - lo) / width * Histogram::kBins) : 0;
            v.histogram.counts[size_t(std::clamp(bin, 0, Histogram::kBins - 1))]++;
        }
    }
}

namespace {
// Packs count samples into v's narrow store if they fit it; false (nothing stored) if not.
template <class T>
bool packIntoNarrow(Volume &v, const T *samples, size_t count) {
    const NarrowWidth w = narrowWidth(samples, count);
    if (w.bytes == 4) return false;
    v.narrowVoxels.assign(count * size_t(w.bytes) + kNarrowSlack, 0);
    packNarrow(samples, count, w, v.narrowVoxels.data());
    v.narrow = w;
    return true;
}
} // namespace

bool holdNarrow(Volume &v) {
    if (v.narrow.bytes < 4) return true;
    if (v.voxels.size() != v.voxelCount()) return false;
    if (!packIntoNarrow(v, v.voxels.data(), v.voxels.size())) return false;
    std::vector<float>().swap(v.voxels); // give the float store's memory back
    return true;
}

template <class T>
void storeSamples(Volume &v, const T *samples) {
    const size_t count = v.voxelCount();
    if (!packIntoNarrow(v, samples, count)) v.voxels.assign(samples, samples + count);
}

template void storeSamples(Volume &, const float *);
template void storeSamples(Volume &, const int8_t *);
template void storeSamples(Volume &, const uint8_t *);
template void storeSamples(Volume &, const int16_t *);
template void storeSamples(Volume &, const uint16_t *);

} // namespace volcast
