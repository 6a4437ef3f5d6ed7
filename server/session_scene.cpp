#include "server/session_scene.hpp"

#include "renderer/io/volume_source.hpp"
#include "renderer/model/presets.hpp"

#include <cmath>

namespace volcast::server {

using nlohmann::json;

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
    // The default preset of the modality chosen for the volume (renderer/model/presets.hpp), as
    // points in data units: a saved scene then renders the same wherever it is opened.
    const Volume &v = *entry.volume;
    const std::vector<ResolvedPreset> presets = presetsFor(v, chooseModality(v, entry.name));
    json points = json::array();
    for (const auto &p : presets.front().points) points.push_back(p);
    return {{"points", std::move(points)}};
}

Camera defaultCamera(const Volume &v, bool builtin) {
    const Vec3d c = v.center();
    const Vec3d e = v.extent();
    const double radius = 0.5 * std::sqrt(e.x * e.x + e.y * e.y + e.z * e.z);
    const double distance = 1.05 * radius / std::sin(15.0 * M_PI / 180.0);   // fov 30°: half-angle 15°
    // Built-ins are y-up (scenes/demo.json's view); scans are in patient space (LPS), where a
    // viewer looks from the front (-y, anterior) with the head (+z) up.
    Vec3d dir = builtin ? Vec3d{196.5, 266.5, 236.5} : Vec3d{0.35, -1.0, 0.3};
    dir = dir * (1.0 / std::sqrt(dir.x * dir.x + dir.y * dir.y + dir.z * dir.z));
    Camera camera;
    camera.eye = c + dir * distance;
    camera.target = c;
    camera.up = builtin ? Vec3d{0, 1, 0} : Vec3d{0, 0, 1};
    camera.projection = Projection::Perspective;
    camera.fovYDeg = 30;
    return camera;
}

SessionScene::SessionScene() {
    scene_.width = 512;
    scene_.height = 512;
}

void SessionScene::openVolume(const VolumeEntry &entry) {
    Scene opened = scene_;
    opened.volume = entry.name;
    readTransferFunction(defaultTransferFunction(entry), opened);
    opened.camera = defaultCamera(*entry.volume, entry.name.starts_with(kBuiltinPrefix));
    opened.clipPlanes.clear();
    scene_ = std::move(opened);
}

void SessionScene::setCamera(const json &camera) { scene_.camera = readCamera(camera); }

void SessionScene::setTransferFunction(const json &tf) { readTransferFunction(tf, scene_); }

void SessionScene::setClipPlanes(const json &planes) { scene_.clipPlanes = readClipPlanes(planes); }

void SessionScene::setViewport(const json &image) { readImage(image, scene_); }

ImageSize SessionScene::readImageSize(const json &image) const {
    Scene read;
    readImage(image, read);
    return {read.width, read.height};
}

void SessionScene::setPolicy(const protocol::QualityPolicy &policy) {
    // An automatic policy without switches means the server's own final level: the defaults.
    scene_.quality = policy.quality.is_null() ? Quality{} : readQuality(policy.quality);
    policy_ = policy;
    policySent_ = true;
}

json SessionScene::sceneJson() const {
    if (hasVolume()) return sceneToJsonValue(scene_);
    json s = {{"image", {{"width", scene_.width}, {"height", scene_.height}}}};
    if (!policy_.quality.is_null()) s["quality"] = qualityToJson(scene_.quality);
    return s;
}

} // namespace volcast::server
