#include "renderer/model/scene.hpp"

#include "util/json_fields.hpp"

#include <nlohmann/json.hpp>

#include <array>
#include <cmath>
#include <cerrno>
#include <cstring>
#include <fstream>
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

using json_fields::array;
using json_fields::boolean;
using json_fields::element;
using json_fields::number;
using json_fields::string;

// The validators of Camera and TransferFunction already name the key in their messages;
// json_fields names the path of the field it refused.
template <typename F>
auto asSceneError(F &&f) {
    try {
        return f();
    } catch (const SceneError &) {
        throw;
    } catch (const json_fields::FieldError &e) {
        fail(e.path, e.problem);
    } catch (const std::invalid_argument &e) {
        throw SceneError(e.what());
    }
}

int64_t integer(const json &j, const std::string &path, int64_t lo, int64_t hi, const std::string &what) {
    return json_fields::integer(j, path, lo, hi, what);
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

// One JSON object of a scene file: refuses keys it does not know ("unknown key", as scene
// files have always said) and reads optional members into their defaults' place.
class Fields : public json_fields::Fields {
  public:
    Fields(const json &j, std::string path, std::initializer_list<std::string_view> known)
        : json_fields::Fields(j, std::move(path), known, Unknown::Refuse, "unknown key") {}

    // Reads an optional member into out, leaving out's default when the key is absent.
    template <typename T, typename Read>
    void optional(std::string_view key, T &out, Read read) const {
        if (const json *v = find(key)) out = read(*v, pathOf(key));
    }
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

// Rows of a signed permutation matrix: [[1, 0, 0], [0, -1, 0], [0, 0, 1]] flips y.
OrientationCorrection parseOrientationCorrection(const json &j, const std::string &path) {
    const std::string what = "a 3x3 signed permutation matrix, rows of -1, 0 or 1, e.g. [[1, 0, 0], [0, -1, 0], [0, 0, 1]]";
    array(j, path, what);
    check(j.size() == 3, path, "must be " + what + ", got " + std::to_string(j.size()) + " rows");
    OrientationCorrection c;
    for (size_t r = 0; r < 3; ++r) {
        const std::string rowPath = element(path, r);
        array(j[r], rowPath, "a row of 3 integers -1, 0 or 1");
        check(j[r].size() == 3, rowPath, "must be a row of 3 integers -1, 0 or 1, got " + std::to_string(j[r].size()));
        for (size_t k = 0; k < 3; ++k)
            c.m[r * 3 + k] = int(integer(j[r][k], element(rowPath, k), -1, 1, "-1, 0 or 1"));
    }
    const std::string problem = signedPermutationProblem(c);
    check(problem.empty(), path, "is not a signed permutation: " + problem);
    return c;
}

ProjectionWindow parseProjectionWindow(const json &j, const std::string &path) {
    const Fields f(j, path, {"window", "level"});
    ProjectionWindow w;
    w.window = number(f.require("window"), f.pathOf("window"));
    w.level = number(f.require("level"), f.pathOf("level"));
    check(w.window > 0, f.pathOf("window"), "must be > 0 (data units)");
    // The ramp's two ends must be distinct finite numbers: a window far below the level's
    // precision, or ends past the double range, would make no ramp at all.
    const double lo = w.level - w.window / 2, hi = w.level + w.window / 2;
    check(std::isfinite(lo) && std::isfinite(hi), f.pathOf("window"),
          "puts the window's ends beyond finite numbers around this level");
    check(lo < hi, f.pathOf("window"), "is too small to be told apart at this level");
    return w;
}

Quality parseQuality(const json &j) {
    const Fields f(j, "quality",
                   {"step", "adaptive_step", "jitter", "preintegrated", "interpolation", "boundary_segment",
                    "early_termination", "empty_space_skipping", "mip_level", "image_scale",
                    "shading", "seed", "compositing", "projection_window", "crop", "orientation_correction"});
    Quality q;
    f.optional("step", q.step, number);
    f.optional("adaptive_step", q.adaptiveStep, boolean);
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
    f.optional("seed", q.seed, json_fields::unsignedInteger);

    f.optional("compositing", q.compositing,
               [](const json &v, const std::string &p) { return choice(v, p, kCompositings); });
    if (const json *w = f.find("projection_window")) q.projectionWindow = parseProjectionWindow(*w, f.pathOf("projection_window"));
    f.optional("crop", q.crop, parseCrop);
    f.optional("orientation_correction", q.orientationCorrection, parseOrientationCorrection);

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

json parseJson(std::string_view text) {
    json_fields::ParsedText parsed = json_fields::parseText(text);
    // The JSON library keeps the last of duplicate keys silently; which one was meant?
    if (!parsed.duplicateKey.empty()) fail(parsed.duplicateKey, "duplicate key");
    return std::move(parsed.value);
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

using ojson = nlohmann::ordered_json;

ojson toJson(const Vec3d &v) { return {v.x, v.y, v.z}; }

ojson transferFunctionJson(const Scene &scene) {
    const TransferFunction &tf = scene.transferFunction;
    ojson out = ojson::object();
    if (!scene.transferFunctionPreset.empty()) {
        out["preset"] = scene.transferFunctionPreset;
    } else {
        out["points"] = ojson::array();
        for (const auto &p : tf.points) out["points"].push_back({p.value, p.r, p.g, p.b, p.a});
    }
    if (tf.opacityUnit) out["opacity_unit"] = *tf.opacityUnit;
    return out;
}

ojson cameraJson(const Camera &cam) {
    ojson out{{"eye", toJson(cam.eye)},
              {"target", toJson(cam.target)},
              {"up", toJson(cam.up)},
              {"projection", nameOf(cam.projection, kProjections)}};
    if (cam.projection == Projection::Perspective)
        out["fov_y_deg"] = cam.fovYDeg;
    else
        out["height"] = cam.height;
    return out;
}

ojson qualityJson(const Quality &q) {
    ojson out{{"step", q.step},
            {"jitter", q.jitter},
            {"preintegrated", q.preintegrated},
            {"interpolation", nameOf(q.interpolation, kInterpolations)},
            {"boundary_segment", q.boundarySegment},
            {"early_termination", q.earlyTermination},
            {"empty_space_skipping", q.emptySpaceSkipping},
            {"mip_level", q.mipLevel},
            {"image_scale", q.imageScale},
            {"shading", q.shading},
            {"seed", q.seed}};
    // Written only where they differ from the default, so that scenes and frame headers
    // without them read as before.
    if (q.adaptiveStep) out["adaptive_step"] = true;
    if (q.compositing != Compositing::EmissionAbsorption) out["compositing"] = nameOf(q.compositing, kCompositings);
    if (q.projectionWindow)
        out["projection_window"] = {{"window", q.projectionWindow->window}, {"level", q.projectionWindow->level}};
    if (!q.crop.full()) out["crop"] = {{"min", toJson(q.crop.min)}, {"max", toJson(q.crop.max)}};
    if (!q.orientationCorrection.identity()) {
        const auto &m = q.orientationCorrection.m;
        out["orientation_correction"] = {{m[0], m[1], m[2]}, {m[3], m[4], m[5]}, {m[6], m[7], m[8]}};
    }
    return out;
}

ojson clipPlanesJson(const std::vector<ClipPlane> &planes) {
    ojson out = ojson::array();
    for (const auto &p : planes) out.push_back({{"point", toJson(p.point)}, {"normal", toJson(p.normal)}});
    return out;
}

ojson sceneJson(const Scene &scene) {
    ojson root{
        {"volume", scene.volume},
        {"transfer_function", transferFunctionJson(scene)},
        {"camera", cameraJson(scene.camera)},
        {"image", {{"width", scene.width}, {"height", scene.height}}},
        {"quality", qualityJson(scene.quality)},
    };
    if (!scene.clipPlanes.empty()) root["clip_planes"] = clipPlanesJson(scene.clipPlanes);
    return root;
}

} // namespace

Scene parseScene(std::string_view jsonText, const std::filesystem::path &baseDir) {
    return asSceneError([&] {
        const json root = parseJson(jsonText);
        const Fields f(root, "",
                       {"volume", "transfer_function", "camera", "image", "quality", "clip_planes", "viewer"});
        // A client's view beyond the picture (its slice panes, the orientation it was told):
        // kept in the file for the client, ignored here; only its kind is checked.
        if (const json *v = f.find("viewer")) check(v->is_object(), "viewer", "must be an object");
        Scene scene;
        scene.volume = parseVolume(f.require("volume"), baseDir);
        parseTransferFunction(f.require("transfer_function"), scene);
        scene.camera = parseCamera(f.require("camera"));
        parseImage(f.require("image"), scene);
        if (const json *q = f.find("quality")) scene.quality = parseQuality(*q);
        if (const json *c = f.find("clip_planes")) scene.clipPlanes = parseClipPlanes(*c);
        return scene;
    });
}

Camera readCamera(const nlohmann::json &camera) {
    return asSceneError([&] { return parseCamera(camera); });
}

void readTransferFunction(const nlohmann::json &tf, Scene &scene) {
    Scene read;
    asSceneError([&] { parseTransferFunction(tf, read); });
    scene.transferFunction = read.transferFunction;
    scene.transferFunctionPreset = read.transferFunctionPreset;
}

void readImage(const nlohmann::json &image, Scene &scene) {
    Scene read;
    asSceneError([&] { parseImage(image, read); });
    scene.width = read.width;
    scene.height = read.height;
}

Quality readQuality(const nlohmann::json &quality) {
    return asSceneError([&] { return parseQuality(quality); });
}

std::vector<ClipPlane> readClipPlanes(const nlohmann::json &planes) {
    return asSceneError([&] { return parseClipPlanes(planes); });
}

nlohmann::json transferFunctionToJson(const Scene &scene) { return nlohmann::json(transferFunctionJson(scene)); }
nlohmann::json cameraToJson(const Camera &camera) { return nlohmann::json(cameraJson(camera)); }
nlohmann::json qualityToJson(const Quality &quality) { return nlohmann::json(qualityJson(quality)); }
nlohmann::json clipPlanesToJson(const std::vector<ClipPlane> &planes) { return nlohmann::json(clipPlanesJson(planes)); }
nlohmann::json sceneToJsonValue(const Scene &scene) { return nlohmann::json(sceneJson(scene)); }

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

TransferFunction projectionTransferFunction(const std::optional<ProjectionWindow> &window, const ValueRange &range) {
    double lo, hi;
    if (window) {
        lo = window->level - window->window / 2;
        hi = window->level + window->window / 2;
    } else if (range.max > range.min) {
        lo = range.min;
        hi = range.max;
    } else {
        lo = range.min - 0.5;
        hi = range.min + 0.5;
    }
    TransferFunction tf;
    tf.points = {{lo, 0, 0, 0, 1}, {hi, 1, 1, 1, 1}};
    return tf;
}

TransferFunction resolvedTransferFunction(const Scene &scene, const ValueRange &range) {
    if (scene.quality.compositing != Compositing::EmissionAbsorption)
        return projectionTransferFunction(scene.quality.projectionWindow, range);
    if (scene.transferFunctionPreset.empty()) return scene.transferFunction;
    TransferFunction tf = presetTransferFunction(scene.transferFunctionPreset, range);
    tf.opacityUnit = scene.transferFunction.opacityUnit;
    return tf;
}

std::string sceneToJson(const Scene &scene) {
    std::string out;
    writePretty(sceneJson(scene), 0, out);
    return out + "\n";
}

} // namespace volcast
