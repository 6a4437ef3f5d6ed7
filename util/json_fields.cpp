#include "util/json_fields.hpp"

#include "util/utf8.hpp"

#include <cmath>
#include <memory>
#include <set>
#include <utility>
#include <vector>

namespace volcast::json_fields {

FieldError::FieldError(Kind k, std::string fieldPath, std::string what)
    : std::runtime_error(fieldPath.empty() ? what : fieldPath + ": " + what),
      kind(k), path(std::move(fieldPath)), problem(std::move(what)) {}

void badField(const std::string &path, const std::string &problem) {
    throw FieldError(FieldError::Kind::BadField, path, problem);
}

std::string member(const std::string &path, std::string_view key) {
    return path.empty() ? std::string(key) : path + "." + std::string(key);
}

std::string element(const std::string &path, size_t i) {
    return path + "[" + std::to_string(i) + "]";
}

namespace {

[[noreturn]] void malformed(const std::string &problem) {
    throw FieldError(FieldError::Kind::Malformed, "", problem);
}

// Follows where the parser is, so that an overflowing number and a duplicate key can be
// reported by their path, and so that nesting is bounded before a deep value is built.
class PathTracker {
  public:
    explicit PathTracker(int maxDepth) : maxDepth_(maxDepth) {}

    bool operator()(int, json::parse_event_t event, json &parsed) {
        using E = json::parse_event_t;
        switch (event) {
        case E::object_start:
        case E::array_start: {
            if (int(stack_.size()) >= maxDepth_)
                throw FieldError(FieldError::Kind::TooDeep, "",
                                 "nested deeper than " + std::to_string(maxDepth_) + " levels (at " +
                                     quotableText(shown(current()), kMaxQuotedBytes) + ")");
            Frame frame;
            frame.isArray = event == E::array_start;
            frame.path = current();
            stack_.push_back(std::move(frame));
            break;
        }
        case E::object_end:
        case E::array_end:
            stack_.pop_back();
            elementDone();
            break;
        case E::key: {
            Frame &top = stack_.back();
            top.key = parsed.get<std::string>();
            if (!top.keys.insert(top.key).second && duplicateKey_.empty())
                duplicateKey_ = member(top.path, top.key);
            break;
        }
        case E::value: elementDone(); break;
        }
        return true;
    }

    // The path of the value being read now (empty at the top level).
    std::string current() const {
        if (stack_.empty()) return {};
        const Frame &top = stack_.back();
        return top.isArray ? element(top.path, top.count) : member(top.path, top.key);
    }
    const std::string &duplicateKey() const { return duplicateKey_; }

    static std::string shown(const std::string &path) { return path.empty() ? "the top" : path; }

