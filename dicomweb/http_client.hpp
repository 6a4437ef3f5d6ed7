#pragma once
// HTTP for DICOMweb through libcurl: TLS verified against the system's CA store, http and
// https only, timeouts on connect, on the whole request and on a stalled transfer, every body
// bounded, redirects followed by hand only to the same scheme, host and port (at most
// HttpOptions::maxRedirects). Failures are DicomWebError: the message names the source and the
// URL's path (never its query), and every one leaves through the source's CredentialScrubber,
// so that no form of the Authorization value a server echoes back is quoted.
//
// One HttpClient holds one curl handle, so consecutive requests reuse the connection; it is
// not shared between threads (make one per thread or per call).

#include "dicomweb/credential_scrubber.hpp"
#include "dicomweb/errors.hpp"

#include <cstdint>
#include <functional>
#include <memory>
#include <string>
#include <string_view>

namespace volcast::dicomweb {

struct HttpOptions {
    std::string sourceName;      // for messages: "DICOMweb source 'NAME'"
    std::string authorization;   // "" or the Authorization header's value; never logged
    double connectTimeoutSeconds = 5;
    double requestTimeoutSeconds = 30;  // the whole request; 0: no limit (use the low-speed limit)
    double lowSpeedSeconds = 15;        // fails if slower than lowSpeedBytesPerSecond this long; 0: off
    long lowSpeedBytesPerSecond = 1024;
    int maxRedirects = 3;
};

struct HttpResponse {
    long status = 0;
    std::string contentType;   // as the server sent it, parameters included; "" if none
    std::string body;
};

// A streamed response's head, given before its first body byte.
struct ResponseHead {
    long status = 0;
    std::string contentType;
    int64_t contentLength = -1;  // -1: not announced (chunked)
};

class HttpClient {
  public:
    explicit HttpClient(HttpOptions options);
    ~HttpClient();
    HttpClient(const HttpClient &) = delete;
    HttpClient &operator=(const HttpClient &) = delete;

    // GET `url` with `accept`; the body is kept up to maxBodyBytes (past it: TooLarge).
    // 401, 403, 404 and other non-2xx statuses throw their ErrorKind.
    HttpResponse get(const std::string &url, const std::string &accept, uint64_t maxBodyBytes);

    // POST `body` (tests upload instances to a PACS with it); statuses as get().
    HttpResponse post(const std::string &url, const std::string &contentType, const std::string &body,
                      const std::string &accept, uint64_t maxBodyBytes);

    // GET streamed: onHead once a 2xx head arrives (it may throw to refuse the response),
    // then onData for each chunk as it arrives; `cancelled` is asked between chunks and while
    // the transfer waits (true: Cancelled). Exceptions thrown by the callbacks end the
    // transfer and come out of this call unchanged (a DicomWebError's message scrubbed).
    // Non-2xx statuses throw as get() does, without calling the callbacks. Returns the bytes
    // received.
    uint64_t getStreaming(const std::string &url, const std::string &accept,
                          const std::function<void(const ResponseHead &)> &onHead,
                          const std::function<void(std::string_view)> &onData,
                          const std::function<bool()> &cancelled);

    // The path of `url` for messages: no scheme, host, query or fragment.
    static std::string pathForMessage(const std::string &url);

    const HttpOptions &options() const { return options_; }

  private:
    struct Transfer;
    uint64_t perform(const std::string &method, const std::string &url, const std::string &accept,
                     const std::string *postContentType, const std::string *postBody, Transfer &transfer);
    std::string source() const;

    HttpOptions options_;
    CredentialScrubber scrubber_;
    void *curl_ = nullptr;   // CURL*, kept out of this header
};

} // namespace volcast::dicomweb
