#include "server/config.hpp"

#include "renderer/make_frame_renderer.hpp"

#include <CLI/CLI.hpp>

#include "protocol/client_messages.hpp"

#include <algorithm>
#include <cstdlib>
#include <fstream>
#include <iostream>
#include <stdexcept>

namespace volcast::server {

#ifndef VOLCAST_DEFAULT_WEB_ROOT
#define VOLCAST_DEFAULT_WEB_ROOT "web"
#endif

namespace {

std::pair<std::string, std::string> splitPair(const std::string &item, const char *flag, const char *form) {
    const size_t eq = item.find('=');
    if (eq == std::string::npos || eq == 0 || eq + 1 == item.size())
        throw std::invalid_argument(std::string(flag) + ": expected " + form + ", got \"" + item + "\"");
    return {item.substr(0, eq), item.substr(eq + 1)};
}

} // namespace

std::vector<DicomWebSourceConfig> parseDicomWebSources(const std::vector<std::string> &sources,
                                                       const std::vector<std::string> &auth) {
    std::vector<DicomWebSourceConfig> out;
    for (const std::string &item : sources) {
        if (item.empty()) continue;
        auto [name, url] = splitPair(item, "--dicomweb", "NAME=URL");
        if (auto problem = protocol::validateSourceName(name))
            throw std::invalid_argument("--dicomweb: source name \"" + name + "\" " + *problem);
        for (const auto &s : out)
            if (s.name == name) throw std::invalid_argument("--dicomweb: source \"" + name + "\" is given twice");
        if (!url.starts_with("http://") && !url.starts_with("https://"))
            throw std::invalid_argument("--dicomweb " + name + ": the URL must start with http:// or https://");
        for (unsigned char ch : url)
            if (ch <= 0x20 || ch == 0x7f)
                throw std::invalid_argument("--dicomweb " + name + ": the URL holds a space or control character");
        const size_t authorityStart = url.find("//") + 2;
        const std::string authority = url.substr(authorityStart, url.find('/', authorityStart) - authorityStart);
        if (authority.find('@') != std::string::npos)
            throw std::invalid_argument("--dicomweb " + name + ": the URL carries a user name or password; give "
                                        "credentials in a file with --dicomweb-auth instead (never on the command line)");
        if (authority.empty()) throw std::invalid_argument("--dicomweb " + name + ": the URL names no host");
        while (url.size() > authorityStart + authority.size() + 1 && url.ends_with("/")) url.pop_back();
        out.push_back({name, url, ""});
    }
    for (const std::string &item : auth) {
        if (item.empty()) continue;
        // Plain names, not a structured binding: the lambda below captures `name` (clang 14,
        // which builds the fuzz targets, cannot capture bindings).
        const auto pair = splitPair(item, "--dicomweb-auth", "NAME=FILE");
        const std::string &name = pair.first, &file = pair.second;
        auto it = std::find_if(out.begin(), out.end(), [&](const auto &s) { return s.name == name; });
        if (it == out.end())
            throw std::invalid_argument("--dicomweb-auth: no --dicomweb source named \"" + name + "\"");
        std::ifstream in(file);
        if (!in) throw std::invalid_argument("--dicomweb-auth " + name + ": cannot read " + file);
        std::string value;
        std::getline(in, value);
        while (!value.empty() && (value.back() == '\r' || value.back() == ' ' || value.back() == '\t')) value.pop_back();
        if (value.empty())
            throw std::invalid_argument("--dicomweb-auth " + name + ": " + file +
                                        " is empty; it must hold an Authorization value such as \"Basic ...\" or "
                                        "\"Bearer ...\" on its first line");
        for (unsigned char ch : value)
            if (ch < 0x20 || ch == 0x7f)
                throw std::invalid_argument("--dicomweb-auth " + name + ": " + file +
                                            " holds a control character on its first line");
        it->authorization = value;
    }
    return out;
}

std::optional<ServerConfig> parseConfig(int argc, char **argv, int &exitCode) {
    ServerConfig c;
    c.webRoot = VOLCAST_DEFAULT_WEB_ROOT;
    CLI::App app{"volcast-server: remote volume rendering over HTTP and WebSocket (see server/README.md)."};
    std::vector<std::string> dataDirs;
    double budgetMiB = double(c.memoryBudgetBytes >> 20);
    std::string webRoot = c.webRoot.string(), portFile;
    // Each option also reads its environment variable; a flag given on the command line wins.
    app.add_option("--bind", c.bindAddress, "Address to listen on (127.0.0.1: this machine only)")
        ->envname("VOLCAST_BIND");
    app.add_option("--port", c.port, "TCP port for HTTP and WebSocket (0: any free port)")->envname("VOLCAST_PORT");
    app.add_option("--data", dataDirs, "Data folder holding volumes; repeat for several (env: ':'-separated)")
        ->envname("VOLCAST_DATA")
        ->delimiter(':');
    app.add_option("--web-root", webRoot, "Folder of static files served over HTTP")->envname("VOLCAST_WEB_ROOT");
    app.add_option("--device", c.device,
                   "Back end: auto (an OpenCL GPU if present, else cpu), cpu (native SIMD), opencl (OpenCL's "
                   "choice), opencl:<part of an OpenCL device's name, gpu or cpu>")
        ->envname("VOLCAST_DEVICE")
        ->capture_default_str()
        ->check([](const std::string &value) {
            try {
                volcast::DeviceChoice::parse(value);
                return std::string();
            } catch (const std::invalid_argument &e) {
                return std::string(e.what());
            }
        });
    app.add_option("--kernel-cache", c.kernelCacheDir, "Folder for PoCL's compiled-kernel cache")
        ->envname("VOLCAST_KERNEL_CACHE");
    app.add_option("--memory-budget-mib", budgetMiB, "Host memory for loaded volumes, MiB")
        ->envname("VOLCAST_MEMORY_BUDGET_MIB")
        ->check(CLI::Range(1.0, 1e9));
    app.add_option("--max-sessions", c.maxSessions, "WebSocket sessions at once")
        ->envname("VOLCAST_MAX_SESSIONS")
        ->check(CLI::Range(1, 100000));
    app.add_option("--allowed-origin", c.allowedOrigins,
                   "Browser Origin allowed to open a session; repeat, or '*' for any (default: loopback "
                   "origins on this port; env: ','-separated)")
        ->envname("VOLCAST_ALLOWED_ORIGINS")
        ->delimiter(',');
    app.add_option("--default-volume", c.defaultVolume, "Volume loaded at start; /readyz waits for it ('' for none)")
        ->envname("VOLCAST_DEFAULT_VOLUME");
    app.add_option("--token", c.token, "Access token clients must give in hello (default: none)")
        ->envname("VOLCAST_TOKEN");
    app.add_option("--io-threads", c.ioThreads, "Threads running the network")
        ->envname("VOLCAST_IO_THREADS")
        ->check(CLI::Range(1, 64));
    app.add_option("--idle-ms", c.idleMs, "ms without input before refinement starts")
        ->envname("VOLCAST_IDLE_MS")
        ->check(CLI::Range(0.0, 60000.0));
    app.add_option("--rest-refinement-s", c.restRefinementS,
                   "Render time (s) a view at rest may get beyond its final frame, toward the exact integral, "
                   "when the server has nothing else to render (0: none)")
        ->envname("VOLCAST_REST_REFINEMENT_S")
        ->check(CLI::Range(0.0, 600.0));
    app.add_option("--target-frame-ms", c.defaultTargetFrameMs, "Default frame-time target while interacting, ms")
        ->envname("VOLCAST_TARGET_FRAME_MS")
        ->check(CLI::Range(1.0, 10000.0));
    app.add_option("--jitter-passes", c.jitterPasses, "Jittered passes a final level with jitter accumulates")
        ->envname("VOLCAST_JITTER_PASSES")
        ->check(CLI::Range(1, 64));
    app.add_option("--error-calibration", c.errorCalibration,
                   "Calibrate each level's error against the reference integrator (true/false)")
        ->envname("VOLCAST_ERROR_CALIBRATION");
    app.add_option("--max-message-bytes", c.maxMessageBytes, "Largest text message accepted, bytes")
        ->envname("VOLCAST_MAX_MESSAGE_BYTES")
        ->check(CLI::Range(1024, 16 << 20));
    // WebSocket sessions and admission control.
    double requestMiB = double(c.maxRequestBytes >> 20);
    app.add_option("--max-pending-sessions", c.maxPendingSessions,
                   "WebSocket connections that have not completed hello yet")
        ->envname("VOLCAST_MAX_PENDING_SESSIONS")
        ->check(CLI::Range(1, 100000));
    app.add_option("--hello-timeout-ms", c.helloTimeoutMs, "ms a new connection has to complete hello")
        ->envname("VOLCAST_HELLO_TIMEOUT_MS")
        ->check(CLI::Range(1.0, 3600e3));
    app.add_option("--max-samples-per-frame", c.maxSamplesPerFrame,
                   "Predicted samples (rays x samples per ray) one frame may take")
        ->envname("VOLCAST_MAX_SAMPLES_PER_FRAME")
        ->check(CLI::Range(int64_t(1000), int64_t(1) << 50));
    app.add_option("--max-still-pixels", c.maxStillPixels, "Pixels (width x height) of a still")
        ->envname("VOLCAST_MAX_STILL_PIXELS")
        ->check(CLI::Range(int64_t(1), int64_t(1) << 40));
    app.add_option("--max-request-mib", requestMiB,
                   "Image memory one view may allocate, MiB (width x height x 16 bytes x passes)")
        ->envname("VOLCAST_MAX_REQUEST_MIB")
        ->check(CLI::Range(1.0, 1e7));
    app.add_option("--max-unsent-bytes", c.maxUnsentBytes,
                   "Bytes waiting to be written to one session (replies and its frame) before it is closed")
        ->envname("VOLCAST_MAX_UNSENT_BYTES")
        ->check(CLI::Range(size_t(64) << 10, size_t(1) << 40));
    app.add_option("--write-timeout-ms", c.writeTimeoutMs, "ms a write to a session may take before it is closed")
        ->envname("VOLCAST_WRITE_TIMEOUT_MS")
        ->check(CLI::Range(1.0, 3600e3));
    app.add_option("--send-buffer-bytes", c.sendBufferBytes, "Kernel send buffer (SO_SNDBUF) of a session's socket")
        ->envname("VOLCAST_SEND_BUFFER_BYTES")
        ->check(CLI::Range(4096, 64 << 20));

    // Files and lifecycle.
    app.add_option("--load-timeout-s", c.loadTimeoutS, "A volume load running longer fails, seconds (0: no limit)")
        ->envname("VOLCAST_LOAD_TIMEOUT_S")
        ->check(CLI::Range(0.0, 86400.0));
    app.add_option("--shutdown-grace-ms", c.shutdownGraceMs,
                   "On SIGTERM/SIGINT, exit within this many ms whatever is still running")
        ->envname("VOLCAST_SHUTDOWN_GRACE_MS")
        ->check(CLI::Range(100, 600000));

    app.add_option("--port-file", portFile, "Write the bound port to this file once listening (for scripts)");
    app.add_option("--log-level", c.logLevel, "trace, debug, info, warn, error")->envname("VOLCAST_LOG_LEVEL");
    // HTTP hardening.
    app.add_option("--allowed-host", c.allowedHosts,
                   "Host header name accepted over HTTP; repeat, or '*' for any (default: localhost, 127.0.0.1 and "
                   "[::1] on a loopback bind, any otherwise; env: ','-separated)")
        ->envname("VOLCAST_ALLOWED_HOSTS")
        ->delimiter(',');
    app.add_option("--metrics-bind", c.metricsBind,
                   "ADDR:PORT serving /metrics, /healthz and /readyz on a listener of their own; the main port then "
                   "answers /metrics with 404")
        ->envname("VOLCAST_METRICS_BIND");
    app.add_option("--max-connections-per-address", c.maxConnectionsPerAddress,
                   "Open TCP connections (HTTP and WebSocket) from one IP address; 0: no cap")
        ->envname("VOLCAST_MAX_CONNECTIONS_PER_ADDRESS")
        ->check(CLI::Range(0, 1000000));
    app.add_option("--header-timeout-ms", c.headerTimeoutMs, "ms a client has to send a request's headers")
        ->envname("VOLCAST_HEADER_TIMEOUT_MS")
        ->check(CLI::Range(100, 3600000));
    // Uploads.
    double uploadMiB = double(c.maxUploadBytes >> 20), uploadStorageMiB = double(c.maxUploadStorageBytes >> 20);
    double uploadTtlMin = c.uploadTtlSeconds / 60;
    std::string uploadDir;
    app.add_option("--max-upload-mib", uploadMiB, "Largest upload (POST /api/volumes), MiB; over it: 413")
        ->envname("VOLCAST_MAX_UPLOAD_MIB")
        ->check(CLI::Range(1.0, 1e7));
    app.add_option("--max-uploads-per-address", c.maxUploadsPerAddress, "Uploads at once from one IP address")
        ->envname("VOLCAST_MAX_UPLOADS_PER_ADDRESS")
        ->check(CLI::Range(1, 10000));
    app.add_option("--max-upload-storage-mib", uploadStorageMiB,
                   "Disk for all uploads kept, MiB; the least recently opened are deleted to make room")
        ->envname("VOLCAST_MAX_UPLOAD_STORAGE_MIB")
        ->check(CLI::Range(1.0, 1e9));
    double uploadQuotaMiB = double(c.uploadQuotaBytes >> 20);
    app.add_option("--upload-quota-mib", uploadQuotaMiB,
                   "Disk one client (one IP address) may hold in uploads, kept and under way, MiB; its own least "
                   "recently opened are deleted to make room for its new one, never another client's")
        ->envname("VOLCAST_UPLOAD_QUOTA_MIB")
        ->check(CLI::Range(1.0, 1e9));
    app.add_option("--upload-parse-workers", c.uploadParseWorkers,
                   "Uploads parsed at once, each in a checker process; the next goes to the client with the fewest")
        ->envname("VOLCAST_UPLOAD_PARSE_WORKERS")
        ->check(CLI::Range(1, 64));
    app.add_option("--upload-min-bytes-per-s", c.uploadMinBytesPerS,
                   "An upload body must bring at least this many bytes per second over each --upload-rate-window-s; "
                   "a slower one is cut with 408")
        ->envname("VOLCAST_UPLOAD_MIN_BYTES_PER_S")
        ->check(CLI::Range(0.0, 1e12));
    app.add_option("--upload-rate-window-s", c.uploadRateWindowS, "Seconds over which --upload-min-bytes-per-s is kept")
        ->envname("VOLCAST_UPLOAD_RATE_WINDOW_S")
        ->check(CLI::Range(0.1, 3600.0));
    app.add_option("--upload-ttl-min", uploadTtlMin, "Minutes an upload is kept after it arrives")
        ->envname("VOLCAST_UPLOAD_TTL_MIN")
        ->check(CLI::Range(0.01, 1e6));
    app.add_option("--upload-dir", uploadDir,
                   "Private folder for uploads (made 0700; what it holds is deleted at start and at shutdown; "
                   "default: a new folder under $TMPDIR or /tmp)")
        ->envname("VOLCAST_UPLOAD_DIR");
    std::vector<std::string> dicomWeb, dicomWebAuth;
    double dicomWebCacheMiB = double(c.dicomWebCacheBytes >> 20);
    app.add_option("--dicomweb", dicomWeb,
                   "A DICOMweb source NAME=URL (the DICOMweb root); repeat for several (env: ','-separated)")
        ->envname("VOLCAST_DICOMWEB")
        ->delimiter(',');
    app.add_option("--dicomweb-auth", dicomWebAuth,
                   "NAME=FILE: the source's Authorization value (\"Basic ...\", \"Bearer ...\") is the first line "
                   "of FILE; repeat for several (env: ','-separated)")
        ->envname("VOLCAST_DICOMWEB_AUTH")
        ->delimiter(',');
    app.add_option("--dicomweb-timeout-s", c.dicomWebTimeoutS,
                   "Seconds a DICOMweb search may take, and a retrieval may stall")
        ->envname("VOLCAST_DICOMWEB_TIMEOUT_S")
        ->check(CLI::Range(1.0, 3600.0));
    app.add_option("--dicomweb-cache-mib", dicomWebCacheMiB, "Retrieved DICOMweb series kept on disk, MiB")
        ->envname("VOLCAST_DICOMWEB_CACHE_MIB")
        ->check(CLI::Range(0.0, 1e9));
    app.add_option("--dicomweb-retrievals", c.dicomWebRetrievals,
                   "Series retrieved at once from one DICOMweb source; more opens of it wait their turn")
        ->envname("VOLCAST_DICOMWEB_RETRIEVALS")
        ->check(CLI::Range(1, 64));
    app.add_option("--dicomweb-searches", c.dicomWebSearches,
                   "Study searches run at once on one DICOMweb source; more wait their turn")
        ->envname("VOLCAST_DICOMWEB_SEARCHES")
        ->check(CLI::Range(1, 64));
    try {
        app.parse(argc, argv);
        c.dicomWebSources = parseDicomWebSources(dicomWeb, dicomWebAuth);
    } catch (const CLI::ParseError &e) {
        exitCode = app.exit(e);
        return std::nullopt;
    } catch (const std::invalid_argument &e) {
        std::cerr << e.what() << "\n";
        exitCode = 2;
        return std::nullopt;
    }
    c.dicomWebCacheBytes = uint64_t(dicomWebCacheMiB * 1024.0 * 1024.0);
    for (const auto &d : dataDirs)
        if (!d.empty()) c.dataDirs.emplace_back(d);
    c.webRoot = webRoot;
    c.portFile = portFile;
    c.memoryBudgetBytes = uint64_t(budgetMiB * 1024.0 * 1024.0);
    c.maxRequestBytes = uint64_t(requestMiB * 1024.0 * 1024.0);
    c.maxUploadBytes = uint64_t(uploadMiB * 1024.0 * 1024.0);
    c.maxUploadStorageBytes = uint64_t(uploadStorageMiB * 1024.0 * 1024.0);
    c.uploadQuotaBytes = uint64_t(uploadQuotaMiB * 1024.0 * 1024.0);
    c.uploadTtlSeconds = uploadTtlMin * 60;
    c.uploadDir = uploadDir;
    return c;
}

} // namespace volcast::server
