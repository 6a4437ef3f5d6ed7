#include "server/dicomweb_provider.hpp"

#include <spdlog/fmt/fmt.h>
#include <spdlog/spdlog.h>

#include <algorithm>
#include <chrono>

namespace volcast::server {

namespace fs = std::filesystem;
using protocol::ErrorCode;
using protocol::ProtocolError;

namespace {

uint64_t folderBytes(const fs::path &folder) {
    uint64_t total = 0;
    std::error_code ec;
    for (fs::directory_iterator it(folder, ec), end; !ec && it != end; it.increment(ec))
        if (it->is_regular_file(ec)) total += it->file_size(ec);
    return total;
}

// What a DICOMweb failure means to a user, naming the source's answer, never its credentials:
// the client scrubbed its message already; scrubbed again here, where it becomes a client's
// message and a log line, so that no message of the library can skip it.
std::string explain(const dicomweb::DicomWebError &e, const dicomweb::SourceConfig &config) {
    using dicomweb::ErrorKind;
    const std::string message = dicomweb::CredentialScrubber(config.authorization)(e.what());
    switch (e.kind) {
    case ErrorKind::Unauthorized:
        return message + " (the server's credentials for this source were refused: --dicomweb-auth)";
    case ErrorKind::Forbidden: return message + " (the source does not allow this server to read it)";
    default: return message;
    }
}

} // namespace

std::variant<DicomWebSeriesName, std::string> parseDicomWebName(std::string_view name) {
    if (!name.starts_with(kDicomWebPrefix)) return std::string("does not start with \"dicomweb:\"");
    std::string_view rest = name.substr(kDicomWebPrefix.size());
    DicomWebSeriesName out;
    const size_t first = rest.find('/');
    const size_t second = first == std::string_view::npos ? first : rest.find('/', first + 1);
    if (second == std::string_view::npos || rest.find('/', second + 1) != std::string_view::npos)
        return std::string("must be dicomweb:SOURCE/STUDY_UID/SERIES_UID");
    out.source = std::string(rest.substr(0, first));
    out.studyUid = std::string(rest.substr(first + 1, second - first - 1));
    out.seriesUid = std::string(rest.substr(second + 1));
    if (auto problem = protocol::validateSourceName(out.source)) return "has a source name that " + *problem;
    if (!dicomweb::isUid(out.studyUid)) return std::string("has a study UID that is not a DICOM UID (digits and dots, at most 64)");
    if (!dicomweb::isUid(out.seriesUid)) return std::string("has a series UID that is not a DICOM UID (digits and dots, at most 64)");
    return out;
}

DicomWebProvider::DicomWebProvider(std::vector<dicomweb::SourceConfig> sources, fs::path cacheFolder,
                                   uint64_t cacheBytes, int searchesPerSource)
    : sources_(std::move(sources)), cacheFolder_(std::move(cacheFolder)), cacheBytes_(cacheBytes) {
    std::error_code ec;
    fs::remove_all(cacheFolder_, ec);   // a folder of ours from an earlier run: nothing in it is trusted
    fs::create_directories(cacheFolder_);
    fs::permissions(cacheFolder_, fs::perms::owner_all, fs::perm_options::replace);
    for (const auto &s : sources_)
        searchLanes_[s.name] = std::make_unique<WorkLane>("search " + s.name, searchesPerSource, kMaxWaitingSearches);
}

DicomWebProvider::~DicomWebProvider() {
    // Waiting searches are answered busy; running ones end with their request's time limit.
    for (auto &[name, lane] : searchLanes_) lane->stop();
    std::error_code ec;
    fs::remove_all(cacheFolder_, ec);
}

const dicomweb::SourceConfig *DicomWebProvider::source(const std::string &name) const {
    for (const auto &s : sources_)
        if (s.name == name) return &s;
    return nullptr;
}

std::vector<protocol::SourceInfo> DicomWebProvider::sources() const {
    std::vector<protocol::SourceInfo> out;
    for (const auto &s : sources_) out.push_back({s.name, "dicomweb"});
    return out;
}

std::optional<ProtocolError> DicomWebProvider::check(const std::string &name) const {
    const auto parsed = parseDicomWebName(name);
    if (const auto *problem = std::get_if<std::string>(&parsed))
        return ProtocolError{ErrorCode::BadVolumeName, "volume name \"" + name + "\" " + *problem, nullptr, "open_volume"};
    const auto &series = std::get<DicomWebSeriesName>(parsed);
    if (!source(series.source))
        return ProtocolError{ErrorCode::NotFound,
                             "no DICOMweb source named \"" + series.source + "\" (list_volumes lists the sources)",
                             nullptr, "open_volume"};
    return std::nullopt;
}

std::string DicomWebProvider::sourceOf(const std::string &name) const {
    const auto parsed = parseDicomWebName(name);
    const auto *series = std::get_if<DicomWebSeriesName>(&parsed);
    return std::string(kDicomWebPrefix) + (series ? series->source : "");
}

void DicomWebProvider::release(const std::string &name, bool refused) {
    const auto parsed = parseDicomWebName(name);
    const auto *series = std::get_if<DicomWebSeriesName>(&parsed);
    if (!series) return;
    std::lock_guard lock(cacheMutex_);
    auto it = cache_.find(series->source + "/" + series->studyUid + "/" + series->seriesUid);
    if (it == cache_.end()) return;
    it->second.readers = std::max(0, it->second.readers - 1);
    if (refused && it->second.readers == 0) {
        spdlog::info("{}: dropped from the retrieval cache, the loader refused it", name);
        std::error_code ec;
        fs::remove_all(it->second.folder, ec);
        cache_.erase(it);
    }
}

FetchedVolume DicomWebProvider::fetch(const std::string &name, const FetchContext &context) {
    const auto series = std::get<DicomWebSeriesName>(parseDicomWebName(name));   // check() passed
    const std::string key = series.source + "/" + series.studyUid + "/" + series.seriesUid;
    {
        std::lock_guard lock(cacheMutex_);
        if (auto it = cache_.find(key); it != cache_.end()) {
            it->second.lastUse = ++useClock_;
            ++it->second.readers;
            spdlog::debug("{}: retrieved before, loaded from the cache", name);
            return {it->second.folder, FetchedVolume::Form::Source, SeriesIdentity{series.studyUid, series.seriesUid}};
        }
    }
    const dicomweb::SourceConfig &config = *source(series.source);
    dicomweb::Client client(config);
    const auto started = std::chrono::steady_clock::now();
    try {
        context.progress({"checking the series", 0, std::nullopt, std::nullopt, std::nullopt});
        const dicomweb::SeriesSize size = client.seriesSize(series.studyUid, series.seriesUid);
        if (size.instances <= 0)
            throw VolumeFetchError(ErrorCode::NotFound, name + ": the source \"" + series.source +
                                                            "\" has no instances of this series");
        if (size.float32Bytes > context.maxFloat32Bytes)
            throw VolumeFetchError(
                ErrorCode::LoadFailed,
                fmt::format("{}: the series has {} images of {} x {}, {:.1f} MiB as float32 voxels, more than this "
                            "server can hold ({:.1f} MiB, from --memory-budget-mib); it is not retrieved",
                            name, size.instances, size.columns, size.rows, double(size.float32Bytes) / (1 << 20),
                            double(context.maxFloat32Bytes) / (1 << 20)));
        uint64_t folderNumber;
        {
            std::lock_guard lock(cacheMutex_);
            folderNumber = ++nextFolder_;
        }
        const fs::path folder = cacheFolder_ / fmt::format("series-{}", folderNumber);
        std::error_code ec;
        fs::remove_all(folder, ec);
        fs::create_directories(folder);
        // The stored bytes are bounded by what the budget allows in memory, with room for
        // DICOM headers and compressed or padded pixel data.
        const uint64_t maxBytes = std::max<uint64_t>(context.maxFloat32Bytes, uint64_t(64) << 20);
        const auto deadline = context.timeLimitSeconds > 0
                                  ? started + std::chrono::duration<double>(context.timeLimitSeconds)
                                  : std::chrono::steady_clock::time_point::max();
        bool timedOut = false;
        dicomweb::RetrieveProgress got;
        try {
            got = client.retrieveSeries(
                series.studyUid, series.seriesUid, folder, maxBytes,
                [&](const dicomweb::RetrieveProgress &p) {
                    const double total = double(std::max<int64_t>(p.instancesTotal, 1));
                    context.progress({"retrieving instances", std::min(1.0, double(p.instancesDone) / total),
                                      p.instancesDone, p.instancesTotal, p.bytes});
                },
                [&] {
                    if (std::chrono::steady_clock::now() > deadline) timedOut = true;
                    return timedOut || context.stopRequested();
                },
                size.instances);
        } catch (...) {
            fs::remove_all(folder, ec);
            throw;
        }
        const uint64_t bytes = folderBytes(folder);
        {
            std::lock_guard lock(cacheMutex_);
            trimCache(bytes);
            cache_[key] = {folder, bytes, ++useClock_, 1};
        }
        spdlog::info("{}: retrieved {} instances, {} MiB in {:.2f} s", name, got.instancesDone, bytes >> 20,
                     std::chrono::duration<double>(std::chrono::steady_clock::now() - started).count());
        return {folder, FetchedVolume::Form::Source, SeriesIdentity{series.studyUid, series.seriesUid}};
    } catch (const dicomweb::DicomWebError &e) {
        if (e.kind == dicomweb::ErrorKind::Cancelled && context.stopRequested())
            throw VolumeFetchError(ErrorCode::Busy, name + ": the server is shutting down");
        if (e.kind == dicomweb::ErrorKind::Cancelled)
            throw VolumeFetchError(ErrorCode::LoadFailed,
                                   fmt::format("{}: retrieval stopped after the load time limit of {} s (--load-timeout-s)",
                                               name, context.timeLimitSeconds));
        const ErrorCode code = e.kind == dicomweb::ErrorKind::NotFound ? ErrorCode::NotFound : ErrorCode::LoadFailed;
        throw VolumeFetchError(code, name + ": " + explain(e, config));
    }
}

void DicomWebProvider::trimCache(uint64_t keepRoomFor) {
    uint64_t used = 0;
    for (const auto &[k, c] : cache_) used += c.bytes;
    while (used + keepRoomFor > cacheBytes_) {
        // A series a load is reading stays (retrievals run beside loads): the cache may hold
        // more than its bound until those loads end.
        auto oldest = cache_.end();
        for (auto it = cache_.begin(); it != cache_.end(); ++it)
            if (it->second.readers == 0 && (oldest == cache_.end() || it->second.lastUse < oldest->second.lastUse))
                oldest = it;
        if (oldest == cache_.end()) break;
        used -= oldest->second.bytes;
        std::error_code ec;
        // The next open retrieves it again.
        fs::remove_all(oldest->second.folder, ec);
        cache_.erase(oldest);
    }
}

void DicomWebProvider::findStudies(const protocol::FindStudiesRequest &request, uint64_t owner, StudiesDone done) {
    const auto lane = searchLanes_.find(request.source);
    if (lane == searchLanes_.end()) return done(search(request));   // names the unknown source
    auto shared = std::make_shared<StudiesDone>(std::move(done));   // one of run and dropped calls it
    const bool queued = lane->second->post(
        {owner,
         [this, request, shared] {
             StudiesResult result;
             try {
                 result = search(request);
             } catch (const std::exception &e) {
                 const dicomweb::SourceConfig *config = source(request.source);
                 const std::string what = dicomweb::CredentialScrubber(config ? config->authorization : "")(e.what());
                 spdlog::error("find_studies on {}: {}", request.source, what);
                 result = ProtocolError{ErrorCode::Internal, "internal error: " + what, request.id, "find_studies"};
             }
             (*shared)(std::move(result));
         },
         [request, shared] {
             (*shared)(ProtocolError{ErrorCode::Busy, "the server is shutting down", request.id, "find_studies"});
         }});
    if (!queued)
        (*shared)(ProtocolError{ErrorCode::Busy,
                                fmt::format("more than {} study searches wait for the source \"{}\"; try again shortly",
                                            kMaxWaitingSearches, request.source),
                                request.id, "find_studies"});
}

DicomWebProvider::StudiesResult DicomWebProvider::search(const protocol::FindStudiesRequest &request) {
    const auto failed = [&](ErrorCode code, std::string message) {
        return ProtocolError{code, std::move(message), request.id, "find_studies"};
    };
    const dicomweb::SourceConfig *config = source(request.source);
    if (!config)
        return failed(ErrorCode::NotFound,
                      "no DICOMweb source named \"" + request.source + "\" (list_volumes lists the sources)");
    dicomweb::StudyQuery query;
    query.patientName = request.filters.patientName;
    query.patientId = request.filters.patientId;
    query.studyDate = request.filters.studyDate;
    query.modality = request.filters.modality;
    query.accessionNumber = request.filters.accessionNumber;
    query.limit = request.limit;
    try {
        dicomweb::Client client(*config);
        const auto started = std::chrono::steady_clock::now();
        const std::vector<dicomweb::StudyRecord> found = client.findStudies(query);
        // Counts only: patient names and IDs stay out of the log at info level.
        spdlog::info("find_studies on {}: {} studies in {:.2f} s", request.source, found.size(),
                     std::chrono::duration<double>(std::chrono::steady_clock::now() - started).count());
        protocol::StudiesMessage m;
        m.id = request.id;
        m.source = request.source;
        for (const auto &s : found) {
            protocol::StudyInfo study{s.studyUid, s.patientName, s.patientId, s.studyDate,
                                      s.description, s.accessionNumber, s.modalities, {}};
            for (const auto &r : s.series)
                study.series.push_back({r.seriesUid, r.modality, r.description, r.instances,
                                        std::string(kDicomWebPrefix) + request.source + "/" + s.studyUid + "/" +
                                            r.seriesUid});
            m.studies.push_back(std::move(study));
        }
        return m;
    } catch (const dicomweb::DicomWebError &e) {
        if (e.kind == dicomweb::ErrorKind::BadQuery) return failed(ErrorCode::BadField, explain(e, *config));
        return failed(ErrorCode::SourceFailed, explain(e, *config));
    }
}

} // namespace volcast::server
