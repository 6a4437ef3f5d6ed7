// The checker's refusal line as the server reads it (renderer/io/dicom_child.hpp,
// throwRefusal): the line the checker process writes when it refuses a file, read by the
// caller as hostile text (the child parsed hostile bytes and may be under their control).
// Byte 0 picks the path the load was asked for (plain, with spaces, with non-ASCII letters,
// a folder); the rest is the line, without its newline: the mark 0x1F, a kind letter
// (R plainly, L too large, T time limit, S over the result limit, K several stacks), a
// space, a number, a space, the message (for K: the stacks as one word, a space, the message).
// Invariants: only VolumeLoadError escapes, always; its message starts with the path, is
// valid UTF-8 without control characters (C0, DEL, C1) and at most 2048 bytes + "…"; a
// well-formed line keeps its kind (VolumeTooLarge with the line's number, VolumeLoadTimeout
// with the caller's own time limit, VolumeOverResultLimit with the number and the caller's
// limit, SeriesHoldsStacks with as many stacks as the number, each of sizes and an orientation
// DICOM can state, or, where the stacks do not read, a plain VolumeLoadError; VolumeLoadError for
// any other letter) and a short printable ASCII message word for word; any other line is a plain VolumeLoadError in general words; the same line gives the
// same answer twice.

#include "renderer/io/dicom_child.hpp"

#include "fuzz/fuzz_check.hpp"

#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <iterator>
#include <limits>
#include <optional>
#include <string>
#include <string_view>
#include <typeinfo>

using namespace volcast;
namespace fs = std::filesystem;

