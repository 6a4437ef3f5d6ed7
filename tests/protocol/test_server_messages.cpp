#include "protocol/server_messages.hpp"

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include <string>
#include <variant>
#include <vector>

namespace volcast::protocol {
namespace {

using json = nlohmann::json;

VolumeInfo loadedVolume() {
    VolumeInfo v;
    v.name = "bonsai";
    v.loaded = true;
    v.dims = {256, 256, 256};
    v.spacing = {1, 1, 1.5};
    v.origin = {0, -10, 2.5};
    v.direction = {{{-1, 0, 0}, {0, -1, 0}, {0, 0, 1}}};   // a RAS file's axes in LPS
    v.voxelType = "uint8";
    v.valueRange = {0, 255};
    v.histogram = HistogramInfo{{0, 255}, std::vector<uint64_t>(256, 0)};
    v.histogram->counts[0] = 12000000;
    v.histogram->counts[200] = 3;
    v.orientationKnown = false;
    v.modality = ModalityInfo{"micro-CT", "inferred", "uint8 values with no Hounsfield air", "micro_ct.default",
                              {PresetInfo{"micro_ct.default", "Micro-CT", 160, 130,
                                          {{{50, 0, 0, 0, 0}, {210, 1, 1, 1, 0.8}}}, true, "micro-CT"}},
                              {"micro-CT", "CT", "MR"}, false};
    return v;
}

VolumeInfo notLoaded(std::string name) {
    VolumeInfo v;
    v.name = std::move(name);
    return v;
}

std::vector<ServerMessage> everyMessage() {
    ServerHello hello;
    hello.id = 1;
    hello.server = "volcast 0.1.0";
    hello.device = {"NVIDIA H100 80GB HBM3", "gpu"};
    hello.limits.maxImageSide = 16384;
    hello.limits.maxImagePixels = int64_t(8192) * 8192;

    VolumesMessage volumes;
    volumes.id = "list";
    volumes.volumes = {loadedVolume(), notLoaded("ct/head.nrrd")};
    VolumesMessage noVolumes;
    VolumesMessage withSources;
    withSources.volumes = {notLoaded("builtin:demo")};
    withSources.sources = {{"pacs", "dicomweb"}, {"cloud-store", "dicomweb"}};

    StudiesMessage studies;
    studies.id = 9;
    studies.source = "pacs";
    studies.studies = {StudyInfo{"1.2.3", "M\u00fcller^Hans", "P-1", "20240102", "CT head", "A-7", {"CT", "SR"},
                                 {SeriesInfo{"1.2.3.4", "CT", "Axial 1 mm", 300, "dicomweb:pacs/1.2.3/1.2.3.4"},
                                  SeriesInfo{"1.2.3.5", "SR", "", 0, "dicomweb:pacs/1.2.3/1.2.3.5"}}},
                       StudyInfo{"1.2.4", "", "", "", "", "", {}, {}}};
    StudiesMessage noStudies;
    noStudies.source = "pacs";

    ProgressMessage progress{2, "bonsai", ProgressStage::Preprocessing, "bspline_coefficients", 0.25, {}, {}};
    ProgressMessage loading{2, "bonsai", ProgressStage::Loading, "", 1.0, {}, {}};
    ProgressMessage uploading{nullptr, "bonsai", ProgressStage::Uploading, "", 0, {}, {}};
    ProgressMessage retrieving{5, "dicomweb:pacs/1.2/1.3", ProgressStage::Retrieving, "retrieving instances", 0.4,
                               std::array<int64_t, 2>{120, 300}, uint64_t(62) << 20};

    StateMessage before;
    StateMessage after;
    after.id = 3;
    after.volume = loadedVolume();
    after.scene = json::parse(R"({"volume": "bonsai",
        "transfer_function": {"preset": "micro_ct"},
        "camera": {"eye": [600, 500, 700], "target": [127.5, 127.5, 127.5], "up": [0, 1, 0],
                   "projection": "perspective", "fov_y_deg": 30},
        "image": {"width": 640, "height": 480}})");
    after.qualityPolicy = {QualityMode::Explicit, kDefaultTargetFrameMs, json{{"step", 0.25}}};
    after.interacting = true;

