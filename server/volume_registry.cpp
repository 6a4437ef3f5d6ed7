#include "server/volume_registry.hpp"

#include "renderer/model/presets.hpp"
#include "renderer/model/synthetic.hpp"
#include "renderer/io/volume_io.hpp"
#include "renderer/cpu/cpu_renderer.hpp"
#include "renderer/make_frame_renderer.hpp"
#include "renderer/io/volume_source.hpp"
#include "protocol/volume_name.hpp"
#include "server/upload_ids.hpp"

#include <spdlog/fmt/fmt.h>
#include <spdlog/spdlog.h>

#include <algorithm>
#include <limits>
#include <regex>

namespace volcast::server {

namespace fs = std::filesystem;
using protocol::ErrorCode;
using protocol::ProtocolError;

namespace {
constexpr size_t kMaxListed = 10000;   // files listed per request: a huge folder is not a hang

bool isInside(const fs::path &p, const fs::path &folder) {
    auto [f, pIt] = std::mismatch(folder.begin(), folder.end(), p.begin(), p.end());
    return f == folder.end();
}
std::string lower(std::string s) {
    std::transform(s.begin(), s.end(), s.begin(), [](unsigned char c) { return char(std::tolower(c)); });
    return s;
}
// The in-memory cost of a volume: its samples (an 8- or 16-bit scan in 1 or 2 bytes a sample,
// narrow_samples.hpp; other types as float32), and what its renderer builds from them at
// most: every mip level (float), a padded copy of B-spline coefficients of each for cubic,
// and brick grids; trilinear frames sample each level where it lies (CpuRenderer::
// plannedBytes; the OpenCL back end holds about the same, as host or device buffers).
// Counted in full at load, so that frames asking for coarse levels or cubic later never take
// the server past its budget.
uint64_t memoryOf(const Volume &v) {
    return uint64_t(v.sampleBytes()) + CpuRenderer::plannedBytes(v.dims, {}, v.narrow.bytes);
}
// The least memoryOf() / float32 voxel bytes, for refusing a file from its header: 1/4 (an
// 8-bit scan's samples) + 1/7 (mips) + 8/7 (coefficients), less rounding.
constexpr double kMemoryFactor = 1.5;
uint64_t mib(uint64_t bytes) { return (bytes + (uint64_t(1) << 20) - 1) >> 20; }

// What a session holds: every copy of the returned pointer (the session's, its render jobs')
// shares one control block holding one reference to the entry, so the entry's use count
// is the registry's own reference plus one per hold.
std::shared_ptr<VolumeEntry> holdOn(const std::shared_ptr<VolumeEntry> &entry) {
    auto hold = std::make_shared<std::shared_ptr<VolumeEntry>>(entry);
    return std::shared_ptr<VolumeEntry>(hold, entry.get());
}
} // namespace

bool hasVolumeExtension(const fs::path &p) {
    const std::string name = lower(p.filename().string());
    for (const char *ext : {".nhdr", ".nrrd", ".mha", ".mhd", ".nii", ".nii.gz"})
        if (name.size() > std::string_view(ext).size() && name.ends_with(ext)) return true;
    return false;
}

protocol::VolumeInfo VolumeEntry::info() const {
    protocol::VolumeInfo i;
    const Volume &v = *volume;
    i.name = name;
    i.loaded = true;
    i.dims = std::array<int64_t, 3>{v.dims.x, v.dims.y, v.dims.z};
    i.spacing = std::array<double, 3>{v.spacing.x, v.spacing.y, v.spacing.z};
    i.origin = std::array<double, 3>{v.origin.x, v.origin.y, v.origin.z};
    std::array<std::array<double, 3>, 3> direction{};
    for (int r = 0; r < 3; ++r)
        for (int c = 0; c < 3; ++c) direction[size_t(r)][size_t(c)] = v.direction(r, c);
    i.direction = direction;
    i.voxelType = std::string(voxelTypeName(v.sourceType));
    i.valueRange = std::array<double, 2>{v.range.min, v.range.max};
    protocol::HistogramInfo h;
    h.range = {v.histogram.range.min, v.histogram.range.max};
    h.counts = v.histogram.counts;
    i.histogram = h;
    i.orientationKnown = v.orientationKnown;
    // Built-ins are phantoms with transfer functions of their own (session_scene.cpp).
    if (!name.starts_with(kBuiltinPrefix)) {
        const ModalityChoice choice = chooseModality(v, name);
        protocol::ModalityInfo m{choice.modality, choice.source, choice.reason, choice.defaultPreset, {}, {}, false};
        for (const ResolvedPreset &p : presetsFor(v, choice))
            m.presets.push_back({p.name, p.label, p.window, p.level, p.points, p.shading, p.modality});
        m.modalities = modalitiesFor(choice);
        m.hounsfield = choice.hounsfield;
        i.modality = std::move(m);
    }
    return i;
}

VolumeRegistry::VolumeRegistry(std::vector<fs::path> dataDirs, uint64_t budgetBytes, std::shared_ptr<OpenClContext> cl,
                               Metrics &metrics, double loadTimeoutSeconds, int retrievalsPerSource)
    : budgetBytes_(budgetBytes), loadTimeoutSeconds_(loadTimeoutSeconds), retrievalsPerSource_(retrievalsPerSource),
      cl_(std::move(cl)), metrics_(metrics) {
    for (const auto &d : dataDirs) {
        std::error_code ec;
        fs::path c = fs::canonical(d, ec);
        if (ec || !fs::is_directory(c)) throw std::invalid_argument("data folder " + d.string() + ": not a folder");
        dataDirs_.push_back(c);
    }
    loads_ = std::make_unique<WorkLane>("loads", 1, std::numeric_limits<size_t>::max());
}

VolumeRegistry::~VolumeRegistry() { stop(); }

void VolumeRegistry::addProvider(std::shared_ptr<VolumeProvider> provider) {
    std::lock_guard lock(mutex_);
    providers_.push_back(std::move(provider));
}

std::shared_ptr<VolumeProvider> VolumeRegistry::providerFor(const std::string &name) const {
    std::lock_guard lock(mutex_);
    for (const auto &p : providers_)
        if (name.starts_with(p->prefix())) return p;
    return nullptr;
}

void VolumeRegistry::forget(const std::string &name) {
    std::lock_guard lock(mutex_);
    if (auto it = loaded_.find(name); it != loaded_.end()) {
        spdlog::info("dropping volume {} from memory: its source is gone", hideUploadIds(name));
        loaded_.erase(it);
        lastUse_.erase(name);
        publishMemory();
    }
}

void VolumeRegistry::stop() {
    stopRequested_ = true;   // the fetches and the load in progress stop at their next step
    std::vector<WorkLane *> lanes;
    {
        std::lock_guard lock(mutex_);
        stopping_ = true;
        for (auto &[source, lane] : fetchLanes_) lanes.push_back(lane.get());
    }
    // Fetch lanes first: a fetch that ends now still hands its volume to loads_, which then
    // answers it; every waiter gets an answer, even at shutdown.
    for (WorkLane *lane : lanes) lane->stop();
    loads_->stop();
}

std::variant<fs::path, ProtocolError> VolumeRegistry::resolve(const std::string &name) const {
    for (const fs::path &folder : dataDirs_) {
        std::error_code ec;
        // weakly_canonical follows every symbolic link of the existing part: a link that
        // points out of the folder lands outside it and is refused below.
        const fs::path p = fs::weakly_canonical(folder / fs::path(name), ec);
        if (ec || !fs::exists(p, ec)) continue;
        if (!isInside(p, folder))
            return ProtocolError{ErrorCode::NotFound,
                                 "volume \"" + name + "\" resolves outside the data folders (a symbolic link?)",
                                 nullptr, "open_volume"};
        if (!fs::is_regular_file(p, ec) && !fs::is_directory(p, ec)) continue;
        return p;
    }
    return ProtocolError{ErrorCode::NotFound, "no volume named \"" + name + "\" (list_volumes lists them)", nullptr,
                         "open_volume"};
}

std::vector<protocol::VolumeInfo> VolumeRegistry::list() const {
    std::vector<protocol::VolumeInfo> out;
    std::lock_guard lock(mutex_);
    auto add = [&](const std::string &name) {
        if (auto it = loaded_.find(name); it != loaded_.end()) {
            out.push_back(it->second->info());
        } else {
            protocol::VolumeInfo i;
            i.name = name;
            out.push_back(i);
        }
    };
    for (const auto &b : builtinVolumeNames()) add(std::string(kBuiltinPrefix) + b);
    for (const fs::path &folder : dataDirs_) {
        std::error_code ec;
        fs::recursive_directory_iterator it(folder, fs::directory_options::skip_permission_denied, ec), end;
        for (; !ec && it != end && out.size() < kMaxListed; it.increment(ec)) {
            if (!hasVolumeExtension(it->path()) || !it->is_regular_file(ec)) continue;
            std::error_code ec2;
            // Symbolic links are listed only when they stay inside the folder.
            if (!isInside(fs::weakly_canonical(it->path(), ec2), folder) || ec2) continue;
            add(it->path().lexically_relative(folder).generic_string());
        }
    }
    return out;
}

bool VolumeRegistry::isLoaded(const std::string &name) const {
    std::lock_guard lock(mutex_);
    return loaded_.count(name) > 0;
}

uint64_t VolumeRegistry::usedBytes() const {
    std::lock_guard lock(mutex_);
    uint64_t total = 0;
    for (const auto &[n, e] : loaded_) total += e->bytes;
    return total;
}

std::string VolumeRegistry::loadingNow() const {
    std::lock_guard lock(mutex_);
    std::string names;
    for (const auto &name : loading_) names += (names.empty() ? "" : ", ") + name;
    return names;
}

void VolumeRegistry::open(const std::string &name, Progress progressFn, Done done,
                          const std::shared_ptr<const VolumeEntry> &releasing, uint64_t owner) {
    fs::path path;
    // A stack of a series: the series is found, fetched and resolved by its own name.
    const protocol::StackSelection selection = protocol::splitStackSelection(name);
    const std::string series(selection.series);
    const std::shared_ptr<VolumeProvider> provider = providerFor(series);
    if (provider) {
        if (auto problem = provider->check(series)) {
            problem->requestType = "open_volume";
            done(*problem);
            return;
        }
    } else if (name.starts_with(kBuiltinPrefix)) {
        const auto names = builtinVolumeNames();
        if (std::find(names.begin(), names.end(), name.substr(kBuiltinPrefix.size())) == names.end()) {
            done(ProtocolError{ErrorCode::NotFound, "no built-in volume named \"" + name + "\"", nullptr, "open_volume"});
            return;
        }
    } else {
        auto resolved = resolve(series);
        if (auto *e = std::get_if<ProtocolError>(&resolved)) {
            done(*e);
            return;
        }
        path = std::get<fs::path>(resolved);
    }
    std::unique_lock lock(mutex_);
    if (stopping_) {
        done(ProtocolError{ErrorCode::Busy, "the server is shutting down", nullptr, "open_volume"});
        return;
    }
    if (auto it = loaded_.find(name); it != loaded_.end()) {
        lastUse_[name] = ++useClock_;
        auto hold = holdOn(it->second);
        lock.unlock();
        done(std::move(hold));
        return;
    }
    auto &pending = pending_[name];
    const bool starting = !pending;
    if (starting) {
        pending = std::make_shared<Pending>();
        pending->name = name;
        pending->series = series;
        pending->stack = selection.stack;
        pending->path = path;
        pending->provider = provider;
    }
    pending->waiters.push_back({std::move(progressFn), std::move(done), releasing.get()});
    if (!starting) return;
    const std::shared_ptr<Pending> started = pending;
    lock.unlock();
    start(started, owner);
}

WorkLane &VolumeRegistry::fetchLane(const std::string &source) {
    auto &lane = fetchLanes_[source];
    // Waiting fetches are bounded by the sessions (one open each) long before this.
    if (!lane) lane = std::make_unique<WorkLane>("fetch " + source, retrievalsPerSource_, 256);
    return *lane;
}

void VolumeRegistry::start(const std::shared_ptr<Pending> &pending, uint64_t owner) {
    if (!pending->provider) return queueLoad(pending, owner);
    WorkLane *lane = nullptr;
    {
        std::lock_guard lock(mutex_);
        if (!stopping_) lane = &fetchLane(pending->provider->sourceOf(pending->series));
    }
    const bool queued = lane && lane->post({owner, [this, pending, owner] { fetchStep(pending, owner); },
                                    [this, pending] {
                                        finish(pending, ProtocolError{ErrorCode::Busy, "the server is shutting down",
                                                                      nullptr, "open_volume"});
                                    }});
    if (!queued)
        finish(pending, ProtocolError{ErrorCode::Busy,
                                      stopRequested_ ? std::string("the server is shutting down")
                                                     : pending->name + ": too many volumes wait for the same source; "
                                                                       "try again shortly",
                                      nullptr, "open_volume"});
}

void VolumeRegistry::queueLoad(const std::shared_ptr<Pending> &pending, uint64_t owner) {
    const auto shuttingDown = [this, pending] {
        if (pending->fetched) pending->provider->release(pending->series, false);
        finish(pending, ProtocolError{ErrorCode::Busy, "the server is shutting down", nullptr, "open_volume"});
    };
    const auto run = [this, pending] {
        {
            std::lock_guard lock(mutex_);
            loading_.insert(pending->name);
        }
        Result result = load(*pending);
        if (pending->fetched) pending->provider->release(pending->series, pending->refused);
        {
            std::lock_guard lock(mutex_);
            loading_.erase(loading_.find(pending->name));
        }
        finish(pending, std::move(result));
    };
    if (!loads_->post({owner, run, shuttingDown})) shuttingDown();
}

void VolumeRegistry::fetchStep(const std::shared_ptr<Pending> &pending, uint64_t owner) {
    using protocol::ProgressStage;
    Pending &p = *pending;
    {
        std::lock_guard lock(mutex_);
        loading_.insert(p.name);
    }
    std::optional<ProtocolError> failure;
    try {
        progress(p.name, ProgressStage::Loading, "", 0.0);
        // Bytes from a browser or a PACS: fetched to a local file or folder first, then
        // every file parsed in the child process before this one reads it (load()).
        FetchContext context;
        double sentFetch = -1;
        context.progress = [&](const FetchProgress &f) {
            if (f.fraction < sentFetch + 0.01 && f.fraction < 1) return;
            sentFetch = f.fraction;
            protocol::ProgressMessage m;
            m.volume = p.name;
            m.stage = ProgressStage::Retrieving;
            m.task = f.task;
            m.fraction = std::clamp(f.fraction, 0.0, 1.0);
            if (f.instancesDone && f.instancesTotal) m.instances = std::array<int64_t, 2>{*f.instancesDone, *f.instancesTotal};
            m.bytes = f.bytes;
            progress(std::move(m));
        };
        context.stopRequested = [this] { return stopRequested_.load(); };
        context.timeLimitSeconds = loadTimeoutSeconds_;
        context.maxFloat32Bytes = uint64_t(double(budgetBytes_) / kMemoryFactor);
        FetchedVolume fetched = p.provider->fetch(p.series, context);
        p.path = std::move(fetched.path);
        p.form = fetched.form;
        p.expectedSeries = std::move(fetched.expectedSeries);
        p.fetched = true;
        // An upload was parsed whole when it arrived; a stack is chosen only as a series is loaded.
        if (p.stack && p.form == FetchedVolume::Form::Parsed)
            failure = ProtocolError{ErrorCode::LoadFailed,
                                    p.name + ": an upload is opened whole; a stack (#stack=N) is chosen only in a "
                                             "series from a DICOMweb source or the data folders",
                                    nullptr, "open_volume"};
    } catch (const VolumeFetchError &e) {
        spdlog::warn("fetching {}: {}", hideUploadIds(p.name), hideUploadIds(e.what()));
        failure = ProtocolError{e.code, e.what(), nullptr, "open_volume"};
    } catch (const std::exception &e) {
        spdlog::warn("fetching {}: {}", hideUploadIds(p.name), hideUploadIds(e.what()));
        failure = ProtocolError{ErrorCode::LoadFailed, forClients(p.name + ": " + e.what(), p), nullptr, "open_volume"};
    }
    {
        std::lock_guard lock(mutex_);
        loading_.erase(loading_.find(p.name));
    }
    if (failure) {
        if (p.fetched) p.provider->release(p.series, false);
        return finish(pending, *failure);
    }
    queueLoad(pending, owner);
}

void VolumeRegistry::finish(const std::shared_ptr<Pending> &pending, Result result) {
    std::vector<Waiter> waiters;
    std::shared_ptr<VolumeEntry> entry;
    {
        std::lock_guard lock(mutex_);
        waiters = std::move(pending->waiters);
        if (auto it = pending_.find(pending->name); it != pending_.end() && it->second == pending) pending_.erase(it);
        if (auto *loaded = std::get_if<std::shared_ptr<VolumeEntry>>(&result)) {
            // Room is made now that the volume is ready, and only if it can be made.
            entry = *loaded;
            if (auto victims = planRoom(entry->bytes, waiters)) {
                evict(*victims);
                loaded_[pending->name] = entry;
                lastUse_[pending->name] = ++useClock_;
                metrics_.volumeLoaded(entry->bytes);
                spdlog::info("loaded volume {} ({}x{}x{}, {} MiB)", hideUploadIds(pending->name), entry->volume->dims.x,
                             entry->volume->dims.y, entry->volume->dims.z, entry->bytes >> 20);
            } else {
                const std::string message = roomMessage(pending->name, entry->bytes, waiters);
                spdlog::warn("loading {}: {}", hideUploadIds(pending->name), hideUploadIds(message));
                result = ProtocolError{ErrorCode::LoadFailed, message, nullptr, "open_volume"};
                entry.reset();
            }
        }
        publishMemory();
    }
    for (auto &w : waiters) {
        if (entry) w.done(holdOn(entry));
        else w.done(result);
    }
}

void VolumeRegistry::progress(const std::string &name, protocol::ProgressStage stage, const std::string &task,
                              double fraction) {
    std::vector<Progress> targets;
    {
        std::lock_guard lock(mutex_);
        if (auto it = pending_.find(name); it != pending_.end())
            for (const auto &w : it->second->waiters) targets.push_back(w.progress);
    }
    protocol::ProgressMessage m;
    m.volume = name;
    m.stage = stage;
    m.task = task;
    m.fraction = fraction;
    for (auto &t : targets) t(m);
}

void VolumeRegistry::progress(protocol::ProgressMessage message) {
    std::vector<Progress> targets;
    {
        std::lock_guard lock(mutex_);
        if (auto it = pending_.find(message.volume); it != pending_.end())
            for (const auto &w : it->second->waiters) targets.push_back(w.progress);
    }
    for (auto &t : targets) t(message);
}

VolumeRegistry::Result VolumeRegistry::load(Pending &p) {
    using protocol::ProgressStage;
    const auto failed = [&](ErrorCode code, const std::string &message) -> Result {
        // The log keeps the server's paths; never an upload's id.
        spdlog::warn("loading {}: {}", hideUploadIds(p.name), hideUploadIds(message));
        return ProtocolError{code, forClients(message, p), nullptr, "open_volume"};
    };
    try {
        progress(p.name, ProgressStage::Loading, "", 0.0);
        LoadOptions options;
        // What the whole budget can hold at most, with the renderer's share: a larger volume
        // is refused from its header, before its voxels are read.
        options.maxBytes = uint64_t(double(budgetBytes_) / kMemoryFactor);
        options.timeLimitSeconds = loadTimeoutSeconds_;
        options.stopRequested = [this] { return stopRequested_.load(); };
        options.seriesStack = p.stack;
        // The loader's own steps, thinned to what a progress bar shows: a new step, or 2 % more.
        double sent = 0;
        std::string sentTask;
        options.progress = [&](double fraction, std::string_view task) {
            if (task == sentTask && fraction < sent + 0.02 && fraction < 1) return;
            sent = fraction;
            sentTask = task;
            progress(p.name, ProgressStage::Loading, sentTask, fraction);
        };
        // Bytes from a browser or a PACS, fetched before (fetchStep): every file is parsed in
        // the child process before this one reads it.
        if (p.provider) {
            options.parseInChild = true;
            options.expectedSeries = p.expectedSeries;
        }
        LoadedVolume loaded = p.path.empty() ? loadSceneVolume(p.name, options)
                              : p.form == FetchedVolume::Form::Parsed
                                  ? LoadedVolume{loadParsedVolume(p.path, p.name, options), {}}
                                  : loadSceneVolume(p.path.string(), options);
        holdNarrow(loaded.volume); // files already are; a built-in volume of integers too
        progress(p.name, ProgressStage::Loading, "", 1.0);
        auto entry = std::make_shared<VolumeEntry>();
        entry->name = p.name;
        entry->bytes = memoryOf(loaded.volume);
        if (entry->bytes > budgetBytes_) return failed(ErrorCode::LoadFailed, tooLargeMessage(p.name, entry->bytes));
        {
            // Checked before the upload; room is made only once the volume is ready (loaderLoop).
            std::lock_guard lock(mutex_);
            if (!planRoom(entry->bytes, pending_.at(p.name)->waiters))
                return failed(ErrorCode::LoadFailed, roomMessage(p.name, entry->bytes, pending_.at(p.name)->waiters));
        }
        entry->volume = std::make_shared<const Volume>(std::move(loaded.volume));
        progress(p.name, ProgressStage::Uploading, "", 0.0);
        entry->renderer = makeFrameRenderer(cl_, entry->volume);
        progress(p.name, ProgressStage::Uploading, "", 1.0);
        return entry;
    } catch (const VolumeTooLarge &e) {
        spdlog::warn("loading {}: {}", hideUploadIds(p.name), hideUploadIds(e.what()));
        return failed(ErrorCode::LoadFailed, tooLargeMessage(p.name, uint64_t(double(e.bytes) * kMemoryFactor)));
    } catch (const VolumeLoadTimeout &e) {
        return failed(ErrorCode::LoadFailed, std::string(e.what()) + " (--load-timeout-s)");
    } catch (const SeriesHoldsStacks &e) {
        // What can be shown instead: each stack by the name that opens it.
        Result answer = failed(ErrorCode::LoadFailed, e.what());
        auto &error = std::get<ProtocolError>(answer);
        for (const SeriesStack &s : e.stacks)
            error.stacks.push_back({protocol::stackVolumeName(p.series, s.number), s.slices, s.rows, s.columns,
                                    s.orientation, s.localizer});
        if (!error.stacks.empty()) error.message += fmt::format(" (stack 1 opens as \"{}\")", error.stacks.front().volume);
        return answer;
    } catch (const VolumeLoadError &e) {
        p.refused = true;   // the checker or the series checks refused these bytes
        return failed(ErrorCode::LoadFailed, e.what());
    } catch (const std::bad_alloc &) {
        return failed(ErrorCode::LoadFailed, p.name + ": out of memory while loading");
    } catch (const OpenClError &e) {
        return failed(ErrorCode::RenderFailed, p.name + ": " + e.what());
    } catch (const std::exception &e) {
        p.refused = true;
        return failed(ErrorCode::LoadFailed, p.name + ": " + e.what());
    }
}

std::string VolumeRegistry::tooLargeMessage(const std::string &name, uint64_t bytes) const {
    return fmt::format("{}: needs {} MiB (its samples, mip levels, B-spline coefficients and brick "
                       "grids), more than the whole memory "
                       "budget of {} MiB (--memory-budget-mib); it cannot be loaded on this server",
                       name, mib(bytes), budgetBytes_ >> 20);
}

std::string VolumeRegistry::roomMessage(const std::string &name, uint64_t bytes,
                                        const std::vector<Waiter> &waiters) const {
    uint64_t held = 0;
    for (const auto &[n, e] : loaded_)
        if (!evictable(e, waiters)) held += e->bytes;
    return fmt::format("{}: needs {} MiB; the memory budget is {} MiB (--memory-budget-mib) and volumes open in "
                       "sessions hold {} MiB of it, which cannot be evicted",
                       name, mib(bytes), budgetBytes_ >> 20, mib(held));
}

bool VolumeRegistry::evictable(const std::shared_ptr<VolumeEntry> &e, const std::vector<Waiter> &waiters) const {
    // The registry's own reference plus one per hold; holds given up by this load's waiters
    // (sessions switching away from the volume) do not keep it.
    const auto releasers = std::count_if(waiters.begin(), waiters.end(),
                                         [&](const Waiter &w) { return w.releasing == e.get(); });
    return e.use_count() - 1 <= releasers;
}

std::optional<std::vector<std::string>> VolumeRegistry::planRoom(uint64_t bytes,
                                                                 const std::vector<Waiter> &waiters) const {
    uint64_t used = 0;
    std::vector<std::pair<uint64_t, std::string>> candidates;   // (last use, name)
    for (const auto &[n, e] : loaded_) {
        used += e->bytes;
        if (evictable(e, waiters)) candidates.emplace_back(lastUse_.at(n), n);
    }
    std::sort(candidates.begin(), candidates.end());
    std::vector<std::string> victims;
    for (const auto &[use, n] : candidates) {
        if (used + bytes <= budgetBytes_) break;
        used -= loaded_.at(n)->bytes;
        victims.push_back(n);
    }
    if (used + bytes > budgetBytes_) return std::nullopt;
    return victims;
}

void VolumeRegistry::evict(const std::vector<std::string> &names) {
    for (const auto &n : names) {
        spdlog::info("evicting volume {} for the memory budget", hideUploadIds(n));
        metrics_.volumeEvicted(loaded_.at(n)->bytes);
        loaded_.erase(n);
        lastUse_.erase(n);
    }
}

std::string VolumeRegistry::forClients(std::string message, const Pending &p) const {
    const auto replaceAll = [&](const std::string &from, const std::string &to) {
        if (from.empty()) return;
        for (size_t at = message.find(from); at != std::string::npos; at = message.find(from, at + to.size()))
            message.replace(at, from.size(), to);
    };
    if (!p.path.empty()) replaceAll(p.path.string(), p.name);
    for (const fs::path &folder : dataDirs_) replaceAll(folder.string() + "/", "");
    // Anything else absolute (a temporary file, a link's target): its last part only.
    static const std::regex absolute(R"((^|[\s'"(=])(/[^\s'"(),;]+))");
    std::string out;
    auto last = message.cbegin();
    for (std::sregex_iterator it(message.begin(), message.end(), absolute), end; it != end; ++it) {
        out.append(last, (*it)[2].first);
        out += fs::path((*it)[2].str()).filename().string();
        last = (*it)[2].second;
    }
    out.append(last, message.cend());
    return out;
}

void VolumeRegistry::publishMemory() {
    uint64_t total = 0;
    for (const auto &[n, e] : loaded_) total += e->bytes;
    metrics_.setVolumeMemory(total, int(loaded_.size()));
}

} // namespace volcast::server