namespace {

// The caller's own bound on the message (dicom_child.cpp kMaxRefusalBytes) and the "…" that
// marks a cut (util/utf8.hpp quotableText).
constexpr size_t kMaxMessageBytes = 2048 + 3;

const fs::path kPaths[] = {"/srv/volcast/uploads/scan.nrrd", "/srv/volcast/uploads/my scan (2).nii",
                           "/srv/volcast/uploads/Schädel–CT.mha", "/srv/volcast/pacs/1.2.840.113619.2"};

// The line as the caller's documented format reads it, worked out here without its code.
struct Parsed {
    char kind;
    uint64_t number;
    std::string_view message;
};

std::optional<Parsed> parse(std::string_view line) {
    if (line.size() < 4 || line[0] != '\x1f' || line[2] != ' ') return std::nullopt;
    uint64_t number = 0;
    size_t at = 3;
    for (; at < line.size() && line[at] != ' '; ++at) {
        const char c = line[at];
        if (c < '0' || c > '9') return std::nullopt;
        const uint64_t digit = uint64_t(c - '0');
        if (number > (std::numeric_limits<uint64_t>::max() - digit) / 10) return std::nullopt;
        number = number * 10 + digit;
    }
    if (at == 3 || at + 1 >= line.size()) return std::nullopt;  // no digits, or no message
    return Parsed{line[1], number, line.substr(at + 1)};
}

bool printableAscii(std::string_view s) {
    for (char c : s)
        if (c < 0x20 || c > 0x7e) return false;
    return true;
}

bool hasControlCharacter(std::string_view s) {
    for (size_t i = 0; i < s.size(); ++i) {
        const auto c = static_cast<unsigned char>(s[i]);
        if (c < 0x20 || c == 0x7f) return true;
        if (c == 0xC2 && i + 1 < s.size() && static_cast<unsigned char>(s[i + 1]) >= 0x80 &&
            static_cast<unsigned char>(s[i + 1]) <= 0x9F)
            return true;
    }
    return false;
}

// What the refusal says and carries, as one string to compare.
std::string answer(const fs::path &path, const LoadOptions &options, const std::string &line) {
    try {
        io::throwRefusal(path, options, line);
    } catch (const VolumeTooLarge &e) {
        return "L " + std::to_string(e.bytes) + " " + e.what();
    } catch (const VolumeLoadTimeout &e) {
        fuzz::check(e.limitSeconds == options.timeLimitSeconds, "a time limit other than the caller's", e.what());
        return "T " + std::string(e.what());
    } catch (const VolumeOverResultLimit &e) {
        fuzz::check(e.limit == options.maxResultBytes, "a result limit other than the caller's", e.what());
        return "S " + std::to_string(e.needed) + " " + e.what();
    } catch (const SeriesHoldsStacks &e) {
        fuzz::check(e.stacks.size() >= 2 && e.stacks.size() <= SeriesHoldsStacks::kMaxListed,
                    "a stack count outside 2..kMaxListed", e.what());
        for (size_t i = 0; i < e.stacks.size(); ++i) {
            const SeriesStack &st = e.stacks[i];
            fuzz::check(st.number == i + 1, "stacks not numbered in order", e.what());
            fuzz::check(st.slices >= 1 && st.rows <= 65535 && st.columns <= 65535, "a stack of sizes DICOM cannot state",
                        e.what());
            fuzz::check(st.orientation == "axial" || st.orientation == "coronal" || st.orientation == "sagittal" ||
                            st.orientation == "oblique" || st.orientation == "unknown",
                        "a stack of an unknown orientation", st.orientation);
        }
        return "K " + std::to_string(e.stacks.size()) + " " + e.what();
    } catch (const VolumeLoadError &e) {
        fuzz::check(typeid(e) == typeid(VolumeLoadError), "another subclass of VolumeLoadError", e.what());
        return "R " + std::string(e.what());
    } catch (const std::exception &e) {
        fuzz::fail("an exception other than VolumeLoadError", e.what());
    } catch (...) {
        fuzz::fail("something other than an exception thrown");
    }
    fuzz::fail("throwRefusal returned");
}

} // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size) {
    if (size < 1) return 0;
    const fs::path &path = kPaths[data[0] % std::size(kPaths)];
    const std::string line(reinterpret_cast<const char *>(data) + 1, size - 1);
    LoadOptions options;
    options.timeLimitSeconds = 120;
    options.maxResultBytes = uint64_t(5) << 30;

    const std::string got = answer(path, options, line);
    fuzz::check(got == answer(path, options, line), "the same line gave another answer", got);

    const char kind = got[0];
    size_t messageAt = 2;
    if (kind == 'L' || kind == 'S' || kind == 'K') messageAt = got.find(' ', 2) + 1;
    const std::string_view message = std::string_view(got).substr(messageAt);
    fuzz::check(message.starts_with(path.string()), "the message does not start with the path", message);
    fuzz::check(fuzz::isValidUtf8(message), "the message is not valid UTF-8", message);
    fuzz::check(!hasControlCharacter(message), "a control character in the message", message);
    fuzz::check(message.size() <= kMaxMessageBytes, "the message is longer than its bound",
                std::to_string(message.size()));

    const std::optional<Parsed> parsed = parse(line);
    if (!parsed) {
        fuzz::check(kind == 'R', "a malformed line refused as a particular kind", got);
        fuzz::check(message == path.string() + ": was refused by the parser in its separate process; it is not loaded",
                    "a malformed line refused in other words than the general ones", message);
        return 0;
    }
    if (parsed->kind == 'K') {
        // Stacks that do not read leave a plain refusal; the message follows the stacks' word.
        fuzz::check(kind == 'K' || kind == 'R', "stacks refused as another particular kind", got);
        if (kind == 'K')
            fuzz::check(got.substr(2, messageAt - 3) == std::to_string(parsed->number),
                        "the line's count of stacks was not carried", got);
        return 0;
    }
    const char expectedKind = parsed->kind == 'L' || parsed->kind == 'T' || parsed->kind == 'S' ? parsed->kind : 'R';
    fuzz::check(kind == expectedKind, "the refusal's kind is not the line's", got);
    if (kind == 'L' || kind == 'S')
        fuzz::check(got.substr(2, messageAt - 3) == std::to_string(parsed->number), "the line's number was not carried",
                    got);
    if (printableAscii(parsed->message) && path.string().size() + 2 + parsed->message.size() <= 2048) {
        const std::string expected = parsed->message.starts_with(path.string())
                                         ? std::string(parsed->message)
                                         : path.string() + ": " + std::string(parsed->message);
        fuzz::check(message == expected, "a short printable message not kept word for word", message);
    }
    return 0;
}
