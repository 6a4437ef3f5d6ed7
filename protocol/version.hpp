#pragma once
// The protocol's version numbers. A client names the version it speaks in its hello; the
// server refuses any other with `unsupported_version`. Bump kProtocolVersion when a message
// changes incompatibly (a field renamed, removed or given another meaning); adding an
// optional field does not need a bump, since clients ignore fields they do not know.

#include <array>
#include <cstdint>

namespace volcast::protocol {

inline constexpr int kProtocolVersion = 1;
// The oldest client version this code still understands (the same, until there is a 2).
inline constexpr int kMinProtocolVersion = 1;

// First four bytes of every binary frame message: "VCF1" (volcast frame, layout 1).
inline constexpr std::array<uint8_t, 4> kFrameMagic = {'V', 'C', 'F', '1'};

} // namespace volcast::protocol
