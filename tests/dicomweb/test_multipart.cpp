// The streaming multipart reader on its own: the same parts whatever the chunk sizes, the
// boundary rules of RFC 2046, and every way a body can be malformed or cut short.

#include "dicomweb/multipart.hpp"

#include <gtest/gtest.h>

#include <string>
#include <vector>

using namespace volcast::dicomweb;

namespace {

struct Part {
    std::vector<std::pair<std::string, std::string>> headers;
    std::string data;
    bool ended = false;
    bool operator==(const Part &) const = default;
};

// Everything the reader reported, parts in order.
struct Recorder {
    std::vector<Part> parts;
    MultipartReader::Callbacks callbacks() {
        MultipartReader::Callbacks c;
        c.partBegin = [this](const MultipartHeaders &h) { parts.push_back({h.fields, {}, false}); };
        c.partData = [this](std::string_view d) { parts.back().data.append(d); };
        c.partEnd = [this] { parts.back().ended = true; };
        return c;
    }
};

// Feeds `body` in chunks of `chunk` bytes, then finishes.
std::vector<Part> readAll(const std::string &boundary, const std::string &body, size_t chunk, MultipartLimits limits = {}) {
    Recorder recorder;
    MultipartReader reader(boundary, recorder.callbacks(), limits);
    for (size_t i = 0; i < body.size(); i += chunk) reader.feed(std::string_view(body).substr(i, chunk));
    reader.finish();
    return recorder.parts;
}

// The message of the MultipartError that reading `body` throws, or "" when none is thrown.
std::string errorOf(const std::string &boundary, const std::string &body, size_t chunk = 7, MultipartLimits limits = {}) {
    try {
        readAll(boundary, body, chunk, limits);
    } catch (const MultipartError &e) {
        return e.what();
    }
    return {};
}

// Two DICOM-like parts whose data hold CR, LF, dashes and most of the boundary, as binary
// pixel data may.
const std::string kBoundary = "c3a1-boundary";
const std::string kPart1 = std::string("DICM\r\n--c3a1-boundar\0\xff\r\n", 24);
const std::string kPart2 = "\r\n\r\n-c3a1-boundary\r\n--c3a1-boundar\n--c3a1-boundary";
const std::string kBody = "--c3a1-boundary\r\nContent-Type: application/dicom\r\nContent-Length: 24\r\n\r\n" + kPart1 +
                          "\r\n--c3a1-boundary\r\nContent-Type: application/dicom\r\n\r\n" + kPart2 +
                          "\r\n--c3a1-boundary--\r\n";

} // namespace

TEST(DicomWebMultipart, EveryChunkSizeGivesTheSameParts) {
    const std::vector<Part> whole = readAll(kBoundary, kBody, kBody.size());
    ASSERT_EQ(whole.size(), 2u);
    EXPECT_EQ(whole[0].data, kPart1);
    EXPECT_EQ(whole[1].data, kPart2);
    EXPECT_TRUE(whole[0].ended && whole[1].ended);
    ASSERT_EQ(whole[0].headers.size(), 2u);
    EXPECT_EQ(whole[0].headers[0], (std::pair<std::string, std::string>{"Content-Type", "application/dicom"}));
    // Every chunk size from 1 byte up to the whole body: each splits delimiters, header lines
    // and CRLFs somewhere else.
    for (size_t chunk = 1; chunk <= kBody.size(); ++chunk)
        ASSERT_EQ(readAll(kBoundary, kBody, chunk), whole) << "chunks of " << chunk << " bytes";
}

TEST(DicomWebMultipart, DelimiterSplitAtEveryPositionBetweenTwoFeeds) {
    const std::vector<Part> whole = readAll(kBoundary, kBody, kBody.size());
    for (size_t cut = 0; cut <= kBody.size(); ++cut) {
        Recorder recorder;
        MultipartReader reader(kBoundary, recorder.callbacks());
        reader.feed(std::string_view(kBody).substr(0, cut));
        reader.feed(std::string_view(kBody).substr(cut));
        reader.finish();
        ASSERT_EQ(recorder.parts, whole) << "cut at byte " << cut;
    }
}

TEST(DicomWebMultipart, PreambleAndEpilogueAreIgnored) {
    const std::string body = "This is the preamble.\r\nIt is to be ignored.\r\n" + kBody +
                             "This is the epilogue. --c3a1-boundary\r\nContent-Type: x/y\r\n\r\nnot a part";
    const auto parts = readAll(kBoundary, body, 5);
    ASSERT_EQ(parts.size(), 2u);
    EXPECT_EQ(parts[1].data, kPart2);
}

