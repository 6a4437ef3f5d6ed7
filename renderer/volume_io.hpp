#pragma once
// Loading volumes from files through ITK's image IO: NRRD (.nrrd, detached .nhdr; raw or
// gzip; either byte order), MetaImage (.mhd, .mha), NIfTI-1 (.nii, .nii.gz) and a DICOM
// series given as a folder.
//
// Non-finite voxels policy: NaN becomes the smallest finite value of the volume, +Inf the
// largest and -Inf the smallest; the count is kept in Volume::nonFiniteReplaced and a
// warning is logged. A volume with no finite voxel is rejected.

#include "renderer/volume.hpp"

#include <cstdint>
#include <filesystem>
#include <stdexcept>

namespace volcast {

struct LoadOptions {
    uint64_t maxBytes = uint64_t(8) << 30;  // in-memory size (float32 voxels) allowed, bytes
    int64_t maxDimension = 32768;           // samples per axis allowed
};

// Every failure to load: the message starts with the file's path and names the problem.
struct VolumeLoadError : std::runtime_error {
    using std::runtime_error::runtime_error;
};

Volume loadVolume(const std::filesystem::path &path, const LoadOptions &options = {});

} // namespace volcast
