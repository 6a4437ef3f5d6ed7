#pragma once
// The volumes the server can open, found only inside its data folders, and the ones in
// memory. A volume is loaded once and shared: sessions hold a shared_ptr to its entry, so an
// entry whose only owner is the registry is unused and may be evicted when a new load needs
// its memory (least recently opened first). Loads run on one loader thread; every session
// waiting for a volume gets its progress and its result through callbacks, which the
// sessions post to their own strands.

#include "protocol/errors.hpp"
#include "protocol/server_messages.hpp"
#include "renderer/opencl_renderer.hpp"
#include "renderer/volume.hpp"
#include "server/metrics.hpp"

#include <atomic>
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

    VolumeRegistry(std::vector<std::filesystem::path> dataDirs, uint64_t budgetBytes, OpenClContext &cl,
                   Metrics &metrics);
    ~VolumeRegistry();   // stops the loader after its current load

    // Every volume a client may open: built-in ones and files with known extensions.
    std::vector<protocol::VolumeInfo> list() const;
    // Open `name` (already through validateVolumeName): at once if loaded, else joining or
    // starting its load. progress and done are called from the loader thread (or this one).
    void open(const std::string &name, Progress progress, Done done);
    bool isLoaded(const std::string &name) const;
    void stop();

    // The file `name` stands for, or an error (not_found) when there is none inside a data
    // folder once links are resolved. Exposed for tests.
    std::variant<std::filesystem::path, protocol::ProtocolError> resolve(const std::string &name) const;

  private:
    struct Waiter {
        Progress progress;
        Done done;
    };
    struct Pending {
        std::string name;
        std::filesystem::path path;   // empty for built-ins
        std::vector<Waiter> waiters;
    };
    void loaderLoop();
    Result load(Pending &pending);
    void progress(const std::string &name, protocol::ProgressStage stage, const std::string &task, double fraction);
    bool makeRoom(uint64_t bytes);   // evict unused entries; false if it cannot fit
    void publishMemory();

    std::vector<std::filesystem::path> dataDirs_;   // canonical
    uint64_t budgetBytes_;
    OpenClContext &cl_;
    Metrics &metrics_;

    mutable std::mutex mutex_;
    std::condition_variable wake_;
    std::map<std::string, std::shared_ptr<VolumeEntry>> loaded_;
    std::map<std::string, uint64_t> lastUse_;   // open counter, for least-recently-opened eviction
    uint64_t useClock_ = 0;
    std::map<std::string, std::shared_ptr<Pending>> pending_;
    std::deque<std::shared_ptr<Pending>> queue_;
    bool stopping_ = false;
    std::thread loader_;
};

// Extensions the listing shows (lower case): .nhdr .nrrd .mha .mhd .nii .nii.gz.
bool hasVolumeExtension(const std::filesystem::path &p);

} // namespace volcast::server
