#pragma once
// The binary frame message (layout in protocol/README.md, "Frames"):
//
//   bytes 0-3   magic "VCF1"
//   bytes 4-7   N, the header's length in bytes, uint32 little-endian
//   bytes 8..   the header: N bytes of UTF-8 JSON, one object
//   then        the encoded image, exactly header.image_bytes bytes, to the message's end
//
// A JSON header rather than packed fields: a browser reads it with DataView + TextDecoder
// + JSON.parse, and fields can be added without a new layout.

#include "protocol/client_messages.hpp"
#include "protocol/errors.hpp"

#include <nlohmann/json.hpp>

#include <cstddef>
#include <cstdint>
#include <optional>
#include <span>
#include <string>
#include <string_view>
#include <vector>

namespace volcast::protocol {

inline constexpr size_t kFramePreambleBytes = 8;          // magic + header length
inline constexpr size_t kMaxFrameHeaderBytes = 64 * 1024; // a header is ~0.5 KiB in practice

enum class Codec {
    Jpeg,   // while interacting and for intermediate levels: small, lossy, no alpha
    Png,    // the final frame: lossless, RGBA
};
std::string_view codecName(Codec codec);

// The server's estimate of the frame's error: RMSE over premultiplied RGBA in [0, 1]
// against the exact image (docs/design.md's error), and how it was estimated:
//   "rmse_vs_next_level"       measured against the next refined level of the same view
//   "calibrated_vs_reference"  predicted from this level's measured error against the
//                              reference integrator on this volume and transfer function
//   "rmse_vs_reference"        measured against the reference integrator (tests, benchmarks)
struct ErrorEstimate {
    double value = 0;
    std::string method;
    bool operator==(const ErrorEstimate &) const = default;
};

struct FrameHeader {
    uint64_t seq = 0;          // per session, from 1, increasing by one per frame sent
    RequestId request;         // id of the latest request the frame reflects; null if none had one
    int level = 0;             // refinement level, 0 the cheapest; explicit quality has only 0
    nlohmann::json quality;    // scene-file "quality" switches this level rendered with
    int width = 0;             // pixels of the encoded image: the rays the level cast
    int height = 0;            //   (image_scale < 1 makes it smaller than the view)
    int viewWidth = 0;         // pixels of the view the image fills (the viewport, a still's
    int viewHeight = 0;        //   size); clients scale the image up to it. 0: the image's own
    Codec codec = Codec::Jpeg;
    double renderMs = 0;       // ms, from render start to pixels on the host
    double encodeMs = 0;       // ms, image encoding
    std::optional<ErrorEstimate> error;   // nullopt: not estimated
    bool final = false;        // the view's final level: the last of its ladder (passes at rest may follow)
    int restPass = 0;          // n ≥ 1: the n-th pass of refinement at rest after the final frame,
                               //   toward the exact integral; 0: not one
    nlohmann::json camera;     // scene-file "camera" this frame shows; null when not sent
    std::string limited;       // what the automatic policy lowered to stay within the server's
                               //   limits ("image scale 0.5 to stay within …"); empty: nothing
    bool operator==(const FrameHeader &) const = default;
    // The size the image is shown at: the view's, or the image's own where none is given.
    int shownWidth() const { return viewWidth != 0 ? viewWidth : width; }
    int shownHeight() const { return viewHeight != 0 ? viewHeight : height; }
};

// The frame message for header and image. Throws std::invalid_argument for a header that
// could not be decoded again (a non-positive size, a negative or non-finite time).
std::vector<uint8_t> encodeFrame(const FrameHeader &header, std::span<const uint8_t> image);

struct DecodedFrame {
    FrameHeader header;
    std::span<const uint8_t> image;   // points into the decoded message
};

// Throws DecodeError naming the problem: too short, wrong magic, header length past the end
// or over kMaxFrameHeaderBytes, header not JSON or a field missing or of the wrong kind, or
// an image length other than the header's image_bytes (a truncated or padded message).
DecodedFrame decodeFrame(std::span<const uint8_t> message);

} // namespace volcast::protocol
