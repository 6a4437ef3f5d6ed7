#include "protocol/client_messages.hpp"
#include "protocol/version.hpp"

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include <string>
#include <string_view>
#include <variant>
#include <vector>

namespace volcast::protocol {
namespace {

using json = nlohmann::json;

// The scene pieces as docs/design.md's scene file writes them.
const json kCamera = json::parse(R"({"eye": [300, 200, 400], "target": [128, 128, 64], "up": [0, 1, 0],
                                     "projection": "perspective", "fov_y_deg": 30})");
const json kTransferFunction = json::parse(
    R"({"points": [[0, 0, 0, 0, 0], [80, 1.0, 0.6, 0.4, 0.05], [255, 1, 1, 1, 0.9]], "opacity_unit": 1.0})");
const json kQuality = json::parse(R"({"step": 0.5, "jitter": false, "preintegrated": true,
    "interpolation": "cubic", "boundary_segment": true, "early_termination": 0.99,
    "empty_space_skipping": true, "mip_level": 0, "image_scale": 1.0, "shading": false, "seed": 0})");
const json kClipPlanes = json::parse(R"([{"point": [128, 128, 64], "normal": [0, 0, 1]}])");
const json kImage = json::parse(R"({"width": 512, "height": 384})");

ProtocolError errorOf(std::string_view text, const Limits &limits = {}) {
    const ParsedClientMessage parsed = parseClientMessage(text, limits);
    if (const auto *error = std::get_if<ProtocolError>(&parsed)) return *error;
    ADD_FAILURE() << "accepted, but should be refused: " << text;
    return {};
}

ClientMessage accepted(std::string_view text) {
    const ParsedClientMessage parsed = parseClientMessage(text);
    if (const auto *error = std::get_if<ProtocolError>(&parsed)) {
        ADD_FAILURE() << "refused (" << errorCodeName(error->code) << ": " << error->message << "): " << text;
        return CloseRequest{};
    }
    return std::get<ClientMessage>(parsed);
}

// One of every request, with ids of each kind (none, integer, string).
std::vector<ClientMessage> everyRequest() {
    HelloRequest hello;
    hello.id = 1;
    hello.protocol = kProtocolVersion;
    hello.token = "s3cret";
    hello.client = "test 1.0";
    HelloRequest bareHello;
    bareHello.protocol = kProtocolVersion;
    QualityPolicyRequest automatic{7, {QualityMode::Automatic, 25, nullptr}};
    QualityPolicyRequest automaticWithFinal{8, {QualityMode::Automatic, 40, kQuality}};
    QualityPolicyRequest explicitPolicy{"q", {QualityMode::Explicit, kDefaultTargetFrameMs, kQuality}};
    return {hello,
            bareHello,
            ListVolumesRequest{2},
            OpenVolumeRequest{"open-1", "ct/head.nrrd"},
            CameraRequest{3, kCamera},
            InteractionStartRequest{4},
            InteractionEndRequest{nullptr},
            ViewportRequest{5, kImage},
            TransferFunctionRequest{6, kTransferFunction},
            TransferFunctionRequest{6, {{"preset", "ct_bone"}}},
            automatic,
            automaticWithFinal,
            explicitPolicy,
            ClipPlanesRequest{9, kClipPlanes},
            ClipPlanesRequest{10, json::array()},
            StillRequest{11, nullptr},
            StillRequest{12, {{"width", 2048}, {"height", 2048}}},
            GetStateRequest{-13},
            CloseRequest{"bye"},
            SliceRequest{14, "axial", std::nullopt, std::nullopt, 64, 32, std::nullopt, std::nullopt, std::nullopt,
                         std::nullopt},
            SliceRequest{"s", "sagittal", std::array<double, 3>{1, 2, 3}, std::array<double, 3>{0, -1, 0.5},
                         512, 512, 0.25, 2000.0, 400.0, std::nullopt},
            FindStudiesRequest{15, "pacs", {}, 100},
            FindStudiesRequest{"f", "orthanc-1", {"DOE^J*", "12345", "20240101-", "CT", "A-77"}, 5},
            SliceRequest{16, "coronal", std::nullopt, std::nullopt, 64, 64, std::nullopt, std::nullopt, std::nullopt,
                         SliceSlab{12.5, "minip"}},
            ProbeRequest{17, {-12.5, 30, 1e5}},
            RoiStatsRequest{"roi", "sagittal", {1, 2, 3}, {4.5, 0.25}, "rectangle"},
            PickRequest{18, 120.5, 0, 640, 480}};
}

