#pragma once
// Volumes users upload (POST /api/volumes), opened as "upload:<id>". The id is 128 random
// bits (getrandom) as 32 lowercase hex characters and is the only way to reach an upload:
// uploads are never listed. Each lives in a folder of its own inside a private folder
// (0700; --upload-dir, else a new folder under $TMPDIR or /tmp), on disk under a name the
// server chose, never the user's; the folder's uploads are deleted at start (a given
// --upload-dir's leftovers), at expiry, at eviction and at shutdown.
//
// An upload goes: begin() (the request's head passed its checks: a slot of its sender's)
// → the body streamed into pending->file(), its bytes reserved as they arrive (reserve()) →
// finish(), which on one of the store's parse workers parses the file in the checker process
// (a parser crash ends the child, not the server) and keeps what the child handed back in
// place of the file (renderer/io/volume_io.hpp's parseToKeep): opening the upload reads that
// back, checked again, without parsing the file a second time. The storage limits count the
// parsed file, which the checker may not make larger than the room its sender has left.
// Limits: bytes per upload, uploads at once per sender, storage per sender (its quota) and in
// all, a lifetime from arrival. Storage is counted per sender (ClientIdentity): a sender may
// evict its own least recently opened uploads to make room for its new one, never another's;
// when the others' uploads fill the storage, the newcomer is refused (507). Parses run a few
// at once; the next goes to the sender with the fewest running, so one sender's queue does not
// hold back another's upload. An upload that expires or is evicted is reported to the forget
// hook (the registry then drops its loaded copy).

#include "server/config.hpp"
#include "server/volume_provider.hpp"

#include <array>
#include <chrono>
#include <condition_variable>
#include <deque>
#include <filesystem>
#include <functional>
#include <map>
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <string_view>
#include <thread>
#include <variant>
#include <vector>

namespace volcast::server {

// Who an upload belongs to: its storage is counted, and its parse takes its turn, per
// identity. Today that is the client's IP address: the server's --token is one secret shared
// by every client, so it tells no two apart. A per-user identity (a login's subject) would be
// another kind of key here, and nothing else in the store would change.
class ClientIdentity {
  public:
    static ClientIdentity ofAddress(std::string_view address) { return ClientIdentity("address " + std::string(address)); }
    auto operator<=>(const ClientIdentity &) const = default;

  private:
    explicit ClientIdentity(std::string key) : key_(std::move(key)) {}
    std::string key_;   // the kind and the value: "address 127.0.0.1"
};

// Why an upload is refused: the HTTP status and one line for the client (no server path).
struct UploadRefusal {
    int status = 400;
    std::string message;
};

// Why `filename` cannot name an upload (400), or nullopt: it must be UTF-8, 1..255 bytes, with
// no '/', '\\', NUL or other control characters.
std::optional<std::string> uploadFilenameProblem(std::string_view filename);
// The format's extension of `filename` in lower case (".nrrd", ".nii", ".nii.gz", ".mha",
// ".zip"), or nullopt for any other (415).
std::optional<std::string> uploadExtension(std::string_view filename);

class UploadStore : public VolumeProvider {
  public:
    static constexpr std::string_view kPrefix = "upload:";

    // Creates (or empties of its own leftovers) the upload folder; throws std::runtime_error
    // naming the folder when it cannot be made private.
    explicit UploadStore(const ServerConfig &config);
    // Stops the worker and deletes every upload (and the folder when the store made it).
    ~UploadStore() override;
    UploadStore(const UploadStore &) = delete;
    UploadStore &operator=(const UploadStore &) = delete;

    // Called (without the store's lock, on whichever thread expired or evicted it) with the
    // name of each upload that is gone.
    void setForgetHook(std::function<void(const std::string &name)> hook);

    std::string_view prefix() const override { return kPrefix; }
    std::optional<protocol::ProtocolError> check(const std::string &name) const override;
    FetchedVolume fetch(const std::string &name, const FetchContext &context) override;

    // One upload under way: its sender's slot and reserved room, released when the last
    // reference goes; its folder is deleted then unless finish() kept it.
    class Pending {
      public:
        ~Pending();
        Pending(const Pending &) = delete;
        Pending &operator=(const Pending &) = delete;
        const std::filesystem::path &file() const { return file_; }
        const std::string &filename() const { return filename_; }

      private:
        friend class UploadStore;
        Pending() = default;
        UploadStore *store_ = nullptr;
        std::optional<ClientIdentity> owner_;
        std::string id_, filename_;
        std::filesystem::path folder_, file_;
        uint64_t reserved_ = 0;
        bool kept_ = false;
    };

