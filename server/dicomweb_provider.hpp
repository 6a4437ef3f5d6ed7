#pragma once
// The DICOMweb sources a server is configured with (--dicomweb NAME=URL): study searches for
// find_studies, and series opened as "dicomweb:SOURCE/STUDY_UID/SERIES_UID". A series is
// checked against the memory budget from its metadata, then retrieved (WADO-RS) into a
// server-private cache folder, one file per instance, and loaded from there as any DICOM
// folder is: parsed first in the child process. Retrieved series stay cached on disk by
// source and series (bounded in bytes, oldest dropped first; the folder is removed when the
// server stops), so a series evicted from memory is loaded again without a new retrieval.
//
// A cached series is kept while a load reads it, and dropped at once when the loader refuses
// it (release()): a second open retrieves it again rather than loading the refused files.
//
// Searches run on their source's lane (work_lane.hpp), a few at a time (--dicomweb-searches),
// never on the network threads: a slow PACS delays only the searches of that PACS. Retrievals
// run on the registry's lane of their source (sourceOf()). Patient names are never logged at
// info level.

#include "dicomweb/dicomweb_client.hpp"
#include "protocol/client_messages.hpp"
#include "protocol/server_messages.hpp"
#include "server/volume_provider.hpp"
#include "server/work_lane.hpp"

#include <filesystem>
#include <functional>
#include <map>
#include <memory>
#include <mutex>
#include <string>
#include <variant>
#include <vector>

namespace volcast::server {

inline constexpr std::string_view kDicomWebPrefix = "dicomweb:";

// What a volume name "dicomweb:SOURCE/STUDY/SERIES" names, or why it names nothing.
struct DicomWebSeriesName {
    std::string source, studyUid, seriesUid;
};
std::variant<DicomWebSeriesName, std::string> parseDicomWebName(std::string_view name);

class DicomWebProvider final : public VolumeProvider {
  public:
    using StudiesResult = std::variant<protocol::StudiesMessage, protocol::ProtocolError>;
    using StudiesDone = std::function<void(StudiesResult)>;

    // sources: each with its name, base URL and Authorization value (may be empty).
    // cacheBytes: retrieved series kept on disk at most. cacheFolder: created, private (0700),
    // emptied now and removed with its contents when the provider goes. searchesPerSource:
    // searches running at once on one source.
    DicomWebProvider(std::vector<dicomweb::SourceConfig> sources, std::filesystem::path cacheFolder,
                     uint64_t cacheBytes, int searchesPerSource = 4);
    ~DicomWebProvider() override;

    std::string_view prefix() const override { return kDicomWebPrefix; }
    std::optional<protocol::ProtocolError> check(const std::string &name) const override;
    std::string sourceOf(const std::string &name) const override;
    FetchedVolume fetch(const std::string &name, const FetchContext &context) override;
    void release(const std::string &name, bool refused) override;

    std::vector<protocol::SourceInfo> sources() const;
    // Searches that may wait for one source, beyond those running; more: busy. A session has
    // one search at a time, so only more sessions than this searching one source meet it.
    static constexpr size_t kMaxWaitingSearches = 64;
    // Queue a search on its source's lane; done is called on that lane's thread (or this one)
    // with the studies or an error (not_found for an unknown source, source_failed naming what
    // the source answered, busy when kMaxWaitingSearches wait). owner: who asks (a session),
    // for the lane's turns.
    void findStudies(const protocol::FindStudiesRequest &request, uint64_t owner, StudiesDone done);

  private:
    struct Cached {
        std::filesystem::path folder;
        uint64_t bytes = 0;
        uint64_t lastUse = 0;
        int readers = 0;   // loads between fetch() and release(): never trimmed then
    };
    const dicomweb::SourceConfig *source(const std::string &name) const;
    StudiesResult search(const protocol::FindStudiesRequest &request);
    void trimCache(uint64_t keepRoomFor);

    std::vector<dicomweb::SourceConfig> sources_;
    std::filesystem::path cacheFolder_;
    uint64_t cacheBytes_;

    std::mutex cacheMutex_;
    std::map<std::string, Cached> cache_;   // by "SOURCE/STUDY/SERIES"
    uint64_t useClock_ = 0;
    uint64_t nextFolder_ = 0;

    std::map<std::string, std::unique_ptr<WorkLane>> searchLanes_;   // by source name, made at construction
};

} // namespace volcast::server
