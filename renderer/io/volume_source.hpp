#pragma once
// The volume a scene names: a file through the loader, or "builtin:NAME" for a synthetic
// volume, which also brings its continuous field.

#include "renderer/model/volume.hpp"
#include "renderer/io/volume_io.hpp"

#include <functional>
#include <string_view>

namespace volcast {

inline constexpr std::string_view kBuiltinPrefix = "builtin:";

struct LoadedVolume {
    Volume volume;
    std::function<double(const Vec3d &world)> analyticField; // empty for scanned volumes
};

LoadedVolume loadSceneVolume(std::string_view spec, const LoadOptions &options = {});

} // namespace volcast