    // The request's head passed its checks (name, extension, token, length): a slot of
    // `owner`'s (429 past --max-uploads-per-address), nothing reserved yet; 507 when
    // `declaredBytes` could not fit even now (over its quota, or the storage full of others').
    std::variant<std::shared_ptr<Pending>, UploadRefusal> begin(const ClientIdentity &owner, const std::string &filename,
                                                                std::optional<uint64_t> declaredBytes);
    // The body has `total` bytes so far: they are reserved, evicting the sender's own least
    // recently opened uploads as needed; 507 naming the limit when they cannot be.
    std::optional<UploadRefusal> reserve(Pending &pending, uint64_t total);

    struct Accepted {
        std::string volume;   // "upload:<id>"
        std::string filename;
        uint64_t bytes = 0;
        double expiresInSeconds = 0;
        std::array<int64_t, 3> dims{};
        std::string voxelType;
    };
    using Result = std::variant<Accepted, UploadRefusal>;
    // The body is all in pending->file() (`bytes` of it): parse it on a parse worker and keep
    // it (201) or refuse it (422 naming the problem; 507 without room). `done` runs on the
    // worker thread; it is dropped uncalled when the store stops first.
    void finish(std::shared_ptr<Pending> pending, uint64_t bytes, std::function<void(Result)> done);

    uint64_t maxUploadBytes() const { return maxUploadBytes_; }
    const std::filesystem::path &folder() const { return folder_; }
    // Uploads kept now (tests).
    size_t count() const;
    // Uploads waiting for a parse worker (tests).
    size_t queued() const;

  private:
    // The checker's parse of an upload, the one file its folder keeps.
    static constexpr const char *kParsedName = "parsed.volcast";
    struct Record {
        ClientIdentity owner;
        std::filesystem::path folder, parsed;
        std::string filename;
        uint64_t bytes = 0;   // of the parsed file
        std::chrono::steady_clock::time_point created, lastUse;
    };
    struct Job {
        std::shared_ptr<Pending> pending;
        uint64_t bytes = 0;
        std::function<void(Result)> done;
    };

    // What one sender holds: kept and reserved bytes, uploads under way.
    struct OwnerUse {
        uint64_t kept = 0, reserved = 0;
        int uploading = 0;
    };
    // One sender's uploads waiting for a parse, and its parses running.
    struct OwnerQueue {
        std::deque<Job> jobs;
        int parsing = 0;
        uint64_t lastTurn = 0;   // when it was last given a worker (0: never)
    };

    void release(Pending &pending);
    void work();
    Result verify(Job &job);
    // With mutex_ held: the ids of expired uploads, removed from the map (their folders are
    // deleted and the hook told by the caller, outside the lock).
    std::vector<std::pair<std::string, Record>> takeExpired(std::chrono::steady_clock::time_point now) const;
    // With mutex_ held: the bytes `owner` could add after evicting every upload of its own.
    uint64_t roomFor(const ClientIdentity &owner) const;
    // With mutex_ held: evict `owner`'s own unused uploads, least recently opened first, until
    // `bytes` more of its fit; the refusal (nothing evicted) when they cannot.
    std::optional<UploadRefusal> makeRoom(const ClientIdentity &owner, uint64_t bytes,
                                          std::vector<std::pair<std::string, Record>> &evicted);
    // With mutex_ held: why `bytes` more of `owner`'s cannot fit even evicting all its own.
    std::optional<UploadRefusal> noRoom(const ClientIdentity &owner, uint64_t bytes) const;
    void dropIfIdle(const ClientIdentity &owner) const;
    void forgetAll(std::vector<std::pair<std::string, Record>> &gone) const;
    std::string notFoundMessage(const std::string &name) const;
    std::optional<std::string> idOf(const std::string &name) const;

    const uint64_t maxUploadBytes_;
    const int maxPerAddress_;
    const uint64_t maxStorageBytes_;
    const uint64_t quotaBytes_;
    const std::chrono::duration<double> ttl_;
    const uint64_t maxLoadBytes_;
    const double loadTimeoutS_;
    std::filesystem::path folder_;
    bool ownFolder_ = false;   // made here: removed whole at the end

    mutable std::mutex mutex_;
    mutable std::map<std::string, Record> uploads_;
    mutable std::map<ClientIdentity, OwnerUse> owners_;
    mutable uint64_t stored_ = 0;
    uint64_t reserved_ = 0;
    std::function<void(const std::string &)> forget_;
    std::map<ClientIdentity, OwnerQueue> queues_;
    size_t queued_ = 0;
    uint64_t turns_ = 0;
    std::condition_variable wake_;
    bool stopping_ = false;
    std::vector<std::thread> workers_;
};

} // namespace volcast::server
