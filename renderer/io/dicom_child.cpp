// The checker process, both sides: the caller's (dicom_child.hpp) and the checker's main
// (dicom_check.hpp, runDicomCheck).

#include "renderer/io/dicom_child.hpp"
#include "renderer/io/dicom_check.hpp"
#include "renderer/io/dicom_series.hpp"
#include "util/utf8.hpp"

#include <itkMetaImageIO.h>
#include <itkNiftiImageIO.h>
#include <itkNrrdImageIO.h>
#include <spdlog/fmt/fmt.h>
#include <spdlog/spdlog.h>

#include <fcntl.h>
#include <poll.h>
#include <signal.h>
#include <spawn.h>
#include <sys/resource.h>
#include <sys/wait.h>
#include <cstdlib>
#include <unistd.h>

#include <algorithm>
#include <array>
#include <cctype>
#include <charconv>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <fstream>
#include <optional>
#include <string>
#include <type_traits>
#include <vector>

extern char **environ;

#if defined(__SANITIZE_ADDRESS__)
#define VOLCAST_ADDRESS_SANITIZER 1
#elif defined(__has_feature)
#if __has_feature(address_sanitizer)
#define VOLCAST_ADDRESS_SANITIZER 1
#endif
#endif

namespace volcast::io {

// ---------------------------------------------------------------------------------------
// DICOM in a child process
//
// GDCM (Debian's build keeps its assertions) aborts the whole process on some damaged files,
// from inside ITK's CanReadFile, before any check of ours can look at the bytes (fuzz/README.md,
// finding 7); the next such assertion or crash would do the same. So every load that will reach
// GDCM runs first, whole, in a child process with its own memory and CPU limits; a child that
// dies by a signal or runs out of memory means the file is refused; a file it refused with an
// ordinary VolumeLoadError is refused here in the child's words (never parsed again here), and
// only what it loaded is taken, from its hand-back.

namespace {

// The DICOM checker's exit statuses.
constexpr int kCheckLoaded = 0;
constexpr int kCheckRefused = 1;      // a VolumeLoadError, its words and kind in a refusal line
constexpr int kCheckUsage = 2;
constexpr int kCheckOutOfMemory = 3;  // past its RLIMIT_AS
constexpr int kCheckFailed = 4;       // anything else thrown

constexpr const char *kCheckerName = "volcast-dicom-check";

// The child's limits. Memory: the float32 volume (at most maxBytes), ITK's image of it during
// the read, and GDCM's buffer of the stored pixels, plus 2 GiB for the libraries themselves.
uint64_t checkerMemoryLimit(const LoadOptions &options) {
    return 3 * std::min(options.maxBytes, uint64_t(1) << 40) + (uint64_t(2) << 30);
}
// CPU seconds: the load's own time limit (kept, by wall clock, by the caller too) plus a
// margin, or 10 minutes where the caller sets none (volcast-render).
uint64_t checkerCpuLimit(const LoadOptions &options) {
    return options.timeLimitSeconds > 0 ? uint64_t(std::ceil(options.timeLimitSeconds)) + 5 : 600;
}

std::optional<fs::path> dicomCheckerPath() {
    const auto runnable = [](const fs::path &p) {
        std::error_code ec;
        return fs::is_regular_file(p, ec) && ::access(p.c_str(), X_OK) == 0;
    };
    if (const char *given = std::getenv("VOLCAST_DICOM_CHECK"); given && *given)
        return runnable(given) ? std::optional<fs::path>(given) : std::nullopt;  // set, so meant: no guessing
    std::error_code ec;
    const fs::path self = fs::read_symlink("/proc/self/exe", ec);
    if (!ec && runnable(self.parent_path() / kCheckerName)) return self.parent_path() / kCheckerName;  // installed
#ifdef VOLCAST_DICOM_CHECK_BUILD_PATH
    if (runnable(VOLCAST_DICOM_CHECK_BUILD_PATH)) return fs::path(VOLCAST_DICOM_CHECK_BUILD_PATH);  // the build tree
#endif
    return std::nullopt;
}

} // namespace

// Whether ITK's factory would ask GDCM about this file: only if none of the readers registered
// before it (registerItkFactories' order) claims it.
bool reachesGdcm(const fs::path &path) {
    const std::string name = path.string();
    return !itk::NrrdImageIO::New()->CanReadFile(name.c_str()) && !itk::MetaImageIO::New()->CanReadFile(name.c_str()) &&
           !itk::NiftiImageIO::New()->CanReadFile(name.c_str());
}

namespace {

std::string signalName(int sig) {
    switch (sig) {
    case SIGABRT: return "SIGABRT, an assertion or abort";
    case SIGSEGV: return "SIGSEGV, a crash";
    case SIGBUS: return "SIGBUS, a crash";
    case SIGFPE: return "SIGFPE, an arithmetic fault";
    case SIGILL: return "SIGILL, a crash";
    case SIGXCPU: return "SIGXCPU, its CPU time limit";
    case SIGKILL: return "SIGKILL";
    default: return fmt::format("signal {}", sig);
    }
}

// The child, killed and reaped however the wait for it ends (a time limit, a stop request).
struct Child {
    pid_t pid = -1;
    int output = -1;  // the read end of its stdout and stderr
    Child() = default;
    Child(const Child &) = delete;
    Child &operator=(const Child &) = delete;
    ~Child() {
        if (pid > 0) {
            ::kill(pid, SIGKILL);
            while (::waitpid(pid, nullptr, 0) < 0 && errno == EINTR) {}
        }
        if (output >= 0) ::close(output);
    }
};

// `dicom`: the file may reach GDCM (the messages say so); otherwise it is checked because the
// caller asked for every file to be (LoadOptions::parseInChild).
// A progress line from the checker: the mark, the fraction, a space, the task.
constexpr char kProgressMark = '\x1e';

// A task name from the child, fit for the client: printable ASCII, one line, short.
std::string quotableTask(std::string_view text) {
    std::string out;
    for (char c : text)
        if (c >= 0x20 && c < 0x7f && out.size() < 64) out += c;
    return out;
}

// The checker's refusal, so that the caller never parses the file itself for its words: one
// line, the mark, the kind (kRefusedPlainly, kRefusedTooLarge with the volume's float32 bytes,
// kRefusedTimeLimit, kRefusedOverResultLimit with the hand-back's bytes), a space, that number,
// a space, the message (a VolumeLoadError's what()). kRefusedStacks (SeriesHoldsStacks) has
// the stacks' count for its number and, before the message, the stacks (stackList).
constexpr char kRefusalMark = '\x1f';
constexpr char kRefusedStacks = 'K';
constexpr char kRefusedPlainly = 'R';
constexpr char kRefusedTooLarge = 'L';
constexpr char kRefusedTimeLimit = 'T';
constexpr char kRefusedOverResultLimit = 'S';
// A line from the child is cut here (a refusal's message with it); what it says besides its
// refusal is kept for the log up to kMaxSaidBytes.
constexpr size_t kMaxLineBytes = 4096;
constexpr size_t kMaxSaidBytes = 4096;
constexpr size_t kMaxRefusalBytes = 2048;

// The checker's side: its refusal as that line (newlines in ITK's messages become spaces).
int writeRefusal(char kind, uint64_t bytes, const std::exception &e, const std::string &stacks = "") {
    std::string message = e.what();
    std::replace_if(message.begin(), message.end(), [](char c) { return c == '\n' || c == '\r'; }, ' ');
    std::fprintf(stderr, "%c%c %llu %s%s%s\n", kRefusalMark, kind, static_cast<unsigned long long>(bytes),
                 stacks.c_str(), stacks.empty() ? "" : " ", message.c_str());
    std::fflush(stderr);
    return kCheckRefused;
}

// SeriesHoldsStacks's stacks as one word: each "slices,rows,columns,orientation,localizer"
// (localizer 0 or 1), joined by '/', in their numbers' order.
std::string stackList(const std::vector<SeriesStack> &stacks) {
    std::string word;
    for (const SeriesStack &s : stacks)
        word += fmt::format("{}{},{},{},{},{}", word.empty() ? "" : "/", s.slices, s.rows, s.columns, s.orientation,
                            s.localizer ? 1 : 0);
    return word;
}

// The caller's side of stackList, read as hostile: `count` stacks of known orientations and
// sizes DICOM can state (rows and columns are 16-bit), or nothing.
std::optional<std::vector<SeriesStack>> readStackList(std::string_view word, uint64_t count) {
    if (count < 2 || count > SeriesHoldsStacks::kMaxListed) return std::nullopt;
    std::vector<SeriesStack> stacks;
    while (!word.empty()) {
        const size_t end = std::min(word.find('/'), word.size());
        const std::string_view one = word.substr(0, end);
        word = end < word.size() ? word.substr(end + 1) : std::string_view();
        std::array<std::string_view, 5> field;
        size_t at = 0;
        for (size_t f = 0; f < field.size(); ++f) {
            const size_t comma = f + 1 < field.size() ? one.find(',', at) : one.size();
            if (comma == std::string_view::npos) return std::nullopt;
            field[f] = one.substr(at, comma - at);
            at = comma + 1;
        }
        SeriesStack s;
        s.number = uint32_t(stacks.size() + 1);
        const auto number = [](std::string_view text, auto &out, uint64_t most) {
            uint64_t n = 0;
            const auto r = std::from_chars(text.data(), text.data() + text.size(), n);
            if (r.ec != std::errc() || r.ptr != text.data() + text.size() || n > most) return false;
            out = static_cast<std::remove_reference_t<decltype(out)>>(n);
            return true;
        };
        constexpr std::array<std::string_view, 5> kOrientations{"axial", "coronal", "sagittal", "oblique", "unknown"};
        if (!number(field[0], s.slices, UINT32_MAX) || s.slices == 0 || !number(field[1], s.rows, 65535) ||
            !number(field[2], s.columns, 65535) ||
            std::find(kOrientations.begin(), kOrientations.end(), field[3]) == kOrientations.end() ||
            (field[4] != "0" && field[4] != "1"))
            return std::nullopt;
        s.orientation = std::string(field[3]);
        s.localizer = field[4] == "1";
        stacks.push_back(std::move(s));
        if (stacks.size() > count) return std::nullopt;
    }
    if (stacks.size() != count) return std::nullopt;
    return stacks;
}

} // namespace

// The caller's side: the refusal line (without its newline) as the error the load throws
// (dicom_child.hpp).
// The child parsed hostile bytes and may be under their control, so the line is read as
// hostile too: its message bounded, invalid UTF-8 and control characters replaced, and made to
// start with the path the caller gave (as every VolumeLoadError does); the time limit is the
// caller's own. A missing or malformed line still refuses the file, in general words.
[[noreturn]] void throwRefusal(const fs::path &path, const LoadOptions &options, const std::string &line) {
    // The mark, the kind, a space, the number's digits, a space, the message.
    const size_t numberEnd = line.find(' ', 3);
    uint64_t bytes = 0;
    const auto digitsRead = [&] {
        // A number past 64 bits stops at its end too, with an error and `bytes` left at 0.
        const auto read = std::from_chars(line.data() + 3, line.data() + numberEnd, bytes);
        return read.ptr == line.data() + numberEnd && read.ec == std::errc();
    };
    const bool wellFormed = line.size() > 3 && line[0] == kRefusalMark && line[2] == ' ' &&
                            numberEnd != std::string::npos && numberEnd > 3 && numberEnd + 1 < line.size() &&
                            digitsRead();
    if (!wellFormed) fail(path, "was refused by the parser in its separate process; it is not loaded");
    const char kind = line[1];
    std::string_view said = std::string_view(line).substr(numberEnd + 1);
    std::optional<std::vector<SeriesStack>> stacks;
    if (kind == kRefusedStacks) {
        const size_t wordEnd = said.find(' ');
        if (wordEnd == std::string_view::npos) fail(path, "was refused by the parser in its separate process; it is not loaded");
        stacks = readStackList(said.substr(0, wordEnd), bytes);
        said = said.substr(wordEnd + 1);
    }
    std::string text = said.starts_with(path.string()) ? "" : path.string() + ": ";
    for (size_t i = 0; i < said.size(); ++i) {
        const auto byte = [&](size_t k) { return static_cast<unsigned char>(said[k]); };
        // C0 controls and DEL, and C1 controls (U+0080..U+009F: C2 80..C2 9F in UTF-8).
        const bool c1 = byte(i) == 0xC2 && i + 1 < said.size() && byte(i + 1) >= 0x80 && byte(i + 1) <= 0x9F;
        if (byte(i) < 0x20 || byte(i) == 0x7F || c1) {
            text += "\xEF\xBF\xBD";  // U+FFFD
            i += c1 ? 1 : 0;
        } else {
            text += said[i];
        }
    }
    // Invalid UTF-8 replaced too, and the whole bounded.
    const std::string message = json_fields::quotableText(text, kMaxRefusalBytes);
    if (kind == kRefusedTooLarge) throw VolumeTooLarge(message, bytes);
    if (kind == kRefusedTimeLimit) throw VolumeLoadTimeout(message, options.timeLimitSeconds);
    if (kind == kRefusedOverResultLimit) throw VolumeOverResultLimit(message, bytes, options.maxResultBytes);
    // Stacks that do not read as stacks: still refused, in the checker's words, with no offer.
    if (stacks) throw SeriesHoldsStacks(message, std::move(*stacks));
    throw VolumeLoadError(message);
}

namespace {

// What the checker hands back: the volume it loaded, so that the file is parsed once, in the
// child, and never again in the caller. A fixed header, the file's modality, then either the
// samples as the volume holds them (narrow integers or float32), or, for an uncompressed
// DICOM series in a folder that outlives the load (planSlices > 0), a plan: the pixel format
// and where each slice's pixels lie, which the caller copies from the files itself. A plan
// spares a copy of the whole volume through the hand-back (the pixels need no parsing; their
// headers were parsed here). The caller reads it as it reads any file from outside: a child
// that a hostile file took over could have written anything here, so every field is checked,
// every file of a plan opened as untrusted, and the statistics are computed again.
struct CheckedHeader {
    char magic[16] = "volcast-checked";
    uint32_t version = 3;
    int32_t sourceType = 0;
    int64_t dims[3] = {0, 0, 0};
    double spacing[3] = {1, 1, 1};
    double origin[3] = {0, 0, 0};
    double direction[9] = {1, 0, 0, 0, 1, 0, 0, 0, 1};
    int32_t narrowBytes = 4;
    float narrowOffset = 0;
    uint64_t nonFiniteReplaced = 0;
    uint32_t orientationKnown = 0;
    uint32_t modalityBytes = 0;
    uint32_t modalityFieldBytes = 0;
    uint32_t planSlices = 0;   // a plan's slices, one per z; 0: the samples follow
};
static_assert(sizeof(CheckedHeader) == 200, "no padding left in the hand-back's header");

// A plan's pixel format, after the header and modality; then per slice, in stack order, the
// pixel data's offset (uint64), its file's name length (uint32) and name (within the folder).
struct CheckedPlanFormat {
    int32_t bitsAllocated = 16;
    int32_t bitsStored = 16;
    int32_t isSigned = 0;
    int32_t zero = 0;   // what would be padding: written as zeros
    double intercept = 0;
};
static_assert(sizeof(CheckedPlanFormat) == 24, "no padding in the plan's format");
constexpr uint32_t kMaxPlanNameBytes = 255;
constexpr uint32_t kMaxCheckedModalityBytes = 64;

// Writes whole buffers to the result file the caller made (O_NOFOLLOW and no O_CREAT: only
// that file is written).
class ResultWriter {
  public:
    explicit ResultWriter(const fs::path &to) : fd_(::open(to.c_str(), O_WRONLY | O_TRUNC | O_NOFOLLOW | O_CLOEXEC)) {
        if (fd_ < 0) throw std::runtime_error("cannot open the result file: " + std::string(std::strerror(errno)));
    }
    ~ResultWriter() { ::close(fd_); }
    ResultWriter(const ResultWriter &) = delete;
    ResultWriter &operator=(const ResultWriter &) = delete;
    void put(const void *data, size_t bytes) {
        const char *at = static_cast<const char *>(data);
        while (bytes > 0) {
            const ssize_t n = ::write(fd_, at, std::min<size_t>(bytes, size_t(1) << 30));
            if (n < 0 && errno == EINTR) continue;
            if (n <= 0) throw std::runtime_error("cannot write the result file: " + std::string(std::strerror(errno)));
            at += n;
            bytes -= size_t(n);
        }
    }

