#pragma once
// Reading JSON text and the members of JSON objects, with errors that name the field path
// ("camera.eye[2]: must be a number, got a string"). Shared by protocol/ (client and server
// messages) and renderer/ (scene files), which must refuse the same things in the same
// words; depends on nlohmann-json only, so neither has to link the other.

#include <nlohmann/json.hpp>

#include <cstdint>
#include <initializer_list>
#include <limits>
#include <stdexcept>
#include <string>
#include <string_view>

namespace volcast::json_fields {

using json = nlohmann::json;

// A field that is wrong, or text that is not JSON. Callers format it their own way (the
// protocol quotes a long path by its start and adds an error code; a scene file names "scene"
// for the top level); what() is "path: problem", or the problem alone at the top level.
struct FieldError : std::runtime_error {
    enum class Kind {
        Malformed,   // not JSON text (syntax, invalid UTF-8, a NUL byte)
        TooDeep,     // nested deeper than parseText's maxDepth
        BadField,    // a value of the wrong kind or range, a missing or unknown key
    };
    FieldError(Kind k, std::string fieldPath, std::string what);
    Kind kind;
    std::string path;      // empty at the top level
    std::string problem;   // the message without the path
};

// The most bytes of outside text (a parser's excerpt) a problem quotes.
inline constexpr size_t kMaxQuotedBytes = 200;

// Throws FieldError{BadField, path, problem}.
[[noreturn]] void badField(const std::string &path, const std::string &problem);

std::string member(const std::string &path, std::string_view key);   // "camera" + "eye"
std::string element(const std::string &path, size_t i);              // "clip_planes[2]"

struct ParsedText {
    json value;
    // The path of the first key repeated within one object, empty when there is none. The
    // JSON library keeps the last of duplicates silently; a text with two "type"s or two
    // "eye"s is ambiguous, so callers refuse it (the protocol after reading the id, to echo it).
    std::string duplicateKey;
};

// Parse JSON text. Throws FieldError: Malformed for syntax and UTF-8 errors and NUL bytes,
// TooDeep for nesting deeper than maxDepth, BadField (with its path) for a number beyond a
// double.
ParsedText parseText(std::string_view text, int maxDepth = std::numeric_limits<int>::max());

// "a string", "an integer", "a fractional number", "null", ... for error messages.
std::string kindOf(const json &j);

// The members of one JSON object. Unknown keys are refused (a typo like "fov_deg" must not
// pass silently) or ignored (clients reading a newer server's messages).
class Fields {
  public:
    enum class Unknown { Refuse, Ignore };
    // unknownProblem: the words for a refused key ("unknown field", or "unknown key" in a
    // scene file), followed by the list of known ones.
    Fields(const json &object, std::string path, std::initializer_list<std::string_view> known,
           Unknown unknown = Unknown::Refuse, std::string_view unknownProblem = "unknown field");

    const json *find(std::string_view key) const;   // null when absent
    const json &require(std::string_view key) const;
    std::string pathOf(std::string_view key) const { return member(path_, key); }
    const std::string &path() const { return path_; }

  private:
    const json &object_;
    std::string path_;
};

// Kind checks; each throws BadField naming the path.
const json &object(const json &j, const std::string &path);
// what: how the expected array is named ("an array of 3 numbers").
const json &array(const json &j, const std::string &path, std::string_view what = "an array");
std::string string(const json &j, const std::string &path, size_t maxBytes = std::string::npos);
bool boolean(const json &j, const std::string &path);
double number(const json &j, const std::string &path);   // finite
// what: how the range is named ("a positive integer of at most 16384"); by default
// "an integer in [lo, hi]".
int64_t integer(const json &j, const std::string &path, int64_t lo, int64_t hi, std::string_view what = {});
uint64_t unsignedInteger(const json &j, const std::string &path);

} // namespace volcast::json_fields
