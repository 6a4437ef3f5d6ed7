// protocol/README.md's worked example session is documentation the tests hold to: every
// client line must parse (or be refused exactly as the next server line says), every server
// line and frame header must decode, and between them every message type must appear.

#include "protocol/protocol.hpp"

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include <fstream>
#include <set>
#include <string>
#include <vector>

namespace volcast::protocol {
namespace {

using json = nlohmann::json;

std::vector<std::string> exampleLines() {
    std::ifstream in(VOLCAST_PROTOCOL_README);
    EXPECT_TRUE(in) << "cannot open " << VOLCAST_PROTOCOL_README;
    std::vector<std::string> lines;
    bool inside = false;
    for (std::string line; std::getline(in, line);) {
        if (line == "<!-- example-session:begin -->") inside = true;
        else if (line == "<!-- example-session:end -->") inside = false;
        else if (inside && (line.starts_with("C: ") || line.starts_with("S: "))) lines.push_back(line);
    }
    return lines;
}

// A frame message around a header written by hand, with image_bytes zero bytes of image.
std::vector<uint8_t> frameAround(const std::string &headerText) {
    const size_t imageBytes = json::parse(headerText).at("image_bytes").get<size_t>();
    std::vector<uint8_t> out = {'V', 'C', 'F', '1'};
    for (size_t i = 0; i < 4; ++i) out.push_back(uint8_t(headerText.size() >> (8 * i)));
    out.insert(out.end(), headerText.begin(), headerText.end());
    out.resize(out.size() + imageBytes, 0);
    return out;
}

TEST(ReadmeExample, EveryLineIsTheProtocol) {
    const std::vector<std::string> lines = exampleLines();
    ASSERT_GT(lines.size(), 30u);
    std::set<std::string> clientTypes, serverTypes;
    for (size_t i = 0; i < lines.size(); ++i) {
        const std::string &line = lines[i];
        SCOPED_TRACE(line);
        const std::string text = line.substr(3);
        if (line.starts_with("C: ")) {
            const ParsedClientMessage parsed = parseClientMessage(text);
            if (const auto *message = std::get_if<ClientMessage>(&parsed)) {
                clientTypes.insert(std::string(messageType(*message)));
                continue;
            }
            // A refusal: the next line is the server's error, and it is the parser's own.
            const ProtocolError &error = std::get<ProtocolError>(parsed);
            ASSERT_LT(i + 1, lines.size());
            ASSERT_TRUE(lines[i + 1].starts_with("S: {")) << "no error line after a refused request";
            const ServerMessage answer = parseServerMessage(lines[i + 1].substr(3));
            ASSERT_TRUE(std::holds_alternative<ProtocolError>(answer));
            EXPECT_EQ(std::get<ProtocolError>(answer), error) << toJsonText(error);
        } else if (text.starts_with("frame ")) {
            const std::vector<uint8_t> bytes = frameAround(text.substr(6));   // frame.image points into it
            const DecodedFrame frame = decodeFrame(bytes);
            // The header says exactly what encodeFrame would write for it.
            const std::vector<uint8_t> again = encodeFrame(frame.header, frame.image);
            EXPECT_EQ(decodeFrame(again).header, frame.header);
            serverTypes.insert("frame");
        } else {
            const ServerMessage message = parseServerMessage(text);
            // Nothing is lost between the text and the structs.
            EXPECT_EQ(json::parse(toJsonText(message)), json::parse(text));
            serverTypes.insert(std::string(messageType(message)));
        }
    }
    for (const char *type : {"hello", "list_volumes", "open_volume", "camera", "interaction_start",
                             "interaction_end", "viewport", "transfer_function", "quality_policy",
                             "clip_planes", "still", "get_state", "close"})
        EXPECT_TRUE(clientTypes.contains(type)) << "the example never sends " << type;
    for (const char *type : {"hello", "volumes", "progress", "state", "error", "frame"})
        EXPECT_TRUE(serverTypes.contains(type)) << "the example never shows " << type;
}

} // namespace
} // namespace volcast::protocol
