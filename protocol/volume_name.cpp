#include "protocol/volume_name.hpp"

#include <cstdio>

namespace volcast::protocol {

StackSelection splitStackSelection(std::string_view name) {
    const size_t at = name.rfind(kStackSuffix);
    if (at == std::string_view::npos || at == 0) return {name, std::nullopt};
    const std::string_view digits = name.substr(at + kStackSuffix.size());
    if (digits.empty() || digits.size() > 5 || digits.front() == '0') return {name, std::nullopt};
    uint32_t n = 0;
    for (const char c : digits) {
        if (c < '0' || c > '9') return {name, std::nullopt};
        n = n * 10 + uint32_t(c - '0');
    }
    return {name.substr(0, at), n};
}

std::string stackVolumeName(std::string_view series, uint32_t stack) {
    return std::string(series) + std::string(kStackSuffix) + std::to_string(stack);
}

std::optional<std::string> validateVolumeName(std::string_view name, size_t maxBytes) {
    if (name.empty()) return "is empty";
    if (name.find(kStackSuffix) != std::string_view::npos) {
        const StackSelection selection = splitStackSelection(name);
        if (!selection.stack)
            return "has a \"#stack=\" that is not followed by a stack number (1 to " +
                   std::to_string(kMaxStackNumber) + ") at its end";
        if (selection.series.find(kStackSuffix) != std::string_view::npos)
            return "names a stack twice (\"#stack=\")";
    }
    if (name.size() > maxBytes)
        return "is " + std::to_string(name.size()) + " bytes long; at most " +
               std::to_string(maxBytes) + " are allowed";
    // Characters first: a NUL would cut the name short in any C API the server calls.
    for (size_t i = 0; i < name.size(); ++i) {
        const auto c = static_cast<unsigned char>(name[i]);
        if (c == 0) return "contains a NUL character (at byte " + std::to_string(i) + ")";
        if (c < 0x20 || c == 0x7f) {
            char code[8];
            std::snprintf(code, sizeof code, "0x%02X", unsigned(c));
            return "contains a control character (" + std::string(code) + " at byte " +
                   std::to_string(i) + ")";
        }
        if (c == '\\') return "contains a backslash; separate folders with \"/\"";
    }
    if (name.front() == '/')
        return "is an absolute path; give a name relative to the server's data folders";
    // "C:/scans/x" is absolute on Windows; refuse it on every platform alike.
    const auto isLetter = [](char c) { return (c >= 'a' && c <= 'z') || (c >= 'A' && c <= 'Z'); };
    if (name.size() >= 2 && isLetter(name[0]) && name[1] == ':')
        return "starts with a drive letter; give a name relative to the server's data folders";
    // "~" is not expanded by the server; a user writing it meant a home folder.
    if (name.front() == '~') return "starts with \"~\"; home folders are not reachable";

    size_t begin = 0;
    while (true) {
        const size_t end = name.find('/', begin);
        const std::string_view component =
            name.substr(begin, end == std::string_view::npos ? std::string_view::npos : end - begin);
        if (component.empty()) return "has an empty path component (\"//\" or a trailing \"/\")";
        if (component == "..")
            return "contains a \"..\" component; names must stay inside the data folders";
        // "." is harmless but would give one volume two names.
        if (component == ".") return "contains a \".\" component";
        if (component.size() > kMaxVolumeNameComponentBytes)
            return "has a component of " + std::to_string(component.size()) +
                   " bytes; at most " + std::to_string(kMaxVolumeNameComponentBytes) +
                   " are allowed";
        if (end == std::string_view::npos) break;
        begin = end + 1;
    }
    return std::nullopt;
}

} // namespace volcast::protocol
