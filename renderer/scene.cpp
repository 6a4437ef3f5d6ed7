#include "renderer/scene.hpp"

#include <nlohmann/json.hpp>

#include <array>
#include <cmath>
#include <cerrno>
#include <cstring>
#include <fstream>
#include <memory>
#include <set>
#include <sstream>
#include <utility>

namespace volcast {

namespace {

using json = nlohmann::json;

// Name tables shared by the parser and the writer, so the two cannot drift apart.
constexpr std::array<std::pair<std::string_view, Projection>, 2> kProjections{{
    {"perspective", Projection::Perspective},
    {"orthographic", Projection::Orthographic},
}};
constexpr std::array<std::pair<std::string_view, Interpolation>, 2> kInterpolations{{
    {"linear", Interpolation::Linear},
    {"cubic", Interpolation::Cubic},
}};
constexpr std::array<std::pair<std::string_view, Compositing>, 3> kCompositings{{
    {"emission_absorption", Compositing::EmissionAbsorption},
    {"mip", Compositing::Maximum},
    {"minip", Compositing::Minimum},
}};

// Below this a ray through a 4096-voxel volume would take billions of steps; it is a typo,
// not a quality setting.
constexpr double kMinStep = 1e-6;

[[noreturn]] void fail(const std::string &path, const std::string &message) {
    throw SceneError((path.empty() ? std::string("scene") : path) + ": " + message);
}

void check(bool ok, const std::string &path, const std::string &message) {
    if (!ok) fail(path, message);
}

std::string member(const std::string &path, std::string_view key) {
    return path.empty() ? std::string(key) : path + "." + std::string(key);
}

std::string element(const std::string &path, size_t i) {
    return path + "[" + std::to_string(i) + "]";
}

std::string typeOf(const json &j) {
    // "number" alone would not tell a user why 512.5 is refused where an integer is wanted.
    if (j.is_number_float()) return "a fractional number";
    if (j.is_number()) return "an integer";
    return j.type_name();
}

// The validators of Camera and TransferFunction already name the key in their messages.
template <typename F>
void asSceneError(F &&f) {
    try {
        f();
    } catch (const SceneError &) {
        throw;
    } catch (const std::invalid_argument &e) {
        throw SceneError(e.what());
    }
}

double number(const json &j, const std::string &path) {
    check(j.is_number(), path, "must be a number, got " + typeOf(j));
    const double v = j.get<double>();
    check(std::isfinite(v), path, "must be a finite number");
    return v;
}

int64_t integer(const json &j, const std::string &path, int64_t lo, int64_t hi,
                const std::string &what) {
    check(j.is_number_integer(), path, "must be " + what + ", got " + typeOf(j));
    // Unsigned values above int64's range are refused before they could wrap around.
    const bool fits = !j.is_number_unsigned() || j.get<uint64_t>() <= uint64_t(hi);
    const int64_t v = fits ? j.get<int64_t>() : hi;
    check(fits && v >= lo && v <= hi, path, "must be " + what + ", got " + j.dump());
    return v;
}

bool boolean(const json &j, const std::string &path) {
    check(j.is_boolean(), path, "must be true or false, got " + typeOf(j));
    return j.get<bool>();
}

std::string string(const json &j, const std::string &path) {
    check(j.is_string(), path, "must be a string, got " + typeOf(j));
    return j.get<std::string>();
}

const json &array(const json &j, const std::string &path, std::string_view what) {
    check(j.is_array(), path, "must be " + std::string(what) + ", got " + typeOf(j));
    return j;
}

Vec3d vec3(const json &j, const std::string &path) {
    array(j, path, "an array of 3 numbers");
    check(j.size() == 3, path, "must be an array of 3 numbers, got " + std::to_string(j.size()));
    return {number(j[0], element(path, 0)), number(j[1], element(path, 1)),
            number(j[2], element(path, 2))};
}

template <typename E, size_t N>
E choice(const json &j, const std::string &path,
         const std::array<std::pair<std::string_view, E>, N> &table) {
    const std::string s = string(j, path);
    std::string known;
    for (const auto &[name, value] : table) {
        if (name == s) return value;
        known += (known.empty() ? "\"" : ", \"") + std::string(name) + "\"";
    }
    fail(path, "must be one of " + known + ", got \"" + s + "\"");
}

template <typename E, size_t N>
std::string nameOf(E value, const std::array<std::pair<std::string_view, E>, N> &table) {
    for (const auto &[name, v] : table)
        if (v == value) return std::string(name);
    return "?";
}

// One JSON object: refuses keys it does not know (typos like "fov_deg" must not pass
// silently) and reads members by name with their full path in every message.
class Fields {
  public:
    Fields(const json &j, std::string path, std::initializer_list<std::string_view> known)
        : j_(j), path_(std::move(path)) {
        check(j.is_object(), path_, "must be a JSON object, got " + typeOf(j));
        for (const auto &[key, value] : j.items()) {
            bool ok = false;
            for (std::string_view k : known) ok = ok || k == key;
            if (ok) continue;
            std::string list;
            for (std::string_view k : known) list += (list.empty() ? "" : ", ") + std::string(k);
            fail(member(path_, key), "unknown key (known here: " + list + ")");
        }
    }

