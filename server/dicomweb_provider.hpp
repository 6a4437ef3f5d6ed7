#pragma once
// The DICOMweb sources a server is configured with (--dicomweb NAME=URL): study searches for
// find_studies, and series opened as "dicomweb:SOURCE/STUDY_UID/SERIES_UID". A series is
// checked against the memory budget from its metadata, then retrieved (WADO-RS) into a
// server-private cache folder, one file per instance, and loaded from there as any DICOM
// folder is: parsed first in the child process. Retrieved series stay cached on disk by
// source and series (bounded in bytes, oldest dropped first; the folder is removed when the
// server stops), so a series evicted from memory is loaded again without a new retrieval.
//
// Searches run on a thread of their own, never on the network threads: a slow PACS delays
// only the sessions that asked it. Patient names are never logged at info level.

#include "dicomweb/dicomweb_client.hpp"
#include "protocol/client_messages.hpp"
#include "protocol/server_messages.hpp"
#include "server/volume_provider.hpp"

#include <condition_variable>
#include <deque>
#include <filesystem>
#include <functional>
#include <map>
#include <memory>
#include <mutex>
#include <string>
#include <thread>
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
    // emptied now and removed with its contents when the provider goes.
    DicomWebProvider(std::vector<dicomweb::SourceConfig> sources, std::filesystem::path cacheFolder,
                     uint64_t cacheBytes);
    ~DicomWebProvider() override;

    std::string_view prefix() const override { return kDicomWebPrefix; }
    std::optional<protocol::ProtocolError> check(const std::string &name) const override;
    FetchedVolume fetch(const std::string &name, const FetchContext &context) override;

    std::vector<protocol::SourceInfo> sources() const;
    // Queue a search; done is called on the search thread with the studies or an error
    // (not_found for an unknown source, source_failed naming what the source answered, busy
    // when too many searches wait).
    void findStudies(const protocol::FindStudiesRequest &request, StudiesDone done);

  private:
    struct Search {
        protocol::FindStudiesRequest request;
        StudiesDone done;
    };
    struct Cached {
        std::filesystem::path folder;
        uint64_t bytes = 0;
        uint64_t lastUse = 0;
    };
    const dicomweb::SourceConfig *source(const std::string &name) const;
    StudiesResult search(const protocol::FindStudiesRequest &request);
    void searchLoop();
    void trimCache(uint64_t keepRoomFor);

    std::vector<dicomweb::SourceConfig> sources_;
    std::filesystem::path cacheFolder_;
    uint64_t cacheBytes_;

    std::mutex cacheMutex_;
    std::map<std::string, Cached> cache_;   // by "SOURCE/STUDY/SERIES"
    uint64_t useClock_ = 0;
    uint64_t nextFolder_ = 0;

    std::mutex searchMutex_;
    std::condition_variable searchWake_;
    std::deque<Search> searches_;
    bool stopping_ = false;
    std::thread searchThread_;
};

} // namespace volcast::server
