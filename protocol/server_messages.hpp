#pragma once
// Server -> client JSON text messages: hello, volumes, progress, state and error. Frames
// are binary messages (frame.hpp). A reply echoes the "id" of the request it answers.
// protocol/README.md documents every field.

#include "protocol/client_messages.hpp"
#include "protocol/errors.hpp"
#include "protocol/version.hpp"

#include <nlohmann/json.hpp>

#include <array>
#include <cstdint>
#include <optional>
#include <string>
#include <string_view>
#include <variant>
#include <vector>

namespace volcast::protocol {

struct DeviceInfo {
    std::string name;   // e.g. "NVIDIA H100 80GB HBM3", "cpu-haswell-Intel(R) Xeon(R) ..."
    std::string type;   // "gpu", "cpu", "accelerator" or "other" (OpenCL's device types)
    bool operator==(const DeviceInfo &) const = default;
};

// The limits a client must stay within, so it can check before sending.
struct ServerLimits {
    size_t maxMessageBytes = Limits{}.maxMessageBytes;   // bytes of one text message
    int maxImageSide = 0;                                // pixels, width or height
    int64_t maxImagePixels = 0;                          // width x height
    size_t maxVolumeNameBytes = kMaxVolumeNameBytes;
    // Admission control: work one request may start. 0 when the server did not say (an
    // older server); requests over them get too_large naming the limit.
    int64_t maxSamplesPerFrame = 0;   // predicted samples of one frame: rays x samples per ray
    int64_t maxStillPixels = 0;       // width x height of a still
    int64_t maxRequestBytes = 0;      // image memory of one view: width x height x 16 x passes
    bool operator==(const ServerLimits &) const = default;
};

struct ServerHello {
    static constexpr std::string_view kType = "hello";
    RequestId id;
    int protocol = kProtocolVersion;
    std::string server;   // name and version, e.g. "volcast 0.1.0"
    DeviceInfo device;
    ServerLimits limits;
    bool operator==(const ServerHello &) const = default;
};

struct HistogramInfo {
    std::array<double, 2> range{0, 0};   // data units; the bins split it evenly
    std::vector<uint64_t> counts;        // voxels per bin (256 bins from the server's loader)
    bool operator==(const HistogramInfo &) const = default;
};

// A display preset resolved on one volume (renderer/model/presets.hpp): window/level and points
// in the volume's data units, and whether it shades.
struct PresetInfo {
    std::string name;
    std::string label;
    double window = 1, level = 0;
    std::vector<std::array<double, 5>> points;   // [value, r, g, b, a]
    bool shading = false;
    std::string modality;   // the modality it belongs to ("CT", "MR", "micro-CT"); empty from older servers
    bool operator==(const PresetInfo &) const = default;
};

// The modality the server chose presets by, and why (a line for the user).
struct ModalityInfo {
    std::string name;           // "CT", "MR", "micro-CT"
    std::string source;         // "file" or "inferred"
    std::string reason;
    std::string defaultPreset;  // the preset the volume opened with
    std::vector<PresetInfo> presets;   // every modality's, the default first
    std::vector<std::string> modalities;   // the modalities presets exist for, the chosen first; empty from older servers
    bool hounsfield = false;    // CT whose values are Hounsfield units
    bool operator==(const ModalityInfo &) const = default;
};

// What is known of one volume. Everything but the name may be missing for a volume not
// loaded yet: the server lists its data folders without reading every scan.
struct VolumeInfo {
    std::string name;                              // what open_volume takes
    bool loaded = false;                           // in the server's memory now
    std::optional<std::array<int64_t, 3>> dims;    // samples per axis
    std::optional<std::array<double, 3>> spacing;  // world units between samples
    std::optional<std::array<double, 3>> origin;   // world position of voxel (0, 0, 0)
    // Rows of the unit direction matrix D: voxel (i, j, k) is at origin + D·(i·sx, j·sy, k·sz).
    std::optional<std::array<std::array<double, 3>, 3>> direction;
    std::string voxelType;                         // in the file: "uint8", "int16", "float32", ...
    std::optional<std::array<double, 2>> valueRange;   // [min, max] of the finite voxels
    std::optional<HistogramInfo> histogram;
    // Whether the file names its patient space (world axes are L, P, S); loaded volumes only.
    std::optional<bool> orientationKnown;
    std::optional<ModalityInfo> modality;          // loaded volumes only
    bool operator==(const VolumeInfo &) const = default;
};

// A place studies can be searched and retrieved from: a PACS over DICOMweb.
struct SourceInfo {
    std::string name;   // what find_studies and dicomweb: volume names take
    std::string kind;   // "dicomweb"
    bool operator==(const SourceInfo &) const = default;
};

struct VolumesMessage {
    static constexpr std::string_view kType = "volumes";
    RequestId id;
    std::vector<VolumeInfo> volumes;
    std::vector<SourceInfo> sources;   // absent from older servers: empty
    bool operator==(const VolumesMessage &) const = default;
};

// One series of a study found on a source; `volume` is the name open_volume takes
// ("dicomweb:SOURCE/STUDY_UID/SERIES_UID").
struct SeriesInfo {
    std::string seriesUid;
    std::string modality;
    std::string description;
    int64_t instances = 0;   // as the source counts them; 0 when it did not say
    std::string volume;
    bool operator==(const SeriesInfo &) const = default;
};

// One study as the source describes it. Patient names travel only in these messages.
struct StudyInfo {
    std::string studyUid;
    std::string patientName;   // DICOM person name, components joined by '^'
    std::string patientId;
    std::string studyDate;     // YYYYMMDD, or empty
    std::string description;
    std::string accessionNumber;
    std::vector<std::string> modalities;
    std::vector<SeriesInfo> series;
    bool operator==(const StudyInfo &) const = default;
};

// The answer to find_studies.
struct StudiesMessage {
    static constexpr std::string_view kType = "studies";
    RequestId id;
    std::string source;
    std::vector<StudyInfo> studies;
    bool operator==(const StudiesMessage &) const = default;
};

enum class ProgressStage {
    Loading,         // reading and converting the file
    Preprocessing,   // statistics, min-max bricks, mipmaps, B-spline coefficients, tables
    Uploading,       // copying to the device
    Retrieving,      // receiving a series from a DICOMweb source
};
std::string_view progressStageName(ProgressStage stage);

// Sent while an open_volume (its id echoed) or a render's preprocessing is under way.
struct ProgressMessage {
    static constexpr std::string_view kType = "progress";
    RequestId id;
    std::string volume;      // the volume's name
    ProgressStage stage = ProgressStage::Loading;
    std::string task;        // within the stage, e.g. "bspline_coefficients"; may be empty
    double fraction = 0;     // of the stage done, in [0, 1]
    // While retrieving: DICOM instances received of those announced, and bytes received.
    std::optional<std::array<int64_t, 2>> instances;
    std::optional<uint64_t> bytes;
    bool operator==(const ProgressMessage &) const = default;
};

// The session as the server holds it; answers get_state and open_volume, and follows any
// change the server made on its own (a default camera and transfer function on open).
struct StateMessage {
    static constexpr std::string_view kType = "state";
    RequestId id;
    std::optional<VolumeInfo> volume;   // the open volume, nullopt before open_volume
    // docs/design.md's scene-file form ("volume", "transfer_function", "camera", "image",
    // "quality", "clip_planes"); keys not set yet are absent. Saved as is, it is a scene file
    // for volcast-render (with "volume" the name in the server's data folders).
    nlohmann::json scene = nlohmann::json::object();
    QualityPolicy qualityPolicy;
    bool interacting = false;   // between interaction_start and interaction_end
    bool operator==(const StateMessage &) const = default;
};

// The answer to probe: the value at the point, null outside the volume. unit "HU" when the
// volume's values are Hounsfield units (a CT), else null: raw data units.
struct ProbeMessage {
    static constexpr std::string_view kType = "probe";
    RequestId id;
    std::array<double, 3> point{};
    bool inside = false;
    std::optional<double> value;
    std::optional<std::string> unit;
    bool operator==(const ProbeMessage &) const = default;
};

// The answer to roi_stats. With samples = 0 (the region misses the volume) the statistics are
// null. std is the population standard deviation of the samples.
struct RoiStatsMessage {
    static constexpr std::string_view kType = "roi_stats";
    RequestId id;
    int64_t samples = 0;
    double areaMm2 = 0;
    std::optional<double> mean, std, min, max;
    std::optional<std::string> unit;
    bool operator==(const RoiStatsMessage &) const = default;
};

// The answer to pick: the world point where the pixel's ray first reached opacity 1/2
// (null when it never did), and the ray's final opacity.
struct PickMessage {
    static constexpr std::string_view kType = "pick";
    RequestId id;
    bool hit = false;
    std::optional<std::array<double, 3>> point;
    double opacity = 0;
    bool operator==(const PickMessage &) const = default;
};

using ServerMessage = std::variant<ServerHello, VolumesMessage, ProgressMessage, StateMessage, StudiesMessage,
                                   ProtocolError, ProbeMessage, RoiStatsMessage, PickMessage>;

std::string_view messageType(const ServerMessage &message);

// Compact JSON text of a server message. An error is {"type": "error", "code", "message",
// "id", "request_type"}.
std::string toJsonText(const ServerMessage &message);

// For clients: read one server text message. Fields a client does not know are ignored
// (a newer server may add them); an unknown type, a missing field or one of the wrong kind
// throws DecodeError.
ServerMessage parseServerMessage(std::string_view text);

} // namespace volcast::protocol