    std::string pathOf(std::string_view key) const { return member(path_, key); }
    const std::string &path() const { return path_; }
    const json *find(std::string_view key) const {
        auto it = j_.find(key);
        return it == j_.end() ? nullptr : &*it;
    }
    const json &require(std::string_view key) const {
        const json *v = find(key);
        if (!v) fail(pathOf(key), "is required");
        return *v;
    }
    // Reads an optional member into out, leaving out's default when the key is absent.
    template <typename T, typename Read>
    void optional(std::string_view key, T &out, Read read) const {
        if (const json *v = find(key)) out = read(*v, pathOf(key));
    }

  private:
    const json &j_;
    std::string path_;
};

std::vector<ControlPoint> parsePoints(const json &j, const std::string &path) {
    array(j, path, "an array of [value, r, g, b, a] rows");
    std::vector<ControlPoint> points;
    for (size_t i = 0; i < j.size(); ++i) {
        const std::string at = element(path, i);
        const json &row = array(j[i], at, "a [value, r, g, b, a] row");
        check(row.size() == 5, at,
              "must be a [value, r, g, b, a] row of 5 numbers, got " + std::to_string(row.size()));
        std::array<double, 5> v{};
        for (size_t c = 0; c < 5; ++c) v[c] = number(row[c], element(at, c));
        points.push_back({v[0], v[1], v[2], v[3], v[4]});
    }
    return points;
}

void parseTransferFunction(const json &j, Scene &scene) {
    const Fields f(j, "transfer_function", {"points", "preset", "opacity_unit"});
    const json *points = f.find("points");
    const json *preset = f.find("preset");
    check(!(points && preset), f.path(), "give either points or preset, not both");
    check(points || preset, f.path(), "needs points or preset");

    TransferFunction &tf = scene.transferFunction;
    f.optional("opacity_unit", tf.opacityUnit, number);
    // What validate() checks: the points as given, or the preset on a unit range.
    TransferFunction checked = tf;
    if (points) {
        tf.points = parsePoints(*points, f.pathOf("points"));
        checked.points = tf.points;
    } else {
        const std::string name = string(*preset, f.pathOf("preset"));
        // Kept by name: presets for MR and micro-CT are placed on the volume's value range,
        // known only once it is loaded (resolvedTransferFunction). Checked on a unit range.
        try {
            checked.points = presetTransferFunction(name, {0, 1}).points;
        } catch (const std::invalid_argument &e) {
            fail(f.pathOf("preset"), e.what());
        }
        scene.transferFunctionPreset = name;
    }
    asSceneError([&] { checked.validate(); });
}

Camera parseCamera(const json &j) {
    const Fields f(j, "camera", {"eye", "target", "up", "projection", "fov_y_deg", "height"});
    Camera cam;
    cam.eye = vec3(f.require("eye"), f.pathOf("eye"));
    cam.target = vec3(f.require("target"), f.pathOf("target"));
    cam.up = vec3(f.require("up"), f.pathOf("up"));
    f.optional("projection", cam.projection,
               [](const json &v, const std::string &p) { return choice(v, p, kProjections); });
    // The key of the other projection would be silently ignored, most likely because
    // "projection" was forgotten; refuse it rather than render something unexpected.
    if (cam.projection == Projection::Perspective) {
        check(!f.find("height"), f.pathOf("height"),
              "is only for an orthographic camera (set \"projection\": \"orthographic\")");
        f.optional("fov_y_deg", cam.fovYDeg, number);
    } else {
        check(!f.find("fov_y_deg"), f.pathOf("fov_y_deg"),
              "is only for a perspective camera; an orthographic one takes \"height\"");
        cam.height = number(f.require("height"), f.pathOf("height"));
    }
    asSceneError([&] { cam.validate(); });
    return cam;
}

void parseImage(const json &j, Scene &scene) {
    const Fields f(j, "image", {"width", "height"});
    const std::string what = "a positive integer of at most " + std::to_string(kMaxImageSide);
    scene.width = int(integer(f.require("width"), f.pathOf("width"), 1, kMaxImageSide, what));
    scene.height = int(integer(f.require("height"), f.pathOf("height"), 1, kMaxImageSide, what));
    check(int64_t(scene.width) * scene.height <= kMaxImagePixels, f.path(),
          std::to_string(scene.width) + " x " + std::to_string(scene.height) +
              " pixels is more than the limit of " + std::to_string(kMaxImagePixels));
}

CropBox parseCrop(const json &j, const std::string &path) {
    const Fields f(j, path, {"min", "max"});
    CropBox c;
    if (const json *v = f.find("min")) c.min = vec3(*v, f.pathOf("min"));
    if (const json *v = f.find("max")) c.max = vec3(*v, f.pathOf("max"));
    for (int a = 0; a < 3; ++a) {
        check(c.min[a] >= 0 && c.min[a] <= 1, element(f.pathOf("min"), size_t(a)),
              "must be in [0, 1] (normalised box coordinates)");
        check(c.max[a] >= 0 && c.max[a] <= 1, element(f.pathOf("max"), size_t(a)),
              "must be in [0, 1] (normalised box coordinates)");
        check(c.min[a] < c.max[a], element(f.pathOf("max"), size_t(a)),
              "must be greater than min[" + std::to_string(a) + "]");
    }
    return c;
}

Quality parseQuality(const json &j) {
    const Fields f(j, "quality",
                   {"step", "jitter", "preintegrated", "interpolation", "boundary_segment",
                    "early_termination", "empty_space_skipping", "mip_level", "image_scale",
                    "shading", "seed", "compositing", "crop"});
    Quality q;
    f.optional("step", q.step, number);
    f.optional("jitter", q.jitter, boolean);
    f.optional("preintegrated", q.preintegrated, boolean);
    f.optional("interpolation", q.interpolation,
               [](const json &v, const std::string &p) { return choice(v, p, kInterpolations); });
    f.optional("boundary_segment", q.boundarySegment, boolean);
    f.optional("early_termination", q.earlyTermination, number);
    f.optional("empty_space_skipping", q.emptySpaceSkipping, boolean);
    f.optional("mip_level", q.mipLevel, [](const json &v, const std::string &p) {
        return int(integer(v, p, 0, 16, "an integer in [0, 16]"));
    });
    f.optional("image_scale", q.imageScale, number);
    f.optional("shading", q.shading, boolean);
    f.optional("seed", q.seed, [](const json &v, const std::string &p) {
        check(v.is_number_unsigned(), p, "must be a non-negative integer, got " +
                                             (v.is_number_integer() ? v.dump() : typeOf(v)));
        return v.get<uint64_t>();
    });

    f.optional("compositing", q.compositing,
               [](const json &v, const std::string &p) { return choice(v, p, kCompositings); });
    f.optional("crop", q.crop, parseCrop);

    check(q.step >= kMinStep, f.pathOf("step"), "must be a positive number of at least 1e-6");
    check(q.earlyTermination > 0 && q.earlyTermination <= 1, f.pathOf("early_termination"),
          "must be in (0, 1]");
    check(q.imageScale > 0 && q.imageScale <= 1, f.pathOf("image_scale"), "must be in (0, 1]");
    return q;
}

std::vector<ClipPlane> parseClipPlanes(const json &j) {
    const std::string path = "clip_planes";
    array(j, path, "an array of {\"point\", \"normal\"} objects");
    std::vector<ClipPlane> planes;
    for (size_t i = 0; i < j.size(); ++i) {
        const Fields f(j[i], element(path, i), {"point", "normal"});
        ClipPlane plane{vec3(f.require("point"), f.pathOf("point")),
                        vec3(f.require("normal"), f.pathOf("normal"))};
        check(length(plane.normal) > 0, f.pathOf("normal"), "has zero length");
        planes.push_back(plane);
    }
    return planes;
}

std::string parseVolume(const json &j, const std::filesystem::path &baseDir) {
    std::string volume = string(j, "volume");
    check(!volume.empty(), "volume", "must not be empty");
    if (volume.starts_with("builtin:")) return volume;
    const std::filesystem::path p(volume);
    if (p.is_relative() && !baseDir.empty()) return (baseDir / p).lexically_normal().string();
    return volume;
}

// Follows where the parser is, so that errors the JSON library raises without a key (a
// number that overflows a double, a syntax error) and duplicate keys, which it would
// silently resolve to the last one, can still be reported by their JSON path.
class PathTracker {
  public:
    bool operator()(int, json::parse_event_t event, json &parsed) {
        using E = json::parse_event_t;
        switch (event) {
        case E::object_start:
        case E::array_start: {
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
            if (!top.keys.insert(top.key).second) fail(member(top.path, top.key), "duplicate key");
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
    std::vector<Frame> stack_;
};

json parseJson(std::string_view text) {
    // The JSON library stops at a NUL byte as at the end of the text: a file with one would be
    // read only up to it. JSON text never holds a raw NUL.
    if (const size_t nul = text.find('\0'); nul != std::string_view::npos)
        fail("", "malformed JSON: a NUL byte at byte " + std::to_string(nul));
    auto tracker = std::make_shared<PathTracker>();
    try {
        // parse() copies its callback, so the tracker is shared to be read afterwards.
        return json::parse(text, [tracker](int depth, json::parse_event_t event, json &parsed) {
            return (*tracker)(depth, event, parsed);
        });
    } catch (const json::exception &e) {
        std::string message = e.what();
        // Drop the library's "[json.exception.parse_error.101] " tag; keep line and column.
        if (const auto close = message.find("] "); message.starts_with("[json.") && close != std::string::npos)
            message.erase(0, close + 2);
        // The parser's excerpt ("last read: ...") may end inside a UTF-8 sequence; a message
        // must stay valid UTF-8 (errors are quoted inside JSON): U+FFFD for the bad bytes.
        message = json::parse(json(message).dump(-1, ' ', false, json::error_handler_t::replace)).get<std::string>();
        const std::string near = tracker->current();
        // An overflowing number is a bad value of a known key; anything else is bad syntax,
        // for which the key is only a hint next to the line and column.
        if (e.id == 406) fail(near, "must be a finite number (" + message + ")");
        fail("", "malformed JSON: " + message + (near.empty() ? "" : " (near " + near + ")"));
    }
}

// Pretty output as people write scenes by hand: objects one key a line, but arrays of plain
// values (vectors, transfer function rows) on one line.
void writePretty(const nlohmann::ordered_json &j, int indent, std::string &out) {
    const std::string pad(size_t(indent + 2), ' ');
    if (j.is_object() && !j.empty()) {
        out += "{\n";
        size_t i = 0;
        for (const auto &[key, value] : j.items()) {
            out += pad + json(key).dump() + ": ";
            writePretty(value, indent + 2, out);
            out += ++i < j.size() ? ",\n" : "\n";
        }
        out += std::string(size_t(indent), ' ') + "}";
    } else if (j.is_array() && !j.empty()) {
        bool flat = true;
        for (const auto &v : j) flat = flat && v.is_primitive() && !v.is_string();
        out += flat ? "[" : "[\n";
        for (size_t i = 0; i < j.size(); ++i) {
            if (!flat) out += pad;
            writePretty(j[i], indent + 2, out);
            if (i + 1 < j.size()) out += flat ? ", " : ",\n";
        }
        out += flat ? "]" : "\n" + std::string(size_t(indent), ' ') + "]";
    } else {
        out += j.dump();
    }
}

nlohmann::ordered_json toJson(const Vec3d &v) { return {v.x, v.y, v.z}; }

} // namespace

Scene parseScene(std::string_view jsonText, const std::filesystem::path &baseDir) {
    const json root = parseJson(jsonText);
    const Fields f(root, "",
                   {"volume", "transfer_function", "camera", "image", "quality", "clip_planes"});
    Scene scene;
    scene.volume = parseVolume(f.require("volume"), baseDir);
    parseTransferFunction(f.require("transfer_function"), scene);
    scene.camera = parseCamera(f.require("camera"));
    parseImage(f.require("image"), scene);
    if (const json *q = f.find("quality")) scene.quality = parseQuality(*q);
    if (const json *c = f.find("clip_planes")) scene.clipPlanes = parseClipPlanes(*c);
    return scene;
}

Scene loadSceneFile(const std::filesystem::path &file) {
    std::ifstream in(file, std::ios::binary);
    if (!in) throw SceneError(file.string() + ": cannot open scene file (" + std::strerror(errno) + ")");
    std::ostringstream text;
    text << in.rdbuf();
    if (in.bad()) throw SceneError(file.string() + ": cannot read scene file");
    try {
        return parseScene(text.str(), file.parent_path());
    } catch (const SceneError &e) {
        throw SceneError(file.string() + ": " + e.what());
    }
}

TransferFunction resolvedTransferFunction(const Scene &scene, const ValueRange &range) {
    if (scene.transferFunctionPreset.empty()) return scene.transferFunction;
    TransferFunction tf = presetTransferFunction(scene.transferFunctionPreset, range);
    tf.opacityUnit = scene.transferFunction.opacityUnit;
    return tf;
}

std::string sceneToJson(const Scene &scene) {
    using ojson = nlohmann::ordered_json;
    const TransferFunction &tf = scene.transferFunction;
    ojson tfJson = ojson::object();
    if (!scene.transferFunctionPreset.empty()) {
        tfJson["preset"] = scene.transferFunctionPreset;
    } else {
        tfJson["points"] = ojson::array();
        for (const auto &p : tf.points) tfJson["points"].push_back({p.value, p.r, p.g, p.b, p.a});
    }
    if (tf.opacityUnit) tfJson["opacity_unit"] = *tf.opacityUnit;

    const Camera &cam = scene.camera;
    ojson camJson{{"eye", toJson(cam.eye)},
                  {"target", toJson(cam.target)},
                  {"up", toJson(cam.up)},
                  {"projection", nameOf(cam.projection, kProjections)}};
    if (cam.projection == Projection::Perspective)
        camJson["fov_y_deg"] = cam.fovYDeg;
    else
        camJson["height"] = cam.height;

    const Quality &q = scene.quality;
    ojson root{
        {"volume", scene.volume},
        {"transfer_function", tfJson},
        {"camera", camJson},
        {"image", {{"width", scene.width}, {"height", scene.height}}},
        {"quality",
         {{"step", q.step},
          {"jitter", q.jitter},
          {"preintegrated", q.preintegrated},
          {"interpolation", nameOf(q.interpolation, kInterpolations)},
          {"boundary_segment", q.boundarySegment},
          {"early_termination", q.earlyTermination},
          {"empty_space_skipping", q.emptySpaceSkipping},
          {"mip_level", q.mipLevel},
          {"image_scale", q.imageScale},
          {"shading", q.shading},
          {"seed", q.seed}}},
    };
    // Written only where they differ from the default, so that scenes and frame headers
    // without them read as before.
    if (q.compositing != Compositing::EmissionAbsorption)
        root["quality"]["compositing"] = nameOf(q.compositing, kCompositings);
    if (!q.crop.full()) root["quality"]["crop"] = {{"min", toJson(q.crop.min)}, {"max", toJson(q.crop.max)}};
    if (!scene.clipPlanes.empty()) {
        ojson planes = ojson::array();
        for (const auto &p : scene.clipPlanes)
            planes.push_back({{"point", toJson(p.point)}, {"normal", toJson(p.normal)}});
        root["clip_planes"] = planes;
    }
    std::string out;
    writePretty(root, 0, out);
    return out + "\n";
}

} // namespace volcast