TEST(DicomWebMultipart, TransportPaddingAndBareLineFeedsAfterTheDelimiterAreAccepted) {
    const std::string body = "--b \t\r\nContent-Type: a/b\n\nxy\r\n--b\t\nContent-Type: a/b\r\n\r\nz\r\n--b--";
    const auto parts = readAll("b", body, 3);
    ASSERT_EQ(parts.size(), 2u);
    EXPECT_EQ(parts[0].data, "xy");
    EXPECT_EQ(parts[1].data, "z");
}

TEST(DicomWebMultipart, FoldedHeaderLinesAreJoined) {
    const std::string body = "--b\r\nContent-Type: application/dicom;\r\n transfer-syntax=1.2.840.10008.1.2.1\r\n\r\nx\r\n--b--";
    const auto parts = readAll("b", body, 4);
    ASSERT_EQ(parts.size(), 1u);
    EXPECT_EQ(parts[0].headers.at(0).second, "application/dicom; transfer-syntax=1.2.840.10008.1.2.1");
}

TEST(DicomWebMultipart, APartWithoutHeadersOrContentTypeIsReadAndItsTypeIsEmpty) {
    // The reader reports the part; refusing it is the DICOMweb client's job (it needs
    // application/dicom).
    std::string type = "unset";
    std::string data;
    MultipartReader::Callbacks callbacks;
    callbacks.partBegin = [&](const MultipartHeaders &h) { type = h.get("content-type"); };
    callbacks.partData = [&](std::string_view d) { data.append(d); };
    MultipartReader reader("b", callbacks);
    reader.feed("--b\r\n\r\nno headers\r\n--b--\r\n");
    reader.finish();
    EXPECT_EQ(type, "");
    EXPECT_EQ(data, "no headers");
}

TEST(DicomWebMultipart, BodyWithoutClosingDelimiterFailsAtFinishNamingThePart) {
    // Cut inside part 2's data: the part is cut short.
    const std::string cut = kBody.substr(0, kBody.find(kPart2) + 10);
    const std::string inData = errorOf(kBoundary, cut);
    EXPECT_NE(inData.find("inside part 2"), std::string::npos) << inData;
    // Everything but the closing "--": a delimiter that never closes.
    const std::string noClose = kBody.substr(0, kBody.rfind("--\r\n"));
    EXPECT_NE(errorOf(kBoundary, noClose).find("without its closing delimiter"), std::string::npos) << errorOf(kBoundary, noClose);
    // Inside the headers of part 2.
    const std::string inHeaders = kBody.substr(0, kBody.find("Content-Type", 20) + 5);
    EXPECT_NE(errorOf(kBoundary, inHeaders).find("headers of part 2"), std::string::npos) << errorOf(kBoundary, inHeaders);
    // No delimiter at all.
    EXPECT_NE(errorOf(kBoundary, "just text").find("before its first delimiter"), std::string::npos);
    EXPECT_NE(errorOf(kBoundary, "").find("before its first delimiter"), std::string::npos);
}

TEST(DicomWebMultipart, OverlongHeadersAreRefused) {
    MultipartLimits limits;
    limits.maxHeaderBytes = 1024;
    const std::string longLine = "--b\r\nX-Long: " + std::string(2000, 'a') + "\r\n\r\ndata\r\n--b--";
    EXPECT_NE(errorOf("b", longLine, 7, limits).find("longer than 1024 bytes"), std::string::npos) << errorOf("b", longLine, 7, limits);
    std::string manyLines = "--b\r\n";
    for (int i = 0; i < 200; ++i) manyLines += "X-Field: value\r\n";
    manyLines += "\r\ndata\r\n--b--";
    EXPECT_NE(errorOf("b", manyLines, 1, limits).find("longer than 1024 bytes"), std::string::npos);
    EXPECT_NE(errorOf("b", manyLines, manyLines.size(), limits).find("longer than 1024 bytes"), std::string::npos);
}

TEST(DicomWebMultipart, HeadersEndingExactlyAtTheLimitPassWhateverTheChunks) {
    // "X: 0123456789abcd\r\n" is 19 bytes, the limit; the blank line after it does not count,
    // even when its CR arrives alone at the end of a chunk (found by fuzz_multipart).
    MultipartLimits limits;
    limits.maxHeaderBytes = 19;
    const std::string body = "--b\r\nX: 0123456789abcd\r\n\r\nz\r\n--b--";
    for (size_t chunk = 1; chunk <= body.size(); ++chunk)
        EXPECT_EQ(errorOf("b", body, chunk, limits), "") << "chunks of " << chunk;
    limits.maxHeaderBytes = 18;
    for (size_t chunk = 1; chunk <= body.size(); ++chunk)
        EXPECT_NE(errorOf("b", body, chunk, limits), "") << "chunks of " << chunk;
}

