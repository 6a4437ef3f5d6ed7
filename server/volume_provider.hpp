#pragma once
// Volumes that do not live in the data folders: a user's uploads ("upload:<id>") and series
// retrieved from a PACS ("dicomweb:SOURCE/STUDY/SERIES"). The registry hands a name carrying a
// provider's prefix to that provider, which makes the volume available as a local file or
// folder on the lane of the volume's source (a few fetches at a time per source, beside the
// local loads: volume_registry.hpp); the registry then loads it as it loads any file, except that
// every file, whatever its format, is parsed first in the child process (LoadOptions::
// parseInChild): bytes from a browser or a PACS are hostile until a parse has survived.

#include "protocol/errors.hpp"
#include "renderer/io/volume_io.hpp"

#include <cstdint>
#include <filesystem>
#include <functional>
#include <optional>
#include <stdexcept>
#include <string>
#include <string_view>

namespace volcast::server {

// Where a fetch stands, for the client's `progress` messages (stage "retrieving").
struct FetchProgress {
    std::string task;                       // "retrieving instances", "checking the series"
    double fraction = 0;                    // of the fetch done, in [0, 1]
    std::optional<int64_t> instancesDone;   // DICOM instances received so far
    std::optional<int64_t> instancesTotal;  // as the source announced them
    std::optional<uint64_t> bytes;          // bytes received so far
};

struct FetchContext {
    std::function<void(const FetchProgress &)> progress;   // never empty
    std::function<bool()> stopRequested;                   // never empty; true: give up (shutdown)
    double timeLimitSeconds = 0;                           // 0: none
    // A volume whose float32 voxels would need more than this is refused from its metadata,
    // before its voxels are retrieved (throw VolumeFetchError with ErrorCode::LoadFailed).
    uint64_t maxFloat32Bytes = 0;
};

// A fetch that failed: the code the client gets (not_found, load_failed, unauthorized is
// never used for a PACS's 401: that is load_failed naming the source's answer) and a message
// fit for clients: it names the volume as the client gave it, never a server path or a
// credential.
struct VolumeFetchError : std::runtime_error {
    VolumeFetchError(protocol::ErrorCode c, const std::string &message) : std::runtime_error(message), code(c) {}
    protocol::ErrorCode code;
};

// What a fetch made available: the volume's bytes as they came (a DICOM series in a folder,
// a file), for the registry to parse in the child process; or what the child already
// parsed from them and handed back (renderer/io/volume_io.hpp's parseToKeep), which the
// registry only reads and checks (loadParsedVolume): an upload is parsed once, when it arrives.
struct FetchedVolume {
    enum class Form { Source, Parsed };
    std::filesystem::path path;
    Form form = Form::Source;
    // A series retrieved as this study and series: the load refuses it unless every instance
    // is theirs (LoadOptions::expectedSeries).
    std::optional<SeriesIdentity> expectedSeries = std::nullopt;
};

class VolumeProvider {
  public:
    virtual ~VolumeProvider() = default;
    // The names this provider answers for start with this ("upload:", "dicomweb:").
    virtual std::string_view prefix() const = 0;
    // A cheap check on the caller's thread, before a load is queued: nullopt if the name may
    // be opened, else the error to answer (not_found for an unknown upload or source).
    virtual std::optional<protocol::ProtocolError> check(const std::string &name) const = 0;
    // What `name` is fetched from: fetches of one source share a lane, so a slow source holds
    // up only its own opens. The provider's prefix by default (one source).
    virtual std::string sourceOf(const std::string &) const { return std::string(prefix()); }
    // On the source's lane, several at once (for different names): the local file or folder
    // holding the volume, which stays there at least until release(). Throws VolumeFetchError.
    virtual FetchedVolume fetch(const std::string &name, const FetchContext &context) = 0;
    // Once for each fetch() that returned, when the registry is done reading what it made
    // available. refused: the loader refused those bytes (the checker, the series checks), so a
    // provider that keeps them drops them, and the next open fetches again.
    virtual void release(const std::string &, bool /*refused*/) {}
};

} // namespace volcast::server
