#pragma once
// A streaming reader of multipart bodies (RFC 2046, as WADO-RS sends them in
// multipart/related): bytes are fed in chunks of any size as they arrive, each part's headers
// are parsed (bounded), and its data are handed on as they come, never held whole.
//
// Accepted: a preamble before the first delimiter (bounded), transport padding (spaces and
// tabs) after a delimiter, CRLF line ends (a bare LF is taken too), header lines folded with
// leading white space, an epilogue after the closing delimiter (ignored). Refused with
// MultipartError, naming the part (1-based) and what was wrong: a delimiter followed by
// anything but padding and a line end or "--", a header block past its limit or a header line
// without a colon, more parts or a larger part than the limits allow, a preamble past its
// limit, and at finish() a body that ended before its closing delimiter.

#include <cstdint>
#include <functional>
#include <stdexcept>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

namespace volcast::dicomweb {

struct MultipartError : std::runtime_error {
    using std::runtime_error::runtime_error;
};

struct MultipartLimits {
    size_t maxHeaderBytes = 16 << 10;        // one part's header block
    size_t maxPreambleBytes = 64 << 10;      // before the first delimiter
    size_t maxParts = 100000;
    uint64_t maxPartBytes = uint64_t(4) << 30;
};

struct MultipartHeaders {
    std::vector<std::pair<std::string, std::string>> fields;  // names as sent, values trimmed
    // The first field of that name (case-insensitive), or "".
    std::string get(std::string_view name) const;
};

// "Multipart/Related; type=\"application/dicom\"; boundary=abc" → media type
// "multipart/related" (lower case), its parameters (names lower case, values unquoted).
struct ContentType {
    std::string mediaType;
    std::vector<std::pair<std::string, std::string>> parameters;
    std::string parameter(std::string_view name) const;  // "" if absent
};
// Throws MultipartError on a malformed value (no type/subtype, a parameter without '=', an
// unterminated quoted string).
ContentType parseContentType(std::string_view value);

// The boundary of a multipart Content-Type: quoted or not, 1 to 70 characters of RFC 2046's
// set, not ending in a space. Throws MultipartError naming what is wrong.
std::string multipartBoundary(std::string_view contentTypeValue);

class MultipartReader {
  public:
    struct Callbacks {
        std::function<void(const MultipartHeaders &)> partBegin;  // headers parsed
        std::function<void(std::string_view)> partData;           // any number of times
        std::function<void()> partEnd;                             // its delimiter was seen
    };

    MultipartReader(std::string boundary, Callbacks callbacks, MultipartLimits limits = {});

    // Feed the next bytes. Callbacks run from inside; an exception (theirs or MultipartError)
    // leaves the reader failed: every later call throws MultipartError.
    void feed(std::string_view chunk);
    // The body has ended: throws MultipartError unless the closing delimiter was seen.
    void finish();

    size_t partsBegun() const { return partsBegun_; }
    size_t partsEnded() const { return partsEnded_; }
    bool closed() const { return state_ == State::Epilogue; }

  private:
    enum class State { Preamble, AfterDelimiter, Headers, Data, Epilogue, Failed };
    void run();
    bool stepPreamble();
    bool stepAfterDelimiter();
    bool stepHeaders();
    bool stepData();
    [[noreturn]] void fail(const std::string &what);
    std::string partName() const;

    std::string boundary_;
    std::string delimiter_;   // "\r\n--" + boundary
    Callbacks callbacks_;
    MultipartLimits limits_;
    State state_ = State::Preamble;
    std::string buffer_;      // bytes fed but not yet consumed
    size_t scanned_ = 0;      // of buffer_, already searched without a match (headers)
    size_t preambleBytes_ = 0;
    size_t partsBegun_ = 0;
    size_t partsEnded_ = 0;
    uint64_t partBytes_ = 0;
};

} // namespace volcast::dicomweb
