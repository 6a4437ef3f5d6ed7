#pragma once
// The `slice` request and its answer, the slice message (protocol/README.md, "slice" and
// "Slice messages"). A slice is a plane of the open volume in the patient frame, resampled
// and windowed to 8-bit grey by the server; it answers one request and changes nothing in
// the session's scene, so it never shows in a frame's `request`.
//
// The answer is its own binary message with its own magic, "VCS1", laid out like a frame
// (magic, uint32 LE header length, JSON header, pixels). A separate magic rather than a flag
// in the frame header: a client that decodes every binary message as a 3D frame (older code)
// can never draw a slice into its 3D view by mistake, and only a client that sent `slice`
// ever receives one.

#include "protocol/errors.hpp"

#include <nlohmann/json.hpp>

#include <array>
#include <cstdint>
#include <optional>
#include <span>
#include <string>
#include <string_view>
#include <vector>

namespace volcast::protocol {

using RequestId = nlohmann::json;

inline constexpr std::array<uint8_t, 4> kSliceMagic = {'V', 'C', 'S', '1'};
// The protocol's own bound on a slice side; the server's max_image_side and
// max_image_pixels bound it further.
inline constexpr int kMaxSliceSide = 16384;

// A thick slab (slice's "slab"): planes across [−thickness/2, +thickness/2] mm along the
// slice's normal, combined per pixel. Thickness 0 is the plane itself.
struct SliceSlab {
    double thickness = 0;       // mm, finite, >= 0
    std::string mode = "mip";   // "mip", "minip" or "mean"
    bool operator==(const SliceSlab &) const = default;
};

struct SliceRequest {
    static constexpr std::string_view kType = "slice";
    RequestId id;
    std::string axis;                               // "axial", "coronal" or "sagittal"
    std::optional<std::array<double, 3>> point;     // world (patient) mm; the volume's centre
    std::optional<std::array<double, 3>> center;    // world point at the image's centre
    int width = 0;                                  // pixels, required
    int height = 0;
    std::optional<double> pixelSpacing;             // mm per pixel; default: fit the volume
    std::optional<double> window;                   // data units; default: the value range
    std::optional<double> level;
    std::optional<SliceSlab> slab;                  // absent: the plane
    bool operator==(const SliceRequest &) const = default;
};

namespace detail {
// Reads a slice request's fields (the message object; "type" and "id" are known fields).
// Throws ReadError (bad_field naming the field).
SliceRequest readSliceRequest(const nlohmann::json &root, const RequestId &id);
nlohmann::json sliceRequestFields(const SliceRequest &m);
// Shared by the readers of probe, roi_stats and slice: three finite numbers, bad_field naming
// the path otherwise.
std::array<double, 3> readVec3(const nlohmann::json &j, const std::string &path);
// Whether `axis` is "axial", "coronal" or "sagittal"; bad_field naming `path` otherwise.
std::string readSliceAxis(const nlohmann::json &j, const std::string &path);
} // namespace detail

// The header of a slice message. Pixel (c, r), row 0 at the top, shows the volume at world
// origin + c·pixel_spacing·column + r·pixel_spacing·row.
struct SliceHeader {
    RequestId request;                 // the slice request's id
    std::string axis;
    int width = 0;
    int height = 0;
    std::string format = "gray8";      // one byte per pixel: window/level applied, 0 outside
    double pixelSpacing = 0;
    std::array<double, 3> origin{};    // world position of pixel (0, 0)'s centre
    std::array<double, 3> column{};    // unit world direction of +column
    std::array<double, 3> row{};       // unit world direction of +row
    std::array<double, 3> point{};     // the plane's point (the crosshair)
    double window = 1;
    double level = 0;
    double renderMs = 0;
    // The request's slab, echoed with the number of planes sampled; absent for a plain slice.
    std::optional<SliceSlab> slab;
    int slabPlanes = 1;
    bool operator==(const SliceHeader &) const = default;
};

// Throws std::invalid_argument when pixels is not width x height bytes or a value is not
// finite.
std::vector<uint8_t> encodeSlice(const SliceHeader &header, std::span<const uint8_t> pixels);

struct DecodedSlice {
    SliceHeader header;
    std::span<const uint8_t> pixels;   // into the decoded message
};
// Throws DecodeError naming the problem (magic, lengths, a field missing or of the wrong
// kind, pixel bytes other than width x height).
DecodedSlice decodeSlice(std::span<const uint8_t> message);

// Whether a binary message is a slice message (its magic), for clients that receive both.
bool isSliceMessage(std::span<const uint8_t> message);

} // namespace volcast::protocol
