#pragma once
// The peers' benchmark phantom (the peers' harness, vtk_bench.py's make_phantom), made here so
// volcast-bench needs no Python: a noisy low background, an ellipsoidal "soft tissue"
// interior with a smooth 3-D ripple, a shell, a dense tube along z and four dense blobs, in
// [0, 1] scaled to 0..255 (8-bit) or 0..4095 (16-bit). The same shapes and values; the noise
// comes from another generator, so voxels differ by the noise only.

#include "renderer/model/volume.hpp"

namespace volcast::bench {

// sourceType UInt8 or UInt16; spacing 1, origin 0.
Volume makePeerPhantom(Vec3i dims, VoxelType sourceType, unsigned seed = 1234);

// The same volume, trilinearly resampled to `dims` over the same sample box (first and last
// samples kept). With dims = 2n − 1 every old sample is a new one and each new cell lies in
// one old cell, so trilinear interpolation of the new grid is exactly that of the old: eight
// times the data, the same picture.
Volume resampleTrilinear(const Volume &volume, Vec3i dims);

} // namespace volcast::bench