  private:
    int fd_;
};

// The header and modality of v; the samples (or a plan) follow.
void putCheckedHeader(ResultWriter &out, const Volume &v, uint32_t planSlices) {
    CheckedHeader h;
    h.sourceType = int32_t(v.sourceType);
    for (int a = 0; a < 3; ++a) {
        h.dims[a] = v.dims[a];
        h.spacing[a] = v.spacing[a];
        h.origin[a] = v.origin[a];
    }
    for (int i = 0; i < 9; ++i) h.direction[i] = v.direction.m[size_t(i)];
    h.narrowBytes = v.narrow.bytes;
    h.narrowOffset = v.narrow.offset;
    h.nonFiniteReplaced = v.nonFiniteReplaced;
    h.orientationKnown = v.orientationKnown ? 1 : 0;
    const std::string modality = v.modality.substr(0, kMaxCheckedModalityBytes);
    h.modalityBytes = uint32_t(modality.size());
    const std::string modalityField = v.modalityField.substr(0, kMaxCheckedModalityBytes);
    h.modalityFieldBytes = uint32_t(modalityField.size());
    h.planSlices = planSlices;
    out.put(&h, sizeof h);
    out.put(modality.data(), modality.size());
    out.put(modalityField.data(), modalityField.size());
}

} // namespace

uint64_t checkedResultBytes(const Volume &v) {
    return sizeof(CheckedHeader) + std::min(v.modality.size(), size_t(kMaxCheckedModalityBytes)) +
           std::min(v.modalityField.size(), size_t(kMaxCheckedModalityBytes)) +
           uint64_t(v.voxelCount()) * uint64_t(v.narrow.bytes);
}

namespace {

void writeCheckedVolume(const Volume &v, const fs::path &to) {
    ResultWriter out(to);
    putCheckedHeader(out, v, 0);
    if (v.narrow.bytes == 4) out.put(v.voxels.data(), v.voxels.size() * sizeof(float));
    else out.put(v.narrowVoxels.data(), v.voxelCount() * size_t(v.narrow.bytes));
}

void writeSeriesPlan(const Volume &v, const UncompressedSeries &series, const fs::path &to) {
    ResultWriter out(to);
    putCheckedHeader(out, v, uint32_t(series.slices.size()));
    const UncompressedSlice &first = series.slices.front();
    CheckedPlanFormat format;
    format.bitsAllocated = first.bitsAllocated;
    format.bitsStored = first.bitsStored;
    format.isSigned = first.isSigned ? 1 : 0;
    format.intercept = first.intercept;
    out.put(&format, sizeof format);
    for (const UncompressedSlice &s : series.slices) {
        const uint64_t offset = s.pixelOffset;
        const uint32_t nameBytes = uint32_t(std::min<size_t>(s.file.size(), kMaxPlanNameBytes + 1));
        out.put(&offset, sizeof offset);
        out.put(&nameBytes, sizeof nameBytes);
        out.put(s.file.data(), nameBytes);
    }
}

void setLimit(int resource, uint64_t value) {
    rlimit limit{};
    limit.rlim_cur = limit.rlim_max = rlim_t(value);
    if (::setrlimit(resource, &limit) != 0)
        std::fprintf(stderr, "%s: cannot set resource limit %d: %s\n", kCheckerName, resource, std::strerror(errno));
}

} // namespace

namespace {

// The rest of a hand-back that is a plan (CheckedHeader::planSlices > 0): its format and
// slices checked, then the slices' pixels copied from the files in `path`, the folder that
// was checked, and packed here.
Volume readSeriesPlan(const fs::path &path, const fs::path &from, std::ifstream &in, const CheckedHeader &h,
                      const LoadOptions &options, bool samples, LoadProgress *progress, Volume v) {
    const auto damaged = [&](const std::string &what) -> Volume {
        fail(path, "the parser in its separate process handed back a damaged plan (" + what + "); it is not loaded");
    };
    // Only a folder's load asks for a plan, and only to load it now.
    if (!samples || !fs::is_directory(path)) return damaged("a plan where the samples were asked for");
    if (int64_t(h.planSlices) != v.dims.z || v.dims.z < 2) return damaged("slice count");
    CheckedPlanFormat format;
    if (!in.read(reinterpret_cast<char *>(&format), sizeof format)) return damaged("short format");
    if ((format.bitsAllocated != 8 && format.bitsAllocated != 16) || format.bitsStored < 1 ||
        format.bitsStored > format.bitsAllocated || format.isSigned < 0 || format.isSigned > 1 ||
        !(format.intercept == std::trunc(format.intercept)) || std::abs(format.intercept) > double(1 << 20))
        return damaged("pixel format");
    UncompressedSeries series;
    series.type = v.sourceType;
    uint64_t expected = sizeof h + h.modalityBytes + h.modalityFieldBytes + sizeof format;
    for (uint32_t k = 0; k < h.planSlices; ++k) {
        UncompressedSlice s;
        uint64_t offset = 0;
        uint32_t nameBytes = 0;
        if (!in.read(reinterpret_cast<char *>(&offset), sizeof offset) ||
            !in.read(reinterpret_cast<char *>(&nameBytes), sizeof nameBytes) || nameBytes == 0 ||
            nameBytes > kMaxPlanNameBytes)
            return damaged("slice entry");
        s.file.resize(nameBytes);
        if (!in.read(s.file.data(), nameBytes)) return damaged("short slice name");
        // A name within the folder: no separator, no NUL, not the folder or its parent.
        if (s.file.find_first_of(std::string("/\0", 2)) != std::string::npos || s.file == "." || s.file == "..")
            return damaged("a slice name outside the folder");
        s.pixelOffset = offset;
        s.columns = v.dims.x;
        s.rows = v.dims.y;
        s.bitsAllocated = format.bitsAllocated;
        s.bitsStored = format.bitsStored;
        s.isSigned = format.isSigned == 1;
        s.intercept = format.intercept;
        series.slices.push_back(std::move(s));
        expected += sizeof offset + sizeof nameBytes + nameBytes;
    }
    if (fileSize(from).value_or(0) != expected) return damaged("its size is not what its header says");
    LoadProgress own(options, path);
    readUncompressedSamples(path, series, progress ? *progress : own, 0.8, 0.9, v);
    return v;
}

} // namespace

// `samples` false: the header only (its fields and the file's size checked), for a caller that
// keeps the result to load later.
Volume readCheckedVolume(const fs::path &path, const fs::path &from, const LoadOptions &options, bool samples,
                         LoadProgress *progress) {
    const auto damaged = [&](const std::string &what) -> Volume {
        fail(path, "the parser in its separate process handed back a damaged result (" + what + "); it is not loaded");
    };
    std::ifstream in(from, std::ios::binary);
    CheckedHeader h;
    if (!in.read(reinterpret_cast<char *>(&h), sizeof h)) return damaged("short header");
    if (std::memcmp(h.magic, CheckedHeader{}.magic, sizeof h.magic) != 0 || h.version != CheckedHeader{}.version)
        return damaged("not a result of this version");
    if (h.sourceType < 0 || h.sourceType > int32_t(VoxelType::Float64)) return damaged("voxel type");
    if (h.narrowBytes != 1 && h.narrowBytes != 2 && h.narrowBytes != 4) return damaged("sample width");
    if (h.modalityBytes > kMaxCheckedModalityBytes || h.modalityFieldBytes > kMaxCheckedModalityBytes ||
        !std::isfinite(h.narrowOffset))
        return damaged("modality");
    Volume v;
    for (int a = 0; a < 3; ++a) {
        if (h.dims[a] < 1 || h.dims[a] > options.maxDimension) return damaged("dimensions");
        v.dims[a] = h.dims[a];
        v.spacing[a] = h.spacing[a];
        v.origin[a] = h.origin[a];
    }
    checkShape(path, v.dims, options);
    Mat3d direction;
    for (int i = 0; i < 9; ++i) direction.m[size_t(i)] = h.direction[i];
    v.direction = checkedGeometry(path, v.spacing, v.origin, direction);
    v.sourceType = VoxelType(h.sourceType);
    v.nonFiniteReplaced = size_t(h.nonFiniteReplaced);
    v.orientationKnown = h.orientationKnown != 0;
    v.modality.resize(h.modalityBytes);
    if (!in.read(v.modality.data(), std::streamsize(h.modalityBytes))) return damaged("short modality");
    v.modalityField.resize(h.modalityFieldBytes);
    if (!in.read(v.modalityField.data(), std::streamsize(h.modalityFieldBytes))) return damaged("short modality");
    if (h.planSlices > 0) return readSeriesPlan(path, from, in, h, options, samples, progress, std::move(v));
    const uint64_t sampleBytes = uint64_t(v.voxelCount()) * uint64_t(h.narrowBytes);
    const uint64_t expected = sizeof h + h.modalityBytes + h.modalityFieldBytes + sampleBytes;
    if (fileSize(from).value_or(0) != expected) return damaged("its size is not what its header says");
    if (!samples) {
        v.narrow = {h.narrowBytes, h.narrowOffset};
        return v;
    }
    if (h.narrowBytes == 4) {
        v.voxels.resize(v.voxelCount());
        in.read(reinterpret_cast<char *>(v.voxels.data()), std::streamsize(sampleBytes));
        replaceNonFinite(path, v.voxels);
    } else {
        v.narrow = {h.narrowBytes, h.narrowOffset};
        v.narrowVoxels.resize(size_t(sampleBytes) + kNarrowSlack);
        in.read(reinterpret_cast<char *>(v.narrowVoxels.data()), std::streamsize(sampleBytes));
    }
    if (!in) return damaged("short samples");
    return v;
}

// Parses the file in the checker process, which writes what it loaded to `result` (a file the
// caller made). Returns when it loaded the file; throws its refusal in its own words and kind
// (throwRefusal) when it refused it, and a VolumeLoadError saying how it ended otherwise.
void runChecker(const fs::path &path, const LoadOptions &options, LoadProgress &progress, bool dicom,
                const fs::path &result, bool planAllowed) {
    const auto checker = dicomCheckerPath();
    if (!checker)
        fail(path, fmt::format("{}, which is first parsed in a separate process, but the DICOM checker '{}' "
                               "was not found (next to this program, in the build tree, or as $VOLCAST_DICOM_CHECK); "
                               "it is not loaded",
                               dicom ? "may be DICOM" : "comes from outside", kCheckerName));
    const std::string parser = dicom ? "the DICOM parser (GDCM)" : "the parser";
    int fds[2];
    if (::pipe2(fds, O_CLOEXEC) != 0) fail(path, fmt::format("cannot start the DICOM checker: {}", std::strerror(errno)));
    Child child;
    child.output = fds[0];

    posix_spawn_file_actions_t actions;
    posix_spawn_file_actions_init(&actions);
    posix_spawn_file_actions_addopen(&actions, 0, "/dev/null", O_RDONLY, 0);
    posix_spawn_file_actions_adddup2(&actions, fds[1], 1);
    posix_spawn_file_actions_adddup2(&actions, fds[1], 2);
    // Default dispositions and no blocked signals, whatever the calling thread had.
    posix_spawnattr_t attr;
    posix_spawnattr_init(&attr);
    sigset_t none, all;
    sigemptyset(&none);
    sigfillset(&all);
    posix_spawnattr_setsigmask(&attr, &none);
    posix_spawnattr_setsigdefault(&attr, &all);
    posix_spawnattr_setflags(&attr, POSIX_SPAWN_SETSIGMASK | POSIX_SPAWN_SETSIGDEF);
    std::vector<std::string> args = {checker->string(), path.string(), std::to_string(options.maxBytes),
                                     std::to_string(options.maxDimension), fmt::format("{}", options.timeLimitSeconds),
                                     std::to_string(options.maxArchiveBytes), result.string()};
    if (planAllowed) args.push_back("plan");
    if (options.expectedSeries)
        args.insert(args.end(), {"expect-series", options.expectedSeries->studyUid, options.expectedSeries->seriesUid});
    if (options.seriesStack) args.insert(args.end(), {"stack", std::to_string(*options.seriesStack)});
    if (options.maxResultBytes != UINT64_MAX) args.push_back(fmt::format("max-result-bytes={}", options.maxResultBytes));
    std::vector<char *> argv;
    for (auto &a : args) argv.push_back(a.data());
    argv.push_back(nullptr);
    const int spawned = ::posix_spawn(&child.pid, argv[0], &actions, &attr, argv.data(), environ);
    posix_spawn_file_actions_destroy(&actions);
    posix_spawnattr_destroy(&attr);
    ::close(fds[1]);
    if (spawned != 0) {
        child.pid = -1;
        fail(path, fmt::format("cannot start the DICOM checker: {}", std::strerror(spawned)));
    }

    // Wait, reading what it writes (GDCM's assertion, say) for the log; the progress call is
    // where the load's time limit and a stop request end the wait, and the child with it.
    std::string said, line, refusal;
    std::string task = dicom ? "checking DICOM in a separate process" : "checking the file in a separate process";
    double fraction = 0;
    int status = 0;
    for (;;) {
        progress(fraction, task);
        if (child.output >= 0) {
            pollfd p{child.output, POLLIN, 0};
            if (::poll(&p, 1, 100) > 0) {
                char buffer[4096];
                const ssize_t n = ::read(child.output, buffer, sizeof buffer);
                if (n > 0) {
                    // Lines starting with kProgressMark are the child's progress (its own
                    // steps, slice by slice), passed on; one starting with kRefusalMark its
                    // refusal, kept; the rest is what it said, for the log.
                    for (ssize_t i = 0; i < n; ++i) {
                        line += buffer[i];
                        if (buffer[i] != '\n' && line.size() < kMaxLineBytes) continue;
                        if (line.starts_with(kRefusalMark)) {
                            if (refusal.empty()) refusal = line.substr(0, line.find('\n'));
                        } else if (line.starts_with(kProgressMark)) {
                            char *end = nullptr;
                            const double f = std::strtod(line.c_str() + 1, &end);
                            if (end && *end == ' ' && std::isfinite(f)) {
                                fraction = std::clamp(f, 0.0, 0.8);   // reading its result is the rest
                                task = quotableTask(std::string_view(end + 1, line.size() - size_t(end + 1 - line.c_str())));
                                progress(fraction, task);   // each step, however many arrive at once
                            }
                        } else {
                            said += line;
                        }
                        line.clear();
                    }
                    if (said.size() > kMaxSaidBytes) said.erase(0, said.size() - kMaxSaidBytes);
                } else if (n == 0) {
                    ::close(child.output);
                    child.output = -1;
                }
            }
        } else {
            ::poll(nullptr, 0, 50);
        }
        const pid_t done = ::waitpid(child.pid, &status, WNOHANG);
        if (done == child.pid) {
            child.pid = -1;
            break;
        }
        if (done < 0 && errno != EINTR) {
            child.pid = -1;
            fail(path, fmt::format("lost the DICOM checker: {}", std::strerror(errno)));
        }
    }
    if (WIFEXITED(status) && WEXITSTATUS(status) == kCheckLoaded) return;
    if (WIFEXITED(status) && WEXITSTATUS(status) == kCheckRefused) throwRefusal(path, options, refusal);
    while (!said.empty() && std::isspace(static_cast<unsigned char>(said.back()))) said.pop_back();
    spdlog::warn("{}: the checker ({}) {}; it said: {}", path.string(), checker->string(),
                 WIFSIGNALED(status) ? "ended with " + signalName(WTERMSIG(status))
                                     : fmt::format("exited with status {}", WEXITSTATUS(status)),
                 said.empty() ? "nothing" : said);
    if (WIFSIGNALED(status))
        fail(path, fmt::format("was rejected by {}: parsing it in a separate process ended with "
                               "{}; the file is damaged{}, and it is not loaded",
                               parser, signalName(WTERMSIG(status)), dicom ? " or not DICOM" : ""));
    if (WIFEXITED(status) && WEXITSTATUS(status) == kCheckOutOfMemory)
        fail(path, fmt::format("was rejected by {}: parsing it in a separate process needed more "
                               "than its limit of {} MiB; it is not loaded",
                               parser, checkerMemoryLimit(options) >> 20));
    fail(path, fmt::format("was rejected by {}: parsing it in a separate process failed (exit "
                           "status {}); it is not loaded",
                           parser, WIFEXITED(status) ? WEXITSTATUS(status) : -1));
}

} // namespace volcast::io

