#include "protocol/frame.hpp"

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include <cmath>
#include <fstream>
#include <limits>
#include <sstream>
#include <stdexcept>
#include <string>
#include <vector>

namespace volcast::protocol {
namespace {

using json = nlohmann::json;
using Bytes = std::vector<uint8_t>;

// The header that tests/protocol/data/frame_example.hex holds.
FrameHeader exampleHeader() {
    FrameHeader h;
    h.seq = 42;
    h.request = 17;
    h.level = 2;
    h.quality = {{"step", 0.25}, {"interpolation", "cubic"}};
    h.width = 4;
    h.height = 2;
    h.codec = Codec::Png;
    h.renderMs = 12.5;
    h.encodeMs = 1.25;
    h.error = ErrorEstimate{0.0042, "rmse_vs_next_level"};
    h.final = true;
    h.camera = json::parse(
        R"({"eye": [0, 0, 5], "target": [0, 0, 0], "up": [0, 1, 0], "projection": "perspective", "fov_y_deg": 30})");
    return h;
}
const Bytes kExampleImage = {0x89, 'P', 'N', 'G', '\r', '\n', 0x1a, '\n'};

Bytes readHexFile(const std::string &path) {
    std::ifstream in(path);
    EXPECT_TRUE(in) << "cannot open " << path;
    std::string line, digits;
    while (std::getline(in, line)) {
        line = line.substr(0, line.find('#'));
        for (char c : line)
            if (!std::isspace(static_cast<unsigned char>(c))) digits += c;
    }
    Bytes out;
    for (size_t i = 0; i + 1 < digits.size(); i += 2) out.push_back(uint8_t(std::stoi(digits.substr(i, 2), nullptr, 16)));
    return out;
}

std::string decodeErrorOf(const Bytes &message) {
    try {
        decodeFrame(message);
    } catch (const DecodeError &e) {
        return e.what();
    }
    return "(decoded without error)";
}

TEST(Frame, MatchesTheDocumentedBytes) {
    // The same bytes the Python client's tests decode: the two implementations agree.
    const Bytes golden = readHexFile(VOLCAST_PROTOCOL_TEST_DATA "/frame_example.hex");
    ASSERT_EQ(golden.size(), 347u);
    EXPECT_EQ(encodeFrame(exampleHeader(), kExampleImage), golden);
    const DecodedFrame frame = decodeFrame(golden);
    EXPECT_EQ(frame.header, exampleHeader());
    EXPECT_EQ(Bytes(frame.image.begin(), frame.image.end()), kExampleImage);
}

TEST(Frame, LayoutByteByByte) {
    const Bytes image(1000, 0xAB);
    const Bytes message = encodeFrame(exampleHeader(), image);
    // Magic, then the header length little-endian.
    EXPECT_EQ(std::string(message.begin(), message.begin() + 4), "VCF1");
    const uint32_t length = uint32_t(message[4]) | uint32_t(message[5]) << 8 | uint32_t(message[6]) << 16 |
                            uint32_t(message[7]) << 24;
    ASSERT_EQ(message.size(), 8 + length + image.size());
    // The header is one JSON object naming the image's length; the image follows untouched.
    const json header = json::parse(message.begin() + 8, message.begin() + 8 + length);
    EXPECT_EQ(header.at("image_bytes"), 1000);
    EXPECT_EQ(header.at("codec"), "png");
    EXPECT_EQ(Bytes(message.begin() + 8 + length, message.end()), image);
}

TEST(Frame, RoundTripsVariants) {
    FrameHeader interactive;
    interactive.seq = std::numeric_limits<uint64_t>::max();
    interactive.request = "cam-9";
    interactive.width = 65536;
    interactive.height = 1;
    interactive.codec = Codec::Jpeg;
    FrameHeader noRequest = exampleHeader();
    noRequest.request = nullptr;
    noRequest.error = std::nullopt;
    noRequest.camera = nullptr;
    noRequest.final = false;
    FrameHeader limited = exampleHeader();   // a level the automatic policy lowered
    limited.limited = "image scale 0.47 to stay within the server's per-frame limit";
    for (const FrameHeader &h : {interactive, noRequest, exampleHeader(), limited}) {
        for (const Bytes &image : {Bytes{}, Bytes{1, 2, 3}, Bytes(70000, 7)}) {
            const Bytes message = encodeFrame(h, image);
            const DecodedFrame frame = decodeFrame(message);
            EXPECT_EQ(frame.header, h);
            EXPECT_EQ(Bytes(frame.image.begin(), frame.image.end()), image);
        }
    }
}

TEST(Frame, LimitedIsSentOnlyWhenALevelWasLowered) {
    // Absent from the header when nothing was lowered: the documented bytes, and older
    // clients' headers, stay as they were.
    const auto headerOf = [](const FrameHeader &h) {
        const Bytes m = encodeFrame(h, Bytes{});
        const uint32_t n = uint32_t(m[4]) | uint32_t(m[5]) << 8 | uint32_t(m[6]) << 16 | uint32_t(m[7]) << 24;
        return nlohmann::json::parse(std::string(m.begin() + 8, m.begin() + 8 + n));
    };
    EXPECT_FALSE(headerOf(exampleHeader()).contains("limited"));
    FrameHeader h = exampleHeader();
    h.limited = "image scale 0.25, step 4, mip level 2 to stay within the server's per-frame limit";
    EXPECT_EQ(headerOf(h).at("limited"), h.limited);
}

TEST(Frame, EveryTruncationIsRefused) {
    const Bytes message = encodeFrame(exampleHeader(), Bytes(100, 9));
    for (size_t n = 0; n < message.size(); ++n) {
        const Bytes cut(message.begin(), message.begin() + std::ptrdiff_t(n));
        EXPECT_THROW(decodeFrame(cut), DecodeError) << n << " bytes";
    }
    // Each part's truncation has its own message.
    EXPECT_EQ(decodeErrorOf(Bytes(message.begin(), message.begin() + 6)),
              "frame: 6 bytes, shorter than the 8-byte preamble (magic and header length)");
    // (The header is 333 bytes here: "image_bytes":100 is two digits longer than the example's.)
    EXPECT_EQ(decodeErrorOf(Bytes(message.begin(), message.begin() + 50)),
              "frame: header length 333 runs past the message's end (42 bytes follow the preamble); truncated?");
    EXPECT_EQ(decodeErrorOf(Bytes(message.begin(), message.end() - 1)),
              "frame: the header's image_bytes is 100 but 99 bytes follow the header; truncated?");
}

TEST(Frame, GarbledFramesAreRefused) {
    const Bytes good = encodeFrame(exampleHeader(), kExampleImage);

    Bytes magic = good;
    magic[3] = '2';
    EXPECT_EQ(decodeErrorOf(magic), "frame: starts with \"VCF2\", not the magic \"VCF1\"");
    Bytes binaryMagic = good;
    binaryMagic[0] = 0x00;
    EXPECT_EQ(decodeErrorOf(binaryMagic), "frame: starts with \"\\x00CF1\", not the magic \"VCF1\"");

    Bytes hugeLength = good;
    hugeLength[7] = 0x7f;
    EXPECT_TRUE(decodeErrorOf(hugeLength).starts_with("frame: header length 2130706763 is over the limit of 65536"));

    Bytes padded = good;
    padded.push_back(0);
    EXPECT_EQ(decodeErrorOf(padded), "frame: the header's image_bytes is 8 but 9 bytes follow the header");

    Bytes notJson = good;
    notJson[8] = '[';   // the header's opening brace
    EXPECT_TRUE(decodeErrorOf(notJson).starts_with("frame header: malformed JSON: ")) << decodeErrorOf(notJson);
}

// A frame with a hand-written header, to break one field at a time.
Bytes frameWith(const json &header, const Bytes &image = {}) {
    const std::string text = header.dump();
    Bytes out = {'V', 'C', 'F', '1'};
    for (size_t i = 0; i < 4; ++i) out.push_back(uint8_t(text.size() >> (8 * i)));
    out.insert(out.end(), text.begin(), text.end());
    out.insert(out.end(), image.begin(), image.end());
    return out;
}

TEST(Frame, HeaderFieldsAreChecked) {
    const json good = json::parse(R"({"seq": 1, "level": 0, "width": 2, "height": 2, "codec": "jpeg",
                                      "render_ms": 3.5, "encode_ms": 1, "final": false, "image_bytes": 0})");
    EXPECT_NO_THROW(decodeFrame(frameWith(good)));
    // A newer server's extra field is ignored.
    json extra = good;
    extra["gpu_temperature"] = 60;
    EXPECT_NO_THROW(decodeFrame(frameWith(extra)));

