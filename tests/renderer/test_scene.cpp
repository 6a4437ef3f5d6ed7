#include "renderer/model/scene.hpp"

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include <filesystem>
#include <fstream>
#include <string>
#include <utility>
#include <vector>

namespace volcast {
namespace {

using json = nlohmann::json;

// The example of docs/design.md's "Scene file", verbatim.
constexpr const char *kExample = R"({
  "volume": "data/head.nhdr",
  "transfer_function": {
    "points": [[0, 0, 0, 0, 0], [80, 1.0, 0.6, 0.4, 0.05], [255, 1, 1, 1, 0.9]],
    "opacity_unit": 1.0
  },
  "camera": {"eye": [300, 200, 400], "target": [128, 128, 64], "up": [0, 1, 0],
             "projection": "perspective", "fov_y_deg": 30},
  "image": {"width": 512, "height": 512},
  "quality": {"step": 0.5, "jitter": false, "preintegrated": true,
              "interpolation": "cubic", "boundary_segment": true,
              "early_termination": 0.99, "empty_space_skipping": true,
              "mip_level": 0, "image_scale": 1.0, "shading": false, "seed": 0},
  "clip_planes": [{"point": [128, 128, 64], "normal": [0, 0, 1]}]
})";

json example() { return json::parse(kExample); }

json with(json j, const std::string &pointer, json value) {
    j[json::json_pointer(pointer)] = std::move(value);
    return j;
}

json without(json j, const std::string &pointer) {
    const json::json_pointer p(pointer);
    j[p.parent_pointer()].erase(p.back());
    return j;
}

bool contains(const std::string &s, const std::string &part) { return s.find(part) != std::string::npos; }

// The SceneError message for text, or a test failure when it parses.
std::string errorOf(const std::string &text) {
    try {
        (void)parseScene(text);
    } catch (const SceneError &e) {
        return e.what();
    }
    ADD_FAILURE() << "parsed without error:\n" << text;
    return {};
}

std::string errorOf(const json &j) { return errorOf(j.dump()); }
std::string errorOf(const char *text) { return errorOf(std::string(text)); }

#define EXPECT_SCENE_ERROR(input, path)                                                        \
    do {                                                                                       \
        const std::string message_ = errorOf(input);                                           \
        EXPECT_TRUE(contains(message_, path)) << "message: " << message_;                      \
    } while (0)

// ---- what parses ----

TEST(SceneParse, DesignExample) {
    const Scene s = parseScene(kExample);
    EXPECT_EQ(s.volume, "data/head.nhdr");
    ASSERT_EQ(s.transferFunction.points.size(), 3u);
    EXPECT_EQ(s.transferFunction.points[1], (ControlPoint{80, 1.0, 0.6, 0.4, 0.05}));
    EXPECT_EQ(s.transferFunction.opacityUnit, 1.0);
    EXPECT_TRUE(s.transferFunctionPreset.empty());
    EXPECT_EQ(s.camera.eye, (Vec3d{300, 200, 400}));
    EXPECT_EQ(s.camera.target, (Vec3d{128, 128, 64}));
    EXPECT_EQ(s.camera.up, (Vec3d{0, 1, 0}));
    EXPECT_EQ(s.camera.projection, Projection::Perspective);
    EXPECT_EQ(s.camera.fovYDeg, 30);
    EXPECT_EQ(s.width, 512);
    EXPECT_EQ(s.height, 512);
    EXPECT_EQ(s.quality.step, 0.5);
    EXPECT_TRUE(s.quality.preintegrated);
    EXPECT_EQ(s.quality.interpolation, Interpolation::Cubic);
    EXPECT_EQ(s.quality.earlyTermination, 0.99);
    ASSERT_EQ(s.clipPlanes.size(), 1u);
    EXPECT_EQ(s.clipPlanes[0], (ClipPlane{{128, 128, 64}, {0, 0, 1}}));
}

