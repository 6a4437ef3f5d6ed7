#include "protocol/errors.hpp"

#include <array>
#include <utility>

namespace volcast::protocol {
namespace {

// One table for both directions, so a name cannot drift from its code.
constexpr std::array<std::pair<ErrorCode, std::string_view>, 15> kNames{{
    {ErrorCode::MalformedJson, "malformed_json"},
    {ErrorCode::TooLarge, "too_large"},
    {ErrorCode::BadMessage, "bad_message"},
    {ErrorCode::UnknownType, "unknown_type"},
    {ErrorCode::BadField, "bad_field"},
    {ErrorCode::UnsupportedVersion, "unsupported_version"},
    {ErrorCode::Unauthorized, "unauthorized"},
    {ErrorCode::BadState, "bad_state"},
    {ErrorCode::BadVolumeName, "bad_volume_name"},
    {ErrorCode::NotFound, "not_found"},
    {ErrorCode::LoadFailed, "load_failed"},
    {ErrorCode::Busy, "busy"},
    {ErrorCode::RenderFailed, "render_failed"},
    {ErrorCode::Internal, "internal"},
    {ErrorCode::SourceFailed, "source_failed"},
}};

} // namespace

std::string_view errorCodeName(ErrorCode code) {
    for (const auto &[c, name] : kNames)
        if (c == code) return name;
    return "internal";
}

std::optional<ErrorCode> errorCodeFromName(std::string_view name) {
    for (const auto &[c, n] : kNames)
        if (n == name) return c;
    return std::nullopt;
}

} // namespace volcast::protocol
