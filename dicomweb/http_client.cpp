#include "dicomweb/http_client.hpp"

#include <curl/curl.h>
#include <spdlog/spdlog.h>

#include <algorithm>
#include <cctype>
#include <chrono>
#include <cmath>
#include <deque>
#include <exception>
#include <mutex>
#include <vector>

namespace volcast::dicomweb {

std::string_view errorKindName(ErrorKind kind) {
    switch (kind) {
    case ErrorKind::Unreachable: return "unreachable";
    case ErrorKind::Timeout: return "timeout";
    case ErrorKind::Unauthorized: return "unauthorized";
    case ErrorKind::Forbidden: return "forbidden";
    case ErrorKind::NotFound: return "not_found";
    case ErrorKind::BadResponse: return "bad_response";
    case ErrorKind::TooLarge: return "too_large";
    case ErrorKind::Cancelled: return "cancelled";
    case ErrorKind::BadQuery: return "bad_query";
    case ErrorKind::Storage: return "storage";
    }
    return "unknown";
}

namespace {

// A body of an error status is kept only to quote a few words of it.
constexpr size_t kErrorBodyBytes = 16 << 10;

CURL *handle(void *p) { return static_cast<CURL *>(p); }

void initCurlOnce() {
    // curl_global_init is not thread-safe before curl 7.84; the library may be used from any thread.
    static std::once_flag once;
    std::call_once(once, [] {
        if (curl_global_init(CURL_GLOBAL_DEFAULT) != CURLE_OK)
            throw DicomWebError(ErrorKind::Unreachable, "libcurl could not be initialised");
    });
}

struct UrlParts {
    std::string scheme, host, port, path;
};

// Parsed by curl itself, so that what is compared is what curl will connect to.
bool parseUrl(const std::string &url, UrlParts &out) {
    CURLU *u = curl_url();
    if (!u) return false;
    bool ok = curl_url_set(u, CURLUPART_URL, url.c_str(), 0) == CURLUE_OK;
    auto part = [&](CURLUPart which, std::string &into, unsigned flags) {
        char *value = nullptr;
        if (curl_url_get(u, which, &value, flags) == CURLUE_OK && value) {
            into = value;
            curl_free(value);
            return true;
        }
        return false;
    };
    ok = ok && part(CURLUPART_SCHEME, out.scheme, 0) && part(CURLUPART_HOST, out.host, 0) &&
         part(CURLUPART_PORT, out.port, CURLU_DEFAULT_PORT);
    if (ok && !part(CURLUPART_PATH, out.path, 0)) out.path = "/";
    curl_url_cleanup(u);
    for (auto *s : {&out.scheme, &out.host})
        std::transform(s->begin(), s->end(), s->begin(), [](unsigned char c) { return char(std::tolower(c)); });
    return ok;
}

// A few words of an error body for the message: Orthanc's JSON "Details"/"Message", else the
// text's first printable characters. Never more than 200 characters, never control bytes.
std::string excerptOf(const std::string &body) {
    std::string text;
    for (const char *key : {"\"Details\"", "\"Message\""}) {
        const size_t at = body.find(key);
        if (at == std::string::npos) continue;
        const size_t open = body.find('"', body.find(':', at) + 1);
        const size_t close = open == std::string::npos ? open : body.find('"', open + 1);
        if (close != std::string::npos) {
            text = body.substr(open + 1, close - open - 1);
            break;
        }
    }
    if (text.empty()) text = body;
    std::string out;
    for (char c : text) {
        if (out.size() >= 200) {
            out += "...";
            break;
        }
        const auto u = static_cast<unsigned char>(c);
        out += (u >= 0x20 && u < 0x7f) ? c : ' ';
    }
    while (!out.empty() && out.back() == ' ') out.pop_back();
    return out;
}

} // namespace

struct HttpClient::Transfer {
    bool streaming = false;
    uint64_t maxBodyBytes = 0;
    const std::function<void(const ResponseHead &)> *onHead = nullptr;
    const std::function<void(std::string_view)> *onData = nullptr;
    const std::function<bool()> *cancelled = nullptr;
    std::string sourceText;   // "DICOMweb source 'NAME'", for the callbacks' own errors
    std::string pathText;

