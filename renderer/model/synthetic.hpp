#pragma once
// Synthetic volumes for tests and the demo. Each is sampled from a continuous field that
// it also exposes, so the reference renderer can integrate the field itself; the difference
// between the two is the reconstruction (interpolation) error.

#include "renderer/model/volume.hpp"

#include <functional>
#include <string>
#include <string_view>
#include <vector>

namespace volcast {

struct SyntheticVolume {
    Volume volume;                                   // the field sampled at voxel centres
    std::function<double(const Vec3d &world)> field; // the continuous field, world coordinates
};

// Sample `field` on the grid of dims/spacing/origin.
SyntheticVolume sampleField(std::string name, Vec3i dims, Vec3d spacing, Vec3d origin,
                            std::function<double(const Vec3d &)> field);

// Constant `value` everywhere.
SyntheticVolume makeConstantBox(Vec3i dims, Vec3d spacing, double value);
// Linear along index axis x: `v0` at the first sample, `v1` at the last (continues linearly
// beyond them; the sampled volume's clamp-to-edge does not).
SyntheticVolume makeLinearRamp(Vec3i dims, Vec3d spacing, double v0, double v1);
// A ball of `value` with a smooth edge of width `edge` (world units) at `radius` from the centre.
SyntheticVolume makeSphere(Vec3i dims, Vec3d spacing, double radius, double edge, double value);
// peak · exp(-r² / 2σ²) around the centre.
SyntheticVolume makeGaussianBlob(Vec3i dims, Vec3d spacing, double sigma, double peak);
// A straight tube through the centre along `axis`, Gaussian cross-section of width sigma:
// thin enough (sigma ~ 1 voxel) that trilinear interpolation shows the paper's "stars".
SyntheticVolume makeThinTube(Vec3i dims, Vec3d spacing, Vec3d axis, double sigma, double peak);
// The demo phantom: a skull-like shell, soft tissue, a vessel tree of thin tubes and blobs,
// values 0..255 like an 8-bit CT.
SyntheticVolume makeDemoPhantom(int64_t n);

// Built-in volumes by name, as used by "builtin:NAME" in scene files.
std::vector<std::string> builtinVolumeNames();
SyntheticVolume makeBuiltinVolume(std::string_view name);

} // namespace volcast
