#pragma once
// Text from outside (a client's message, a scene file), made safe to quote in an error message: JSON
// strings must be valid UTF-8, and a client's bytes (or a parser's excerpt of them, which
// may stop in the middle of a character) need not be. Invalid or cut sequences become
// U+FFFD; a long text is shortened only between code points, with "…" at the end.

#include <cstddef>
#include <string>
#include <string_view>

namespace volcast::json_fields {

// True when `text` is well-formed UTF-8 (RFC 3629: no overlong forms, no surrogates,
// nothing above U+10FFFF).
bool isValidUtf8(std::string_view text);

// `text` as valid UTF-8: each byte of an ill-formed sequence (a stray continuation byte, a
// sequence cut short, an overlong form, a surrogate, 0xF5..0xFF) and each NUL are replaced by U+FFFD. When the
// result would be longer than maxBytes it ends at the last whole code point that fits
// before "…", so the whole is at most maxBytes + 3 bytes.
std::string quotableText(std::string_view text, size_t maxBytes = std::string_view::npos);

} // namespace volcast::json_fields