TEST(ClientMessages, EveryRequestRoundTrips) {
    for (const ClientMessage &message : everyRequest()) {
        const std::string text = toJsonText(message);
        SCOPED_TRACE(text);
        const ParsedClientMessage parsed = parseClientMessage(text);
        ASSERT_TRUE(std::holds_alternative<ClientMessage>(parsed))
            << std::get<ProtocolError>(parsed).message;
        EXPECT_TRUE(std::get<ClientMessage>(parsed) == message);
        EXPECT_EQ(json::parse(text).at("type"), messageType(message));
    }
}

TEST(ClientMessages, EveryTypeIsCovered) {
    // A new request type must be added to everyRequest() to be tested.
    std::vector<bool> seen(std::variant_size_v<ClientMessage>, false);
    for (const ClientMessage &message : everyRequest()) seen[message.index()] = true;
    for (size_t i = 0; i < seen.size(); ++i) EXPECT_TRUE(seen[i]) << "variant alternative " << i;
}

TEST(ClientMessages, ScenePiecesKeepTheSceneFileForm) {
    // The payload is carried untouched, so the server can hand it to the scene parser.
    const ClientMessage m = accepted(R"({"type": "camera", "id": 3, "camera": )" + kCamera.dump() + "}");
    ASSERT_TRUE(std::holds_alternative<CameraRequest>(m));
    EXPECT_EQ(std::get<CameraRequest>(m).camera, kCamera);
    EXPECT_EQ(std::get<CameraRequest>(m).id, 3);
    // Only the kind is checked here: a camera the scene parser would refuse still passes.
    EXPECT_TRUE(std::holds_alternative<CameraRequest>(accepted(R"({"type": "camera", "camera": {"eye": "x"}})")));
}

TEST(ClientMessages, QualityPolicyDefaultsAndForms) {
    const ClientMessage automatic = accepted(R"({"type": "quality_policy", "mode": "automatic"})");
    const QualityPolicy &policy = std::get<QualityPolicyRequest>(automatic).policy;
    EXPECT_EQ(policy.mode, QualityMode::Automatic);
    EXPECT_EQ(policy.targetFrameMs, kDefaultTargetFrameMs);
    EXPECT_TRUE(policy.quality.is_null());

    const ClientMessage explicitPolicy =
        accepted(R"({"type": "quality_policy", "mode": "explicit", "quality": {"step": 0.25}})");
    EXPECT_EQ(std::get<QualityPolicyRequest>(explicitPolicy).policy.quality, json({{"step", 0.25}}));

    EXPECT_EQ(errorOf(R"({"type": "quality_policy", "mode": "explicit"})").message, "quality: is required");
    EXPECT_EQ(errorOf(R"({"type": "quality_policy", "mode": "explicit", "quality": {}, "target_frame_ms": 30})").message,
              "target_frame_ms: is only for mode \"automatic\"");
    EXPECT_EQ(errorOf(R"({"type": "quality_policy", "mode": "fast"})").message,
              "mode: must be \"automatic\" or \"explicit\", got \"fast\"");
    for (const char *ms : {"0", "-5", "10001", "\"40\""}) {
        const ProtocolError e =
            errorOf(std::string(R"({"type": "quality_policy", "mode": "automatic", "target_frame_ms": )") + ms + "}");
        EXPECT_EQ(e.code, ErrorCode::BadField) << ms;
        EXPECT_TRUE(e.message.starts_with("target_frame_ms: ")) << e.message;
    }
}

