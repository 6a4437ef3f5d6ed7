#include "dicomweb/credential_scrubber.hpp"

#include <algorithm>
#include <cctype>
#include <optional>

namespace volcast::dicomweb {

namespace {

// A run of this many characters of a credential is cut out wherever it stands.
constexpr size_t kMinPartialRun = 8;

bool equalsIgnoringCase(std::string_view a, std::string_view b) {
    return a.size() == b.size() && std::equal(a.begin(), a.end(), b.begin(), [](char x, char y) {
               return std::tolower(static_cast<unsigned char>(x)) == std::tolower(static_cast<unsigned char>(y));
           });
}

// Base64, standard or URL-safe alphabet, padding optional; nullopt if it is not base64.
std::optional<std::string> base64Decoded(std::string_view text) {
    while (!text.empty() && text.back() == '=') text.remove_suffix(1);
    std::string out;
    uint32_t bits = 0;
    int count = 0;
    for (char c : text) {
        int v;
        if (c >= 'A' && c <= 'Z') v = c - 'A';
        else if (c >= 'a' && c <= 'z') v = c - 'a' + 26;
        else if (c >= '0' && c <= '9') v = c - '0' + 52;
        else if (c == '+' || c == '-') v = 62;
        else if (c == '/' || c == '_') v = 63;
        else return std::nullopt;
        bits = (bits << 6) | uint32_t(v);
        count += 6;
        if (count >= 8) {
            count -= 8;
            out += char((bits >> count) & 0xFF);
        }
    }
    return out;
}

int hexValue(char c) {
    if (c >= '0' && c <= '9') return c - '0';
    if (c >= 'a' && c <= 'f') return c - 'a' + 10;
    if (c >= 'A' && c <= 'F') return c - 'A' + 10;
    return -1;
}

// Whether `text` at `at` holds `wanted` percent-encoded, in either case.
bool percentEncodes(std::string_view text, size_t at, char wanted) {
    if (at + 2 >= text.size() || text[at] != '%') return false;
    const int high = hexValue(text[at + 1]), low = hexValue(text[at + 2]);
    return high >= 0 && low >= 0 && char(high * 16 + low) == wanted;
}

// The longest run of `secret`'s characters from `from` on, at least `enough` of them, that
// `text` holds from `at` (each character as itself, percent-encoded, or '+' for a space): how
// far it reaches in text bytes, or 0. A '%' before "25" may stand for itself or begin "%25"
// (a password holding '%', sent back percent-encoded): both readings are followed.
size_t longestRun(std::string_view text, size_t at, std::string_view secret, size_t from, size_t enough) {
    size_t longest = 0, used = at, matched = 0;
    for (size_t k = from; k < secret.size(); ++k, ++matched) {
        const char wanted = secret[k];
        const bool itself = used < text.size() && (text[used] == wanted || (wanted == ' ' && text[used] == '+'));
        const bool encoded = percentEncodes(text, used, wanted);
        if (itself && encoded) {
            const size_t stillWanted = enough > matched + 1 ? enough - matched - 1 : 1;
            const size_t rest = longestRun(text, used + 3, secret, k + 1, stillWanted);
            if (rest > 0) longest = std::max(longest, used + 3 + rest - at);
            else if (matched + 1 >= enough) longest = std::max(longest, used + 3 - at);
        }
        if (!itself && !encoded) break;
        used += itself ? 1 : 3;
        if (matched + 1 >= enough) longest = std::max(longest, used - at);
    }
    return longest;
}

} // namespace

CredentialScrubber::CredentialScrubber(const std::string &authorization) {
    const auto add = [&](std::string_view secret) {
        if (!secret.empty() && std::find(secrets_.begin(), secrets_.end(), secret) == secrets_.end())
            secrets_.emplace_back(secret);
    };
    add(authorization);
    const size_t space = authorization.find(' ');
    if (space != std::string::npos) {
        std::string_view credentials = std::string_view(authorization).substr(space + 1);
        while (!credentials.empty() && credentials.front() == ' ') credentials.remove_prefix(1);
        add(credentials);
        if (equalsIgnoringCase(std::string_view(authorization).substr(0, space), "Basic")) {
            if (const auto userAndPassword = base64Decoded(credentials)) {
                add(*userAndPassword);
                if (const size_t colon = userAndPassword->find(':'); colon != std::string::npos)
                    add(std::string_view(*userAndPassword).substr(colon + 1));
            }
        }
    }
    std::stable_sort(secrets_.begin(), secrets_.end(), [](const auto &a, const auto &b) { return a.size() > b.size(); });
}

std::string CredentialScrubber::withoutCredentials(std::string_view text) const {
    std::string out;
    out.reserve(text.size());
    size_t i = 0;
    while (i < text.size()) {
        // The longest run of a credential's characters (any part of it) beginning here, in text bytes.
        size_t cut = 0;
        for (const std::string &secret : secrets_) {
            const size_t enough = std::min(kMinPartialRun, secret.size());
            for (size_t from = 0; from + enough <= secret.size(); ++from) {
                // Only the character itself, a '%' or a '+' can begin a run: most bytes begin none.
                if (text[i] != secret[from] && text[i] != '%' && text[i] != '+') continue;
                cut = std::max(cut, longestRun(text, i, secret, from, enough));
            }
        }
        if (cut > 0) {
            out += kReplacement;
            i += cut;
            continue;
        }
        out += text[i];
        ++i;
    }
    return out;
}

std::string CredentialScrubber::operator()(std::string_view text) const {
    std::string out = withoutCredentials(text);
    for (char &c : out)
        if (static_cast<unsigned char>(c) < 0x20 || c == 0x7f) c = ' ';
    // Those spaces can complete a credential that holds one ("pass word" sent back as
    // "pass<TAB>word"): look again.
    out = withoutCredentials(out);
    if (out.size() > kMaxMessageBytes) {
        size_t end = kMaxMessageBytes;
        while (end > 0 && (static_cast<unsigned char>(out[end]) & 0xC0) == 0x80) --end;
        out.resize(end);
        out += "...";
    }
    return out;
}

} // namespace volcast::dicomweb
