#pragma once
// What went wrong talking to a DICOMweb source. Every failure of this library is a
// DicomWebError: its kind says what to tell the user, its message names the source and what
// was wrong (the URL's path, never its query, which may hold a patient's name, and never the
// Authorization value).

#include <stdexcept>
#include <string>
#include <string_view>

namespace volcast::dicomweb {

enum class ErrorKind {
    Unreachable,   // no connection, connection lost, TLS failure, 502/503/504 from a gateway
    Timeout,       // connect or request time limit, or slower than the low-speed limit
    Unauthorized,  // 401
    Forbidden,     // 403
    NotFound,      // 404, or a series with no instances
    BadResponse,   // malformed JSON or multipart, wrong content type, truncated body, other HTTP status
    TooLarge,      // a body past its byte limit
    Cancelled,     // the caller's cancelled() said so
    BadQuery,      // refused before anything was sent: a bad filter, UID, URL or configuration
    Storage,       // the local folder could not be written (retrieveSeries)
};

// "unreachable", "timeout", "unauthorized", ...: for logs and tests.
std::string_view errorKindName(ErrorKind kind);

struct DicomWebError : std::runtime_error {
    DicomWebError(ErrorKind errorKind, const std::string &message)
        : std::runtime_error(message), kind(errorKind) {}
    ErrorKind kind;
};

} // namespace volcast::dicomweb