TEST(SceneParse, QualityDefaultsWhenKeysMissing) {
    EXPECT_EQ(parseScene(without(example(), "/quality").dump()).quality, Quality{});
    EXPECT_EQ(parseScene(with(example(), "/quality", json::object()).dump()).quality, Quality{});
    Quality expected;
    expected.shading = true;
    EXPECT_EQ(parseScene(with(example(), "/quality", {{"shading", true}}).dump()).quality, expected);
}

TEST(SceneParse, OptionalKeysDefault) {
    json j = without(without(without(example(), "/clip_planes"), "/transfer_function/opacity_unit"),
                     "/camera/fov_y_deg");
    j = without(j, "/camera/projection");
    const Scene s = parseScene(j.dump());
    EXPECT_TRUE(s.clipPlanes.empty());
    EXPECT_FALSE(s.transferFunction.opacityUnit.has_value());
    EXPECT_EQ(s.camera.projection, Projection::Perspective);
    EXPECT_EQ(s.camera.fovYDeg, 30);
}

TEST(SceneParse, RelativeVolumeResolvesAgainstBaseDir) {
    const Scene s = parseScene(kExample, "/scenes/demo");
    EXPECT_EQ(std::filesystem::path(s.volume), std::filesystem::path("/scenes/demo/data/head.nhdr"));
    const Scene up = parseScene(with(example(), "/volume", "../vol/a.nrrd").dump(), "/scenes/demo");
    EXPECT_EQ(std::filesystem::path(up.volume), std::filesystem::path("/scenes/vol/a.nrrd"));
    // Without a base folder the path is left for the caller's working directory.
    EXPECT_EQ(parseScene(kExample).volume, "data/head.nhdr");
}

TEST(SceneParse, AbsoluteVolumeKept) {
    const Scene s = parseScene(with(example(), "/volume", "/data/ct.nii.gz").dump(), "/scenes");
    EXPECT_EQ(s.volume, "/data/ct.nii.gz");
}

TEST(SceneParse, BuiltinVolumeKept) {
    const Scene s = parseScene(with(example(), "/volume", "builtin:sphere").dump(), "/scenes");
    EXPECT_EQ(s.volume, "builtin:sphere");
}

TEST(SceneParse, OrthographicCamera) {
    json j = without(example(), "/camera/fov_y_deg");
    j = with(with(j, "/camera/projection", "orthographic"), "/camera/height", 300);
    const Scene s = parseScene(j.dump());
    EXPECT_EQ(s.camera.projection, Projection::Orthographic);
    EXPECT_EQ(s.camera.height, 300);
}

TEST(SceneParse, PresetIsKeptByNameAndResolvedWithItsOpacityUnit) {
    const json tf = {{"preset", "ct_bone"}, {"opacity_unit", 0.5}};
    const Scene s = parseScene(with(example(), "/transfer_function", tf).dump());
    EXPECT_EQ(s.transferFunctionPreset, "ct_bone");
    const TransferFunction resolved = resolvedTransferFunction(s, {-1000, 3000});
    EXPECT_EQ(resolved.points, presetTransferFunction("ct_bone", {}).points); // Hounsfield: range-free
    EXPECT_EQ(resolved.opacityUnit, 0.5);
}

TEST(SceneParse, RelativePresetResolvedAgainstVolumeRange) {
    for (const char *name : {"mr", "micro_ct"}) {
        const json tf = {{"preset", name}};
        const Scene s = parseScene(with(example(), "/transfer_function", tf).dump());
        EXPECT_EQ(s.transferFunctionPreset, name);
        EXPECT_TRUE(s.transferFunction.points.empty());
        const ValueRange range{100, 4000};
        const TransferFunction resolved = resolvedTransferFunction(s, range);
        EXPECT_EQ(resolved.points, presetTransferFunction(name, range).points);
        EXPECT_EQ(resolved.points.front().value, 100);
        EXPECT_EQ(resolved.points.back().value, 4000);
    }
}