  private:
    struct Frame {
        bool isArray = false;
        std::string path;
        size_t count = 0;
        std::string key;
        std::set<std::string> keys;
    };
    void elementDone() {
        if (!stack_.empty() && stack_.back().isArray) ++stack_.back().count;
    }
    int maxDepth_;
    std::vector<Frame> stack_;
    std::string duplicateKey_;
};

} // namespace

ParsedText parseText(std::string_view text, int maxDepth) {
    // The JSON library stops at a NUL byte as at the end of the text, so `{...}\0anything` would
    // be taken as the text before it with no word about the rest. JSON text never holds a
    // raw NUL (inside a string it is written \u0000).
    if (const size_t nul = text.find('\0'); nul != std::string_view::npos)
        malformed("malformed JSON: a NUL byte at byte " + std::to_string(nul) +
                  " (write it as \\u0000 inside a string)");
    auto tracker = std::make_shared<PathTracker>(maxDepth);
    ParsedText out;
    try {
        // parse() copies its callback, so the tracker is shared to be read afterwards.
        out.value = json::parse(text, [tracker](int depth, json::parse_event_t event, json &parsed) {
            return (*tracker)(depth, event, parsed);
        });
    } catch (const json::exception &e) {
        // The library's message quotes the last bytes it read, which may stop inside a
        // character (the text "é" fails at its first byte): quoted as valid UTF-8 only.
        std::string message = quotableText(e.what(), kMaxQuotedBytes);
        // Drop the library's "[json.exception.parse_error.101] " tag; keep line and column.
        if (const auto close = message.find("] "); message.starts_with("[json.") && close != std::string::npos)
            message.erase(0, close + 2);
        const std::string near = tracker->current();
        // A number beyond a double is a bad value of a known field; anything else is bad
        // syntax, for which the field is only a hint next to the line and column.
        if (e.id == 406) badField(near, "must be a finite number (" + message + ")");
        malformed("malformed JSON: " + message +
                  (near.empty() ? "" : " (near " + quotableText(near, kMaxQuotedBytes) + ")"));
    }
    out.duplicateKey = tracker->duplicateKey();
    return out;
}

std::string kindOf(const json &j) {
    // "number" alone would not tell a user why 512.5 is refused where an integer is wanted.
    if (j.is_number_float()) return "a fractional number";
    if (j.is_number()) return "an integer";
    if (j.is_string()) return "a string";
    if (j.is_boolean()) return "a boolean";
    if (j.is_array()) return "an array";
    if (j.is_object()) return "a JSON object";
    if (j.is_null()) return "null";
    return "a binary value";
}

Fields::Fields(const json &obj, std::string path, std::initializer_list<std::string_view> known,
               Unknown unknown, std::string_view unknownProblem)
    : object_(object(obj, path)), path_(std::move(path)) {
    if (unknown == Unknown::Ignore) return;
    for (const auto &[key, value] : object_.items()) {
        bool isKnown = false;
        for (std::string_view k : known) isKnown = isKnown || k == key;
        if (isKnown) continue;
        std::string list;
        for (std::string_view k : known) list += (list.empty() ? "" : ", ") + std::string(k);
        badField(pathOf(key), std::string(unknownProblem) + " (known here: " + list + ")");
    }
}

const json *Fields::find(std::string_view key) const {
    const auto it = object_.find(key);
    return it == object_.end() ? nullptr : &*it;
}

const json &Fields::require(std::string_view key) const {
    const json *value = find(key);
    if (!value) badField(pathOf(key), "is required");
    return *value;
}

const json &object(const json &j, const std::string &path) {
    if (!j.is_object()) badField(path, "must be a JSON object, got " + kindOf(j));
    return j;
}

const json &array(const json &j, const std::string &path, std::string_view what) {
    if (!j.is_array()) badField(path, "must be " + std::string(what) + ", got " + kindOf(j));
    return j;
}

std::string string(const json &j, const std::string &path, size_t maxBytes) {
    if (!j.is_string()) badField(path, "must be a string, got " + kindOf(j));
    std::string s = j.get<std::string>();
    if (s.size() > maxBytes)
        badField(path, "is " + std::to_string(s.size()) + " bytes long; at most " +
                           std::to_string(maxBytes) + " are allowed");
    return s;
}

bool boolean(const json &j, const std::string &path) {
    if (!j.is_boolean()) badField(path, "must be true or false, got " + kindOf(j));
    return j.get<bool>();
}

double number(const json &j, const std::string &path) {
    if (!j.is_number()) badField(path, "must be a number, got " + kindOf(j));
    const double v = j.get<double>();
    if (!std::isfinite(v)) badField(path, "must be a finite number");
    return v;
}

int64_t integer(const json &j, const std::string &path, int64_t lo, int64_t hi, std::string_view what) {
    const std::string expected = what.empty() ? "an integer in [" + std::to_string(lo) + ", " + std::to_string(hi) + "]"
                                              : std::string(what);
    if (!j.is_number_integer()) badField(path, "must be " + expected + ", got " + kindOf(j));
    // An unsigned value above the int64 range is out of range, not a wrapped negative.
    const bool fits = !j.is_number_unsigned() ||
                      j.get<uint64_t>() <= uint64_t(std::numeric_limits<int64_t>::max());
    const int64_t v = fits ? j.get<int64_t>() : 0;
    if (!fits || v < lo || v > hi) badField(path, "must be " + expected + ", got " + j.dump());
    return v;
}

uint64_t unsignedInteger(const json &j, const std::string &path) {
    if (!j.is_number_unsigned())
        badField(path, "must be a non-negative integer, got " +
                           (j.is_number_integer() ? j.dump() : kindOf(j)));
    return j.get<uint64_t>();
}

} // namespace volcast::json_fields
