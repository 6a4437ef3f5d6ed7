#include "server/session_scene.hpp"

#include "renderer/io/volume_source.hpp"
#include "renderer/presets.hpp"

#include <cmath>

namespace volcast::server {

using nlohmann::json;

namespace {
json vec(const Vec3d &v) { return json::array({v.x, v.y, v.z}); }

// Pieces a check needs before the client has set them; never sent or rendered.
const json kPlaceholderTf = {{"points", json::array({json::array({0, 0, 0, 0, 0}), json::array({1, 0, 0, 0, 0})})}};
const json kPlaceholderCamera = {{"eye", {0, 0, 1}}, {"target", {0, 0, 0}}, {"up", {0, 1, 0}},
                                 {"projection", "perspective"}, {"fov_y_deg", 30}};
} // namespace

json defaultTransferFunction(const VolumeEntry &entry) {
    if (entry.name == "builtin:demo")
        // scenes/demo.json's: soft tissue faint, the skull-like shell white, vessels red.
        return {{"points",
                 {{0, 0, 0, 0, 0},
                  {30, 0.6, 0.35, 0.3, 0},
                  {40, 0.85, 0.55, 0.45, 0.004},
                  {55, 0.85, 0.55, 0.45, 0},
                  {175, 0.95, 0.9, 0.8, 0.0},
                  {190, 1, 0.97, 0.9, 0.06},
                  {205, 1, 0.97, 0.9, 0.02},
                  {225, 0.85, 0.15, 0.1, 0.3},
                  {255, 1, 0.25, 0.2, 0.95}}},
                {"opacity_unit", 1.0}};
    // The default preset of the modality chosen for the volume (renderer/presets.hpp), as
    // points in data units: a saved scene then renders the same wherever it is opened.
    const Volume &v = *entry.volume;
    const std::vector<ResolvedPreset> presets = presetsFor(v, chooseModality(v, entry.name));
    json points = json::array();
    for (const auto &p : presets.front().points) points.push_back(p);
    return {{"points", std::move(points)}};
}

json defaultCamera(const Volume &v, bool builtin) {
    const Vec3d c = v.center();
    const Vec3d e = v.extent();
    const double radius = 0.5 * std::sqrt(e.x * e.x + e.y * e.y + e.z * e.z);
    const double distance = 1.05 * radius / std::sin(15.0 * M_PI / 180.0);   // fov 30°: half-angle 15°
    // Built-ins are y-up (scenes/demo.json's view); scans are in patient space (LPS), where a
    // viewer looks from the front (-y, anterior) with the head (+z) up.
    Vec3d dir = builtin ? Vec3d{196.5, 266.5, 236.5} : Vec3d{0.35, -1.0, 0.3};
    dir = dir * (1.0 / std::sqrt(dir.x * dir.x + dir.y * dir.y + dir.z * dir.z));
    const Vec3d up = builtin ? Vec3d{0, 1, 0} : Vec3d{0, 0, 1};
    return {{"eye", vec(c + dir * distance)}, {"target", vec(c)}, {"up", vec(up)},
            {"projection", "perspective"}, {"fov_y_deg", 30}};
}

SessionScene::SessionScene() : image_({{"width", 512}, {"height", 512}}), clipPlanes_(json::array()) {}

json SessionScene::assemble() const {
    json root = {{"volume", volume_.empty() ? "-" : volume_},
                 {"transfer_function", transferFunction_.is_null() ? kPlaceholderTf : transferFunction_},
                 {"camera", camera_.is_null() ? kPlaceholderCamera : camera_},
                 {"image", image_},
                 {"clip_planes", clipPlanes_}};
    if (!policy_.quality.is_null()) root["quality"] = policy_.quality;
    return root;
}

void SessionScene::check(const json &candidate) const { parseScene(candidate.dump()); }

void SessionScene::openVolume(const VolumeEntry &entry) {
    volume_ = entry.name;
    transferFunction_ = defaultTransferFunction(entry);
    camera_ = defaultCamera(*entry.volume, entry.name.starts_with(kBuiltinPrefix));
    clipPlanes_ = json::array();
}

void SessionScene::setCamera(const json &camera) {
    json c = assemble();
    c["camera"] = camera;
    check(c);
    camera_ = camera;
}

void SessionScene::setTransferFunction(const json &tf) {
    json c = assemble();
    c["transfer_function"] = tf;
    check(c);
    transferFunction_ = tf;
}

void SessionScene::setClipPlanes(const json &planes) {
    json c = assemble();
    c["clip_planes"] = planes;
    check(c);
    clipPlanes_ = planes;
}

void SessionScene::setViewport(const json &image) {
    checkImage(image);
    image_ = image;
}

void SessionScene::checkImage(const json &image) const {
    json c = assemble();
    c["image"] = image;
    check(c);
}

void SessionScene::setPolicy(const protocol::QualityPolicy &policy) {
    json c = assemble();
    c.erase("quality");
    if (!policy.quality.is_null()) c["quality"] = policy.quality;
    check(c);
    policy_ = policy;
    policySent_ = true;
}

Scene SessionScene::scene() const { return parseScene(assemble().dump()); }

json SessionScene::sceneJson() const {
    json s = json::object();
    if (!volume_.empty()) {
        s = json::parse(sceneToJson(scene()));
        if (clipPlanes_.empty()) s.erase("clip_planes");
    } else {
        s["image"] = image_;
        if (!policy_.quality.is_null()) s["quality"] = json::parse(sceneToJson(scene())).at("quality");
    }
    return s;
}

} // namespace volcast::server