namespace volcast {

int runDicomCheck(int argc, char **argv) {
    using namespace io; // the checker's limits and statuses, and the load (dicom_child.hpp)
    // After RESULT: "plan", "expect-series STUDY SERIES" (LoadOptions::expectedSeries),
    // "stack N" (LoadOptions::seriesStack) and "max-result-bytes=N" (LoadOptions::maxResultBytes),
    // in any order.
    constexpr std::string_view kMaxResult = "max-result-bytes=";
    bool planAllowed = false, usage = argc < 5;
    std::optional<SeriesIdentity> expectedSeries;
    std::optional<uint32_t> seriesStack;
    const char *maxResult = nullptr;
    for (int i = 7; i < argc && !usage; ++i) {
        if (std::strcmp(argv[i], "plan") == 0) {
            planAllowed = true;
        } else if (std::strcmp(argv[i], "expect-series") == 0 && i + 2 < argc) {
            expectedSeries = SeriesIdentity{argv[i + 1], argv[i + 2]};
            i += 2;
        } else if (std::strcmp(argv[i], "stack") == 0 && i + 1 < argc) {
            uint32_t n = 0;
            const std::string_view text = argv[i + 1];
            const auto r = std::from_chars(text.data(), text.data() + text.size(), n);
            usage = r.ec != std::errc() || r.ptr != text.data() + text.size();
            seriesStack = n;
            i += 1;
        } else if (std::string_view(argv[i]).starts_with(kMaxResult)) {
            maxResult = argv[i] + kMaxResult.size();
        } else {
            usage = true;
        }
    }
    if (usage) {
        std::fprintf(stderr, "usage: %s FILE-OR-FOLDER MAX-BYTES MAX-DIMENSION TIME-LIMIT-S [MAX-ARCHIVE-BYTES [RESULT "
                             "[plan] [expect-series STUDY-UID SERIES-UID] [stack N] [max-result-bytes=N]]]\n"
                             "Loads a volume as volcast's loader does, in this process (volcast runs it to parse "
                             "files from outside away from the server), and writes what it loaded to the existing "
                             "file RESULT; with 'plan', an uncompressed DICOM series in a folder is handed back as "
                             "where its slices' pixels lie rather than as samples; with 'expect-series', a DICOM "
                             "folder is refused unless every instance is of that study and series; with 'stack', "
                             "only that stack of a DICOM series is read (the series still checked whole); with "
                             "max-result-bytes, a volume whose hand-back would be larger is refused before any of "
                             "it is written. Exit status 0 loaded, 1 refused, 3 out of memory.\n",
                     kCheckerName);
        return kCheckUsage;
    }
    LoadOptions options;
    // Only files from outside (LoadOptions::parseInChild) and DICOM, which names no data files
    // beside it, are sent here: the rules for a file from outside hold (an upload carries its data).
    options.parseInChild = true;
    options.expectedSeries = std::move(expectedSeries);
    options.seriesStack = seriesStack;
    try {
        options.maxBytes = std::stoull(argv[2]);
        options.maxDimension = std::stoll(argv[3]);
        options.timeLimitSeconds = std::stod(argv[4]);
        if (argc >= 6) options.maxArchiveBytes = std::stoull(argv[5]);
        if (maxResult) options.maxResultBytes = std::stoull(maxResult);
    } catch (const std::exception &) {
        std::fprintf(stderr, "%s: bad limits '%s' '%s' '%s'\n", kCheckerName, argv[2], argv[3], argv[4]);
        return kCheckUsage;
    }
    // Whatever the caller left open without close-on-exec (a server's sockets) is not the
    // business of a process that parses hostile files.
    ::close_range(3, ~0U, 0);
    setLimit(RLIMIT_CORE, 0);  // an assertion in GDCM is expected here; no core file for it
#ifndef VOLCAST_ADDRESS_SANITIZER
    setLimit(RLIMIT_AS, checkerMemoryLimit(options));  // (AddressSanitizer reserves terabytes of it: not there)
#endif
    setLimit(RLIMIT_CPU, checkerCpuLimit(options));
    // The load's own progress, for the caller to pass on (checkInChild).
    options.progress = [](double fraction, std::string_view task) {
        std::printf("%c%.4f %.*s\n", kProgressMark, fraction, int(std::min<size_t>(task.size(), 64)), task.data());
        std::fflush(stdout);
    };
    try {
        if (planAllowed && fs::is_directory(argv[1])) {
            // The series' headers parsed and checked here as the load would; its pixels, which
            // need no parsing, left for the caller to copy from the files.
            LoadProgress progress(options, argv[1]);
            progress(0, "reading header");
            const StackFiles only = checkDicomFolder(argv[1], options, progress);
            Volume placed;
            if (const auto series = placedUncompressedSeries(argv[1], options, progress, placed, only)) {
                writeSeriesPlan(placed, *series, argv[6]);
                return kCheckLoaded;
            }
        }
        const Volume v = loadVolumeHere(argv[1], options, false);
        if (argc >= 7) writeCheckedVolume(v, argv[6]);
        return kCheckLoaded;
    } catch (const LoadOutOfMemory &e) {
        std::fprintf(stderr, "%s\n", e.what());
        return kCheckOutOfMemory;
    } catch (const VolumeTooLarge &e) {
        return writeRefusal(kRefusedTooLarge, e.bytes, e);
    } catch (const VolumeLoadTimeout &e) {
        return writeRefusal(kRefusedTimeLimit, 0, e);
    } catch (const VolumeOverResultLimit &e) {
        return writeRefusal(kRefusedOverResultLimit, e.needed, e);
    } catch (const SeriesHoldsStacks &e) {
        return writeRefusal(kRefusedStacks, e.stacks.size(), e, stackList(e.stacks));
    } catch (const VolumeLoadError &e) {
        return writeRefusal(kRefusedPlainly, 0, e);
    } catch (const std::exception &e) {
        std::fprintf(stderr, "%s\n", e.what());
        return kCheckFailed;
    }
}

} // namespace volcast
