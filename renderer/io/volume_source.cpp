#include "renderer/io/volume_source.hpp"

#include "renderer/model/synthetic.hpp"

namespace volcast {

LoadedVolume loadSceneVolume(std::string_view spec, const LoadOptions &options) {
    if (spec.starts_with(kBuiltinPrefix)) {
        SyntheticVolume s = makeBuiltinVolume(spec.substr(kBuiltinPrefix.size()));
        return {std::move(s.volume), std::move(s.field)};
    }
    return {loadVolume(std::filesystem::path(spec), options), {}};
}

} // namespace volcast
