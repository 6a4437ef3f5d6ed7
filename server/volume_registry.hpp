#pragma once
// The volumes the server can open, found only inside its data folders, and the ones in
// memory. A volume is loaded once and shared: every successful open() hands out a hold on
// its entry (a shared_ptr whose copies, in the session and its render jobs, all count as
// that one hold), so an entry nobody holds is unused and may be evicted when a new load
// needs its memory (least recently opened first). Every session waiting for a volume gets
// its progress and its result through callbacks, which the sessions post to their own strands.
//
// Lanes (work_lane.hpp): a provider's fetch (a PACS retrieval: network, seconds to minutes)
// runs on the lane of its source, a few at a time (retrievalsPerSource); what a volume's
// bytes become in memory (parse, checks, renderer) runs on the loads lane, one at a time, for
// local files and fetched ones alike. So a local open never waits behind a retrieval, and a
// slow source delays only the opens of that source.
//
// Memory budget: a volume larger than the whole budget is refused from its header, before
// its voxels are read. Room is made only once a new volume is loaded and ready to be
// inserted, and only if evicting enough is possible: a failed load evicts nothing. A
// session switching volumes passes the hold it will give up (`releasing`): that volume
// counts as evictable for this load when no one else holds it. The session keeps it until
// the new volume arrives; if the new load fails, nothing was evicted and it keeps it.

#include "protocol/errors.hpp"
#include "protocol/server_messages.hpp"
#include "renderer/common/frame_renderer.hpp"
#include "renderer/opencl/opencl_context.hpp"
#include "renderer/model/volume.hpp"
#include "server/metrics.hpp"
#include "server/volume_provider.hpp"
#include "server/work_lane.hpp"

#include <atomic>
#include <filesystem>
#include <functional>
#include <map>
#include <memory>
#include <mutex>
#include <optional>
#include <set>
#include <string>
#include <variant>
#include <vector>

namespace volcast::server {

// One volume in memory and the renderer that draws it; shared by the sessions that opened it.
// Ids of loaded volumes, from 1, never reused in a process: what caches key on (an
// address would be reused by the next volume loaded after an eviction).
inline uint64_t newVolumeId() {
    static std::atomic<uint64_t> next{1};
    return next++;
}

struct VolumeEntry {
    uint64_t id = newVolumeId();
    std::string name;                          // as clients name it
    std::shared_ptr<const Volume> volume;
    std::unique_ptr<FrameRenderer> renderer;  // thread-safe; serialises its frames
    uint64_t bytes = 0;                        // host memory counted against the budget
    protocol::VolumeInfo info() const;
};

class VolumeRegistry {
  public:
    using Progress = std::function<void(const protocol::ProgressMessage &)>;
    using Result = std::variant<std::shared_ptr<VolumeEntry>, protocol::ProtocolError>;
    using Done = std::function<void(Result)>;

    // cl: the OpenCL device every volume's renderer draws on; null: the native CPU path.
    // loadTimeoutSeconds: a load running longer fails (load_failed naming the limit); 0: none.
    // retrievalsPerSource: fetches running at once for one source (--dicomweb-retrievals).
    VolumeRegistry(std::vector<std::filesystem::path> dataDirs, uint64_t budgetBytes, std::shared_ptr<OpenClContext> cl,
                   Metrics &metrics, double loadTimeoutSeconds = 120, int retrievalsPerSource = 2);
    ~VolumeRegistry();   // stop()

    // Names carrying provider->prefix() are opened through it (uploads, DICOMweb), never
    // listed. Add providers before the first open.
    void addProvider(std::shared_ptr<VolumeProvider> provider);
    // Drop a loaded volume from memory (an upload that expired): sessions that hold it keep
    // it until they let go; the next open loads it again, or fails if it is gone for good.
    void forget(const std::string &name);

    // Every volume a client may open: built-in ones and files with known extensions.
    std::vector<protocol::VolumeInfo> list() const;
    // Open `name` (already through validateVolumeName): at once if loaded, else joining or
    // starting its load. progress and done are called from a lane's thread (or this one).
    // `releasing`: the hold the caller gives up once it has the new one (its current volume).
    // `owner`: who asks (a session), for the lanes' turns.
    void open(const std::string &name, Progress progress, Done done,
              const std::shared_ptr<const VolumeEntry> &releasing = nullptr, uint64_t owner = 0);
    bool isLoaded(const std::string &name) const;
    // Host memory counted against the budget by the volumes in the registry.
    uint64_t usedBytes() const;
    // The volumes being fetched or loaded now, or "" (for the shutdown log).
    std::string loadingNow() const;
    // Waiting opens are answered busy; a fetch or load in progress stops at its next step.
    void stop();