TEST(SceneParse, ResolvedTransferFunctionWithPointsIsTheScenes) {
    const Scene s = parseScene(kExample);
    EXPECT_EQ(resolvedTransferFunction(s, {-5, 5}), s.transferFunction);
}

// ---- writing ----

Scene richScene() {
    Scene s;
    s.volume = "/data/volumes/head.nhdr";
    s.transferFunction.points = {{-1000.25, 0, 0, 0, 0}, {0.1, 0.3, 0.2, 0.1, 0.123456789012345},
                                 {3000, 1, 1, 1, 1}};
    s.transferFunction.opacityUnit = 0.7;
    s.camera.eye = {1.5, -2.25, 1e-3};
    s.camera.target = {0.1, 0.2, 0.3};
    s.camera.up = {0, 0, 1};
    s.camera.projection = Projection::Orthographic;
    s.camera.height = 123.456;
    s.width = 640;
    s.height = 480;
    s.quality.step = 0.125;
    s.quality.adaptiveStep = true;
    s.quality.jitter = true;
    s.quality.preintegrated = true;
    s.quality.interpolation = Interpolation::Cubic;
    s.quality.boundarySegment = false;
    s.quality.earlyTermination = 1;
    s.quality.emptySpaceSkipping = false;
    s.quality.mipLevel = 2;
    s.quality.imageScale = 0.25;
    s.quality.shading = true;
    s.quality.seed = 18446744073709551615u;
    s.clipPlanes = {{{1, 2, 3}, {0, 0, -1}}, {{0, 0, 0}, {0.6, 0.8, 0}}};
    return s;
}

TEST(SceneRoundTrip, ParseOfToJsonIsIdentity) {
    const Scene s = richScene();
    EXPECT_EQ(parseScene(sceneToJson(s), "/elsewhere"), s);
}

TEST(SceneRoundTrip, DefaultsPresetAndBuiltin) {
    Scene s;
    s.volume = "builtin:marschner_lobb";
    s.transferFunctionPreset = "mr";
    EXPECT_EQ(parseScene(sceneToJson(s), "/elsewhere"), s);
    const Scene example = parseScene(kExample, "/scenes");
    EXPECT_EQ(parseScene(sceneToJson(example)), example);
}

TEST(SceneRoundTrip, WritesDesignKeys) {
    const json j = json::parse(sceneToJson(richScene()));
    for (const char *key : {"volume", "transfer_function", "camera", "image", "quality", "clip_planes"})
        EXPECT_TRUE(j.contains(key)) << key;
    EXPECT_EQ(j["camera"]["projection"], "orthographic");
    EXPECT_EQ(j["camera"]["height"], 123.456);
    EXPECT_FALSE(j["camera"].contains("fov_y_deg"));
    EXPECT_EQ(j["quality"]["interpolation"], "cubic");
    EXPECT_EQ(j["transfer_function"]["points"][2], json::array({3000, 1, 1, 1, 1}));
    EXPECT_EQ(j["clip_planes"][1]["normal"], json::array({0.6, 0.8, 0}));
}

// ---- every kind of mistake names its key ----

TEST(SceneRefuses, MalformedJsonIsNamedWithItsLine) {
    const std::string message = errorOf("{\n  \"volume\": \"a.nrrd\",\n  oops\n}");
    EXPECT_TRUE(contains(message, "line 3")) << message;
    EXPECT_TRUE(contains(message, "malformed JSON")) << message;
    EXPECT_SCENE_ERROR(("{\"camera\": {\"eye\": [1, 2"), "camera.eye[2]");
    EXPECT_SCENE_ERROR((""), "malformed JSON");
}

TEST(SceneRefuses, NulByteInTheFileIsMalformedNotTheEndOfTheText) {
    using namespace std::string_literals;
    const std::string message = errorOf("{\"volume\": \"builtin:demo\"}\0{\"camera\": 1}"s);
    EXPECT_TRUE(contains(message, "NUL byte at byte 26")) << message;
}

