// The DICOMweb multipart reader (dicomweb/multipart.hpp) on a hostile body.
// Input: byte 0 picks the chunk size (1..255 bytes, 0: the whole body at once); then a
// Content-Type line up to the first LF, from which the boundary is read as the client reads
// it; the rest is the body. Small limits, so that every limit is reached.
// Invariants: only MultipartError escapes, with a message; the same parts come out whatever
// the chunk size (compared with the body fed whole); callbacks are well ordered (data only
// inside a part, every end after its begin); counts and sizes stay within the limits; a
// finished body has every part ended.

#include "dicomweb/multipart.hpp"
#include "fuzz/fuzz_check.hpp"

#include <cstddef>
#include <cstdint>
#include <string>
#include <string_view>
#include <vector>

using namespace volcast::dicomweb;
using volcast::fuzz::check;

namespace {

struct Part {
    std::vector<std::pair<std::string, std::string>> headers;
    std::string data;
    bool ended = false;
    bool operator==(const Part &) const = default;
};

struct Outcome {
    std::vector<Part> parts;
    bool finished = false;
    std::string error;
    bool operator==(const Outcome &o) const { return parts == o.parts && finished == o.finished; }
};

MultipartLimits limits() {
    MultipartLimits l;
    l.maxHeaderBytes = 256;
    l.maxPreambleBytes = 1024;
    l.maxParts = 16;
    l.maxPartBytes = 4096;
    return l;
}

Outcome read(const std::string &boundary, std::string_view body, size_t chunk) {
    Outcome out;
    bool inPart = false;
    MultipartReader::Callbacks callbacks;
    callbacks.partBegin = [&](const MultipartHeaders &headers) {
        check(!inPart, "a part began inside another");
        inPart = true;
        out.parts.push_back({headers.fields, {}, false});
        // The client reads each part's type this way; it must throw nothing but MultipartError.
        try {
            const ContentType type = parseContentType(headers.get("Content-Type"));
            check(!type.mediaType.empty() && type.mediaType.find('/') != std::string::npos, "media type without '/'");
        } catch (const MultipartError &e) {
            check(*e.what() != 0, "empty content type error");
        }
    };
    callbacks.partData = [&](std::string_view data) {
        check(inPart, "data outside a part");
        check(!data.empty(), "empty data callback");
        out.parts.back().data.append(data);
        check(out.parts.back().data.size() <= limits().maxPartBytes, "a part past maxPartBytes");
    };
    callbacks.partEnd = [&] {
        check(inPart, "a part ended that never began");
        inPart = false;
        out.parts.back().ended = true;
    };
    MultipartReader reader(boundary, callbacks, limits());
    try {
        for (size_t i = 0; i < body.size(); i += chunk) reader.feed(body.substr(i, chunk));
        reader.finish();
        out.finished = true;
        check(reader.closed(), "finished without the closing delimiter");
        check(!inPart && reader.partsBegun() == reader.partsEnded(), "finished inside a part");
    } catch (const MultipartError &e) {
        out.error = e.what();
        check(!out.error.empty(), "empty multipart error");
    }
    check(reader.partsBegun() <= limits().maxParts, "more parts than maxParts");
    // partsBegun counts delimiters passed: a part refused in its headers was never reported.
    check(reader.partsBegun() == out.parts.size() || (!out.error.empty() && reader.partsBegun() == out.parts.size() + 1),
          "partsBegun differs from the parts reported");
    for (const Part &p : out.parts)
        for (const auto &[name, value] : p.headers) check(!name.empty(), "a header without a name");
    return out;
}

} // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size) {
    if (size < 1) return 0;
    const size_t chunkByte = data[0];
    const std::string_view rest(reinterpret_cast<const char *>(data + 1), size - 1);
    const size_t lineEnd = rest.find('\n');
    if (lineEnd == std::string_view::npos) return 0;
    std::string boundary;
    try {
        boundary = multipartBoundary(rest.substr(0, lineEnd));
    } catch (const MultipartError &e) {
        check(*e.what() != 0, "empty boundary error");
        return 0;
    }
    check(!boundary.empty() && boundary.size() <= 70, "boundary outside 1..70 characters", boundary);
    const std::string_view body = rest.substr(lineEnd + 1);
    const Outcome whole = read(boundary, body, body.size() + 1);
    if (chunkByte != 0) {
        const Outcome chunked = read(boundary, body, chunkByte);
        // A refusal may come at a different part's byte when a limit and a malformed byte are
        // both in the body, so only the parts completed before either refusal are compared.
        if (whole.finished || chunked.finished) {
            check(whole == chunked, "chunked feeding gave other parts than the whole body");
        } else {
            const size_t n = std::min(whole.parts.size(), chunked.parts.size());
            for (size_t i = 0; i + 1 < n; ++i) check(whole.parts[i] == chunked.parts[i], "a completed part differs by chunking");
        }
    }
    return 0;
}
