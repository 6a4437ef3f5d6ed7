#include "server/upload_store.hpp"

#include "renderer/io/volume_io.hpp"
#include "server/upload_ids.hpp"

#include <spdlog/fmt/fmt.h>
#include <spdlog/spdlog.h>

#include <sys/random.h>
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <cstdlib>
#include <cstring>
#include <stdexcept>

namespace volcast::server {

namespace fs = std::filesystem;
using Clock = std::chrono::steady_clock;

namespace {

constexpr size_t kIdHexChars = 32;   // 128 bits

bool isHex(std::string_view s, size_t digits) {
    return s.size() == digits &&
           std::all_of(s.begin(), s.end(), [](char c) { return (c >= '0' && c <= '9') || (c >= 'a' && c <= 'f'); });
}

bool isId(std::string_view s) { return isHex(s, kIdHexChars); }

// An upload's folder is named by its id's SHA-256 (upload_ids.hpp), never by the id.
bool isFolderName(std::string_view s) { return isHex(s, 64); }

std::string newId() {
    unsigned char bytes[kIdHexChars / 2];
    size_t got = 0;
    while (got < sizeof bytes) {
        const ssize_t n = ::getrandom(bytes + got, sizeof bytes - got, 0);
        if (n < 0) {
            if (errno == EINTR) continue;
            throw std::runtime_error(std::string("getrandom failed: ") + std::strerror(errno));
        }
        got += size_t(n);
    }
    std::string id;
    for (const unsigned char b : bytes) id += fmt::format("{:02x}", b);
    return id;
}

// Valid UTF-8 (no overlong forms, no surrogates, nothing past U+10FFFF).
bool validUtf8(std::string_view s) {
    size_t i = 0;
    while (i < s.size()) {
        const auto c = (unsigned char)s[i];
        int more = 0;
        uint32_t cp = 0;
        if (c < 0x80) {
            ++i;
            continue;
        } else if ((c & 0xE0) == 0xC0) {
            more = 1, cp = c & 0x1F;
        } else if ((c & 0xF0) == 0xE0) {
            more = 2, cp = c & 0x0F;
        } else if ((c & 0xF8) == 0xF0) {
            more = 3, cp = c & 0x07;
        } else {
            return false;
        }
        if (i + size_t(more) >= s.size()) return false;
        for (int k = 1; k <= more; ++k) {
            const auto d = (unsigned char)s[i + size_t(k)];
            if ((d & 0xC0) != 0x80) return false;
            cp = (cp << 6) | (d & 0x3F);
        }
        if ((more == 1 && cp < 0x80) || (more == 2 && cp < 0x800) || (more == 3 && cp < 0x10000) || cp > 0x10FFFF ||
            (cp >= 0xD800 && cp <= 0xDFFF))
            return false;
        i += size_t(more) + 1;
    }
    return true;
}

// Bytes as MiB for a message, one decimal.
std::string mib(uint64_t bytes) { return fmt::format("{:.1f} MiB", double(bytes) / double(1 << 20)); }

std::string lower(std::string_view s) {
    std::string out(s);
    std::transform(out.begin(), out.end(), out.begin(), [](unsigned char c) { return char(std::tolower(c)); });
    return out;
}

void removeFolder(const fs::path &folder) {
    std::error_code ec;
    fs::remove_all(folder, ec);
    if (ec) spdlog::warn("uploads: cannot delete {}: {}", folder.string(), ec.message());
}

// The folder for uploads: given (made if missing, our leftovers in it deleted) or a new one.
fs::path makeFolder(const fs::path &given, bool &own) {
    if (given.empty()) {
        const char *tmp = std::getenv("TMPDIR");
        std::string pattern = (((tmp && *tmp) ? fs::path(tmp) : fs::path("/tmp")) / "volcast-uploads-XXXXXX").string();
        if (!::mkdtemp(pattern.data()))   // mkdtemp makes it 0700
            throw std::runtime_error(fmt::format("cannot create the upload folder {}: {}", pattern, std::strerror(errno)));
        own = true;
        return pattern;
    }
    std::error_code ec;
    fs::create_directories(given, ec);
    struct stat st{};
    if (::lstat(given.c_str(), &st) != 0 || !S_ISDIR(st.st_mode))
        throw std::runtime_error(fmt::format("the upload folder {} is not a folder (a link is not taken)", given.string()));
    if (st.st_uid != ::geteuid())
        throw std::runtime_error(fmt::format("the upload folder {} belongs to another user", given.string()));
    if (::chmod(given.c_str(), 0700) != 0)
        throw std::runtime_error(
            fmt::format("cannot make the upload folder {} private: {}", given.string(), std::strerror(errno)));
    // Only what this server would have made there: a given folder may hold other things.
    for (const auto &entry : fs::directory_iterator(given, ec))
        if (const std::string name = entry.path().filename().string(); isFolderName(name) || isId(name))
            removeFolder(entry.path());   // isId: a folder of an older server, named by the id itself
    own = false;
    return given;
}

} // namespace

std::optional<std::string> uploadFilenameProblem(std::string_view name) {
    if (name.empty()) return "the file name is empty";
    if (name.size() > 255) return fmt::format("the file name is {} bytes long, over 255", name.size());
    if (!validUtf8(name)) return "the file name is not valid UTF-8";
    for (const char c : name) {
        if (c == '/' || c == '\\') return "the file name holds a '/' or '\\' (give the name only, not a path)";
        if ((unsigned char)c < 0x20 || c == 0x7f) return "the file name holds a control character";
    }
    return std::nullopt;
}

std::optional<std::string> uploadExtension(std::string_view name) {
    const std::string l = lower(name);
    for (const char *ext : {".nii.gz", ".nrrd", ".nii", ".mha", ".zip"})
        if (l.size() > std::strlen(ext) && l.ends_with(ext)) return std::string(ext);
    return std::nullopt;
}

UploadStore::UploadStore(const ServerConfig &config)
    : maxUploadBytes_(config.maxUploadBytes), maxPerAddress_(config.maxUploadsPerAddress),
      maxStorageBytes_(config.maxUploadStorageBytes), quotaBytes_(config.uploadQuotaBytes),
      ttl_(config.uploadTtlSeconds), maxLoadBytes_(config.memoryBudgetBytes), loadTimeoutS_(config.loadTimeoutS) {
    folder_ = makeFolder(config.uploadDir, ownFolder_);
    spdlog::debug("uploads: kept in {}", folder_.string());
    for (int i = 0; i < std::max(1, config.uploadParseWorkers); ++i) workers_.emplace_back([this] { work(); });
}

UploadStore::~UploadStore() {
    std::map<ClientIdentity, OwnerQueue> dropped;
    {
        std::lock_guard lock(mutex_);
        stopping_ = true;
        dropped.swap(queues_);
        queued_ = 0;
    }
    wake_.notify_all();
    for (auto &worker : workers_)
        if (worker.joinable()) worker.join();
    dropped.clear();   // their Pending release into the store: while it is whole
    std::lock_guard lock(mutex_);
    for (const auto &[id, record] : uploads_) removeFolder(record.folder);
    uploads_.clear();
    if (ownFolder_) removeFolder(folder_);
}

void UploadStore::setForgetHook(std::function<void(const std::string &)> hook) {
    std::lock_guard lock(mutex_);
    forget_ = std::move(hook);
}

size_t UploadStore::count() const {
    std::lock_guard lock(mutex_);
    return uploads_.size();
}

size_t UploadStore::queued() const {
    std::lock_guard lock(mutex_);
    return queued_;
}

std::optional<std::string> UploadStore::idOf(const std::string &name) const {
    if (!name.starts_with(kPrefix)) return std::nullopt;
    const std::string id = name.substr(kPrefix.size());
    return isId(id) ? std::optional(id) : std::nullopt;
}

std::string UploadStore::notFoundMessage(const std::string &name) const {
    std::string shown = name.substr(0, 100);
    for (char &c : shown)
        if ((unsigned char)c < 0x20 || (unsigned char)c >= 0x7f) c = '?';
    return fmt::format("no uploaded volume \"{}\" (uploads expire after {:g} minutes, and a client's new upload may "
                       "replace its own least recently opened ones)",
                       shown, ttl_.count() / 60);
}

std::vector<std::pair<std::string, UploadStore::Record>> UploadStore::takeExpired(Clock::time_point now) const {
    std::vector<std::pair<std::string, Record>> gone;
    for (auto it = uploads_.begin(); it != uploads_.end();) {
        if (now - it->second.created >= ttl_) {
            stored_ -= it->second.bytes;
            owners_[it->second.owner].kept -= it->second.bytes;
            dropIfIdle(it->second.owner);
            gone.emplace_back(it->first, std::move(it->second));
            it = uploads_.erase(it);
        } else {
            ++it;
        }
    }
    return gone;
}

void UploadStore::forgetAll(std::vector<std::pair<std::string, Record>> &gone) const {
    std::function<void(const std::string &)> hook;
    {
        std::lock_guard lock(mutex_);
        hook = forget_;
    }
    for (const auto &[id, record] : gone) {
        spdlog::info("uploads: deleted {}", hideUploadIds(std::string(kPrefix) + id));
        removeFolder(record.folder);
        if (hook) hook(std::string(kPrefix) + id);
    }
}

std::optional<protocol::ProtocolError> UploadStore::check(const std::string &name) const {
    const auto id = idOf(name);
    std::vector<std::pair<std::string, Record>> gone;
    bool found = false;
    {
        std::lock_guard lock(mutex_);
        gone = takeExpired(Clock::now());
        if (id) {
            const auto it = uploads_.find(*id);
            if (it != uploads_.end()) {
                found = true;
                it->second.lastUse = Clock::now();
            }
        }
    }
    forgetAll(gone);
    if (found) return std::nullopt;
    protocol::ProtocolError e;
    e.code = protocol::ErrorCode::NotFound;
    e.message = notFoundMessage(name);
    return e;
}

FetchedVolume UploadStore::fetch(const std::string &name, const FetchContext &) {
    const auto id = idOf(name);
    std::lock_guard lock(mutex_);
    const auto it = id ? uploads_.find(*id) : uploads_.end();
    if (it == uploads_.end() || Clock::now() - it->second.created >= ttl_)
        throw VolumeFetchError(protocol::ErrorCode::NotFound, notFoundMessage(name));
    it->second.lastUse = Clock::now();
    return {it->second.parsed, FetchedVolume::Form::Parsed};
}

void UploadStore::dropIfIdle(const ClientIdentity &owner) const {
    const auto it = owners_.find(owner);
    if (it != owners_.end() && it->second.kept == 0 && it->second.reserved == 0 && it->second.uploading == 0)
        owners_.erase(it);
}

uint64_t UploadStore::roomFor(const ClientIdentity &owner) const {
    const auto it = owners_.find(owner);
    const OwnerUse use = it == owners_.end() ? OwnerUse{} : it->second;
    const uint64_t others = stored_ + reserved_ - use.kept - use.reserved;
    const uint64_t storageRoom = maxStorageBytes_ > others + use.reserved ? maxStorageBytes_ - others - use.reserved : 0;
    const uint64_t quotaRoom = quotaBytes_ > use.reserved ? quotaBytes_ - use.reserved : 0;
    return std::min(storageRoom, quotaRoom);
}

std::optional<UploadRefusal> UploadStore::noRoom(const ClientIdentity &owner, uint64_t bytes) const {
    if (bytes <= roomFor(owner)) return std::nullopt;
    const auto it = owners_.find(owner);
    const uint64_t reserved = it == owners_.end() ? 0 : it->second.reserved;
    if (reserved + bytes > quotaBytes_)
        return UploadRefusal{507, fmt::format("this client's uploads would take {}, more than the {} of upload storage "
                                              "one client may hold (server flag --upload-quota-mib)",
                                              mib(reserved + bytes), mib(quotaBytes_))};
    return UploadRefusal{507, fmt::format("the upload storage is full: {} more do not fit in its {}, which other "
                                          "clients' uploads hold until they expire (server flag "
                                          "--max-upload-storage-mib); try again later",
                                          mib(bytes), mib(maxStorageBytes_))};
}

std::optional<UploadRefusal> UploadStore::makeRoom(const ClientIdentity &owner, uint64_t bytes,
                                                   std::vector<std::pair<std::string, Record>> &evicted) {
    if (auto refusal = noRoom(owner, bytes)) return refusal;
    OwnerUse &use = owners_[owner];
    const auto fits = [&] {
        return stored_ + reserved_ + bytes <= maxStorageBytes_ && use.kept + use.reserved + bytes <= quotaBytes_;
    };
    while (!fits()) {
        // Only the owner's own: what others keep is never taken to make room.
        auto oldest = uploads_.end();
        for (auto it = uploads_.begin(); it != uploads_.end(); ++it)
            if (it->second.owner == owner && (oldest == uploads_.end() || it->second.lastUse < oldest->second.lastUse))
                oldest = it;
        if (oldest == uploads_.end()) break;   // roomFor said it would fit: not reached
        stored_ -= oldest->second.bytes;
        use.kept -= oldest->second.bytes;
        evicted.emplace_back(oldest->first, std::move(oldest->second));
        uploads_.erase(oldest);
    }
    return std::nullopt;
}

std::variant<std::shared_ptr<UploadStore::Pending>, UploadRefusal>
UploadStore::begin(const ClientIdentity &owner, const std::string &filename, std::optional<uint64_t> declaredBytes) {
    std::vector<std::pair<std::string, Record>> gone;
    std::shared_ptr<Pending> pending(new Pending());
    std::optional<UploadRefusal> refusal;
    {
        std::lock_guard lock(mutex_);
        gone = takeExpired(Clock::now());
        if (stopping_) {
            refusal = UploadRefusal{503, "the server is shutting down"};
        } else if (const auto it = owners_.find(owner); it != owners_.end() && it->second.uploading >= maxPerAddress_) {
            refusal = UploadRefusal{429, fmt::format("{} uploads from this address are already under way, the most "
                                                     "at once (server flag --max-uploads-per-address)",
                                                     it->second.uploading)};
        } else if (auto full = noRoom(owner, declaredBytes.value_or(0))) {
            // Nothing is reserved until bytes arrive: a head alone holds no room.
            refusal = std::move(full);
        } else {
            pending->store_ = this;
            pending->id_ = newId();
            pending->owner_ = owner;
            pending->filename_ = filename;
            pending->folder_ = folder_ / uploadFolderName(pending->id_);
            pending->file_ = pending->folder_ / ("volume" + uploadExtension(filename).value_or(".bin"));
            ++owners_[owner].uploading;
        }
    }
    forgetAll(gone);
    if (refusal) return *refusal;
    std::error_code ec;
    if (!fs::create_directory(pending->folder_, ec) || ec)
        return UploadRefusal{500, "cannot store the upload: " + (ec ? ec.message() : std::string("id in use"))};
    return pending;
}

UploadStore::Pending::~Pending() {
    if (store_) store_->release(*this);
}

std::optional<UploadRefusal> UploadStore::reserve(Pending &p, uint64_t total) {
    if (total <= p.reserved_) return std::nullopt;
    std::vector<std::pair<std::string, Record>> evicted;
    std::optional<UploadRefusal> refusal;
    {
        std::lock_guard lock(mutex_);
        const uint64_t more = total - p.reserved_;
        refusal = makeRoom(*p.owner_, more, evicted);
        if (!refusal) {
            reserved_ += more;
            owners_[*p.owner_].reserved += more;
            p.reserved_ = total;
        }
    }
    forgetAll(evicted);
    return refusal;
}

void UploadStore::release(Pending &p) {
    {
        std::lock_guard lock(mutex_);
        OwnerUse &use = owners_[*p.owner_];
        reserved_ -= p.reserved_;
        use.reserved -= p.reserved_;
        --use.uploading;
        dropIfIdle(*p.owner_);
    }
    if (!p.kept_) removeFolder(p.folder_);
}

void UploadStore::finish(std::shared_ptr<Pending> pending, uint64_t bytes, std::function<void(Result)> done) {
    {
        std::lock_guard lock(mutex_);
        if (stopping_) return;
        const ClientIdentity owner = *pending->owner_;
        queues_[owner].jobs.push_back(Job{std::move(pending), bytes, std::move(done)});
        ++queued_;
    }
    wake_.notify_one();
}

void UploadStore::work() {
    // Expired uploads are deleted at least this often, even with no request coming.
    const auto sweepEvery = std::chrono::duration_cast<Clock::duration>(
        std::clamp(ttl_ / 10, std::chrono::duration<double>(0.05), std::chrono::duration<double>(30)));
    std::unique_lock lock(mutex_);
    while (!stopping_) {
        wake_.wait_for(lock, sweepEvery, [&] { return stopping_ || queued_ > 0; });
        if (stopping_) break;
        auto gone = takeExpired(Clock::now());
        std::optional<Job> job;
        std::optional<ClientIdentity> owner;
        // The sender with the fewest parses running goes next, and among those the one that
        // waited longest for a turn: one sender's queue does not hold back another's upload.
        auto next = queues_.end();
        for (auto it = queues_.begin(); it != queues_.end(); ++it)
            if (!it->second.jobs.empty() &&
                (next == queues_.end() || std::pair(it->second.parsing, it->second.lastTurn) <
                                              std::pair(next->second.parsing, next->second.lastTurn)))
                next = it;
        if (next != queues_.end()) {
            job = std::move(next->second.jobs.front());
            next->second.jobs.pop_front();
            ++next->second.parsing;
            next->second.lastTurn = ++turns_;
            --queued_;
            owner = next->first;
        }
        lock.unlock();
        forgetAll(gone);
        if (job) {
            Result result = verify(*job);
            // A refused upload's file is gone before the client hears of it.
            auto done = std::move(job->done);
            job.reset();
            done(std::move(result));
        }
        lock.lock();
        if (owner) {
            const auto it = queues_.find(*owner);
            if (it != queues_.end() && --it->second.parsing == 0 && it->second.jobs.empty()) queues_.erase(it);
        }
    }
}

UploadStore::Result UploadStore::verify(Job &job) {
    Pending &p = *job.pending;
    LoadOptions options;
    options.parseInChild = true;
    options.maxBytes = maxLoadBytes_;
    options.maxArchiveBytes = maxUploadBytes_;
    options.timeLimitSeconds = loadTimeoutS_;
    {
        // The parse may keep what its sender has room for: what it reserved for the body
        // (given back once the parse replaces the file) and what evicting its own would free.
        std::lock_guard lock(mutex_);
        options.maxResultBytes = roomFor(*p.owner_) + p.reserved_;
    }
    options.stopRequested = [this] {
        std::lock_guard lock(mutex_);
        return stopping_;
    };
    Accepted accepted;
    // What the checker parsed is kept, not the file: opening the upload reads it back without
    // a second parse (an upload may never be opened, and the registry's budget decides what
    // stays in memory, so nothing is held here).
    const fs::path parsed = p.folder_ / kParsedName;
    uint64_t keptBytes = 0;
    try {
        const ParsedVolumeSummary summary = parseToKeep(p.file_, parsed, options);
        accepted.dims = summary.dims;
        accepted.voxelType = std::string(voxelTypeName(summary.sourceType));
        std::error_code ec;
        fs::remove(p.file_, ec);
        keptBytes = fs::file_size(parsed);
    } catch (const std::exception &e) {
        // The loader names the file by its path: the client sees its own file name instead.
        std::string message = e.what();
        for (const std::string &path : {p.file_.string(), p.folder_.string(), folder_.string()})
            for (size_t at; (at = message.find(path)) != std::string::npos;)
                message.replace(at, path.size(), path == p.file_.string() ? p.filename_ : "");
        // The file name may name a patient: at debug level only.
        spdlog::info("uploads: refused an upload of {} bytes", job.bytes);
        spdlog::debug("uploads: refused {}: {}", p.filename_, message);
        // Too large once parsed for the room its sender has left: refused before it was written.
        if (dynamic_cast<const VolumeOverResultLimit *>(&e))
            return UploadRefusal{507, message + " (server flags --upload-quota-mib, --max-upload-storage-mib)"};
        return UploadRefusal{422, message};
    }
    std::vector<std::pair<std::string, Record>> evicted;
    std::optional<UploadRefusal> refusal;
    {
        std::lock_guard lock(mutex_);
        // What the body reserved is this upload's own room.
        reserved_ -= p.reserved_;
        owners_[*p.owner_].reserved -= p.reserved_;
        p.reserved_ = 0;
        if (auto full = makeRoom(*p.owner_, keptBytes, evicted)) {
            refusal = UploadRefusal{507, "no room for it as parsed: " + full->message};
        } else {
            const auto now = Clock::now();
            uploads_.emplace(p.id_, Record{*p.owner_, p.folder_, parsed, p.filename_, keptBytes, now, now});
            stored_ += keptBytes;
            owners_[*p.owner_].kept += keptBytes;
            p.kept_ = true;
        }
    }
    forgetAll(evicted);
    if (refusal) return *refusal;
    accepted.volume = std::string(kPrefix) + p.id_;
    accepted.filename = p.filename_;
    accepted.bytes = job.bytes;
    accepted.expiresInSeconds = ttl_.count();
    spdlog::info("uploads: kept {} ({} bytes, {} x {} x {} {})", hideUploadIds(accepted.volume), job.bytes, accepted.dims[0],
                 accepted.dims[1], accepted.dims[2], accepted.voxelType);
    return accepted;
}

} // namespace volcast::server