    // Per attempt (a redirect starts a new one).
    CURL *curl = nullptr;
    bool headSeen = false;
    long status = 0;
    std::string contentType;
    int64_t contentLength = -1;
    std::string body;       // a buffered 2xx body, or the start of an error body
    uint64_t received = 0;  // 2xx body bytes
    std::exception_ptr error;

    void reset() {
        headSeen = false;
        status = 0;
        contentType.clear();
        contentLength = -1;
        body.clear();
        received = 0;
        error = nullptr;
    }

    bool success() const { return status >= 200 && status < 300; }

    void readHead() {
        headSeen = true;
        curl_easy_getinfo(curl, CURLINFO_RESPONSE_CODE, &status);
        const char *type = nullptr;
        if (curl_easy_getinfo(curl, CURLINFO_CONTENT_TYPE, &type) == CURLE_OK && type) contentType = type;
        curl_off_t length = -1;
        if (curl_easy_getinfo(curl, CURLINFO_CONTENT_LENGTH_DOWNLOAD_T, &length) == CURLE_OK) contentLength = length;
        if (streaming && success() && onHead && *onHead) (*onHead)(ResponseHead{status, contentType, contentLength});
    }

    void checkCancelled() const {
        if (cancelled && *cancelled && (*cancelled)())
            throw DicomWebError(ErrorKind::Cancelled, sourceText + ": " + pathText + " was cancelled");
    }

    void take(std::string_view chunk) {
        if (!headSeen) readHead();
        if (!success()) {
            if (body.size() < kErrorBodyBytes) body.append(chunk.substr(0, kErrorBodyBytes - body.size()));
            return;
        }
        checkCancelled();
        received += chunk.size();
        if (streaming) {
            if (onData && *onData) (*onData)(chunk);
            return;
        }
        if (received > maxBodyBytes)
            throw DicomWebError(ErrorKind::TooLarge, sourceText + " answered more than " +
                                                         std::to_string(maxBodyBytes) + " bytes to GET " + pathText);
        body.append(chunk);
    }

    static size_t onWrite(char *data, size_t size, size_t count, void *user) {
        auto &t = *static_cast<Transfer *>(user);
        const size_t bytes = size * count;
        try {
            t.take(std::string_view(data, bytes));
        } catch (...) {
            t.error = std::current_exception();
            return bytes == 0 ? 1 : 0;  // anything but `bytes` stops the transfer
        }
        return bytes;
    }

    // The low-speed limit, measured here rather than by curl: curl averages its speed over
    // the last 5 seconds, so a transfer that stops dead failed only 5 s after its limit.
    double lowSpeedSeconds = 0;
    double lowSpeedBytesPerSecond = 0;
    using Clock = std::chrono::steady_clock;
    Clock::time_point started;
    std::deque<std::pair<Clock::time_point, curl_off_t>> samples;  // (when, bytes moved so far)

    void checkSpeed(curl_off_t moved) {
        if (lowSpeedSeconds <= 0) return;
        const auto now = Clock::now();
        const auto window = std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(lowSpeedSeconds));
        samples.emplace_back(now, moved);
        // Keep one sample at or before the window's start, to measure across the whole window.
        while (samples.size() > 1 && samples[1].first <= now - window) samples.pop_front();
        if (now - started < window || samples.front().first > now - window) return;
        const double bytes = double(moved - samples.front().second);
        if (bytes < lowSpeedBytesPerSecond * lowSpeedSeconds)
            throw DicomWebError(ErrorKind::Timeout, sourceText + " timed out (" + pathText + "): less than " +
                                                        std::to_string(long(lowSpeedBytesPerSecond)) + " bytes/s for " +
                                                        std::to_string(lowSpeedSeconds).substr(0, 4) + " s");
    }

    static int onProgress(void *user, curl_off_t, curl_off_t downloaded, curl_off_t, curl_off_t uploaded) {
        auto &t = *static_cast<Transfer *>(user);
        try {
            t.checkCancelled();
            t.checkSpeed(downloaded + uploaded);
        } catch (...) {
            t.error = std::current_exception();
            return 1;
        }
        return 0;
    }
};