TEST(SceneRefuses, TopLevelThatIsNotAnObject) {
    EXPECT_SCENE_ERROR(("[1, 2]"), "scene: must be a JSON object");
    EXPECT_SCENE_ERROR(("\"scene\""), "scene: must be a JSON object");
}

TEST(SceneRefuses, MissingRequiredKeyIsNamedByItsPath) {
    for (const char *key : {"volume", "transfer_function", "camera", "image"})
        EXPECT_SCENE_ERROR(without(example(), std::string("/") + key), std::string(key) + ": is required");
    for (const char *key : {"eye", "target", "up"})
        EXPECT_SCENE_ERROR(without(example(), std::string("/camera/") + key), std::string("camera.") + key);
    for (const char *key : {"width", "height"})
        EXPECT_SCENE_ERROR(without(example(), std::string("/image/") + key), std::string("image.") + key);
    json plane = example();
    plane["clip_planes"][0].erase("normal");
    EXPECT_SCENE_ERROR(plane, "clip_planes[0].normal: is required");
}

// {JSON pointer to change, the path the message must name, the wrong value}.
struct Mistake {
    std::string pointer, path;
    json value;
};

TEST(SceneRefuses, ValueOfTheWrongTypeIsNamedByItsPath) {
    const std::vector<Mistake> cases = {
        {"/volume", "volume", 3},
        {"/transfer_function", "transfer_function", json::array()},
        {"/transfer_function/points", "transfer_function.points", "ramp"},
        {"/transfer_function/points/1", "transfer_function.points[1]", 80},
        {"/transfer_function/points/1/0", "transfer_function.points[1][0]", "80"},
        {"/transfer_function/opacity_unit", "transfer_function.opacity_unit", true},
        {"/camera", "camera", "front"},
        {"/camera/eye", "camera.eye", "300, 200, 400"},
        {"/camera/eye/1", "camera.eye[1]", nullptr},
        {"/camera/projection", "camera.projection", 1},
        {"/camera/fov_y_deg", "camera.fov_y_deg", "30"},
        {"/image/width", "image.width", "512"},
        {"/image/width", "image.width", 512.5},
        {"/image/height", "image.height", true},
        {"/quality", "quality", 1},
        {"/quality/step", "quality.step", "0.5"},
        {"/quality/jitter", "quality.jitter", 1},
        {"/quality/adaptive_step", "quality.adaptive_step", "yes"},
        {"/quality/preintegrated", "quality.preintegrated", "true"},
        {"/quality/boundary_segment", "quality.boundary_segment", 0},
        {"/quality/early_termination", "quality.early_termination", false},
        {"/quality/empty_space_skipping", "quality.empty_space_skipping", nullptr},
        {"/quality/mip_level", "quality.mip_level", 1.5},
        {"/quality/image_scale", "quality.image_scale", "1"},
        {"/quality/shading", "quality.shading", 0},
        {"/quality/seed", "quality.seed", 1.5},
        {"/quality/interpolation", "quality.interpolation", false},
        {"/clip_planes", "clip_planes", json::object()},
        {"/clip_planes/0", "clip_planes[0]", json::array({1, 2})},
        {"/clip_planes/0/point", "clip_planes[0].point", 5},
    };
    for (const auto &[pointer, path, value] : cases) {
        SCOPED_TRACE(pointer + " = " + value.dump());
        EXPECT_SCENE_ERROR(with(example(), pointer, value), path + ": must be");
    }
}

TEST(SceneRefuses, FractionalNumberWhereAnIntegerBelongs) {
    EXPECT_SCENE_ERROR(with(example(), "/image/width", 512.5), "image.width: must be a positive integer");
}

TEST(SceneRefuses, PointValuesNotIncreasing) {
    json j = with(example(), "/transfer_function/points/2/0", 40);
    EXPECT_SCENE_ERROR(j, "transfer_function.points[2]: values must be strictly increasing");
}