    return {hello,
            volumes,
            noVolumes,
            withSources,
            studies,
            noStudies,
            retrieving,
            progress,
            loading,
            uploading,
            before,
            after,
            ProtocolError{ErrorCode::NotFound, "no volume \"bonsia\" in the data folders", 4, "open_volume"},
            ProtocolError{ErrorCode::MalformedJson, "malformed JSON: ...", nullptr, ""},
            ProbeMessage{20, {1, 2, 3}, true, -998.25, "HU"},
            ProbeMessage{"p", {1e6, 2, 3}, false, std::nullopt, std::nullopt},
            RoiStatsMessage{21, 1200, 75.0, 40.5, 3.25, 12, 88, "HU"},
            RoiStatsMessage{22, 0, 0, std::nullopt, std::nullopt, std::nullopt, std::nullopt, std::nullopt},
            PickMessage{23, true, std::array<double, 3>{10, -20.5, 30}, 0.98},
            PickMessage{24, false, std::nullopt, 0.125}};
}

TEST(ServerMessages, EveryMessageRoundTrips) {
    for (const ServerMessage &message : everyMessage()) {
        const std::string text = toJsonText(message);
        SCOPED_TRACE(text);
        const ServerMessage back = parseServerMessage(text);
        EXPECT_TRUE(back == message);
        const json j = json::parse(text);
        EXPECT_EQ(j.at("type"), messageType(message));
        EXPECT_TRUE(j.contains("id")) << "every server message carries an id, null when none";
    }
}

TEST(ServerMessages, ALoadFailedOfASeriesOfSeveralStacksOffersEachByItsVolumeName) {
    ProtocolError error{ErrorCode::LoadFailed, "the series holds a localizer besides 120 axial slices", 3, "open_volume"};
    error.stacks = {{"dicomweb:pacs/1.2.3/1.2.3.4#stack=1", 120, 512, 512, "axial", false},
                    {"dicomweb:pacs/1.2.3/1.2.3.4#stack=2", 1, 256, 256, "coronal", true}};
    const std::string text = toJsonText(error);
    EXPECT_EQ(json::parse(text).at("stacks"), json::parse(R"([
        {"volume": "dicomweb:pacs/1.2.3/1.2.3.4#stack=1", "slices": 120, "rows": 512, "columns": 512,
         "orientation": "axial", "localizer": false},
        {"volume": "dicomweb:pacs/1.2.3/1.2.3.4#stack=2", "slices": 1, "rows": 256, "columns": 256,
         "orientation": "coronal", "localizer": true}])"));
    EXPECT_TRUE(parseServerMessage(text) == ServerMessage(error)) << text;
    // A stack without the field a client needs to open it is not a protocol message.
    json broken = json::parse(text);
    broken["stacks"][1].erase("volume");
    EXPECT_THROW(parseServerMessage(broken.dump()), DecodeError);
}

TEST(ServerMessages, EveryTypeIsCovered) {
    std::vector<bool> seen(std::variant_size_v<ServerMessage>, false);
    for (const ServerMessage &message : everyMessage()) seen[message.index()] = true;
    for (size_t i = 0; i < seen.size(); ++i) EXPECT_TRUE(seen[i]) << "variant alternative " << i;
}

TEST(ServerMessages, ErrorMessageForm) {
    const json j = json::parse(toJsonText(
        ProtocolError{ErrorCode::BadField, "camera: must be a JSON object, got an integer", 7, "camera"}));
    EXPECT_EQ(j, json::parse(R"({"type": "error", "code": "bad_field", "id": 7, "request_type": "camera",
                                 "message": "camera: must be a JSON object, got an integer"})"));
    EXPECT_FALSE(j.contains("stacks")) << "an error without stacks to offer sends none";
    // An error answering an unreadable request has null id and request_type.
    const json unreadable = json::parse(toJsonText(ProtocolError{ErrorCode::MalformedJson, "x", nullptr, ""}));
    EXPECT_TRUE(unreadable.at("id").is_null());
    EXPECT_TRUE(unreadable.at("request_type").is_null());
}

TEST(ServerMessages, EveryErrorCodeHasAStableUniqueName) {
    const std::vector<std::pair<ErrorCode, std::string>> names = {
        {ErrorCode::MalformedJson, "malformed_json"}, {ErrorCode::TooLarge, "too_large"},
        {ErrorCode::BadMessage, "bad_message"},       {ErrorCode::UnknownType, "unknown_type"},
        {ErrorCode::BadField, "bad_field"},           {ErrorCode::UnsupportedVersion, "unsupported_version"},
        {ErrorCode::Unauthorized, "unauthorized"},    {ErrorCode::BadState, "bad_state"},
        {ErrorCode::BadVolumeName, "bad_volume_name"}, {ErrorCode::NotFound, "not_found"},
        {ErrorCode::LoadFailed, "load_failed"},       {ErrorCode::Busy, "busy"},
        {ErrorCode::RenderFailed, "render_failed"},   {ErrorCode::Internal, "internal"},
    };
    for (const auto &[code, name] : names) {
        EXPECT_EQ(errorCodeName(code), name);
        EXPECT_EQ(errorCodeFromName(name), code);
        // Each one survives the trip through an error message.
        const ServerMessage back = parseServerMessage(toJsonText(ProtocolError{code, "m", 1, "still"}));
        EXPECT_EQ(std::get<ProtocolError>(back).code, code);
    }
    EXPECT_EQ(errorCodeFromName("no_such_code"), std::nullopt);
}

TEST(ServerMessages, ClientsIgnoreWhatTheyDoNotKnow) {
    // A newer server may add fields and error codes; an older client still reads the rest.
    const ServerMessage m = parseServerMessage(
        R"({"type": "progress", "id": 2, "volume": "bonsai", "stage": "loading", "fraction": 0.5, "eta_ms": 300})");
    EXPECT_EQ(std::get<ProgressMessage>(m).fraction, 0.5);
    const ServerMessage e = parseServerMessage(
        R"({"type": "error", "id": null, "code": "quota_exceeded", "message": "too many frames"})");
    EXPECT_EQ(std::get<ProtocolError>(e).code, ErrorCode::Internal);
    EXPECT_EQ(std::get<ProtocolError>(e).message, "too many frames");
}

TEST(ServerMessages, BrokenServerMessagesThrow) {
    const std::vector<std::pair<std::string, std::string>> cases = {
        {"{", "server message: malformed JSON: "},
        {"[]", "server message: a message must be a JSON object, got an array"},
        {R"({"type": "frame"})", "server message: unknown message type \"frame\""},
        {R"({"id": 1})", "server message: type: is required"},
        {R"({"type": "progress", "volume": "v", "stage": "loading", "fraction": 2})",
         "server message: fraction: must be in [0, 1]"},
        {R"({"type": "progress", "volume": "v", "stage": "dreaming", "fraction": 0})",
         "server message: stage: unknown stage \"dreaming\""},
        {R"({"type": "volumes", "volumes": [{"name": "a", "dims": [1, 2]}]})",
         "server message: volumes[0].dims: must have 3 integers"},
        {R"({"type": "volumes", "volumes": [{"name": "a", "direction": [[1, 0, 0], [0, 1, 0]]}]})",
         "server message: volumes[0].direction: must have 3 rows, got 2"},
        {R"({"type": "volumes", "volumes": [{"name": "a", "direction": [[1, 0, 0], [0, 1], [0, 0, 1]]}]})",
         "server message: volumes[0].direction[1]: must have 3 numbers, got 2"},
        {R"({"type": "state", "scene": {}, "quality_policy": {"mode": "automatic"}})",
         "server message: interacting: is required"},
    };
    for (const auto &[text, message] : cases) {
        try {
            parseServerMessage(text);
            ADD_FAILURE() << "accepted: " << text;
        } catch (const DecodeError &e) {
            EXPECT_TRUE(std::string(e.what()).starts_with(message)) << e.what();
        }
    }
}

} // namespace
} // namespace volcast::protocol