HttpClient::HttpClient(HttpOptions options) : options_(std::move(options)), scrubber_(options_.authorization) {
    initCurlOnce();
    // A CR or LF in the value would let a configuration file add headers of its own.
    if (options_.authorization.find_first_of("\r\n") != std::string::npos)
        throw DicomWebError(ErrorKind::BadQuery,
                            source() + ": the Authorization value holds a line break (it must be one line)");
    curl_ = curl_easy_init();
    if (!curl_) throw DicomWebError(ErrorKind::Unreachable, source() + ": libcurl could not make a handle");
}

HttpClient::~HttpClient() {
    if (curl_) curl_easy_cleanup(handle(curl_));
}

std::string HttpClient::source() const { return "DICOMweb source '" + options_.sourceName + "'"; }

std::string HttpClient::pathForMessage(const std::string &url) {
    UrlParts parts;
    if (!parseUrl(url, parts)) return "(an unparsable URL)";
    return parts.path;
}

HttpResponse HttpClient::get(const std::string &url, const std::string &accept, uint64_t maxBodyBytes) {
    Transfer t;
    t.maxBodyBytes = maxBodyBytes;
    scrubbingErrors(scrubber_, [&] { return perform("GET", url, accept, nullptr, nullptr, t); });
    return {t.status, t.contentType, std::move(t.body)};
}

HttpResponse HttpClient::post(const std::string &url, const std::string &contentType, const std::string &body,
                              const std::string &accept, uint64_t maxBodyBytes) {
    Transfer t;
    t.maxBodyBytes = maxBodyBytes;
    scrubbingErrors(scrubber_, [&] { return perform("POST", url, accept, &contentType, &body, t); });
    return {t.status, t.contentType, std::move(t.body)};
}

uint64_t HttpClient::getStreaming(const std::string &url, const std::string &accept,
                                  const std::function<void(const ResponseHead &)> &onHead,
                                  const std::function<void(std::string_view)> &onData,
                                  const std::function<bool()> &cancelled) {
    Transfer t;
    t.streaming = true;
    t.onHead = &onHead;
    t.onData = &onData;
    t.cancelled = &cancelled;
    return scrubbingErrors(scrubber_, [&] { return perform("GET", url, accept, nullptr, nullptr, t); });
}

