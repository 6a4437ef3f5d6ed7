// The scrubbing of a DICOMweb source's credentials out of text a PACS sent
// (dicomweb/credential_scrubber.hpp), on hostile text that reflects them.
// Input: byte 0 picks how the Authorization value is made from the first line (up to LF, at
// most 40 bytes): bits 0-1 = 0, the line is the value itself; 1-3, the line is "user:password"
// and the value is "Basic ", "basic " or "Basic  " (two spaces) and its base64, bit 2 in the
// URL-safe alphabet, bit 3 without padding. The rest is the text; in it, 0x01 followed by three
// bytes (form, start, length) is replaced by a piece of one of the credential's forms (the
// value, its credentials, for Basic the decoded "user:password" and the password), raw or
// percent-encoded (every byte, upper- or lower-case hex; or URL-style, '+' for a space), so
// that the text reflects the credentials where the fuzzer chooses.
// Invariants: neither the scrubbed text (operator()) nor withoutCredentials() holds any form
// whole (one shorter than 8 bytes) or any 8-byte run of one, raw or in any of those four
// encodings; "[credentials]" and the "..." of a cut are taken as opaque for this (they are
// the scrubber's own words, and the fuzzer may choose credentials made of their letters); the
// scrubbed text has no C0 control character or DEL, is at most kMaxMessageBytes + "...",
// and, where every form is ASCII, is valid UTF-8 where withoutCredentials() gave valid UTF-8
// (the cut is on a character boundary); a scrubber made again from the same value gives the
// same text.

#include "dicomweb/credential_scrubber.hpp"

#include "fuzz/fuzz_check.hpp"

#include <algorithm>
#include <array>
#include <cstddef>
#include <cstdint>
#include <string>
#include <string_view>
#include <vector>

using namespace volcast;
using dicomweb::CredentialScrubber;