TEST(SceneRefuses, TwoPointsWithTheSameValue) {
    json j = with(example(), "/transfer_function/points/2/0", 80);
    EXPECT_SCENE_ERROR(j, "transfer_function.points[2]: values must be strictly increasing");
}

TEST(SceneRefuses, PointRowThatIsNotFiveNumbers) {
    EXPECT_SCENE_ERROR(with(example(), "/transfer_function/points/1", json::array({80, 1, 1, 1})),
                       "transfer_function.points[1]: must be a [value, r, g, b, a] row of 5");
    EXPECT_SCENE_ERROR(with(example(), "/transfer_function/points/0", json::array({0, 0, 0, 0, 0, 0})),
                       "transfer_function.points[0]");
}

TEST(SceneRefuses, ColourOrOpacityOutsideZeroToOne) {
    EXPECT_SCENE_ERROR(with(example(), "/transfer_function/points/1/1", 1.5), "transfer_function.points[1]");
    EXPECT_SCENE_ERROR(with(example(), "/transfer_function/points/2/4", -0.1), "transfer_function.points[2]");
}

TEST(SceneRefuses, NeitherOrBothOfPointsAndPreset) {
    EXPECT_SCENE_ERROR(with(example(), "/transfer_function/points", json::array()),
                       "transfer_function.points: needs at least one point");
    EXPECT_SCENE_ERROR(without(example(), "/transfer_function/points"), "transfer_function: needs points or preset");
    EXPECT_SCENE_ERROR(with(example(), "/transfer_function/preset", "ct_bone"),
                       "transfer_function: give either points or preset");
}

TEST(SceneRefuses, UnknownPresetName) {
    const json tf = {{"preset", "ct_lungs"}};
    EXPECT_SCENE_ERROR(with(example(), "/transfer_function", tf), "transfer_function.preset: unknown");
}

TEST(SceneRefuses, NonFiniteNumber) {
    std::string text = kExample;
    text.replace(text.find("[300, 200, 400]"), 15, "[300, 1e400, 400]");
    EXPECT_SCENE_ERROR(text, "camera.eye[1]");
    text = kExample;
    text.replace(text.find("\"opacity_unit\": 1.0"), 19, "\"opacity_unit\": -1e999");
    EXPECT_SCENE_ERROR(text, "transfer_function.opacity_unit");
    // NaN and Infinity are not JSON at all.
    text = kExample;
    text.replace(text.find("\"step\": 0.5"), 11, "\"step\": NaN");
    EXPECT_SCENE_ERROR(text, "quality.step");
}

TEST(SceneRefuses, ZeroOrNegativeOpacityUnit) {
    EXPECT_SCENE_ERROR(with(example(), "/transfer_function/opacity_unit", 0), "transfer_function.opacity_unit");
    EXPECT_SCENE_ERROR(with(example(), "/transfer_function/opacity_unit", -2), "transfer_function.opacity_unit");
    const json tf = {{"preset", "mr"}, {"opacity_unit", 0}};
    EXPECT_SCENE_ERROR(with(example(), "/transfer_function", tf), "transfer_function.opacity_unit");
}

TEST(SceneRefuses, UnknownProjection) {
    EXPECT_SCENE_ERROR(with(example(), "/camera/projection", "fisheye"),
                       "camera.projection: must be one of \"perspective\", \"orthographic\"");
}

TEST(SceneRefuses, OrthographicCameraWithoutHeight) {
    json j = without(with(example(), "/camera/projection", "orthographic"), "/camera/fov_y_deg");
    EXPECT_SCENE_ERROR(j, "camera.height: is required");
}

