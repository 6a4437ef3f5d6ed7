#pragma once
// The scene contract of docs/design.md: volume + transfer function + camera + image size +
// quality + clip planes. One JSON form, read by volcast-render and the server alike.

#include "renderer/model/camera.hpp"
#include "renderer/model/orientation_correction.hpp"
#include "renderer/model/transfer_function.hpp"

#include <nlohmann/json.hpp>

#include <cstdint>
#include <filesystem>
#include <optional>
#include <stdexcept>
#include <string>
#include <string_view>
#include <vector>

namespace volcast {

enum class Interpolation { Linear, Cubic };

// How samples along a ray make a pixel: the emission–absorption integral, or the maximum /
// minimum of the field along the ray (MIP / MinIP) shown as windowed grey (ProjectionWindow).
enum class Compositing { EmissionAbsorption, Maximum, Minimum };

// The grey window of a MIP / MinIP (quality.projection_window), in data units: the extreme
// value v along a ray shows as grey clamp((v − (level − window/2)) / window, 0, 1), opaque.
// Unset: the volume's value range. Emission–absorption ignores it.
struct ProjectionWindow {
    double window = 1;   // > 0
    double level = 0;
    bool operator==(const ProjectionWindow &) const = default;
};

// Six axis-aligned planes in the volume's own axes, in normalised box coordinates: 0 and 1
// are the outer faces of the outermost voxels' cells, so index = −1/2 + f·n on an axis of n
// samples (docs/design.md). The full box by default.
struct CropBox {
    Vec3d min{0, 0, 0};
    Vec3d max{1, 1, 1};
    bool full() const { return min == Vec3d{0, 0, 0} && max == Vec3d{1, 1, 1}; }
    bool operator==(const CropBox &) const = default;
};

// The quality switches of docs/design.md's table, each measurable alone.
struct Quality {
    double step = 0.5;                 // segment length in units of the smallest spacing
    // Segment lengths from a per-brick error estimate, between step / 8 and step
    // (renderer/common/adaptive_step.hpp); step is then the longest.
    bool adaptiveStep = false;
    bool jitter = false;
    bool preintegrated = false;
    Interpolation interpolation = Interpolation::Linear;
    bool boundarySegment = true;
    double earlyTermination = 0.99;    // opacity at which a ray stops; 1 turns it off
    bool emptySpaceSkipping = true;
    int mipLevel = 0;
    double imageScale = 1.0;
    bool shading = false;
    uint64_t seed = 0;
    // Not remedies, but part of every frame the ladder derives from the final quality, and
    // set by the protocol's quality_policy: the compositing mode, the crop box and the
    // user's correction of the patient orientation (orientation_correction.hpp).
    Compositing compositing = Compositing::EmissionAbsorption;
    std::optional<ProjectionWindow> projectionWindow;
    CropBox crop;
    OrientationCorrection orientationCorrection;
    bool operator==(const Quality &) const = default;
};

// Keeps the half-space its normal points into.
struct ClipPlane {
    Vec3d point;
    Vec3d normal;
    bool operator==(const ClipPlane &) const = default;
};

struct Scene {
    // A file path (relative paths resolved against the scene file's folder when parsed)
    // or "builtin:NAME" for a built-in synthetic volume (see synthetic.hpp).
    std::string volume;
    // Points in data units, or, when transferFunctionPreset is set, no points and only the
    // opacity unit: some presets (MR, micro-CT) are placed on the value range, known once the
    // volume is loaded, so renderers call resolvedTransferFunction() then.
    TransferFunction transferFunction;
    std::string transferFunctionPreset;
    Camera camera;
    int width = 256;
    int height = 256;
    Quality quality;
    std::vector<ClipPlane> clipPlanes;
    bool operator==(const Scene &) const = default;
};

// Largest image side and pixel count a scene may ask for; beyond them the parser refuses
// before anything is allocated.
inline constexpr int kMaxImageSide = 16384;
inline constexpr int64_t kMaxImagePixels = int64_t(8192) * 8192;

// Parse scene JSON text. Relative volume paths are resolved against baseDir.
// Throws SceneError whose message names the offending key, e.g. "camera.up: ...".
Scene parseScene(std::string_view jsonText, const std::filesystem::path &baseDir = {});
Scene loadSceneFile(const std::filesystem::path &file);
std::string sceneToJson(const Scene &scene);

// Scene pieces one at a time, in their scene-file JSON form under the scene file's key
// ("camera", "transfer_function", "image", "quality", "clip_planes"). The server keeps a
// session's scene as typed values and reads each change with these, the same code that
// parseScene runs, so it refuses exactly what volcast-render would. Each reader throws
// SceneError naming the key ("camera.up: has zero length") and changes nothing then.
Camera readCamera(const nlohmann::json &camera);
void readTransferFunction(const nlohmann::json &tf, Scene &scene);   // points or preset
void readImage(const nlohmann::json &image, Scene &scene);           // width and height
Quality readQuality(const nlohmann::json &quality);
std::vector<ClipPlane> readClipPlanes(const nlohmann::json &planes);

// The writers: what sceneToJson writes for each piece (every quality switch spelled out).
nlohmann::json cameraToJson(const Camera &camera);
nlohmann::json transferFunctionToJson(const Scene &scene);
nlohmann::json qualityToJson(const Quality &quality);
nlohmann::json clipPlanesToJson(const std::vector<ClipPlane> &planes);
nlohmann::json sceneToJsonValue(const Scene &scene);   // sceneToJson as a value

// The transfer function a renderer is given for this scene: for emission–absorption the
// scene's own, with a range-relative preset placed on the loaded volume's value range (range
// is ignored when the scene has points); for MIP / MinIP the projection's grey ramp
// (projectionTransferFunction), whatever the scene's transfer function. Every back end, the
// reference, volcast-render and the server take their transfer function from here, so a
// projection is windowed alike everywhere.
TransferFunction resolvedTransferFunction(const Scene &scene, const ValueRange &range);

// The grey ramp of a projection: black at level − window/2, white at level + window/2, opacity
// 1 throughout (a projection's pixel is opaque wherever its ray crosses the drawn box), clamped
// outside. Without a window: the value range (window 1 around a constant volume's value).
TransferFunction projectionTransferFunction(const std::optional<ProjectionWindow> &window, const ValueRange &range);

struct SceneError : std::invalid_argument {
    using std::invalid_argument::invalid_argument;
};

} // namespace volcast