TEST(ClientMessages, IdIsEchoedInErrors) {
    const ProtocolError e = errorOf(R"({"type": "camera", "id": "cam-7", "camera": 5})");
    EXPECT_EQ(e.code, ErrorCode::BadField);
    EXPECT_EQ(e.requestId, "cam-7");
    EXPECT_EQ(e.requestType, "camera");
    EXPECT_EQ(e.message, "camera: must be a JSON object, got an integer");
    // Also when the type is unknown: the id was readable.
    EXPECT_EQ(errorOf(R"({"type": "fly", "id": 99})").requestId, 99);
}

// --- One crafted message per error code the parser can raise -------------------------------

TEST(ClientMessageErrors, MalformedJson) {
    for (const char *text : {"", "not json", R"({"type": "hello",)", R"({"type": "hello" "protocol": 1})",
                             "{\"type\": \"open_volume\", \"name\": \"\xff\xfe\"}", R"({"type": 'close'})"}) {
        const ProtocolError e = errorOf(text);
        EXPECT_EQ(e.code, ErrorCode::MalformedJson) << text;
        EXPECT_TRUE(e.message.starts_with("malformed JSON: ")) << e.message;
        EXPECT_TRUE(e.requestId.is_null());
    }
    // Line and column help a person find the mistake.
    EXPECT_NE(errorOf("{\"type\": \"close\",\n  oops}").message.find("line 2"), std::string::npos);
}

// The soak's one finding: the JSON library ends the text at a NUL byte, so a valid request
// followed by a NUL and anything was applied with no answer about the rest.
TEST(ClientMessageErrors, NulByteAfterAValidMessageIsMalformedNotIgnored) {
    using namespace std::string_literals;
    for (const std::string &text : {"{\"type\":\"get_state\",\"id\":5}\0{{{"s, "{\"type\":\"close\"}\0"s,
                                   "{\"type\":\"open_volume\",\"name\":\"a\0b\"}"s}) {
        const ProtocolError e = errorOf(text);
        EXPECT_EQ(e.code, ErrorCode::MalformedJson) << e.message;
        EXPECT_NE(e.message.find("NUL byte"), std::string::npos) << e.message;
    }
}

TEST(ClientMessageErrors, TooLargeIsRefusedBeforeParsing) {
    Limits limits;
    limits.maxMessageBytes = 100;
    // Valid JSON, padded past the limit: refused for its size alone.
    const std::string padded = R"({"type": "close"})" + std::string(100, ' ');
    const ProtocolError e = errorOf(padded, limits);
    EXPECT_EQ(e.code, ErrorCode::TooLarge);
    EXPECT_EQ(e.message, "message is 117 bytes; the limit is 100");
    // Garbage past the limit is too large, not malformed: the parser never ran.
    EXPECT_EQ(errorOf(std::string(101, '{'), limits).code, ErrorCode::TooLarge);
    // Exactly at the limit is fine.
    EXPECT_TRUE(std::holds_alternative<ClientMessage>(parseClientMessage(padded.substr(0, 100), limits)));
    // The default limit: 64 KiB.
    EXPECT_EQ(errorOf(R"({"type": "close", "id": ")" + std::string(70000, 'x') + "\"}").code, ErrorCode::TooLarge);
}

TEST(ClientMessageErrors, DeepNestingIsTooLarge) {
    const std::string deep = R"({"type": "camera", "camera": {"eye": )" + std::string(40, '[') +
                             std::string(40, ']') + "}}";
    const ProtocolError e = errorOf(deep);
    EXPECT_EQ(e.code, ErrorCode::TooLarge);
    EXPECT_NE(e.message.find("nested deeper than 32 levels"), std::string::npos) << e.message;
}

