#include "util/utf8.hpp"

namespace volcast::json_fields {
namespace {

constexpr std::string_view kReplacement = "\xEF\xBF\xBD";   // U+FFFD
constexpr std::string_view kEllipsis = "\xE2\x80\xA6";      // U+2026

// The length of the well-formed sequence starting at text[i], or 0 when it is ill-formed.
// The allowed second bytes follow RFC 3629's table, which is what rules out overlong forms
// (E0 80..9F, F0 80..8F), surrogates (ED A0..BF) and code points above U+10FFFF (F4 90..).
size_t sequenceLength(std::string_view text, size_t i) {
    const auto byte = [&](size_t k) { return static_cast<unsigned char>(text[k]); };
    const unsigned char b0 = byte(i);
    if (b0 < 0x80) return 1;
    size_t length = 0;
    unsigned char lo = 0x80, hi = 0xBF;   // the range of the second byte
    if (b0 >= 0xC2 && b0 <= 0xDF) {
        length = 2;
    } else if (b0 >= 0xE0 && b0 <= 0xEF) {
        length = 3;
        if (b0 == 0xE0) lo = 0xA0;
        if (b0 == 0xED) hi = 0x9F;
    } else if (b0 >= 0xF0 && b0 <= 0xF4) {
        length = 4;
        if (b0 == 0xF0) lo = 0x90;
        if (b0 == 0xF4) hi = 0x8F;
    } else {
        return 0;   // a continuation byte first, C0/C1 (always overlong), F5..FF
    }
    if (i + length > text.size()) return 0;
    if (byte(i + 1) < lo || byte(i + 1) > hi) return 0;
    for (size_t k = 2; k < length; ++k)
        if (byte(i + k) < 0x80 || byte(i + k) > 0xBF) return 0;
    return length;
}

} // namespace

bool isValidUtf8(std::string_view text) {
    for (size_t i = 0; i < text.size();) {
        const size_t n = sequenceLength(text, i);
        if (n == 0) return false;
        i += n;
    }
    return true;
}

std::string quotableText(std::string_view text, size_t maxBytes) {
    std::string out;
    out.reserve(text.size() < 256 ? text.size() : 256);
    for (size_t i = 0; i < text.size();) {
        const size_t n = sequenceLength(text, i);
        // A NUL goes too: messages travel through std::exception::what(), which ends at one
        // (a key "\u0000id" emptied the whole error message).
        const bool keep = n != 0 && text[i] != '\0';
        const std::string_view piece = keep ? text.substr(i, n) : kReplacement;
        if (out.size() + piece.size() > maxBytes) {
            out += kEllipsis;
            return out;
        }
        out += piece;
        i += n ? n : 1;   // an ill-formed byte is replaced on its own, then decoding resyncs
    }
    return out;
}

} // namespace volcast::json_fields
