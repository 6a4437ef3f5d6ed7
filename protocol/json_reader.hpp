#pragma once
// Internal to protocol/: reading JSON text and the members of JSON objects with errors
// that name the field path ("camera: must be a JSON object, got a number"), the way
// renderer/scene.cpp names scene-file keys. The public parse functions catch ReadError
// once and turn it into a ProtocolError carrying the request's id.

#include "protocol/errors.hpp"

#include <nlohmann/json.hpp>

#include <cstdint>
#include <initializer_list>
#include <stdexcept>
#include <string>
#include <string_view>

namespace volcast::protocol::detail {

using json = nlohmann::json;

struct ReadError : std::runtime_error {
    ReadError(ErrorCode c, const std::string &message) : std::runtime_error(message), code(c) {}
    ErrorCode code;
};

// The most bytes of client text (a key path, a parser's excerpt) an error message quotes.
constexpr size_t kMaxQuotedBytes = 200;

[[noreturn]] void fail(ErrorCode code, const std::string &message);
// Throws bad_field with "path: message" (just the message at the top level).
[[noreturn]] void badField(const std::string &path, const std::string &message);

std::string member(const std::string &path, std::string_view key);   // "camera" + "eye"
std::string element(const std::string &path, size_t i);              // "clip_planes[2]"

struct ParsedText {
    json value;
    // The path of the first key repeated within one object, empty when there is none. The
    // JSON library keeps the last of duplicates silently; a message with two "type"s or two
    // "eye"s is ambiguous, so callers refuse it (after reading the id, to echo it).
    std::string duplicateKey;
};

// Parse JSON text. Throws ReadError: malformed_json for syntax and UTF-8 errors, too_large
// for nesting deeper than maxDepth, bad_field (with its path) for a number beyond a double.
ParsedText parseText(std::string_view text, int maxDepth);

// "a string", "an integer", "a fractional number", "null", ... for error messages.
std::string kindOf(const json &j);

// The members of one JSON object. Unknown keys are refused (a typo like "fov_deg" must not
// pass silently) or ignored (clients reading a newer server's messages).
class Fields {
  public:
    enum class Unknown { Refuse, Ignore };
    Fields(const json &object, std::string path, std::initializer_list<std::string_view> known,
           Unknown unknown = Unknown::Refuse);

    const json *find(std::string_view key) const;   // null when absent
    const json &require(std::string_view key) const;
    std::string pathOf(std::string_view key) const { return member(path_, key); }

  private:
    const json &object_;
    std::string path_;
};

// Kind checks; each throws bad_field naming the path.
const json &object(const json &j, const std::string &path);
const json &array(const json &j, const std::string &path);
std::string string(const json &j, const std::string &path, size_t maxBytes);
bool boolean(const json &j, const std::string &path);
double number(const json &j, const std::string &path);   // finite
int64_t integer(const json &j, const std::string &path, int64_t lo, int64_t hi);
uint64_t unsignedInteger(const json &j, const std::string &path);

// A request id: null, an integer, or a string of at most maxBytes bytes.
json requestId(const json &j, const std::string &path, size_t maxBytes);

} // namespace volcast::protocol::detail