uint64_t HttpClient::perform(const std::string &method, const std::string &firstUrl, const std::string &accept,
                             const std::string *postContentType, const std::string *postBody, Transfer &t) {
    CURL *curl = handle(curl_);
    const std::string src = source();
    UrlParts origin;
    if (!parseUrl(firstUrl, origin))
        throw DicomWebError(ErrorKind::BadQuery, src + ": the URL could not be parsed");
    if (origin.scheme != "http" && origin.scheme != "https")
        throw DicomWebError(ErrorKind::BadQuery, src + ": only http and https URLs are supported, not " + origin.scheme);

    std::string url = firstUrl;
    for (int redirects = 0;; ++redirects) {
        const std::string path = pathForMessage(url);
        t.curl = curl;
        t.sourceText = src;
        t.pathText = path;
        t.reset();

        curl_easy_reset(curl);  // keeps the connection cache
        char errorText[CURL_ERROR_SIZE] = {};
        curl_easy_setopt(curl, CURLOPT_ERRORBUFFER, errorText);
        curl_easy_setopt(curl, CURLOPT_URL, url.c_str());
        curl_easy_setopt(curl, CURLOPT_PROTOCOLS_STR, "http,https");
        curl_easy_setopt(curl, CURLOPT_FOLLOWLOCATION, 0L);  // redirects are checked below
        curl_easy_setopt(curl, CURLOPT_NOSIGNAL, 1L);        // threads: no SIGALRM for DNS timeouts
        curl_easy_setopt(curl, CURLOPT_SSL_VERIFYPEER, 1L);
        curl_easy_setopt(curl, CURLOPT_SSL_VERIFYHOST, 2L);
        curl_easy_setopt(curl, CURLOPT_USERAGENT, "volcast-dicomweb");
        curl_easy_setopt(curl, CURLOPT_CONNECTTIMEOUT_MS, long(std::lround(options_.connectTimeoutSeconds * 1000)));
        if (options_.requestTimeoutSeconds > 0)
            curl_easy_setopt(curl, CURLOPT_TIMEOUT_MS, long(std::lround(options_.requestTimeoutSeconds * 1000)));
        t.lowSpeedSeconds = options_.lowSpeedSeconds;
        t.lowSpeedBytesPerSecond = double(options_.lowSpeedBytesPerSecond);
        t.started = Transfer::Clock::now();
        t.samples.clear();
        // Compressed answers for buffered (JSON) bodies only; the bound applies to the decoded
        // bytes. Retrieval asks for none: a PACS compressing DICOM costs more than it saves.
        if (!t.streaming) {
            curl_easy_setopt(curl, CURLOPT_ACCEPT_ENCODING, "");
            curl_easy_setopt(curl, CURLOPT_MAXFILESIZE_LARGE, curl_off_t(t.maxBodyBytes));
        } else {
            // A series is hundreds of MiB: larger reads mean fewer callbacks, searches and writes.
            curl_easy_setopt(curl, CURLOPT_BUFFERSIZE, 512L << 10);
        }
        curl_easy_setopt(curl, CURLOPT_WRITEFUNCTION, &Transfer::onWrite);
        curl_easy_setopt(curl, CURLOPT_WRITEDATA, &t);
        curl_easy_setopt(curl, CURLOPT_NOPROGRESS, 0L);
        curl_easy_setopt(curl, CURLOPT_XFERINFOFUNCTION, &Transfer::onProgress);
        curl_easy_setopt(curl, CURLOPT_XFERINFODATA, &t);

        struct curl_slist *headers = nullptr;
        const std::string acceptHeader = "Accept: " + accept;
        const std::string authHeader = "Authorization: " + options_.authorization;
        headers = curl_slist_append(headers, acceptHeader.c_str());
        if (!options_.authorization.empty()) headers = curl_slist_append(headers, authHeader.c_str());
        std::string typeHeader;
        if (method == "POST") {
            typeHeader = "Content-Type: " + *postContentType;
            headers = curl_slist_append(headers, typeHeader.c_str());
            headers = curl_slist_append(headers, "Expect:");  // no 100-continue round trip
            curl_easy_setopt(curl, CURLOPT_POST, 1L);
            curl_easy_setopt(curl, CURLOPT_POSTFIELDS, postBody->data());
            curl_easy_setopt(curl, CURLOPT_POSTFIELDSIZE_LARGE, curl_off_t(postBody->size()));
        }
        curl_easy_setopt(curl, CURLOPT_HTTPHEADER, headers);
        spdlog::debug("{}: {} {}", src, method, scrubber_(path));  // a redirect's path is the server's
        const CURLcode code = curl_easy_perform(curl);
        curl_slist_free_all(headers);
        curl_easy_setopt(curl, CURLOPT_ERRORBUFFER, nullptr);

        if (t.error) std::rethrow_exception(t.error);
        const std::string what = method + " " + path;
        const std::string curlText = errorText[0] ? std::string(errorText) : std::string(curl_easy_strerror(code));
        switch (code) {
        case CURLE_OK: break;
        case CURLE_COULDNT_RESOLVE_HOST:
        case CURLE_COULDNT_RESOLVE_PROXY:
        case CURLE_COULDNT_CONNECT:
            throw DicomWebError(ErrorKind::Unreachable, src + " is unreachable (" + what + "): " + curlText);
        case CURLE_OPERATION_TIMEDOUT:
            throw DicomWebError(ErrorKind::Timeout, src + " timed out (" + what + "): " + curlText);
        case CURLE_FILESIZE_EXCEEDED:
            throw DicomWebError(ErrorKind::TooLarge, src + " announced more than " + std::to_string(t.maxBodyBytes) +
                                                         " bytes for " + what);
        case CURLE_PARTIAL_FILE:
            throw DicomWebError(ErrorKind::BadResponse, src + " sent a truncated body (" + what + "): " + curlText);
        case CURLE_RECV_ERROR:
        case CURLE_SEND_ERROR:
        case CURLE_GOT_NOTHING:
            throw DicomWebError(ErrorKind::Unreachable, src + " closed the connection (" + what + "): " + curlText);
        case CURLE_PEER_FAILED_VERIFICATION:
        case CURLE_SSL_CONNECT_ERROR:
        case CURLE_SSL_CERTPROBLEM:
        case CURLE_SSL_CIPHER:
        case CURLE_SSL_CACERT_BADFILE:
        case CURLE_SSL_ISSUER_ERROR:
            throw DicomWebError(ErrorKind::Unreachable, src + ": TLS failed (" + what + "): " + curlText);
        case CURLE_URL_MALFORMAT:
        case CURLE_UNSUPPORTED_PROTOCOL:
            throw DicomWebError(ErrorKind::BadQuery, src + ": bad URL (" + what + "): " + curlText);
        case CURLE_WEIRD_SERVER_REPLY:
        case CURLE_BAD_CONTENT_ENCODING:
        case CURLE_HTTP2:
        case CURLE_HTTP2_STREAM:
            throw DicomWebError(ErrorKind::BadResponse, src + " sent a malformed HTTP answer (" + what + "): " + curlText);
        default:
            throw DicomWebError(ErrorKind::Unreachable, src + ": " + what + " failed: " + curlText);
        }
        if (!t.headSeen) t.readHead();  // a body-less answer never reached the write callback

        const long status = t.status;
        if (t.success()) return t.received;
        if (status >= 300 && status < 400 && status != 304) {
            char *location = nullptr;
            curl_easy_getinfo(curl, CURLINFO_REDIRECT_URL, &location);
            if (!location)
                throw DicomWebError(ErrorKind::BadResponse, src + " answered HTTP " + std::to_string(status) +
                                                                " without a Location to " + what);
            const std::string next = location;
            UrlParts target;
            if (!parseUrl(next, target) || target.scheme != origin.scheme || target.host != origin.host ||
                target.port != origin.port)
                throw DicomWebError(ErrorKind::BadResponse,
                                    src + " redirected " + what + " to another scheme, host or port (" +
                                        (target.scheme.empty() ? std::string("?") : target.scheme) + "://" +
                                        target.host + ":" + target.port + "), which is refused");
            if (method != "GET")
                throw DicomWebError(ErrorKind::BadResponse, src + " redirected " + what + ", which is refused for a " + method);
            if (redirects >= options_.maxRedirects)
                throw DicomWebError(ErrorKind::BadResponse, src + " redirected " + what + " more than " +
                                                                std::to_string(options_.maxRedirects) + " times");
            url = next;
            continue;
        }
        const std::string answered = " (HTTP " + std::to_string(status) + ")";
        // A hostile server could echo the request's headers back: scrubbed before the excerpt
        // is cut, so that no cut leaves part of a credential.
        const std::string excerpt = excerptOf(scrubber_.withoutCredentials(t.body));
        const std::string details = excerpt.empty() ? "" : ": " + excerpt;
        switch (status) {
        case 401:
            throw DicomWebError(ErrorKind::Unauthorized,
                                src + " refused the credentials" + answered + " for " + what +
                                    (options_.authorization.empty() ? ": none are configured" : ""));
        case 403:
            throw DicomWebError(ErrorKind::Forbidden, src + " forbade " + what + answered + details);
        case 404:
            throw DicomWebError(ErrorKind::NotFound, src + " has nothing at " + what + answered + details);
        case 502:
        case 503:
        case 504:
            throw DicomWebError(ErrorKind::Unreachable, src + " answered" + answered + " to " + what +
                                                            " (a gateway could not reach the PACS)" + details);
        default:
            throw DicomWebError(ErrorKind::BadResponse, src + " answered" + answered + " to " + what + details);
        }
    }
}

} // namespace volcast::dicomweb