namespace {

constexpr size_t kMaxCredentialLine = 40;
// The text is cut a little past the scrubber's bound (so the cut is reached, at any byte): the
// scrub looks at every byte for every run of every form, and longer texts only slow the run.
constexpr size_t kMaxText = CredentialScrubber::kMaxMessageBytes + 200;
constexpr size_t kRun = 8;   // the header's "run of 8 or more characters"
constexpr char kSplice = '\x01';

std::string base64(std::string_view bytes, bool urlSafe, bool padded) {
    const char *alphabet = urlSafe ? "ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789-_"
                                   : "ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
    std::string out;
    size_t i = 0;
    for (; i + 3 <= bytes.size(); i += 3) {
        const uint32_t v = uint32_t(uint8_t(bytes[i])) << 16 | uint32_t(uint8_t(bytes[i + 1])) << 8 | uint8_t(bytes[i + 2]);
        for (int shift = 18; shift >= 0; shift -= 6) out += alphabet[(v >> shift) & 63];
    }
    const size_t rest = bytes.size() - i;
    if (rest > 0) {
        uint32_t v = uint32_t(uint8_t(bytes[i])) << 16;
        if (rest == 2) v |= uint32_t(uint8_t(bytes[i + 1])) << 8;
        out += alphabet[(v >> 18) & 63];
        out += alphabet[(v >> 12) & 63];
        if (rest == 2) out += alphabet[(v >> 6) & 63];
        if (padded) out.append(3 - rest, '=');
    }
    return out;
}

// The four encodings the invariant covers, and the raw form: index 0 raw, 1 and 2 every byte
// as %XX (upper, lower hex), 3 and 4 URL-style (unreserved bytes kept, '+' for a space).
constexpr size_t kEncodings = 5;

std::string encoded(std::string_view raw, size_t encoding) {
    if (encoding == 0) return std::string(raw);
    const char *hex = encoding % 2 == 1 ? "0123456789ABCDEF" : "0123456789abcdef";
    const bool everyByte = encoding <= 2;
    std::string out;
    for (char c : raw) {
        const bool unreserved = (c >= 'A' && c <= 'Z') || (c >= 'a' && c <= 'z') || (c >= '0' && c <= '9') ||
                                c == '-' || c == '.' || c == '_' || c == '~';
        if (!everyByte && unreserved) {
            out += c;
        } else if (!everyByte && c == ' ') {
            out += '+';
        } else {
            out += '%';
            out += hex[uint8_t(c) >> 4];
            out += hex[uint8_t(c) & 15];
        }
    }
    return out;
}

// Every piece of text that must not come out: each form whole when shorter than a run, else
// each of its runs, in each encoding.
std::vector<std::string> forbidden(const std::vector<std::string> &forms) {
    std::vector<std::string> out;
    for (const std::string &form : forms) {
        const size_t length = std::min(kRun, form.size());
        for (size_t from = 0; from + length <= form.size(); ++from)
            for (size_t e = 0; e < kEncodings; ++e) out.push_back(encoded(std::string_view(form).substr(from, length), e));
    }
    std::sort(out.begin(), out.end());
    out.erase(std::unique(out.begin(), out.end()), out.end());
    return out;
}

// `text` with the scrubber's own words replaced by one byte that no forbidden piece holds.
std::string withOpaqueMarks(std::string text, const std::vector<std::string> &pieces, bool cutMark) {
    std::array<bool, 256> used{};
    for (const std::string &p : pieces)
        for (char c : p) used[uint8_t(c)] = true;
    const auto free = std::find(used.begin(), used.end(), false);
    fuzz::check(free != used.end(), "no byte left to stand for the scrubber's marks");
    const char opaque = char(free - used.begin());
    if (cutMark && text.ends_with("...")) text.replace(text.size() - 3, 3, 1, opaque);
    const std::string_view mark = CredentialScrubber::kReplacement;
    for (size_t at = text.find(mark); at != std::string::npos; at = text.find(mark, at + 1))
        text.replace(at, mark.size(), 1, opaque);
    return text;
}

void checkNoCredential(const std::string &text, const std::vector<std::string> &pieces, bool cutMark,
                       std::string_view what) {
    const std::string seen = withOpaqueMarks(text, pieces, cutMark);
    for (const std::string &piece : pieces)
        if (seen.find(piece) != std::string::npos) fuzz::fail(what, "'" + piece + "' in: " + text);
}

} // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size) {
    if (size < 1) return 0;
    const uint8_t mode = data[0];
    const std::string_view input(reinterpret_cast<const char *>(data) + 1, size - 1);
    const size_t lineEnd = std::min(input.find('\n'), input.size());
    const std::string line(input.substr(0, std::min(lineEnd, kMaxCredentialLine)));
    const std::string_view rest = input.substr(std::min(lineEnd + 1, input.size()));

    std::vector<std::string> forms;
    std::string authorization;
    const size_t scheme = mode & 3;
    if (scheme == 0) {
        authorization = line;
        forms.push_back(authorization);
        if (const size_t space = authorization.find(' '); space != std::string::npos) {
            const size_t credentials = authorization.find_first_not_of(' ', space);
            if (credentials != std::string::npos) forms.push_back(authorization.substr(credentials));
        }
    } else {
        const char *schemes[] = {"Basic ", "basic ", "Basic  "};
        const std::string credentials = base64(line, (mode & 4) != 0, (mode & 8) == 0);
        authorization = schemes[scheme - 1] + credentials;
        forms = {authorization, credentials, line};
        if (const size_t colon = line.find(':'); colon != std::string::npos) forms.push_back(line.substr(colon + 1));
    }
    const CredentialScrubber scrub(authorization);
    // For a value given as it is, the decoded forms are the scrubber's own decoding.
    for (const std::string &secret : scrub.secrets()) forms.push_back(secret);
    std::erase_if(forms, [](const std::string &f) { return f.empty(); });
    std::sort(forms.begin(), forms.end());
    forms.erase(std::unique(forms.begin(), forms.end()), forms.end());
    if (forms.empty()) return 0;

    std::string text;
    for (size_t i = 0; i < rest.size() && text.size() < kMaxText; ++i) {
        if (rest[i] != kSplice || i + 3 >= rest.size()) {
            text += rest[i];
            continue;
        }
        const size_t pick = uint8_t(rest[i + 1]) % (forms.size() * kEncodings);
        const std::string &form = forms[pick / kEncodings];
        const size_t start = uint8_t(rest[i + 2]) % form.size();
        const size_t length = rest[i + 3] == 0 ? std::string::npos : uint8_t(rest[i + 3]);
        text += encoded(std::string_view(form).substr(start, length), pick % kEncodings);
        i += 3;
    }

    const std::vector<std::string> pieces = forbidden(forms);
    const std::string bare = scrub.withoutCredentials(text);
    checkNoCredential(bare, pieces, false, "withoutCredentials left a form of the credentials");

    const std::string out = scrub(text);
    checkNoCredential(out, pieces, true, "the scrubbed text holds a form of the credentials");
    fuzz::check(out.size() <= CredentialScrubber::kMaxMessageBytes + 3, "the scrubbed text is longer than its bound",
                std::to_string(out.size()));
    for (char c : out)
        if (uint8_t(c) < 0x20 || c == 0x7f) fuzz::fail("a control character in the scrubbed text", out);
    // A form with bytes above 0x7F may be cut from the middle of a character (the scrubber does
    // not promise UTF-8 then); with ASCII forms only the cut can break a character.
    const bool asciiForms = std::all_of(forms.begin(), forms.end(), [](const std::string &f) {
        return std::all_of(f.begin(), f.end(), [](char c) { return uint8_t(c) < 0x80; });
    });
    if (asciiForms && fuzz::isValidUtf8(bare))
        fuzz::check(fuzz::isValidUtf8(out), "the cut made valid UTF-8 invalid", out);
    fuzz::check(CredentialScrubber(authorization)(text) == out, "the same value and text scrubbed otherwise", out);
    return 0;
}