    // The file `name` stands for, or an error (not_found) when there is none inside a data
    // folder once links are resolved. Exposed for tests.
    std::variant<std::filesystem::path, protocol::ProtocolError> resolve(const std::string &name) const;

  private:
    struct Waiter {
        Progress progress;
        Done done;
        const VolumeEntry *releasing = nullptr;   // identity only: never dereferenced
    };
    struct Pending {
        std::string name;
        std::string series;             // the name without its "#stack=N" (volume_name.hpp)
        std::optional<uint32_t> stack;  // the one stack of a DICOM series asked for by name
        std::filesystem::path path;   // empty for built-ins; for a provider's volume, set once fetched
        FetchedVolume::Form form = FetchedVolume::Form::Source;
        std::shared_ptr<VolumeProvider> provider;   // null for built-ins and data-folder files
        bool fetched = false;   // the provider's fetch succeeded: release() is owed
        bool refused = false;   // the loader refused the fetched bytes (not a budget, time or shutdown failure)
        std::optional<SeriesIdentity> expectedSeries;   // what a fetched DICOM series must be (FetchedVolume)
        std::vector<Waiter> waiters;
    };
    // Queues the pending load on its lane: the provider's source's for a fetch, else loads_.
    void start(const std::shared_ptr<Pending> &pending, uint64_t owner);
    void fetchStep(const std::shared_ptr<Pending> &pending, uint64_t owner);
    void queueLoad(const std::shared_ptr<Pending> &pending, uint64_t owner);
    Result load(Pending &pending);
    // The end of every load: the volume inserted (room made) or the error, to every waiter.
    void finish(const std::shared_ptr<Pending> &pending, Result result);
    WorkLane &fetchLane(const std::string &source);   // under mutex_
    void progress(const std::string &name, protocol::ProgressStage stage, const std::string &task, double fraction);
    void progress(protocol::ProgressMessage message);
    std::shared_ptr<VolumeProvider> providerFor(const std::string &name) const;
    // The entries to evict so that `bytes` more fit, least recently opened first, or nothing
    // if they cannot be made to fit. Evictable: held by no one, or only by waiters releasing it.
    std::optional<std::vector<std::string>> planRoom(uint64_t bytes, const std::vector<Waiter> &waiters) const;
    void evict(const std::vector<std::string> &names);
    void publishMemory();
    bool evictable(const std::shared_ptr<VolumeEntry> &entry, const std::vector<Waiter> &waiters) const;
    std::string tooLargeMessage(const std::string &name, uint64_t bytes) const;
    std::string roomMessage(const std::string &name, uint64_t bytes, const std::vector<Waiter> &waiters) const;
    // A loader message fit for clients: no absolute server path (the log keeps them).
    std::string forClients(std::string message, const Pending &pending) const;

    std::vector<std::filesystem::path> dataDirs_;   // canonical
    std::vector<std::shared_ptr<VolumeProvider>> providers_;
    uint64_t budgetBytes_;
    double loadTimeoutSeconds_;
    int retrievalsPerSource_;
    std::atomic<bool> stopRequested_{false};   // read by the fetches and the load in progress at each step
    std::multiset<std::string> loading_;       // guarded by mutex_
    std::shared_ptr<OpenClContext> cl_;
    Metrics &metrics_;

    mutable std::mutex mutex_;
    std::map<std::string, std::shared_ptr<VolumeEntry>> loaded_;
    std::map<std::string, uint64_t> lastUse_;   // open counter, for least-recently-opened eviction
    uint64_t useClock_ = 0;
    std::map<std::string, std::shared_ptr<Pending>> pending_;
    bool stopping_ = false;
    std::map<std::string, std::unique_ptr<WorkLane>> fetchLanes_;   // by provider->sourceOf(); kept until destruction
    std::unique_ptr<WorkLane> loads_;                             // one at a time: the memory budget
};

// Extensions the listing shows (lower case): .nhdr .nrrd .mha .mhd .nii .nii.gz.
bool hasVolumeExtension(const std::filesystem::path &p);

} // namespace volcast::server