TEST(ClientMessageErrors, BadMessage) {
    EXPECT_EQ(errorOf("[1, 2]").message, "a message must be a JSON object, got an array");
    EXPECT_EQ(errorOf("\"hello\"").code, ErrorCode::BadMessage);
    const ProtocolError noType = errorOf(R"({"id": 4, "camera": {}})");
    EXPECT_EQ(noType.code, ErrorCode::BadMessage);
    EXPECT_EQ(noType.message, "a message needs a \"type\"");
    EXPECT_EQ(noType.requestId, 4);
    EXPECT_EQ(errorOf(R"({"type": 5})").message, "\"type\" must be a string, got an integer");
    const ProtocolError binary = binaryMessageError(12);
    EXPECT_EQ(binary.code, ErrorCode::BadMessage);
    EXPECT_NE(binary.message.find("12 bytes"), std::string::npos);
}

TEST(ClientMessageErrors, UnknownType) {
    const ProtocolError e = errorOf(R"({"type": "render_everything", "id": "x"})");
    EXPECT_EQ(e.code, ErrorCode::UnknownType);
    EXPECT_TRUE(e.message.starts_with("unknown message type \"render_everything\" (known: hello, list_volumes,"))
        << e.message;
    EXPECT_EQ(e.requestId, "x");
    EXPECT_EQ(e.requestType, "");   // only known types are echoed
    // Type names are case-sensitive.
    EXPECT_EQ(errorOf(R"({"type": "Hello", "protocol": 1})").code, ErrorCode::UnknownType);
}

TEST(ClientMessageErrors, WrongFieldKinds) {
    const std::vector<std::pair<std::string, std::string>> cases = {
        {R"({"type": "camera", "camera": [1, 2, 3]})", "camera: must be a JSON object, got an array"},
        {R"({"type": "transfer_function", "transfer_function": "ct_bone"})",
         "transfer_function: must be a JSON object, got a string"},
        {R"({"type": "viewport", "image": 512})", "image: must be a JSON object, got an integer"},
        {R"({"type": "clip_planes", "clip_planes": {}})", "clip_planes: must be an array, got a JSON object"},
        {R"({"type": "quality_policy", "mode": "explicit", "quality": "best"})",
         "quality: must be a JSON object, got a string"},
        {R"({"type": "quality_policy", "mode": true})", "mode: must be a string, got a boolean"},
        {R"({"type": "open_volume", "name": 42})", "name: must be a string, got an integer"},
        {R"({"type": "hello", "protocol": "1"})", "protocol: must be an integer in [0, 1073741824], got a string"},
        {R"({"type": "hello", "protocol": 1.5})",
         "protocol: must be an integer in [0, 1073741824], got a fractional number"},
        {R"({"type": "hello", "protocol": 1, "token": 123})", "token: must be a string, got an integer"},
        {R"({"type": "still", "image": null})", "image: must be a JSON object, got null"},
        {R"({"type": "close", "id": 1.5})", "id: must be an integer or a string, got a fractional number"},
        {R"({"type": "close", "id": {"n": 1}})", "id: must be an integer or a string, got a JSON object"},
        {R"({"type": "camera", "camera": {"eye": [1e999, 0, 0]}})",
         "camera.eye[0]: must be a finite number (number overflow parsing '1e999')"},
    };
    for (const auto &[text, message] : cases) {
        const ProtocolError e = errorOf(text);
        EXPECT_EQ(e.code, ErrorCode::BadField) << text;
        EXPECT_EQ(e.message, message) << text;
    }
}

TEST(ClientMessageErrors, MissingAndUnknownFields) {
    EXPECT_EQ(errorOf(R"({"type": "open_volume"})").message, "name: is required");
    EXPECT_EQ(errorOf(R"({"type": "camera", "id": 1})").message, "camera: is required");
    EXPECT_EQ(errorOf(R"({"type": "hello"})").message, "protocol: is required");
    EXPECT_EQ(errorOf(R"({"type": "quality_policy"})").message, "mode: is required");
    const ProtocolError typo = errorOf(R"({"type": "open_volume", "nmae": "bonsai"})");
    EXPECT_EQ(typo.code, ErrorCode::BadField);
    EXPECT_EQ(typo.message, "nmae: unknown field (known here: type, id, name)");
    EXPECT_EQ(errorOf(R"({"type": "list_volumes", "filter": "ct"})").message,
              "filter: unknown field (known here: type, id)");
}