    const std::vector<std::pair<std::string, std::string>> cases = {
        {"/seq", "frame header: seq: is required"},
        {"/width", "frame header: width: is required"},
        {"/codec", "frame header: codec: is required"},
        {"/final", "frame header: final: is required"},
        {"/image_bytes", "frame header: image_bytes: is required"},
    };
    for (const auto &[pointer, message] : cases) {
        json missing = good;
        missing.erase(pointer.substr(1));
        EXPECT_EQ(decodeErrorOf(frameWith(missing)), message);
    }
    const auto withField = [&](const char *key, json value) {
        json h = good;
        h[key] = std::move(value);
        return decodeErrorOf(frameWith(h));
    };
    EXPECT_EQ(withField("codec", "webp"), "frame header: codec: unknown codec \"webp\" (known: jpeg, png)");
    EXPECT_EQ(withField("width", 0), "frame header: width: must be an integer in [1, 65536], got 0");
    EXPECT_EQ(withField("seq", -1), "frame header: seq: must be a non-negative integer, got -1");
    EXPECT_EQ(withField("final", "yes"), "frame header: final: must be true or false, got a string");
    EXPECT_EQ(withField("render_ms", "fast"), "frame header: render_ms: must be a number, got a string");
    EXPECT_EQ(withField("error", {{"value", 0.1}}), "frame header: error.method: is required");
    // What the encoder refuses, the decoder refuses too (fuzz_frame found a negative
    // render_ms that decoded but could not be encoded again).
    EXPECT_EQ(withField("render_ms", -2.5), "frame header: render_ms: must not be negative, got -2.5");
    EXPECT_EQ(withField("encode_ms", -1), "frame header: encode_ms: must not be negative, got -1.0");
    EXPECT_EQ(withField("error", {{"value", -0.5}, {"method", "rmse"}}),
              "frame header: error.value: must not be negative, got -0.5");
    EXPECT_EQ(withField("error", {{"value", 0.5}, {"method", ""}}), "frame header: error.method: must not be empty");
    EXPECT_EQ(withField("camera", 3), "frame header: camera: must be a JSON object, got an integer");
    // The view is at least the image: an image is never sent larger than the view it fills.
    EXPECT_EQ(withField("view_width", 1), "frame header: view_width: must be an integer in [2, 65536], got 1");
    EXPECT_EQ(withField("view_height", 65537), "frame header: view_height: must be an integer in [2, 65536], got 65537");
    EXPECT_EQ(withField("view_width", "wide"), "frame header: view_width: must be an integer in [2, 65536], got a string");
    EXPECT_EQ(withField("rest_pass", -1), "frame header: rest_pass: must be an integer in [0, 64], got -1");
    EXPECT_EQ(withField("rest_pass", 65), "frame header: rest_pass: must be an integer in [0, 64], got 65");
    EXPECT_EQ(withField("rest_pass", 1.5), "frame header: rest_pass: must be an integer in [0, 64], got a fractional number");
    EXPECT_EQ(decodeErrorOf(frameWith(json::array())), "frame header: must be a JSON object, got an array");
}

// A level of fewer rays is sent at its own size with the view's beside it; a header without
// the view's size (an older server's, which sent every frame at the view's size) is shown at
// the image's own.
TEST(Frame, TheViewsSizeTravelsBesideTheImagesAndDefaultsToIt) {
    FrameHeader h = exampleHeader();
    h.width = 240;
    h.height = 135;
    h.viewWidth = 960;
    h.viewHeight = 540;
    const DecodedFrame d = decodeFrame(encodeFrame(h, kExampleImage));
    EXPECT_EQ(d.header, h);
    EXPECT_EQ(d.header.shownWidth(), 960);
    EXPECT_EQ(d.header.shownHeight(), 540);
    const DecodedFrame old = decodeFrame(encodeFrame(exampleHeader(), kExampleImage));
    EXPECT_EQ(old.header.viewWidth, 0);
    EXPECT_EQ(old.header.shownWidth(), 4);
    EXPECT_EQ(old.header.shownHeight(), 2);
    const Bytes bytes = encodeFrame(exampleHeader(), kExampleImage);
    const json sent = json::parse(std::string(bytes.begin() + 8, bytes.end() - std::ptrdiff_t(kExampleImage.size())));
    EXPECT_EQ(sent.count("view_width"), 0u) << "a header without a view sends none";
}

// A pass of refinement at rest says which; other frames send no rest_pass at all.
TEST(Frame, APassAtRestSaysItsNumberAndOtherFramesSendNone) {
    FrameHeader h = exampleHeader();
    h.restPass = 3;
    EXPECT_EQ(decodeFrame(encodeFrame(h, kExampleImage)).header, h);
    const Bytes bytes = encodeFrame(exampleHeader(), kExampleImage);
    const json sent = json::parse(std::string(bytes.begin() + 8, bytes.end() - std::ptrdiff_t(kExampleImage.size())));
    EXPECT_EQ(sent.count("rest_pass"), 0u);
    h.restPass = -1;
    EXPECT_THROW(encodeFrame(h, kExampleImage), std::invalid_argument);
}

TEST(Frame, EncoderRefusesHeadersThatCouldNotBeDecoded) {
    const auto refused = [](FrameHeader h) {
        EXPECT_THROW(encodeFrame(h, kExampleImage), std::invalid_argument);
    };
    FrameHeader h = exampleHeader();
    h.width = 0;
    refused(h);
    h = exampleHeader();
    h.viewWidth = 3;   // smaller than the image's 4
    refused(h);
    h = exampleHeader();
    h.viewHeight = 65537;
    refused(h);
    h = exampleHeader();
    h.renderMs = std::nan("");
    refused(h);
    h = exampleHeader();
    h.encodeMs = -1;
    refused(h);
    h = exampleHeader();
    h.error->value = std::numeric_limits<double>::infinity();
    refused(h);
    h = exampleHeader();
    h.error->method.clear();
    refused(h);
    h = exampleHeader();
    h.camera = {{"padding", std::string(kMaxFrameHeaderBytes, 'x')}};
    refused(h);
}

} // namespace
} // namespace volcast::protocol
