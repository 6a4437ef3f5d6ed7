// A volume name from open_volume (validateVolumeName). Invariants for an accepted name:
// not empty, within the byte limits, relative, no "." or ".." component, no empty
// component, no backslash, no control character.

#include "fuzz/fuzz_check.hpp"
#include "protocol/volume_name.hpp"

#include <algorithm>
#include <cstddef>
#include <cstdint>
#include <string_view>

using namespace volcast;
using namespace volcast::protocol;

extern "C" int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size) {
    const std::string_view name(reinterpret_cast<const char *>(data), size);
    const auto refusal = validateVolumeName(name);
    if (refusal) {
        fuzz::check(!refusal->empty(), "a refusal without a reason");
        // The reason goes into an error message as it is; it must never quote bad UTF-8.
        fuzz::check(fuzz::isValidUtf8(*refusal), "a refusal reason is not valid UTF-8", *refusal);
        return 0;
    }
    fuzz::check(!name.empty() && name.size() <= kMaxVolumeNameBytes, "an accepted name is empty or too long");
    fuzz::check(name.front() != '/' && name.front() != '~', "an accepted name is absolute or starts with ~");
    for (const char c : name) {
        const auto u = static_cast<unsigned char>(c);
        fuzz::check(u >= 0x20 && u != 0x7F, "an accepted name holds a control character");
        fuzz::check(c != '\\', "an accepted name holds a backslash");
    }
    size_t start = 0;
    while (true) {
        const size_t end = std::min(name.find('/', start), name.size());
        const std::string_view part = name.substr(start, end - start);
        fuzz::check(!part.empty(), "an accepted name has an empty component", name);
        fuzz::check(part != "." && part != "..", "an accepted name has a . or .. component", name);
        fuzz::check(part.size() <= kMaxVolumeNameComponentBytes, "an accepted name has an over-long component");
        if (end == name.size()) break;
        start = end + 1;
    }
    // A drive letter ("C:...") would be absolute on Windows.
    const auto isLetter = [](char c) { return (c >= 'a' && c <= 'z') || (c >= 'A' && c <= 'Z'); };
    fuzz::check(!(name.size() >= 2 && name[1] == ':' && isLetter(name[0])),
                "an accepted name starts with a drive letter", name);
    return 0;
}