TEST(ClientMessageErrors, DuplicateKeysAreAmbiguous) {
    const ProtocolError top = errorOf(R"({"type": "close", "id": 1, "type": "hello"})");
    EXPECT_EQ(top.code, ErrorCode::BadField);
    EXPECT_EQ(top.message, "type: duplicate key");
    EXPECT_EQ(errorOf(R"({"type": "camera", "camera": {"eye": [0, 0, 1], "eye": [0, 0, 2]}})").message,
              "camera.eye: duplicate key");
    EXPECT_EQ(errorOf(R"({"type": "clip_planes", "clip_planes": [{}, {"point": 1, "point": 2}]})").message,
              "clip_planes[1].point: duplicate key");
}

TEST(ClientMessageErrors, IdLimits) {
    EXPECT_EQ(errorOf(R"({"type": "close", "id": ")" + std::string(65, 'x') + "\"}").message,
              "id: is 65 bytes long; at most 64 are allowed");
    // An integer beyond int64 parses as a fractional number in JSON libraries; refused.
    EXPECT_EQ(errorOf(R"({"type": "close", "id": 1e30})").code, ErrorCode::BadField);
    // null is the same as no id.
    EXPECT_TRUE(requestIdOf(accepted(R"({"type": "close", "id": null})")).is_null());
}

TEST(ClientMessageErrors, UnsupportedVersion) {
    for (int version : {0, kProtocolVersion + 1, 1000}) {
        const ProtocolError e =
            errorOf(R"({"type": "hello", "id": 1, "protocol": )" + std::to_string(version) + "}");
        EXPECT_EQ(e.code, ErrorCode::UnsupportedVersion);
        EXPECT_EQ(e.message, "protocol version " + std::to_string(version) +
                                 " is not supported; this server speaks 1");
        EXPECT_EQ(e.requestId, 1);
        EXPECT_EQ(e.requestType, "hello");
    }
}

TEST(ClientMessageErrors, BadVolumeNames) {
    const std::vector<std::pair<std::string, std::string>> cases = {
        {R"("../etc/passwd")", "contains a \"..\" component"},
        {R"("ct/../../secret.nrrd")", "contains a \"..\" component"},
        {R"("/etc/passwd")", "is an absolute path"},
        {R"("ct\\head.nrrd")", "contains a backslash"},
        {R"("bon\u0000sai")", "contains a NUL character"},
        {R"("bon\nsai")", "contains a control character (0x0A"},
        {R"("")", "is empty"},
        {R"("C:/scans/head.nrrd")", "starts with a drive letter"},
        {"\"" + std::string(1025, 'a') + "\"", "is 1025 bytes long"},
    };
    for (const auto &[name, reason] : cases) {
        const ProtocolError e = errorOf(R"({"type": "open_volume", "id": 5, "name": )" + name + "}");
        EXPECT_EQ(e.code, ErrorCode::BadVolumeName) << name;
        EXPECT_NE(e.message.find(reason), std::string::npos) << e.message;
        EXPECT_EQ(e.requestId, 5);
    }
    // The refused name is quoted as JSON, so a NUL or newline cannot garble the message.
    EXPECT_EQ(errorOf(R"({"type": "open_volume", "name": "a\nb"})").message,
              "volume name \"a\\nb\" contains a control character (0x0A at byte 1)");
}

TEST(ClientMessageErrors, ParsingStaysUsableAfterAnError) {
    // The parser holds no state: a refused message does not affect the next one.
    EXPECT_EQ(errorOf("{").code, ErrorCode::MalformedJson);
    EXPECT_TRUE(std::holds_alternative<ListVolumesRequest>(accepted(R"({"type": "list_volumes"})")));
}

} // namespace
} // namespace volcast::protocol

