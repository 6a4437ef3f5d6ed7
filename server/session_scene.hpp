#pragma once
// A session's scene as the client built it: docs/design.md's scene-file pieces (camera, transfer
// function, image, quality, clip planes) kept in their JSON form, plus the quality policy.
// Every change is checked by assembling the whole scene and running the scene-file parser,
// so the server refuses exactly what volcast-render would; a refused change (SceneError,
// whose message names the key) leaves the scene as it was.

#include "protocol/client_messages.hpp"
#include "renderer/scene.hpp"
#include "server/volume_registry.hpp"

#include <nlohmann/json.hpp>

namespace volcast::server {

class SessionScene {
  public:
    SessionScene();

    // A starting scene for the volume: a camera framing it, a transfer function suited to
    // it, no clip planes; the viewport and the policy are kept.
    void openVolume(const VolumeEntry &entry);
    bool hasVolume() const { return !volume_.empty(); }

    // Each throws SceneError (the parser's message) and then changes nothing.
    void setCamera(const nlohmann::json &camera);
    void setTransferFunction(const nlohmann::json &tf);
    void setClipPlanes(const nlohmann::json &planes);
    void setViewport(const nlohmann::json &image);
    void setPolicy(const protocol::QualityPolicy &policy);
    // Checks a still's own image size without keeping it.
    void checkImage(const nlohmann::json &image) const;

    Scene scene() const;                  // parsed; requires a volume
    nlohmann::json sceneJson() const;     // scene-file form for the state message
    const nlohmann::json &cameraJson() const { return camera_; }
    const protocol::QualityPolicy &policy() const { return policy_; }
    bool policySent() const { return policySent_; }

  private:
    nlohmann::json assemble() const;      // with placeholders for pieces not set yet
    void check(const nlohmann::json &candidate) const;

    std::string volume_;
    nlohmann::json transferFunction_, camera_, image_, clipPlanes_;
    protocol::QualityPolicy policy_;
    bool policySent_ = false;
};

// The transfer function a volume starts with: the demo's own, else a preset fitting its values.
nlohmann::json defaultTransferFunction(const VolumeEntry &entry);
// A perspective camera (30°) framing the volume's bounding sphere.
nlohmann::json defaultCamera(const Volume &volume, bool builtin);

} // namespace volcast::server
