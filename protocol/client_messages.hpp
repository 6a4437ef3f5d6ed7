#pragma once
// Client -> server messages: one JSON text message each, {"type": ..., "id": ..., fields}.
// protocol/README.md documents every field. Scene pieces (camera, transfer function,
// image size, quality switches, clip planes) travel in exactly the JSON form of docs/design.md's
// scene file, under the same keys, so a session's state can be saved as a scene file. Here
// only their JSON kind is checked (camera must be an object, ...): their detailed checks
// belong to renderer/model/scene.cpp's parseScene, which the server runs on the assembled scene.

#include "protocol/errors.hpp"
#include "protocol/slice.hpp"
#include "protocol/volume_name.hpp"

#include <nlohmann/json.hpp>

#include <array>
#include <cstddef>
#include <optional>
#include <string>
#include <string_view>
#include <variant>

namespace volcast::protocol {

// What parseClientMessage accepts. The server reports its own values in its hello.
struct Limits {
    size_t maxMessageBytes = 64 * 1024;   // bytes of one text message, checked before parsing
    int maxDepth = 32;                    // JSON nesting; the deepest real message needs 4
    size_t maxIdBytes = 64;               // a string request id
    size_t maxTokenBytes = 1024;          // hello's token
    size_t maxVolumeNameBytes = kMaxVolumeNameBytes;
};

// Every request may carry "id": null, an integer or a string, chosen by the client and
// echoed in the replies and errors that answer it. null here means the request had none.
using RequestId = nlohmann::json;

struct HelloRequest {
    static constexpr std::string_view kType = "hello";
    RequestId id;
    int protocol = 0;                    // the protocol version the client speaks
    std::optional<std::string> token;    // access token, when the server asks for one
    std::string client;                  // free text for the server's log ("orbit.py 1.0")
    bool operator==(const HelloRequest &) const = default;
};

struct ListVolumesRequest {
    static constexpr std::string_view kType = "list_volumes";
    RequestId id;
    bool operator==(const ListVolumesRequest &) const = default;
};

struct OpenVolumeRequest {
    static constexpr std::string_view kType = "open_volume";
    RequestId id;
    std::string name;   // passed validateVolumeName
    bool operator==(const OpenVolumeRequest &) const = default;
};

// A study search on a DICOMweb source (QIDO-RS). Empty filters match everything; the
// protocol checks their form, the source answers what matches.
struct StudyFilters {
    std::string patientName;       // DICOM wildcards * and ? allowed
    std::string patientId;
    std::string studyDate;         // "YYYYMMDD", or a range "YYYYMMDD-YYYYMMDD" with either end empty
    std::string modality;          // "CT", "MR", ...
    std::string accessionNumber;
    bool operator==(const StudyFilters &) const = default;
};

inline constexpr int kMaxStudiesLimit = 1000;
inline constexpr size_t kMaxSourceNameBytes = 64;

struct FindStudiesRequest {
    static constexpr std::string_view kType = "find_studies";
    RequestId id;
    std::string source;   // a source as volumes' "sources" lists it: [A-Za-z0-9_-], at most 64
    StudyFilters filters;
    int limit = 100;      // studies at most, in [1, kMaxStudiesLimit]
    bool operator==(const FindStudiesRequest &) const = default;
};

// Why `name` cannot be a source name, or nullopt.
std::optional<std::string> validateSourceName(std::string_view name);

struct CameraRequest {
    static constexpr std::string_view kType = "camera";
    RequestId id;
    nlohmann::json camera;   // a JSON object, scene-file form
    bool operator==(const CameraRequest &) const = default;
};

struct InteractionStartRequest {
    static constexpr std::string_view kType = "interaction_start";
    RequestId id;
    bool operator==(const InteractionStartRequest &) const = default;
};

struct InteractionEndRequest {
    static constexpr std::string_view kType = "interaction_end";
    RequestId id;
    bool operator==(const InteractionEndRequest &) const = default;
};

// The size of the client's view; the scene file's "image".
struct ViewportRequest {
    static constexpr std::string_view kType = "viewport";
    RequestId id;
    nlohmann::json image;   // a JSON object, scene-file form {"width", "height"}
    bool operator==(const ViewportRequest &) const = default;
};

struct TransferFunctionRequest {
    static constexpr std::string_view kType = "transfer_function";
    RequestId id;
    nlohmann::json transferFunction;   // a JSON object, scene-file form
    bool operator==(const TransferFunctionRequest &) const = default;
};

enum class QualityMode {
    Automatic,   // the server picks the level: cheap while interacting, refined when still
    Explicit,    // every frame uses exactly the given switches
};

inline constexpr double kDefaultTargetFrameMs = 40;   // ms; 25 frames a second
inline constexpr double kMaxTargetFrameMs = 10000;    // ms

struct QualityPolicy {
    QualityMode mode = QualityMode::Automatic;
    double targetFrameMs = kDefaultTargetFrameMs;   // ms; automatic only
    // Scene-file "quality" object: the final level's switches when automatic (null: the
    // server's own final level), every frame's switches when explicit (required).
    nlohmann::json quality;
    bool operator==(const QualityPolicy &) const = default;
};

struct QualityPolicyRequest {
    static constexpr std::string_view kType = "quality_policy";
    RequestId id;
    QualityPolicy policy;
    bool operator==(const QualityPolicyRequest &) const = default;
};

struct ClipPlanesRequest {
    static constexpr std::string_view kType = "clip_planes";
    RequestId id;
    nlohmann::json clipPlanes;   // a JSON array, scene-file form; empty removes all planes
    bool operator==(const ClipPlanesRequest &) const = default;
};

// Render the current view at the final level now and send it as one final frame.
struct StillRequest {
    static constexpr std::string_view kType = "still";
    RequestId id;
    nlohmann::json image;   // null: the viewport's size; else a scene-file "image" object
    bool operator==(const StillRequest &) const = default;
};

struct GetStateRequest {
    static constexpr std::string_view kType = "get_state";
    RequestId id;
    bool operator==(const GetStateRequest &) const = default;
};

// The volume's value at one world point (mm, the patient frame the slices use), by the
// slices' trilinear reconstruction. Answered by a probe message; changes nothing.
struct ProbeRequest {
    static constexpr std::string_view kType = "probe";
    RequestId id;
    std::array<double, 3> point{};   // finite
    bool operator==(const ProbeRequest &) const = default;
};

// Statistics of the values in an ellipse or rectangle on a slice pane's plane. Answered by a
// roi_stats message; changes nothing.
struct RoiStatsRequest {
    static constexpr std::string_view kType = "roi_stats";
    RequestId id;
    std::string axis;                  // "axial", "coronal" or "sagittal"
    std::array<double, 3> center{};    // world mm, finite
    std::array<double, 2> radii{};     // mm, finite and > 0: along the pane's column, row
    std::string shape = "ellipse";     // "ellipse" or "rectangle" (half sides)
    bool operator==(const RoiStatsRequest &) const = default;
};

// Where the ray through one pixel of the session's current view first becomes half opaque.
// Answered by a pick message; changes nothing.
struct PickRequest {
    static constexpr std::string_view kType = "pick";
    RequestId id;
    double x = 0, y = 0;     // pixels from the image's top-left corner; pixel centres at +0.5
    int width = 0;           // the image the client shows the view in, pixels
    int height = 0;
    bool operator==(const PickRequest &) const = default;
};

struct CloseRequest {
    static constexpr std::string_view kType = "close";
    RequestId id;
    bool operator==(const CloseRequest &) const = default;
};

using ClientMessage =
    std::variant<HelloRequest, ListVolumesRequest, OpenVolumeRequest, CameraRequest,
                 InteractionStartRequest, InteractionEndRequest, ViewportRequest,
                 TransferFunctionRequest, QualityPolicyRequest, ClipPlanesRequest,
                 StillRequest, GetStateRequest, CloseRequest, SliceRequest, FindStudiesRequest, ProbeRequest,
                 RoiStatsRequest, PickRequest>;

// The wire "type" of each request, e.g. "open_volume".
std::string_view messageType(const ClientMessage &message);
const RequestId &requestIdOf(const ClientMessage &message);

// Parse one text message. The size limit is checked before any parsing; every failure is
// a ProtocolError with a stable code, the id echoed when it could be read, and a message
// naming the field. Nothing throws.
using ParsedClientMessage = std::variant<ClientMessage, ProtocolError>;
ParsedClientMessage parseClientMessage(std::string_view text, const Limits &limits = {});

// The error for a binary message from a client: clients send only JSON text.
ProtocolError binaryMessageError(size_t bytes);

// Compact JSON text of a request, as a client sends it (what parseClientMessage reads back).
std::string toJsonText(const ClientMessage &message);

std::string_view qualityModeName(QualityMode mode);

} // namespace volcast::protocol
namespace volcast::json_fields {
class Fields;
}
namespace volcast::protocol {
namespace detail {
// Reads "mode", "target_frame_ms" and "quality" from a quality_policy request or from a
// state message's "quality_policy" object; throws ReadError or json_fields::FieldError.
QualityPolicy readQualityPolicy(const json_fields::Fields &fields);
} // namespace detail
// The policy's JSON form {"mode", "target_frame_ms", "quality"}; used by the state message.
nlohmann::json qualityPolicyToJson(const QualityPolicy &policy);

} // namespace volcast::protocol