namespace volcast::protocol {
namespace {

TEST(FindStudies, FiltersAndLimitAreRead) {
    const ClientMessage m = accepted(R"({"type": "find_studies", "id": 1, "source": "pacs",
        "filters": {"patient_name": "Müller*", "study_date": "-20241231", "modality": "MR"}, "limit": 3})");
    const auto &f = std::get<FindStudiesRequest>(m);
    EXPECT_EQ(f.source, "pacs");
    EXPECT_EQ(f.filters.patientName, "M\u00fcller*") << "non-ASCII names pass untouched";
    EXPECT_EQ(f.filters.studyDate, "-20241231");
    EXPECT_EQ(f.filters.modality, "MR");
    EXPECT_EQ(f.limit, 3);
    EXPECT_EQ(std::get<FindStudiesRequest>(accepted(R"({"type": "find_studies", "source": "a"})")).limit, 100)
        << "the default limit";
}

// The measurement requests and the slab: each bad field is named, with bad_field, whatever
// kind of wrong it is (missing, wrong type, out of range, huge).
TEST(Measurements, EachMalformedFieldIsNamed) {
    const auto refused = [](std::string_view text, std::string_view path, std::string_view type) {
        const ProtocolError e = errorOf(text);
        EXPECT_EQ(e.code, ErrorCode::BadField) << text;
        EXPECT_TRUE(e.message.starts_with(path)) << "the message should start with " << path << ": " << e.message;
        EXPECT_EQ(e.requestType, type);
    };
    refused(R"({"type": "probe"})", "point", "probe");
    refused(R"({"type": "probe", "point": [1, 2]})", "point", "probe");
    refused(R"({"type": "probe", "point": [1, 2, "3"]})", "point[2]", "probe");
    refused(R"({"type": "probe", "point": {"x": 1}})", "point", "probe");
    refused(R"({"type": "probe", "point": [1, 2, 3], "value": 1})", "value", "probe");

    const std::string roi = R"({"type": "roi_stats", "axis": "axial", "center": [0, 0, 0], )";
    refused(roi + R"("radii": [1, 2], "shape": "circle"})", "shape", "roi_stats");
    refused(roi + R"("radii": [1, 2], "shape": 1})", "shape", "roi_stats");
    refused(roi + R"("radii": [1]})", "radii", "roi_stats");
    refused(roi + R"("radii": [1, 0]})", "radii[1]", "roi_stats");
    refused(roi + R"("radii": [-1, 2]})", "radii[0]", "roi_stats");
    refused(roi + R"("radii": "big"})", "radii", "roi_stats");
    refused(R"({"type": "roi_stats", "axis": "oblique", "center": [0, 0, 0], "radii": [1, 1]})", "axis", "roi_stats");
    refused(R"({"type": "roi_stats", "axis": "axial", "radii": [1, 1]})", "center", "roi_stats");

    const std::string pick = R"({"type": "pick", "width": 640, "height": 480, )";
    refused(pick + R"("x": -0.5, "y": 1})", "x", "pick");
    refused(pick + R"("x": 640.5, "y": 1})", "x", "pick");
    refused(pick + R"("x": 1, "y": 1e300})", "y", "pick");
    refused(pick + R"("x": "1", "y": 1})", "x", "pick");
    refused(R"({"type": "pick", "x": 1, "y": 1, "width": 0, "height": 480})", "width", "pick");
    refused(R"({"type": "pick", "x": 1, "y": 1, "width": 64.5, "height": 480})", "width", "pick");
    refused(R"({"type": "pick", "x": 1, "y": 1, "width": 64, "height": 100000})", "height", "pick");

    const std::string slice = R"({"type": "slice", "axis": "axial", "width": 8, "height": 8, )";
    refused(slice + R"("slab": {"thickness": -1}})", "slab.thickness", "slice");
    refused(slice + R"("slab": {"thickness": "thick"}})", "slab.thickness", "slice");
    refused(slice + R"("slab": {"thickness": 2, "mode": "max"}})", "slab.mode", "slice");
    refused(slice + R"("slab": {"mode": "mip"}})", "slab.thickness", "slice");
    refused(slice + R"("slab": 5})", "slab", "slice");
    refused(slice + R"("slab": {"thickness": 2, "planes": 5}})", "slab.planes", "slice");
    // A number beyond a double fails while parsing, before the type and id are read: still
    // bad_field naming the field.
    for (const auto &[text, path] : std::vector<std::pair<std::string, std::string>>{
             {R"({"type": "probe", "point": [1, 2, 1e999]})", "point[2]"},
             {roi + R"("radii": [1, 1e400]})", "radii[1]"},
             {slice + R"("slab": {"thickness": 1e999}})", "slab.thickness"}}) {
        const ProtocolError e = errorOf(text);
        EXPECT_EQ(e.code, ErrorCode::BadField) << text;
        EXPECT_TRUE(e.message.starts_with(path)) << e.message;
    }
    // The defaults: an ellipse, a MIP slab.
    EXPECT_EQ(std::get<RoiStatsRequest>(accepted(roi + R"("radii": [1, 2]})")).shape, "ellipse");
    EXPECT_EQ(std::get<SliceRequest>(accepted(slice + R"("slab": {"thickness": 0}})")).slab->mode, "mip");
}

TEST(FindStudies, EachMalformedFieldIsNamed) {
    const auto refused = [](std::string_view text, std::string_view path) {
        const ProtocolError e = errorOf(text);
        EXPECT_EQ(e.code, ErrorCode::BadField) << text;
        EXPECT_TRUE(e.message.starts_with(path)) << "the message should start with " << path << ": " << e.message;
        EXPECT_EQ(e.requestType, "find_studies");
    };
    refused(R"({"type": "find_studies"})", "source");
    refused(R"({"type": "find_studies", "source": ""})", "source");
    refused(R"({"type": "find_studies", "source": "a/b"})", "source");
    refused(R"({"type": "find_studies", "source": "pacs:1"})", "source");
    refused(R"({"type": "find_studies", "source": "é"})", "source");
    refused(R"({"type": "find_studies", "source": "pacs", "filters": []})", "filters");
    refused(R"({"type": "find_studies", "source": "pacs", "filters": {"name": "x"}})", "filters");
    refused(R"({"type": "find_studies", "source": "pacs", "filters": {"patient_id": 12}})", "filters.patient_id");
    refused(R"({"type": "find_studies", "source": "pacs", "filters": {"patient_id": "a\\b"}})", "filters.patient_id");
    refused(R"({"type": "find_studies", "source": "pacs", "filters": {"patient_id": "a\u0001"}})", "filters.patient_id");
    refused(R"({"type": "find_studies", "source": "pacs", "filters": {"patient_name": ")" + std::string(65, 'x') + R"("}})",
            "filters.patient_name");
    for (const char *date : {"2024", "20241301", "20240132", "2024-01-01", "-", "20240101-2024", "x20240101"})
        refused(std::string(R"({"type": "find_studies", "source": "pacs", "filters": {"study_date": ")") + date + "\"}}",
                "filters.study_date");
    refused(R"({"type": "find_studies", "source": "pacs", "filters": {"modality": "ct"}})", "filters.modality");
    refused(R"({"type": "find_studies", "source": "pacs", "limit": 0})", "limit");
    refused(R"({"type": "find_studies", "source": "pacs", "limit": 1001})", "limit");
    refused(R"({"type": "find_studies", "source": "pacs", "limit": -1})", "limit");
    refused(R"({"type": "find_studies", "source": "pacs", "limit": 1e300})", "limit");
}

TEST(FindStudies, DicomWebAndUploadNamesPassTheVolumeNameGate) {
    EXPECT_EQ(validateVolumeName("dicomweb:pacs/1.2.840.113619.2.55/1.2.840.113619.2.55.3"), std::nullopt);
    EXPECT_EQ(validateVolumeName("upload:0123456789abcdef0123456789abcdef"), std::nullopt);
}

} // namespace
} // namespace volcast::protocol
