// The slice request and the slice message (protocol/slice.hpp): every field read and
// written back, every bad field refused by name, and the VCS1 message decoded and refused
// when damaged.

#include "protocol/client_messages.hpp"
#include "protocol/frame.hpp"
#include "protocol/slice.hpp"

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include <string>
#include <variant>
#include <vector>

namespace volcast::protocol {
namespace {

using json = nlohmann::json;

TEST(SliceRequest, ReadsEveryFieldAndWritesItBack) {
    const std::string text =
        R"({"type": "slice", "id": 7, "axis": "coronal", "point": [1, 2.5, -3], "center": [0, 0, 0],
            "width": 256, "height": 128, "pixel_spacing": 0.5, "window": 400, "level": 40})";
    const ParsedClientMessage parsed = parseClientMessage(text);
    ASSERT_TRUE(std::holds_alternative<ClientMessage>(parsed)) << std::get<ProtocolError>(parsed).message;
    const auto &m = std::get<SliceRequest>(std::get<ClientMessage>(parsed));
    EXPECT_EQ(m.id, 7);
    EXPECT_EQ(m.axis, "coronal");
    EXPECT_EQ(m.point, (std::array<double, 3>{1, 2.5, -3}));
    EXPECT_EQ(m.center, (std::array<double, 3>{0, 0, 0}));
    EXPECT_EQ(m.width, 256);
    EXPECT_EQ(m.height, 128);
    EXPECT_EQ(m.pixelSpacing, 0.5);
    EXPECT_EQ(m.window, 400);
    EXPECT_EQ(m.level, 40);
    const ParsedClientMessage again = parseClientMessage(toJsonText(m));
    ASSERT_TRUE(std::holds_alternative<ClientMessage>(again));
    EXPECT_EQ(std::get<SliceRequest>(std::get<ClientMessage>(again)), m);

    // Only axis, width and height are required; the rest stay unset (server defaults).
    const ParsedClientMessage minimal = parseClientMessage(R"({"type": "slice", "axis": "axial", "width": 1, "height": 1})");
    ASSERT_TRUE(std::holds_alternative<ClientMessage>(minimal));
    const auto &min = std::get<SliceRequest>(std::get<ClientMessage>(minimal));
    EXPECT_FALSE(min.point || min.center || min.pixelSpacing || min.window || min.level);
}

TEST(SliceRequest, BadFieldsAreRefusedByName) {
    const std::string base = R"("type": "slice", "id": "s1", )";
    const std::vector<std::pair<std::string, std::string>> cases = {
        {R"("width": 4, "height": 4)", "axis: is required"},
        {R"("axis": "transverse", "width": 4, "height": 4)", "axis: must be \"axial\", \"coronal\" or \"sagittal\", got \"transverse\""},
        {R"("axis": "axial", "height": 4)", "width: is required"},
        {R"("axis": "axial", "width": 0, "height": 4)", "width: must be an integer in [1, 16384], got 0"},
        {R"("axis": "axial", "width": 4, "height": 100000)", "height: must be an integer in [1, 16384], got 100000"},
        {R"("axis": "axial", "width": 4.5, "height": 4)", "width: must be an integer in [1, 16384], got a fractional number"},
        {R"("axis": "axial", "width": 4, "height": 4, "point": [1, 2])", "point: must have 3 numbers, got 2"},
        {R"("axis": "axial", "width": 4, "height": 4, "point": [1, "2", 3])", "point[1]: must be a number, got a string"},
        {R"("axis": "axial", "width": 4, "height": 4, "center": {})", "center: must be an array, got a JSON object"},
        {R"("axis": "axial", "width": 4, "height": 4, "pixel_spacing": 0)", "pixel_spacing: must be > 0, got 0"},
        {R"("axis": "axial", "width": 4, "height": 4, "window": -5)", "window: must be > 0, got -5"},
        {R"("axis": "axial", "width": 4, "height": 4, "level": "high")", "level: must be a number, got a string"},
        {R"("axis": "axial", "width": 4, "height": 4, "zoom": 2)", "zoom: unknown field"},
    };
    for (const auto &[fields, expected] : cases) {
        const ParsedClientMessage parsed = parseClientMessage("{" + base + fields + "}");
        ASSERT_TRUE(std::holds_alternative<ProtocolError>(parsed)) << "accepted: " << fields;
        const ProtocolError &e = std::get<ProtocolError>(parsed);
        EXPECT_EQ(e.code, ErrorCode::BadField) << fields;
        EXPECT_EQ(e.requestId, "s1");
        EXPECT_EQ(e.requestType, "slice");
        EXPECT_EQ(e.message.substr(0, expected.size()), expected) << "full message: " << e.message;
    }
}