TEST(SceneRefuses, KeyOfTheOtherProjection) {
    // Most likely a forgotten "projection": refused rather than silently ignored.
    EXPECT_SCENE_ERROR(with(example(), "/camera/height", 300), "camera.height: is only for an orthographic");
    json j = with(with(example(), "/camera/projection", "orthographic"), "/camera/height", 300);
    EXPECT_SCENE_ERROR(j, "camera.fov_y_deg: is only for a perspective");
}

TEST(SceneRefuses, FieldOfViewOutsideItsRange) {
    for (double fov : {0.0, -10.0, 180.0, 200.0})
        EXPECT_SCENE_ERROR(with(example(), "/camera/fov_y_deg", fov), "camera.fov_y_deg");
}

TEST(SceneRefuses, ZeroOrNegativeOrthographicHeight) {
    json j = without(with(example(), "/camera/projection", "orthographic"), "/camera/fov_y_deg");
    EXPECT_SCENE_ERROR(with(j, "/camera/height", 0), "camera.height");
}

TEST(SceneRefuses, ZeroOrNegativeImageSize) {
    EXPECT_SCENE_ERROR(with(example(), "/image/width", 0), "image.width: must be a positive integer");
    EXPECT_SCENE_ERROR(with(example(), "/image/height", -3), "image.height: must be a positive integer");
}

TEST(SceneRefuses, ImageLargerThanTheLimit) {
    EXPECT_SCENE_ERROR(with(example(), "/image/width", kMaxImageSide + 1), "image.width");
    EXPECT_SCENE_ERROR(with(example(), "/image/height", 1'000'000'000'000), "image.height");
    EXPECT_SCENE_ERROR(with(example(), "/image/width", 18446744073709551615u), "image.width");
    const json big = {{"width", kMaxImageSide}, {"height", kMaxImageSide}};
    EXPECT_SCENE_ERROR(with(example(), "/image", big), "image: ");
}

TEST(SceneRefuses, EyeEqualToTarget) {
    EXPECT_SCENE_ERROR(with(example(), "/camera/eye", json::array({128, 128, 64})), "camera.target");
}

TEST(SceneRefuses, UpOfZeroLength) {
    EXPECT_SCENE_ERROR(with(example(), "/camera/up", json::array({0, 0, 0})), "camera.up: has zero length");
}

TEST(SceneRefuses, UpParallelToTheViewDirection) {
    // View direction is target - eye = (-172, -72, -336).
    EXPECT_SCENE_ERROR(with(example(), "/camera/up", json::array({172, 72, 336})),
                       "camera.up: is parallel to the view direction");
}

TEST(SceneRefuses, VectorThatIsNotThreeNumbers) {
    EXPECT_SCENE_ERROR(with(example(), "/camera/eye", json::array({1, 2})), "camera.eye: must be an array of 3");
}

TEST(SceneRefuses, QualitySwitchOutsideItsRange) {
    const std::vector<std::pair<std::string, json>> cases = {
        {"step", 0},      {"step", -0.5},  {"step", 1e-9},
        {"early_termination", 0}, {"early_termination", 1.01}, {"early_termination", -1},
        {"mip_level", -1}, {"mip_level", 17},
        {"image_scale", 0}, {"image_scale", 1.5},
        {"seed", -1},
    };
    for (const auto &[key, value] : cases) {
        SCOPED_TRACE(key + " = " + value.dump());
        EXPECT_SCENE_ERROR(with(example(), "/quality/" + key, value), "quality." + key + ": must be");
    }
}

TEST(SceneParse, QualitySwitchesAtTheirLimitsAreAccepted) {
    const json q = {{"step", 1e-6}, {"early_termination", 1}, {"mip_level", 16}, {"image_scale", 1},
                    {"seed", 18446744073709551615u}};
    EXPECT_NO_THROW((void)parseScene(with(example(), "/quality", q).dump()));
}

TEST(SceneRefuses, UnknownInterpolation) {
    EXPECT_SCENE_ERROR(with(example(), "/quality/interpolation", "nearest"),
                       "quality.interpolation: must be one of \"linear\", \"cubic\"");
}