TEST(DicomWebMultipart, MalformedHeaderLinesAndDelimitersAreRefused) {
    EXPECT_NE(errorOf("b", "--b\r\nno colon here\r\n\r\nx\r\n--b--").find("not 'Name: value'"), std::string::npos);
    EXPECT_NE(errorOf("b", "--b\r\n continued: x\r\n\r\nx\r\n--b--").find("continuation line"), std::string::npos);
    EXPECT_NE(errorOf("b", "--bX\r\n\r\nx\r\n--b--").find("not a line end"), std::string::npos);
    EXPECT_NE(errorOf("b", "--b\r\n\r\nx\r\n--b\rX").find("lone CR"), std::string::npos);
}

TEST(DicomWebMultipart, PartAndPartCountLimitsAreEnforced) {
    MultipartLimits limits;
    limits.maxPartBytes = 10;
    EXPECT_NE(errorOf("b", "--b\r\n\r\n0123456789A\r\n--b--", 3, limits).find("larger than 10 bytes"), std::string::npos);
    EXPECT_EQ(errorOf("b", "--b\r\n\r\n0123456789\r\n--b--", 3, limits), "");
    limits = {};
    limits.maxParts = 2;
    EXPECT_EQ(errorOf("b", "--b\r\n\r\n1\r\n--b\r\n\r\n2\r\n--b--", 3, limits), "");
    EXPECT_NE(errorOf("b", "--b\r\n\r\n1\r\n--b\r\n\r\n2\r\n--b\r\n\r\n3\r\n--b--", 3, limits).find("more than 2 parts"),
              std::string::npos);
    limits = {};
    limits.maxPreambleBytes = 100;
    EXPECT_NE(errorOf("b", std::string(1000, 'p') + "\r\n--b\r\n\r\nx\r\n--b--", 9, limits).find("no delimiter"), std::string::npos);
}

TEST(DicomWebMultipart, AnErrorLeavesTheReaderFailed) {
    MultipartReader reader("b", {});
    EXPECT_THROW(reader.feed("--bX"), MultipartError);
    EXPECT_THROW(reader.feed("\r\n\r\nx\r\n--b--"), MultipartError);
    EXPECT_THROW(reader.finish(), MultipartError);
}

TEST(DicomWebMultipart, BoundaryIsReadFromTheContentTypeQuotedOrNot) {
    EXPECT_EQ(multipartBoundary("multipart/related; type=\"application/dicom\"; boundary=abc-123"), "abc-123");
    EXPECT_EQ(multipartBoundary("Multipart/Related;boundary=\"a b:c\";type=application/dicom"), "a b:c");
    EXPECT_EQ(multipartBoundary("multipart/related; BOUNDARY = \"q\\?x\""), "q?x") << "a quoted pair keeps its character";
}

TEST(DicomWebMultipart, BoundaryOutsideRfc2046IsRefused) {
    const auto error = [](const std::string &type) -> std::string {
        try {
            multipartBoundary(type);
        } catch (const MultipartError &e) {
            return e.what();
        }
        return {};
    };
    EXPECT_NE(error("multipart/related").find("no boundary"), std::string::npos);
    EXPECT_NE(error("multipart/related; boundary=\"\"").find("1 to 70"), std::string::npos);
    EXPECT_NE(error("multipart/related; boundary=" + std::string(71, 'a')).find("1 to 70"), std::string::npos);
    EXPECT_EQ(error("multipart/related; boundary=" + std::string(70, 'a')), "");
    EXPECT_NE(error("multipart/related; boundary=\"ab \"").find("ends in a space"), std::string::npos);
    EXPECT_NE(error("multipart/related; boundary=a{b").find("does not allow"), std::string::npos);
    EXPECT_NE(error("multipart/related; boundary=\"unterminated").find("unterminated"), std::string::npos);
    EXPECT_NE(error("application/dicom; boundary=x").find("not multipart"), std::string::npos);
    EXPECT_NE(error("no-slash; boundary=x").find("type/subtype"), std::string::npos);
    EXPECT_NE(error("multipart/related; boundary").find("no '='"), std::string::npos);
}