SliceHeader exampleHeader() {
    SliceHeader h;
    h.request = 12;
    h.axis = "sagittal";
    h.width = 3;
    h.height = 2;
    h.pixelSpacing = 0.75;
    h.origin = {1, 2, 3};
    h.column = {0, 1, 0};
    h.row = {0, 0, -1};
    h.point = {4, 5, 6};
    h.window = 2000;
    h.level = 400;
    h.renderMs = 1.5;
    return h;
}

TEST(SliceMessage, RoundTripsAndIsNotAFrame) {
    const std::vector<uint8_t> pixels{0, 10, 20, 30, 40, 255};
    const std::vector<uint8_t> bytes = encodeSlice(exampleHeader(), pixels);
    EXPECT_TRUE(isSliceMessage(bytes));
    const DecodedSlice d = decodeSlice(bytes);
    EXPECT_EQ(d.header, exampleHeader());
    EXPECT_EQ(std::vector<uint8_t>(d.pixels.begin(), d.pixels.end()), pixels);
    // An older client decoding it as a frame gets a clear refusal, not a picture.
    EXPECT_THROW(decodeFrame(bytes), DecodeError);
}

TEST(SliceMessage, EchoesTheSlabWithItsPlanes) {
    SliceHeader h = exampleHeader();
    h.slab = SliceSlab{10, "mean"};
    h.slabPlanes = 41;
    const std::vector<uint8_t> pixels(6, 7);
    const std::vector<uint8_t> bytes = encodeSlice(h, pixels);
    EXPECT_EQ(decodeSlice(bytes).header, h);
    const std::string text(bytes.begin() + 8, bytes.end() - 6);
    EXPECT_EQ(json::parse(text).at("slab"), (json{{"thickness", 10}, {"mode", "mean"}, {"planes", 41}}));
    // A plain slice's header has no slab.
    const std::vector<uint8_t> plain = encodeSlice(exampleHeader(), pixels);
    EXPECT_FALSE(json::parse(std::string(plain.begin() + 8, plain.end() - 6)).contains("slab"));
}

TEST(SliceMessage, DamagedMessagesAreRefusedNamingTheProblem) {
    const std::vector<uint8_t> pixels(6, 1);
    std::vector<uint8_t> bytes = encodeSlice(exampleHeader(), pixels);
    const auto message = [](const std::vector<uint8_t> &b) {
        try {
            decodeSlice(b);
        } catch (const DecodeError &e) {
            return std::string(e.what());
        }
        return std::string("(accepted)");
    };
    std::vector<uint8_t> truncated(bytes.begin(), bytes.end() - 1);
    EXPECT_NE(message(truncated).find("5 pixel bytes"), std::string::npos) << message(truncated);
    std::vector<uint8_t> badMagic = bytes;
    badMagic[2] = 'F';
    EXPECT_NE(message(badMagic).find("VCS1"), std::string::npos) << message(badMagic);
    EXPECT_NE(message({'V', 'C', 'S', '1'}).find("shorter"), std::string::npos);
    // Header fields are checked on encode too.
    EXPECT_THROW(encodeSlice(exampleHeader(), std::vector<uint8_t>(5)), std::invalid_argument);
    SliceHeader nan = exampleHeader();
    nan.level = std::nan("");
    EXPECT_THROW(encodeSlice(nan, pixels), std::invalid_argument);
}

} // namespace
} // namespace volcast::protocol