TEST(SceneRefuses, ClipPlaneNormalOfZeroLength) {
    EXPECT_SCENE_ERROR(with(example(), "/clip_planes/0/normal", json::array({0, 0, 0})),
                       "clip_planes[0].normal: has zero length");
}

TEST(SceneRefuses, UnknownKeyAtAnyLevel) {
    const std::vector<Mistake> cases = {
        {"/volumes", "volumes", 1},
        {"/camera/fov_deg", "camera.fov_deg", 1},
        {"/transfer_function/opacity", "transfer_function.opacity", 1},
        {"/image/depth", "image.depth", 1},
        {"/quality/steps", "quality.steps", 1},
        {"/clip_planes/0/offset", "clip_planes[0].offset", 1},
    };
    for (const auto &[pointer, path, value] : cases)
        EXPECT_SCENE_ERROR(with(example(), pointer, value), path + ": unknown key");
}

// The client's own view travels in the file and changes nothing the renderer draws.
TEST(SceneViewer, AnObjectIsKeptOutOfTheSceneAndAnythingElseIsRefused) {
    const json viewer = {{"crosshair", {1.5, 2, 3}}, {"slab", {{"thickness", 5}, {"mode", "mip"}}}};
    EXPECT_EQ(volcast::parseScene(with(example(), "/viewer", viewer).dump()), volcast::parseScene(example().dump()));
    EXPECT_SCENE_ERROR(with(example(), "/viewer", json::array({1})), "viewer: must be an object");
    EXPECT_SCENE_ERROR(with(example(), "/viewer", "lps"), "viewer: must be an object");
}

TEST(SceneRefuses, DuplicateKey) {
    std::string text = kExample;
    text.replace(text.find("\"fov_y_deg\": 30"), 15, "\"fov_y_deg\": 30, \"fov_y_deg\": 60");
    EXPECT_SCENE_ERROR(text, "camera.fov_y_deg: duplicate key");
}

TEST(SceneRefuses, EmptyVolumeName) {
    EXPECT_SCENE_ERROR(with(example(), "/volume", ""), "volume: must not be empty");
}

// ---- files ----

class SceneFile : public testing::Test {
  protected:
    void SetUp() override {
        dir_ = std::filesystem::temp_directory_path() /
               ("volcast_scene_test_" + std::to_string(::testing::UnitTest::GetInstance()->random_seed()) +
                "_" + testing::UnitTest::GetInstance()->current_test_info()->name());
        std::filesystem::create_directories(dir_);
    }
    void TearDown() override { std::filesystem::remove_all(dir_); }
    std::filesystem::path write(const std::string &name, const std::string &text) {
        const auto path = dir_ / name;
        std::ofstream(path) << text;
        return path;
    }
    std::filesystem::path dir_;
};

TEST_F(SceneFile, VolumeRelativeToTheFile) {
    const Scene s = loadSceneFile(write("scene.json", kExample));
    EXPECT_EQ(std::filesystem::path(s.volume), (dir_ / "data/head.nhdr").lexically_normal());
}

TEST_F(SceneFile, MissingFileIsNamed) {
    const auto missing = dir_ / "nope.json";
    try {
        (void)loadSceneFile(missing);
        ADD_FAILURE() << "no error";
    } catch (const SceneError &e) {
        EXPECT_TRUE(contains(e.what(), missing.string())) << e.what();
    }
}

TEST_F(SceneFile, ErrorsNameTheFileAndTheKey) {
    const auto file = write("bad.json", with(example(), "/camera/up", json::array({0, 0, 0})).dump());
    try {
        (void)loadSceneFile(file);
        ADD_FAILURE() << "no error";
    } catch (const SceneError &e) {
        EXPECT_TRUE(contains(e.what(), file.string())) << e.what();
        EXPECT_TRUE(contains(e.what(), "camera.up")) << e.what();
    }
}

} // namespace
} // namespace volcast
