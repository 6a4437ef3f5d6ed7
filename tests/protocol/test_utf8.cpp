// Client text quoted in the server's answers: always valid UTF-8, never an exception. The
// check of validity is nlohmann's own parser (it refuses ill-formed UTF-8 in strings), not
// the code under test.

#include "protocol/client_messages.hpp"
#include "protocol/server_messages.hpp"
#include "protocol/utf8.hpp"

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include <string>
#include <variant>

namespace volcast::protocol {
namespace {

using json = nlohmann::json;
const std::string kFffd = "\xEF\xBF\xBD";
const std::string kEllipsis = "\xE2\x80\xA6";

// The error the server would send for `text`, as the JSON text it sends. Fails the test if
// the message is accepted or if serialising it throws (what crashed the server).
json answerTo(const std::string &text) {
    const ParsedClientMessage parsed = parseClientMessage(text);
    const auto *error = std::get_if<ProtocolError>(&parsed);
    if (!error) {
        ADD_FAILURE() << "accepted, but should be refused: " << json(quotableText(text)).dump();
        return {};
    }
    EXPECT_TRUE(isValidUtf8(error->message)) << "the error message is not valid UTF-8";
    std::string sent;
    try {
        sent = toJsonText(ServerMessage(*error));
    } catch (const std::exception &e) {
        ADD_FAILURE() << "serialising the answer threw: " << e.what();
        return {};
    }
    try {
        return json::parse(sent);   // throws on ill-formed UTF-8
    } catch (const json::exception &e) {
        ADD_FAILURE() << "the answer is not valid JSON text: " << e.what();
        return {};
    }
}

TEST(Utf8, ValidityFollowsRfc3629) {
    EXPECT_TRUE(isValidUtf8(""));
    EXPECT_TRUE(isValidUtf8("plain ASCII"));
    EXPECT_TRUE(isValidUtf8("\xC3\xA9"));               // é
    EXPECT_TRUE(isValidUtf8("\xE2\x82\xAC"));           // €
    EXPECT_TRUE(isValidUtf8("\xF0\x9F\x98\x80"));       // U+1F600
    EXPECT_TRUE(isValidUtf8("\xF4\x8F\xBF\xBF"));       // U+10FFFF, the last code point
    EXPECT_FALSE(isValidUtf8("\xC3"));                  // cut 2-byte sequence
    EXPECT_FALSE(isValidUtf8("\xE2\x82"));              // cut 3-byte sequence
    EXPECT_FALSE(isValidUtf8("\xA9"));                  // lone continuation byte
    EXPECT_FALSE(isValidUtf8("\xC0\xAF"));              // overlong '/'
    EXPECT_FALSE(isValidUtf8("\xE0\x80\xAF"));          // overlong '/', 3 bytes
    EXPECT_FALSE(isValidUtf8("\xF0\x80\x80\xAF"));      // overlong '/', 4 bytes
    EXPECT_FALSE(isValidUtf8("\xED\xA0\x80"));          // U+D800, a surrogate
    EXPECT_FALSE(isValidUtf8("\xF4\x90\x80\x80"));      // U+110000, beyond Unicode
    EXPECT_FALSE(isValidUtf8("\xFF"));
    EXPECT_FALSE(isValidUtf8("\xFE\xFF"));
}

TEST(Utf8, QuotableTextReplacesEachBadByteAndKeepsGoodText) {
    EXPECT_EQ(quotableText("caf\xC3\xA9"), "caf\xC3\xA9");
    EXPECT_EQ(quotableText("\xC3"), kFffd);
    EXPECT_EQ(quotableText("a\xE2\x82z"), "a" + kFffd + kFffd + "z");
    EXPECT_EQ(quotableText("\xC0\xAF"), kFffd + kFffd);
    EXPECT_EQ(quotableText("\xED\xA0\x80"), kFffd + kFffd + kFffd);
    EXPECT_EQ(quotableText("x\xFFy"), "x" + kFffd + "y");
}

TEST(Utf8, QuotableTextShortensOnlyBetweenCodePoints) {
    std::string e100;
    for (int i = 0; i < 100; ++i) e100 += "\xC3\xA9";   // 200 bytes
    // 7 bytes allow three whole é (6 bytes); the fourth would be cut, so it is left out.
    EXPECT_EQ(quotableText(e100, 7), "\xC3\xA9\xC3\xA9\xC3\xA9" + kEllipsis);
    EXPECT_EQ(quotableText(e100, 200), e100);   // fits: not shortened
    const std::string euros = "\xE2\x82\xAC\xE2\x82\xAC\xE2\x82\xAC";
    for (size_t limit = 0; limit <= euros.size(); ++limit) {
        const std::string q = quotableText(euros, limit);
        EXPECT_TRUE(isValidUtf8(q)) << "limit " << limit;
        EXPECT_LE(q.size(), limit + kEllipsis.size()) << "limit " << limit;
    }
}

// The crash this guards against: the text "é" (2 bytes) made the parser's message quote 0xC3 alone,
// and serialising the error threw type_error 316 outside any catch.
TEST(Utf8, AnswerToALoneEAcuteIsValidAndSaysMalformedJson) {
    const json answer = answerTo("\xC3\xA9");
    EXPECT_EQ(answer.value("code", ""), "malformed_json") << answer.dump();
    EXPECT_NE(answer.value("message", "").find("malformed JSON"), std::string::npos) << answer.dump();
}

TEST(Utf8, AnswersToIllFormedSequencesAreValidAndNameTheProblem) {
    const std::string cases[] = {
        "\xE2\x82",                                   // cut 3-byte sequence, alone
        "{\"type\": \"\xE2\x82\"}",                   // ... inside a string
        "{\"type\": \"hello\", \"id\": 1, \"protocol\": 1, \"client\": \"\xC0\xAF\"}",       // overlong
        "{\"type\": \"hello\", \"id\": 1, \"protocol\": 1, \"client\": \"\xE0\x80\xAF\"}",   // overlong
        "{\"type\": \"\xED\xA0\x80\"}",               // a surrogate
        "{\"type\": \"\xFF\"}",                       // 0xFF
        "\xFF\xFE",
        "{\"\xC3\": 1}",                              // a key cut short
        "\xE2\x82\xAC",                               // a whole € where JSON must start
        "[\"\xF0\x9F\x98\"",                           // a cut 4-byte sequence at the end
    };
    for (const std::string &text : cases) {
        const json answer = answerTo(text);
        EXPECT_EQ(answer.value("code", ""), "malformed_json") << answer.dump();
        EXPECT_NE(answer.value("message", "").find("malformed JSON"), std::string::npos) << answer.dump();
    }
}

TEST(Utf8, LongNonAsciiTextIsQuotedShortenedAtACodePoint) {
    std::string e300;
    for (int i = 0; i < 300; ++i) e300 += "\xC3\xA9";   // 600 bytes

    const json type = answerTo(json{{"type", "x" + e300}, {"id", 1}}.dump());
    EXPECT_EQ(type.value("code", ""), "unknown_type");
    const std::string typeMessage = type.value("message", "");
    EXPECT_NE(typeMessage.find("unknown message type \"x\xC3\xA9"), std::string::npos) << typeMessage;
    EXPECT_NE(typeMessage.find(kEllipsis + "\" (known:"), std::string::npos) << typeMessage;

    const json name = answerTo(json{{"type", "open_volume"}, {"id", 2}, {"name", "x" + e300}}.dump());
    EXPECT_EQ(name.value("code", ""), "bad_volume_name");
    const std::string nameMessage = name.value("message", "");
    EXPECT_NE(nameMessage.find(kEllipsis + "\""), std::string::npos) << nameMessage;
    EXPECT_LT(nameMessage.size(), 400u) << "the 601-byte name is quoted by its start only";

    const json key = answerTo(json{{"type", "hello"}, {"id", 3}, {"protocol", 1}, {"x" + e300, 1}}.dump());
    EXPECT_EQ(key.value("code", ""), "bad_field");
    const std::string keyMessage = key.value("message", "");
    EXPECT_NE(keyMessage.find(kEllipsis + ": unknown field"), std::string::npos) << keyMessage;
}

// A fuzzer found 26 crashes in 14 000 non-ASCII messages and none in 200 000 ASCII
// ones. 20 000 seeded random messages built from JSON pieces and multi-byte characters
// (whole, cut, or invalid), each of which must get an answer that serialises to valid JSON.
TEST(Utf8, RandomNonAsciiMessagesAlwaysGetAValidAnswer) {
    const std::vector<std::string> pieces = {
        "{", "}", "[", "]", ":", ",", "\"", "\"type\"", "\"hello\"", "\"id\"", "\"name\"", "\"open_volume\"",
        "1", "-0.5e3", "true", "null", "\\u00e9", "\\ud800", "\\", " ", "\n",
        "\xC3\xA9", "\xE2\x82\xAC", "\xF0\x9F\x98\x80", "\xC3", "\xE2\x82", "\xF0\x9F", "\xA9", "\xFF", "\xC0\xAF",
        "\xED\xA0\x80", "\xF4\x90\x80\x80"};
    uint64_t state = 0x9E3779B97F4A7C15u;   // xorshift64: the same messages every run
    const auto next = [&] {
        state ^= state << 13;
        state ^= state >> 7;
        state ^= state << 17;
        return state;
    };
    int failures = 0;
    for (int i = 0; i < 20000 && failures < 5; ++i) {
        std::string text;
        const size_t n = 1 + next() % 12;
        for (size_t k = 0; k < n; ++k) text += pieces[next() % pieces.size()];
        const ParsedClientMessage parsed = parseClientMessage(text);
        const auto *error = std::get_if<ProtocolError>(&parsed);
        if (!error) continue;   // by chance a valid request
        try {
            const json answer = json::parse(toJsonText(ServerMessage(*error)));
            if (!answer.contains("code")) ADD_FAILURE() << "an answer without a code: " << answer.dump();
        } catch (const std::exception &e) {
            ++failures;
            ADD_FAILURE() << "message " << json(quotableText(text)).dump() << ": " << e.what();
        }
    }
}

// Second line of defence: a message that quotes raw bytes still serialises.
TEST(Utf8, ServerMessagesWithInvalidBytesSerialiseWithReplacement) {
    const ProtocolError error{ErrorCode::Internal, "bad \xC3 byte", nullptr, ""};
    std::string sent;
    ASSERT_NO_THROW(sent = toJsonText(ServerMessage(error)));
    const json answer = json::parse(sent);
    EXPECT_EQ(answer.at("message"), "bad " + kFffd + " byte");
}

} // namespace
} // namespace volcast::protocol
