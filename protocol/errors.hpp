#pragma once
// Stable error codes. Their names are part of the protocol: clients switch on them, so a
// name is never changed or reused; new codes may be added (clients treat an unknown code
// as a plain error). Each one's meaning is in protocol/README.md's error table.

#include <nlohmann/json.hpp>

#include <cstdint>
#include <optional>
#include <stdexcept>
#include <string>
#include <string_view>
#include <vector>

namespace volcast::protocol {

enum class ErrorCode {
    MalformedJson,      // the text is not JSON (syntax, bad UTF-8)
    TooLarge,           // over the message size limit, or nested too deep
    BadMessage,         // JSON, but not a message: not an object, no "type", binary from a client
    UnknownType,        // "type" names no message
    BadField,           // a field missing, unknown, of the wrong kind or out of range
    UnsupportedVersion, // hello names a protocol version this server does not speak
    Unauthorized,       // hello's token is missing or wrong
    BadState,           // not allowed now (before hello, a frame before a volume is open)
    BadVolumeName,      // absolute, "..", backslash, control characters, empty, too long
    NotFound,           // a well-formed volume name that names no volume
    LoadFailed,         // the volume's file is damaged or refused by the loader
    Busy,               // the server is at capacity (sessions, loads); try again later
    RenderFailed,       // the renderer failed (device error, out of device memory)
    Internal,           // a bug; the message says what was caught
    SourceFailed,       // a DICOMweb source refused a search or is unreachable
};

// The wire name, e.g. "malformed_json".
std::string_view errorCodeName(ErrorCode code);
// The code with that wire name, if any.
std::optional<ErrorCode> errorCodeFromName(std::string_view name);

// An error answer: the code, a message for people naming what was wrong (field paths as in
// scene-file errors, e.g. "camera: must be a JSON object, got a number"), and the request
// it answers. The server sends it as an `error` message and the connection stays usable.
// One stack of a series that load_failed offers (a series holding several stacks): the
// volume name that opens it, and what it holds.
struct StackOffer {
    std::string volume;         // the series' name with "#stack=N" (volume_name.hpp)
    int64_t slices = 0;
    int64_t rows = 0, columns = 0;
    std::string orientation;    // "axial", "coronal", "sagittal", "oblique" or "unknown"
    bool localizer = false;     // one to three slices beside a larger stack
    bool operator==(const StackOffer &) const = default;
};

struct ProtocolError {
    static constexpr std::string_view kType = "error";
    ErrorCode code = ErrorCode::Internal;
    std::string message;
    nlohmann::json requestId;   // the request's "id" echoed; null when it had none or was unreadable
    std::string requestType;    // the request's "type" when it was a known one, else empty
    std::vector<StackOffer> stacks = {};   // load_failed of a series of several stacks; sent only when not empty
    bool operator==(const ProtocolError &) const = default;
};

// Thrown by the client-side decoders (parseServerMessage, decodeFrame) for a message that
// does not follow the protocol; what() names the problem.
struct DecodeError : std::runtime_error {
    using std::runtime_error::runtime_error;
};

} // namespace volcast::protocol
