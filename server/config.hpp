#pragma once
// Everything the server can be told, from flags or environment (flags win). server/README.md
// lists each one; parseConfig fills this from argv and the VOLCAST_* variables.

#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <optional>
#include <string>
#include <vector>

namespace volcast::server {

// A DICOMweb source (--dicomweb NAME=URL, --dicomweb-auth NAME=FILE; docs/data-sources.md).
struct DicomWebSourceConfig {
    std::string name;            // [A-Za-z0-9_-], at most 64: what find_studies and volume names use
    std::string url;             // the DICOMweb root, http:// or https://, e.g. http://pacs:8042/dicom-web
    std::string authorization;   // the Authorization header's value read from its file, or empty; never logged
};

struct ServerConfig {
    std::string bindAddress = "127.0.0.1";   // loopback: nothing outside this machine by default
    uint16_t port = 8080;                     // 0: any free port (tests)
    std::vector<std::filesystem::path> dataDirs;   // empty: only the built-in volumes
    std::filesystem::path webRoot;            // static files (the browser client)
    std::string device = "auto";              // back end: auto, cpu, opencl, opencl:<part of a device name> (DeviceChoice)
    std::string kernelCacheDir;               // PoCL's kernel cache folder
    uint64_t memoryBudgetBytes = uint64_t(4096) << 20;   // loaded volumes, host side
    int maxSessions = 16;
    std::vector<std::string> allowedOrigins;  // empty: loopback origins on our port only; "*": any
    std::string defaultVolume = "builtin:demo";   // loaded at start; /readyz waits for it
    std::string token;                        // empty: no token needed in hello
    int ioThreads = 2;                        // threads running the network
    double idleMs = 150;                      // ms without input before refinement starts
    double restRefinementS = 10;              // render time a resting view may get beyond its final frame
    double defaultTargetFrameMs = 40;         // ms, the automatic policy's target
    int jitterPasses = 4;                     // passes accumulated by a jittered final level
    bool errorCalibration = true;             // calibrate error estimates against the reference
    size_t maxMessageBytes = 64 * 1024;       // one text message

    // WebSocket sessions and admission control (server/README.md; docs/hardening.md).
    int maxPendingSessions = 64;              // connections not past hello yet; more get busy (1013)
    double helloTimeoutMs = 10000;            // a connection without a good hello by then: close 1008
    int64_t maxSamplesPerFrame = int64_t(1) << 32;   // predicted samples of one frame (one pass)
    int64_t maxStillPixels = int64_t(4096) * 4096;   // width x height of a still
    uint64_t maxRequestBytes = uint64_t(1) << 30;    // image buffers one view may allocate
    size_t maxUnsentBytes = size_t(80) << 20; // replies + the frame not yet written, per session
    double writeTimeoutMs = 10000;            // a write not done by then closes the session
    int sendBufferBytes = 256 * 1024;         // SO_SNDBUF of a session's socket

    // Files and lifecycle.
    double loadTimeoutS = 120;                // a volume load running longer fails (0: no limit)
    int shutdownGraceMs = 5000;               // SIGTERM: exit within this, whatever still runs

    std::filesystem::path portFile;           // write the bound port here once listening
    std::string logLevel = "info";

    // HTTP hardening (server/README.md, "HTTP"; docs/hardening.md).
    std::vector<std::string> allowedHosts;    // Host names accepted; empty: loopback names on a loopback bind, else any; "*": any
    std::string metricsBind;                  // "ADDR:PORT": /metrics, /healthz, /readyz there, and /metrics off the main port
    int maxConnectionsPerAddress = 64;        // open TCP connections from one IP (HTTP and WebSocket); 0: no cap
    int headerTimeoutMs = 10000;              // ms for a request's headers to arrive (slowloris)

    // Uploads: POST /api/volumes (server/upload_store.hpp; docs/hardening.md).
    uint64_t maxUploadBytes = uint64_t(1024) << 20;        // one upload's body; over it: 413
    int maxUploadsPerAddress = 2;                          // uploads at once from one IP; more: 429
    uint64_t maxUploadStorageBytes = uint64_t(8192) << 20; // all uploads kept and under way; full: 507
    uint64_t uploadQuotaBytes = uint64_t(2048) << 20;      // one client's share of it; its own oldest unused evicted, else 507
    int uploadParseWorkers = 2;                            // uploads parsed at once (each in a checker process)
    double uploadMinBytesPerS = 1024;                      // an upload body slower than this over a window: 408
    double uploadRateWindowS = 20;                         // the window, seconds
    double uploadTtlSeconds = 3600;                        // an upload's life (--upload-ttl-min; seconds for tests)
    std::filesystem::path uploadDir;                       // empty: a new private folder under $TMPDIR or /tmp

    // Bringing your own scan from a PACS: DICOMweb sources (docs/data-sources.md).
    std::vector<DicomWebSourceConfig> dicomWebSources;
    double dicomWebTimeoutS = 30;             // one search or metadata request; retrievals stall out after it
    uint64_t dicomWebCacheBytes = uint64_t(4096) << 20;   // retrieved series kept on disk
    int dicomWebRetrievals = 2;               // retrievals running at once per source
    int dicomWebSearches = 4;                 // searches running at once per source
};

// "NAME=URL" pairs and "NAME=FILE" credentials into sources; throws std::invalid_argument
// naming what is wrong (an unknown name, a URL that is not http(s), a credential file that
// cannot be read). The error never quotes a credential.
std::vector<DicomWebSourceConfig> parseDicomWebSources(const std::vector<std::string> &sources,
                                                       const std::vector<std::string> &auth);

// Parse flags and environment. Returns nullopt after printing help or an error (exitCode set).
std::optional<ServerConfig> parseConfig(int argc, char **argv, int &exitCode);

} // namespace volcast::server
