#pragma once
// A session's scene as the client built it: docs/design.md's scene-file pieces (camera, transfer
// function, image, quality, clip planes) kept as typed values, plus the quality policy. Each
// change arrives in scene-file JSON form and is read once, by the scene-file parser's own
// piece readers (renderer/model/scene.hpp), so the server refuses exactly what volcast-render
// would; a refused change (SceneError, whose message names the key) leaves the scene as it was.

#include "protocol/client_messages.hpp"
#include "renderer/model/scene.hpp"
#include "server/volume_registry.hpp"

#include <nlohmann/json.hpp>

namespace volcast::server {

struct ImageSize {
    int width = 0;
    int height = 0;
};

class SessionScene {
  public:
    SessionScene();

    // A starting scene for the volume: a camera framing it, a transfer function suited to
    // it, no clip planes; the viewport and the policy are kept.
    void openVolume(const VolumeEntry &entry);
    bool hasVolume() const { return !scene_.volume.empty(); }

    // Each throws SceneError (the parser's message) and then changes nothing.
    void setCamera(const nlohmann::json &camera);
    void setTransferFunction(const nlohmann::json &tf);
    void setClipPlanes(const nlohmann::json &planes);
    void setViewport(const nlohmann::json &image);
    void setPolicy(const protocol::QualityPolicy &policy);
    // A still's own image size, checked like a viewport but not kept.
    ImageSize readImageSize(const nlohmann::json &image) const;
    ImageSize imageSize() const { return {scene_.width, scene_.height}; }

    // The scene; its volume is empty until one is open, and its quality is the policy's
    // (the default switches when the policy gives none).
    const Scene &scene() const { return scene_; }
    nlohmann::json sceneJson() const;     // scene-file form for the state message
    const protocol::QualityPolicy &policy() const { return policy_; }
    bool policySent() const { return policySent_; }

  private:
    Scene scene_;
    protocol::QualityPolicy policy_;
    bool policySent_ = false;
};

// The transfer function a volume starts with: the demo's own, else a preset fitting its values.
nlohmann::json defaultTransferFunction(const VolumeEntry &entry);
// A perspective camera (30°) framing the volume's bounding sphere.
Camera defaultCamera(const Volume &volume, bool builtin);

} // namespace volcast::server
