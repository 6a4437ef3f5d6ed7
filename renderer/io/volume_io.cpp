#include "renderer/io/volume_io.hpp"
#include "renderer/io/dicom_check.hpp"
#include "renderer/io/zip_extract.hpp"

#include <itkCommand.h>
#include <itkGDCMImageIO.h>
#include <itkGDCMImageIOFactory.h>
#include <itkGDCMSeriesFileNames.h>
#include <itkImage.h>
#include <itkImageIOBase.h>
#include <itkImageIOFactory.h>
#include <itkImageSeriesReader.h>
#include <itkMetaDataObject.h>
#include <itkMetaImageIO.h>
#include <itkMetaImageIOFactory.h>
#include <itkNiftiImageIO.h>
#include <itkNiftiImageIOFactory.h>
#include <itkNrrdImageIO.h>
#include <itkNrrdImageIOFactory.h>
#include <itkProcessObject.h>
#include <spdlog/fmt/fmt.h>
#include <spdlog/spdlog.h>
#include <gdcmExplicitDataElement.h>
#include <gdcmImplicitDataElement.h>
#include <gdcmReader.h>
#include <zlib.h>

#include <bit>
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
#include <chrono>
#include <cctype>
#include <cmath>
#include <cstring>
#include <exception>
#include <fstream>
#include <limits>
#include <optional>
#include <random>
#include <regex>
#include <sstream>
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

namespace volcast {
namespace {

// LoadOptions::progress, kept from going backwards; every step is also where the time
// limit and a stop request end the load.
class LoadProgress {
  public:
    LoadProgress(const LoadOptions &options, const std::filesystem::path &path)
        : fn_(options.progress), stopRequested_(options.stopRequested), limit_(options.timeLimitSeconds),
          path_(path.string()) {}
    void operator()(double fraction, std::string_view task) {
        if (stopRequested_ && stopRequested_()) throw VolumeLoadError(path_ + ": loading was stopped");
        const double elapsed = std::chrono::duration<double>(std::chrono::steady_clock::now() - start_).count();
        if (limit_ > 0 && elapsed > limit_)
            throw VolumeLoadTimeout(fmt::format("{}: loading took longer than the time limit of {:g} s (stopped "
                                                "while {})",
                                                path_, limit_, task.empty() ? "starting" : std::string(task)),
                                    limit_);
        if (!fn_) return;
        last_ = std::clamp(fraction, last_, 1.0);
        fn_(last_, task);
    }

  private:
    std::function<void(double, std::string_view)> fn_;
    std::function<bool()> stopRequested_;
    double limit_ = 0;
    std::string path_;
    std::chrono::steady_clock::time_point start_ = std::chrono::steady_clock::now();
    double last_ = 0;
};

// Forwards an ITK filter's ProgressEvent (a DICOM series: one per slice) into [from, to].
class ItkProgress : public itk::Command {
  public:
    using Self = ItkProgress;
    using Superclass = itk::Command;
    using Pointer = itk::SmartPointer<Self>;
    itkNewMacro(Self)

    LoadProgress *progress = nullptr;
    double from = 0, to = 1;
    std::string task;
    // What stopped the load (time limit, stop request): ITK may send progress from a
    // destructor, so nothing is thrown through it; the filter is aborted and the loader
    // rethrows this once Update() returns.
    std::exception_ptr stopped;

    void Execute(itk::Object *caller, const itk::EventObject &event) override {
        auto *filter = dynamic_cast<itk::ProcessObject *>(caller);
        if (!progress || !filter || stopped || !itk::ProgressEvent().CheckEvent(&event)) return;
        try {
            (*progress)(from + (to - from) * double(filter->GetProgress()), task);
        } catch (...) {
            stopped = std::current_exception();
            filter->AbortGenerateDataOn();
        }
    }
    void Execute(const itk::Object *, const itk::EventObject &) override {}

  protected:
    ItkProgress() = default;
};

namespace fs = std::filesystem;

[[noreturn]] void fail(const fs::path &path, const std::string &problem) {
    throw VolumeLoadError(path.string() + ": " + problem);
}

// ITK's IO factories are registered explicitly (we do not use ITK_USE_FILE's generated
// registration); a function-local static makes it happen once, thread-safely.
void registerItkFactories() {
    static const bool registered = [] {
        itk::NrrdImageIOFactory::RegisterOneFactory();
        itk::MetaImageIOFactory::RegisterOneFactory();
        itk::NiftiImageIOFactory::RegisterOneFactory();
        itk::GDCMImageIOFactory::RegisterOneFactory();
        return true;
    }();
    (void)registered;
}

// ---------------------------------------------------------------------------------------
// Small helpers

std::string lower(std::string s) {
    std::transform(s.begin(), s.end(), s.begin(), [](unsigned char c) { return char(std::tolower(c)); });
    return s;
}

std::string trim(const std::string &s) {
    const auto b = s.find_first_not_of(" \t\r\n");
    if (b == std::string::npos) return {};
    const auto e = s.find_last_not_of(" \t\r\n");
    return s.substr(b, e - b + 1);
}

std::optional<int64_t> parseInt(const std::string &s) {
    try {
        size_t used = 0;
        const long long v = std::stoll(s, &used);
        if (trim(s.substr(used)).empty()) return int64_t(v);
    } catch (const std::exception &) {
    }
    return std::nullopt;
}

std::string withThousands(uint64_t n) {
    const std::string digits = std::to_string(n);
    std::string out;
    for (size_t i = 0; i < digits.size(); ++i) {
        if (i > 0 && (digits.size() - i) % 3 == 0) out.push_back(',');
        out.push_back(digits[i]);
    }
    return out;
}

std::string humanBytes(uint64_t n) {
    if (n < 1024) return fmt::format("{} bytes", n);
    if (n < (uint64_t(1) << 20)) return fmt::format("{:.1f} KiB", double(n) / 1024.0);
    if (n < (uint64_t(1) << 30)) return fmt::format("{:.1f} MiB", double(n) / double(1 << 20));
    return fmt::format("{:.2f} GiB", double(n) / double(1 << 30));
}

// Multiplication that reports overflow instead of wrapping (sizes come from untrusted headers).
std::optional<uint64_t> checkedMul(uint64_t a, uint64_t b) {
    if (a != 0 && b > std::numeric_limits<uint64_t>::max() / a) return std::nullopt;
    return a * b;
}

// ITK's messages carry the source location, the object address and teem's whole error
// stack; keep the lines that say what went wrong.
std::string cleanItkMessage(const itk::ExceptionObject &e) {
    static const std::regex itkPrefix(R"(^(itk::ERROR|ITK ERROR): \w+\(0x[0-9a-fA-F]+\): )");
    static const std::regex biffPrefix(R"(^\[\w+\] \w+:\s?)");
    std::string description = e.GetDescription();
    std::vector<std::string> kept;
    size_t start = 0;
    while (start <= description.size()) {
        size_t end = description.find('\n', start);
        if (end == std::string::npos) end = description.size();
        std::string line = trim(description.substr(start, end - start));
        start = end + 1;
        line = std::regex_replace(line, itkPrefix, "");
        line = trim(std::regex_replace(line, biffPrefix, ""));
        // Headlines ("Read: Error reading x:") and teem's "trouble" breadcrumbs say nothing.
        if (line.empty() || line.back() == ':' || line == "trouble" || line.starts_with("trouble reading"))
            continue;
        kept.push_back(line);
    }
    std::string out;
    for (const auto &line : kept) out += (out.empty() ? "" : "; ") + line;
    if (out.empty()) out = trim(description);
    if (out.size() > 400) out = out.substr(0, 400) + "...";
    return out;
}

std::optional<uint64_t> fileSize(const fs::path &p) {
    std::error_code ec;
    const auto size = fs::file_size(p, ec);
    if (ec) return std::nullopt;
    return uint64_t(size);
}

bool isInside(const fs::path &p, const fs::path &folder) {
    auto [f, pIt] = std::mismatch(folder.begin(), folder.end(), p.begin(), p.end());
    return f == folder.end();
}

// A data file a header names: relative to the header's folder and inside it once symbolic
// links are resolved (no absolute name, no "..", no link out), and a regular file. Only
// stat() is used, never open(): a FIFO named as data would block the loader. The messages
// name the data file as the header wrote it, never the server's absolute paths.
fs::path confinedDataFile(const fs::path &header, const std::string &name) {
    const auto refuse = [&](const std::string &why) {
        fail(header, fmt::format("data file '{}' named by the header {}", name, why));
    };
    const fs::path given(name);
    if (name.empty()) refuse("is empty");
    if (given.is_absolute() || given.has_root_name() || given.has_root_directory())
        refuse("is an absolute path; data files must lie in the header's folder (give a relative name)");
    std::error_code ec;
    const fs::path folder = fs::canonical(fs::absolute(header, ec).parent_path(), ec);
    if (ec) refuse("cannot be checked: the header's folder cannot be resolved");
    const fs::path candidate = folder / given;
    if (!fs::exists(fs::symlink_status(candidate, ec))) refuse("was not found");
    const fs::path resolved = fs::weakly_canonical(candidate, ec);
    if (ec || !fs::exists(resolved, ec)) refuse("was not found (a broken symbolic link?)");
    if (!isInside(resolved, folder))
        refuse("lies outside the header's folder (through '..' or a symbolic link); data files must lie in the "
               "header's folder");
    const auto status = fs::status(resolved, ec);
    if (ec) refuse("cannot be checked: " + ec.message());
    if (fs::is_directory(status)) refuse("is a folder, not a data file");
    if (!fs::is_regular_file(status)) refuse("is not a regular file (a FIFO, socket or device)");
    return resolved;
}

// Expands a teem/MetaIO file-name pattern ("slice%03d.raw" with min, max, step) into names.
// Only one %d conversion, with an optional 0 flag and width, is accepted: the format
// comes from an untrusted header and is never handed to printf.
std::vector<std::string> expandPattern(const fs::path &header, const std::string &spec) {
    std::istringstream in(spec);
    std::string format;
    int64_t first = 0, last = 0, step = 0;
    if (!(in >> format >> first >> last >> step))
        fail(header, fmt::format("data file pattern '{}' is not 'format min max step'", spec));
    static const std::regex conversion(R"(^([^%]*)%(0?)([0-9]{0,2})d([^%]*)$)");
    std::smatch m;
    if (!std::regex_match(format, m, conversion))
        fail(header, fmt::format("data file pattern '{}' must hold exactly one %d conversion", format));
    if (step == 0 || (step > 0 ? first > last : first < last))
        fail(header, fmt::format("data file pattern '{}' has an empty or endless range {} {} {}", format, first,
                                 last, step));
    constexpr int64_t kMaxFiles = 100000;
    const int64_t count = (last - first) / step + 1;
    if (count > kMaxFiles)
        fail(header, fmt::format("data file pattern '{}' names {} files, more than the {} allowed", format, count,
                                 kMaxFiles));
    const bool zeros = m[2].length() > 0;
    const int width = m[3].length() > 0 ? std::stoi(m[3].str()) : 0;
    std::vector<std::string> names;
    for (int64_t i = 0; i < count; ++i) {
        const int64_t n = first + i * step;
        std::string digits = std::to_string(n < 0 ? -n : n);
        const size_t signWidth = n < 0 ? 1 : 0;
        if (digits.size() + signWidth < size_t(width))
            digits.insert(0, size_t(width) - digits.size() - signWidth, zeros ? '0' : ' ');
        if (n < 0) digits.insert(zeros ? 0 : digits.find_first_not_of(' '), "-");
        names.push_back(m[1].str() + digits + m[4].str());
    }
    return names;
}

bool startsWithGzipMagic(const fs::path &file, uint64_t offset) {
    std::ifstream in(file, std::ios::binary);
    in.seekg(std::streamoff(offset));
    unsigned char magic[2] = {0, 0};
    in.read(reinterpret_cast<char *>(magic), 2);
    return in.gcount() == 2 && magic[0] == 0x1f && magic[1] == 0x8b;
}

// ---------------------------------------------------------------------------------------
// Byte counts on disk. ITK accepts raw and gzip NRRD data longer than the header says, and
// MetaImageIO and NiftiImageIO "read" truncated data into garbage (MetaIO only prints a line
// on stderr), so the loader compares what the data holds with what the header promises.

struct Decoded {
    uint64_t bytes = 0;
    bool complete = false;  // the stream ended properly (false: truncated or corrupt)
};

// Decompressed length of the gzip or zlib stream starting at `offset` (concatenated gzip
// members count together, trailing non-gzip bytes are ignored as teem and zlib do).
Decoded inflatedSize(const fs::path &file, uint64_t offset) {
    std::ifstream in(file, std::ios::binary);
    in.seekg(std::streamoff(offset));
    z_stream zs{};
    if (inflateInit2(&zs, 15 + 32) != Z_OK) return {};  // 15 + 32: gzip or zlib header
    std::vector<unsigned char> inBuf(size_t(1) << 16);
    std::vector<unsigned char> outBuf(size_t(1) << 18);
    // Keep the unread input and append more from the file.
    auto refill = [&] {
        const size_t keep = zs.avail_in;
        if (keep > 0) std::memmove(inBuf.data(), zs.next_in, keep);
        in.read(reinterpret_cast<char *>(inBuf.data() + keep), std::streamsize(inBuf.size() - keep));
        zs.next_in = inBuf.data();
        zs.avail_in = uInt(keep + size_t(in.gcount()));
    };
    Decoded result;
    for (;;) {
        if (zs.avail_in == 0) {
            refill();
            if (zs.avail_in == 0) break;  // the file ended inside the stream
        }
        zs.next_out = outBuf.data();
        zs.avail_out = uInt(outBuf.size());
        const int ret = inflate(&zs, Z_NO_FLUSH);
        result.bytes += outBuf.size() - zs.avail_out;
        if (ret == Z_STREAM_END) {
            result.complete = true;
            if (zs.avail_in < 2) refill();
            if (zs.avail_in >= 2 && zs.next_in[0] == 0x1f && zs.next_in[1] == 0x8b) {
                inflateReset(&zs);  // another gzip member follows
                result.complete = false;
                continue;
            }
            break;
        }
        if (ret != Z_OK && ret != Z_BUF_ERROR) break;  // corrupt stream
    }
    inflateEnd(&zs);
    return result;
}

// Fast path: a single gzip member records its length (mod 2^32) in its last 4 bytes; only
// when that disagrees is the whole stream inflated to count.
Decoded compressedSize(const fs::path &file, uint64_t offset, uint64_t expected) {
    const auto size = fileSize(file);
    if (size && *size >= offset + 18 && startsWithGzipMagic(file, offset)) {
        std::ifstream in(file, std::ios::binary);
        in.seekg(std::streamoff(*size - 4));
        unsigned char t[4] = {0, 0, 0, 0};
        in.read(reinterpret_cast<char *>(t), 4);
        const uint32_t isize = uint32_t(t[0]) | uint32_t(t[1]) << 8 | uint32_t(t[2]) << 16 | uint32_t(t[3]) << 24;
        if (in.gcount() == 4 && isize == uint32_t(expected)) return {expected, true};
    }
    return inflatedSize(file, offset);
}

// `where` names the bytes ("data file 'x.raw'"); `need` is what the header promises.
void checkLength(const fs::path &path, const std::string &where, uint64_t have, uint64_t need,
                 const std::string &shape, bool extraAllowed = false) {
    if (have < need)
        fail(path, fmt::format("data is truncated: {} holds {} bytes, but the header's sizes and type "
                               "({}) need {} bytes",
                               where, withThousands(have), shape, withThousands(need)));
    if (have > need && !extraAllowed)
        fail(path, fmt::format("header sizes disagree with the data: {} holds {} bytes, more than the {} "
                               "bytes the header's sizes and type ({}) need",
                               where, withThousands(have), withThousands(need), shape));
}

void checkCompressedLength(const fs::path &path, const std::string &where, const Decoded &d, uint64_t need,
                           const std::string &shape) {
    if (!d.complete)
        fail(path, fmt::format("data is truncated or corrupt: the compressed stream in {} breaks off "
                               "after {} decompressed bytes (the header's sizes and type ({}) need {} bytes)",
                               where, withThousands(d.bytes), shape, withThousands(need)));
    checkLength(path, where + " (decompressed)", d.bytes, need, shape);
}

// Offset after skipping `lines` text lines from `offset`, or nothing if the file ends first.
std::optional<uint64_t> skipLines(const fs::path &file, uint64_t offset, int64_t lines) {
    std::ifstream in(file, std::ios::binary);
    in.seekg(std::streamoff(offset));
    std::string line;
    for (int64_t i = 0; i < lines; ++i)
        if (!std::getline(in, line)) return std::nullopt;
    const auto pos = in.tellg();
    if (pos < 0) return fileSize(file);
    return uint64_t(pos);
}

// --- NRRD: just the fields that locate the data (ITK reads everything else).
struct NrrdLayout {
    std::string encoding = "raw";
    std::optional<std::string> dataFile;  // a single detached data file, as written
    bool multiFile = false;               // LIST or a file-name pattern: lengths not checked here
    std::vector<std::string> dataFiles;   // every detached data file, in every form, as written
    int64_t lineSkip = 0;
    int64_t byteSkip = 0;
    bool attached = false;                // data follows the header's blank line
    uint64_t headerEnd = 0;
    std::vector<uint64_t> sizes;          // the "sizes:" field, each a whole number
};

std::optional<NrrdLayout> scanNrrdHeader(const fs::path &path) {
    std::ifstream in(path, std::ios::binary);
    std::string line;
    if (!std::getline(in, line) || !line.starts_with("NRRD")) return std::nullopt;
    NrrdLayout layout;
    for (int count = 0; count < 100000 && std::getline(in, line); ++count) {
        if (!line.empty() && line.back() == '\r') line.pop_back();
        if (line.empty()) {
            const auto pos = in.tellg();
            layout.attached = !layout.dataFile && !layout.multiFile;
            layout.headerEnd = pos < 0 ? fileSize(path).value_or(0) : uint64_t(pos);
            break;
        }
        if (line[0] == '#') continue;
        const auto colon = line.find(": ");
        const auto kv = line.find(":=");
        if (colon == std::string::npos || (kv != std::string::npos && kv < colon)) continue;
        const std::string key = lower(trim(line.substr(0, colon)));
        const std::string value = trim(line.substr(colon + 2));
        if (key == "sizes") {
            // Read here too: ITK 5.2 keeps each size as a 32-bit number, so 21474836481 reached
            // our checks as 1 while NrrdIO allocated 343 GB for it (fuzz finding 13).
            std::istringstream tokens(value);
            for (std::string token; tokens >> token;) {
                const bool digits = token.size() <= 19 && std::all_of(token.begin(), token.end(), [](char c) {
                    return c >= '0' && c <= '9';
                });
                if (!digits)
                    fail(path, fmt::format("NRRD header's sizes hold '{}', which is not a whole number",
                                           token.size() > 24 ? token.substr(0, 24) + "..." : token));
                layout.sizes.push_back(std::stoull(token));
            }
        } else if (key == "encoding") {
            layout.encoding = lower(value);
        } else if (key == "data file" || key == "datafile") {
            // "LIST" and "pattern min max step [subdim]" name several files.
            const bool pattern = value.find('%') != std::string::npos &&
                                 std::count(value.begin(), value.end(), ' ') >= 3;
            if (value.starts_with("LIST")) {
                // The header's remaining lines are the file names.
                layout.multiFile = true;
                while (std::getline(in, line) && layout.dataFiles.size() < 100000)
                    if (const std::string name = trim(line); !name.empty()) layout.dataFiles.push_back(name);
                break;
            }
            if (pattern) {
                layout.multiFile = true;
                layout.dataFiles = expandPattern(path, value);
            } else {
                layout.dataFile = value;
                layout.dataFiles = {value};
            }
        } else if (key == "line skip" || key == "lineskip") {
            layout.lineSkip = parseInt(value).value_or(0);
        } else if (key == "byte skip" || key == "byteskip") {
            layout.byteSkip = parseInt(value).value_or(0);
        }
    }
    return layout;
}

void checkNrrdData(const fs::path &path, const NrrdLayout &layout, uint64_t need, const std::string &shape) {
    if (layout.multiFile || (!layout.dataFile && !layout.attached)) return;
    const fs::path file = layout.dataFile ? confinedDataFile(path, *layout.dataFile) : path;
    const std::string where = layout.dataFile ? fmt::format("data file '{}'", *layout.dataFile) : "the file";
    uint64_t start = layout.dataFile ? 0 : layout.headerEnd;
    if (layout.lineSkip > 0) {
        const auto skipped = skipLines(file, start, layout.lineSkip);
        if (!skipped) fail(path, fmt::format("data is truncated: {} ends within the header's line skip", where));
        start = *skipped;
    }
    const std::string encoding = layout.encoding;
    if (encoding == "raw") {
        const uint64_t size = fileSize(file).value_or(0);
        uint64_t have = size > start ? size - start : 0;
        if (layout.byteSkip == -1) {
            checkLength(path, where, have, need, shape, /*extraAllowed=*/true);  // data sits at the end
            return;
        }
        const uint64_t skip = uint64_t(std::max<int64_t>(layout.byteSkip, 0));
        have = have > skip ? have - skip : 0;
        checkLength(path, where, have, need, shape);
    } else if (encoding == "gzip" || encoding == "gz") {
        // teem applies a byte skip to the decompressed bytes; -1 is not allowed with gzip.
        if (layout.byteSkip < 0) return;
        const uint64_t skip = uint64_t(layout.byteSkip);
        const Decoded d = compressedSize(file, start, skip + need);
        checkCompressedLength(path, where, {d.bytes >= skip ? d.bytes - skip : 0, d.complete}, need, shape);
    }
    // ascii/hex/bzip2: teem itself fails on short data; not checked further here.
}

// --- MetaImage: the fields that locate the data.
struct MetaLayout {
    std::string dataFile;  // "LOCAL" or a file name
    bool multiFile = false;
    std::vector<std::string> dataFiles;  // every detached data file (LIST, pattern or one), as written
    bool compressed = false;
    bool binary = true;
    int64_t headerSize = 0;
    uint64_t localStart = 0;
};

constexpr size_t kMetaIoLongestFieldName = 254;   // MET_FieldRecordType::name is char[255]
constexpr int64_t kMetaIoMostDimensions = 10;      // MetaImage's per-axis arrays hold 10

std::optional<MetaLayout> scanMetaHeader(const fs::path &path) {
    std::ifstream in(path, std::ios::binary);
    std::string line;
    MetaLayout layout;
    for (int count = 0; count < 10000 && std::getline(in, line); ++count) {
        // MetaIO takes ':' as well as '=' between a field's name and value, and compares
        // names as C strings (a NUL ends one): "ElementDataFile: LIST…" and
        // "ElementDataFile<NUL>…: LIST…" were its ElementDataFile but not ours, and reached
        // MetaIO's LIST reader unchecked (a segmentation fault; fuzz finding 12). A header is
        // text: a NUL in it is refused.
        if (line.find('\0') != std::string::npos)
            fail(path, fmt::format("MetaImage header line {} holds a NUL byte; the header must be text", count + 1));
        const auto eq = line.find_first_of("=:");
        // MetaIO copies each line's field name (up to the '=' or the line's end) into a
        // 255-byte buffer unchecked: a longer one overflowed it and aborted the process
        // (fortified strcpy; fuzz finding 9).
        if (const size_t name = trim(line.substr(0, eq)).size(); name > kMetaIoLongestFieldName)
            fail(path, fmt::format("MetaImage header line {} has a field name of {} bytes; at most {} are allowed",
                                   count + 1, name, kMetaIoLongestFieldName));
        if (eq == std::string::npos) continue;
        const std::string key = lower(trim(line.substr(0, eq)));
        const std::string value = trim(line.substr(eq + 1));
        // MetaIO reads NDims values into arrays of 10 and loops NDims times over the stream
        // for DimSize and the rest: a huge NDims kept the loader reading for good (fuzz
        // finding 10).
        if (key == "ndims") {
            const auto n = parseInt(value);
            if (!n || *n < 1 || *n > kMetaIoMostDimensions)
                fail(path, fmt::format("MetaImage header's NDims is '{}'; it must be a whole number from 1 to {}",
                                       value.size() > 24 ? value.substr(0, 24) + "..." : value,
                                       kMetaIoMostDimensions));
        }
        if (key == "compresseddata") layout.compressed = lower(value) == "true";
        else if (key == "binarydata") layout.binary = lower(value) != "false";
        else if (key == "headersize") layout.headerSize = parseInt(value).value_or(0);
        else if (key == "elementdatafile") {
            // ElementDataFile is the header's last field; LOCAL data starts right after it.
            layout.dataFile = value;
            layout.multiFile = value.starts_with("LIST") || value.find('%') != std::string::npos;
            const auto pos = in.tellg();
            layout.localStart = pos < 0 ? fileSize(path).value_or(0) : uint64_t(pos);
            if (value.starts_with("LIST")) {
                // The header's remaining lines are the file names.
                while (std::getline(in, line) && layout.dataFiles.size() < 100000)
                    if (const std::string name = trim(line); !name.empty()) layout.dataFiles.push_back(name);
            } else if (layout.multiFile) {
                layout.dataFiles = expandPattern(path, value);
            } else if (value != "LOCAL") {
                layout.dataFiles = {value};
            }
            return layout;
        }
    }
    return std::nullopt;
}

void checkMetaData(const fs::path &path, const MetaLayout &layout, uint64_t need, const std::string &shape) {
    if (layout.multiFile || !layout.binary) return;
    const bool local = layout.dataFile == "LOCAL";
    const fs::path file = local ? path : confinedDataFile(path, layout.dataFile);
    const std::string where = local ? "the file" : fmt::format("data file '{}'", layout.dataFile);
    const uint64_t start = local ? layout.localStart : uint64_t(std::max<int64_t>(layout.headerSize, 0));
    if (layout.compressed) {
        checkCompressedLength(path, where, inflatedSize(file, start), need, shape);
        return;
    }
    const uint64_t size = fileSize(file).value_or(0);
    const uint64_t have = size > start ? size - start : 0;
    // HeaderSize -1 means "the data is the last bytes of the file".
    checkLength(path, where, have, need, shape, /*extraAllowed=*/!local && layout.headerSize == -1);
}

// --- NIfTI-1/2: the header's fields, read by the loader itself.
template <typename T>
T readScalar(const unsigned char *p, bool swap) {
    std::array<unsigned char, sizeof(T)> b;
    std::memcpy(b.data(), p, sizeof(T));
    if (swap) std::reverse(b.begin(), b.end());
    T v;
    std::memcpy(&v, b.data(), sizeof(T));
    return v;
}

// The NIfTI-1 data types and the bits per voxel the specification ties to each.
std::optional<int> niftiBitsOf(int datatype) {
    switch (datatype) {
    case 1: return 1;                                  // binary
    case 2: case 256: return 8;                        // uint8, int8
    case 4: case 512: return 16;                       // int16, uint16
    case 8: case 16: case 768: return 32;              // int32, float32, uint32
    case 128: return 24;                               // rgb24
    case 2304: return 32;                              // rgba32
    case 32: case 64: case 1024: case 1280: return 64; // complex64, float64, int64, uint64
    case 1536: case 1792: return 128;                  // float128, complex128
    case 2048: return 256;                             // complex256
    default: return std::nullopt;
    }
}

struct NiftiHeader {
    std::array<int64_t, 8> dim{};
    int bitpix = 0;
    uint64_t voxOffset = 0;
    bool singleFile = false;
    uint64_t bytes = 0;   // voxel bytes the dims and bitpix promise
    std::string shape;
};

// Reads and checks the header fields niftilib would trust: ITK reads a header that breaks
// the specification (sizeof_hdr, dim, bitpix against datatype, vox_offset inside the
// header, pixdim 0, negative or NaN) into a zero-filled or shifted volume without a word.
// Each refusal names the field.
constexpr double kNiftiLargestCoordinate = 1e9;   // mm; squares stay far below float overflow (3.4e38)

NiftiHeader readNiftiHeader(const fs::path &path) {
    std::array<unsigned char, 540> h{};
    int got = 0;
    if (gzFile g = gzopen(path.string().c_str(), "rb")) {  // gzread also reads plain files
        got = gzread(g, h.data(), unsigned(h.size()));
        gzclose(g);
    }
    if (got < 348) fail(path, "NIfTI header is truncated");
    const int32_t sizeofHdr = readScalar<int32_t>(h.data(), false);
    const int32_t swappedSize = readScalar<int32_t>(h.data(), true);
    const bool swap = sizeofHdr != 348 && sizeofHdr != 540;
    const int32_t hdrSize = swap ? swappedSize : sizeofHdr;
    if (hdrSize != 348 && hdrSize != 540)
        fail(path, fmt::format("NIfTI header's sizeof_hdr is {}; the specification requires 348 (NIfTI-1) or 540 "
                               "(NIfTI-2)",
                               sizeofHdr));
    if (hdrSize == 540 && got < 540) fail(path, "NIfTI-2 header is truncated");
    NiftiHeader n;
    int datatype = 0;
    std::array<double, 8> pixdim{};
    int64_t rawOffset = 0;
    uint64_t headerBytes = 352;
    int qformCode = 0, sformCode = 0;
    std::array<double, 6> quatern{};  // quatern_b, _c, _d, qoffset_x, _y, _z
    std::array<double, 12> srow{};    // srow_x, srow_y, srow_z
    if (hdrSize == 348) {
        for (size_t i = 0; i < 8; ++i) n.dim[i] = readScalar<int16_t>(h.data() + 40 + 2 * i, swap);
        datatype = readScalar<int16_t>(h.data() + 70, swap);
        n.bitpix = readScalar<int16_t>(h.data() + 72, swap);
        for (size_t i = 0; i < 8; ++i) pixdim[i] = readScalar<float>(h.data() + 76 + 4 * i, swap);
        const float off = readScalar<float>(h.data() + 108, swap);
        rawOffset = std::isfinite(off) && off > 0 && off < 9e18f ? int64_t(off) : -1;
        n.singleFile = std::memcmp(h.data() + 344, "n+1", 4) == 0;
        qformCode = readScalar<int16_t>(h.data() + 252, swap);
        sformCode = readScalar<int16_t>(h.data() + 254, swap);
        for (size_t i = 0; i < 6; ++i) quatern[i] = readScalar<float>(h.data() + 256 + 4 * i, swap);
        for (size_t i = 0; i < 12; ++i) srow[i] = readScalar<float>(h.data() + 280 + 4 * i, swap);
    } else {
        for (size_t i = 0; i < 8; ++i) n.dim[i] = readScalar<int64_t>(h.data() + 16 + 8 * i, swap);
        datatype = readScalar<int16_t>(h.data() + 12, swap);
        n.bitpix = readScalar<int16_t>(h.data() + 14, swap);
        for (size_t i = 0; i < 8; ++i) pixdim[i] = readScalar<double>(h.data() + 104 + 8 * i, swap);
        rawOffset = readScalar<int64_t>(h.data() + 168, swap);
        n.singleFile = std::memcmp(h.data() + 4, "n+2", 4) == 0;
        headerBytes = 544;
        qformCode = readScalar<int32_t>(h.data() + 344, swap);
        sformCode = readScalar<int32_t>(h.data() + 348, swap);
        for (size_t i = 0; i < 6; ++i) quatern[i] = readScalar<double>(h.data() + 352 + 8 * i, swap);
        for (size_t i = 0; i < 12; ++i) srow[i] = readScalar<double>(h.data() + 400 + 8 * i, swap);
    }
    if (n.dim[0] < 1 || n.dim[0] > 7)
        fail(path, fmt::format("NIfTI header's dim[0] (the number of dimensions) is {}; the specification allows "
                               "1 to 7",
                               n.dim[0]));
    for (int64_t i = 1; i <= n.dim[0]; ++i)
        if (n.dim[size_t(i)] < 1)
            fail(path, fmt::format("NIfTI header's dim[{}] (size of axis {}) is {}; every size must be at least 1",
                                   i, i - 1, n.dim[size_t(i)]));
    const auto bits = niftiBitsOf(datatype);
    if (!bits) fail(path, fmt::format("NIfTI header's datatype {} is not a NIfTI data type", datatype));
    if (n.bitpix != *bits)
        fail(path, fmt::format("NIfTI header's bitpix is {}, but its datatype {} has {} bits per voxel", n.bitpix,
                               datatype, *bits));
    if (n.bitpix % 8 != 0)
        fail(path, fmt::format("NIfTI header's datatype {} ({} bits per voxel) is not supported", datatype,
                               n.bitpix));
    for (int64_t i = 1; i <= std::min<int64_t>(n.dim[0], 3); ++i)
        if (!std::isfinite(pixdim[size_t(i)]) || pixdim[size_t(i)] <= 0)
            fail(path, fmt::format("NIfTI header's pixdim[{}] (spacing of axis {}) is {}; it must be finite and "
                                   "greater than 0",
                                   i, i - 1, pixdim[size_t(i)]));
    // niftilib builds the orientation from the quaternion (qform_code > 0) or the affine rows
    // (sform_code > 0), and ITK takes a single-precision SVD of it: on a NaN, an infinity or
    // values whose products overflow a float (-1.7e38 beside 1.5e26) that SVD never ends (fuzz
    // findings 8 and 11: the one loader spun for good). Nothing physical comes near 1e9 mm.
    // The codes are the specification's NIFTI_XFORM_* values, 0 to 5.
    for (const auto &[name, code] : {std::pair{"qform_code", qformCode}, std::pair{"sform_code", sformCode}})
        if (code < 0 || code > 5)
            fail(path, fmt::format("NIfTI header's {} is {}; the specification's codes are 0 to 5", name, code));
    const auto checkFinite = [&](const std::string &field, double v) {
        if (!std::isfinite(v) || std::abs(v) > kNiftiLargestCoordinate)
            fail(path, fmt::format("NIfTI header's {} is {}; it must be finite and at most {:g} in size", field, v,
                                   kNiftiLargestCoordinate));
    };
    for (int64_t i = 1; i <= std::min<int64_t>(n.dim[0], 3); ++i)
        checkFinite(fmt::format("pixdim[{}]", i), pixdim[size_t(i)]);
    if (qformCode > 0) {
        static constexpr const char *kNames[] = {"quatern_b", "quatern_c", "quatern_d",
                                                 "qoffset_x", "qoffset_y", "qoffset_z"};
        for (size_t i = 0; i < 6; ++i) checkFinite(kNames[i], quatern[i]);
    }
    if (sformCode > 0)
        for (size_t i = 0; i < 12; ++i)
            checkFinite(fmt::format("srow_{}[{}]", "xyz"[i / 4], i % 4), srow[i]);
    if (n.singleFile && (rawOffset < 0 || uint64_t(rawOffset) < headerBytes))
        fail(path, fmt::format("NIfTI header's vox_offset is {}; in a single-file NIfTI the voxels start after "
                               "the {}-byte header",
                               rawOffset, headerBytes));
    n.voxOffset = uint64_t(std::max<int64_t>(rawOffset, 0));
    std::optional<uint64_t> bytes = uint64_t(n.bitpix / 8);
    for (int64_t i = 1; i <= n.dim[0]; ++i) {
        bytes = bytes ? checkedMul(*bytes, uint64_t(n.dim[size_t(i)])) : std::nullopt;
        n.shape += (n.shape.empty() ? "" : " x ") + std::to_string(n.dim[size_t(i)]);
    }
    if (!bytes) fail(path, "header sizes are absurd (the voxel count overflows)");
    n.bytes = *bytes;
    n.shape += fmt::format(", {} bits per voxel, data at byte {}", n.bitpix, n.voxOffset);
    return n;
}

// NiftiImageIO reports a size of 0 as 1 and reads short data without complaint, so the
// data's length is checked against the header's own fields.
void checkNiftiData(const fs::path &path, const NiftiHeader &n) {
    fs::path dataFile = path;
    std::string where = "the file";
    if (!n.singleFile) {
        // A .hdr/.img pair (NIfTI "ni1"/"ni2" or Analyze): the voxels are in the .img file.
        std::string stem = path.string();
        const bool gz = stem.ends_with(".gz");
        if (gz) stem.resize(stem.size() - 3);
        if (!lower(stem).ends_with(".hdr")) return;
        stem.resize(stem.size() - 4);
        dataFile = fs::path(stem + (gz ? ".img.gz" : ".img"));
        if (!fs::exists(dataFile)) dataFile = fs::path(stem + (gz ? ".img" : ".img.gz"));
        if (!fs::exists(dataFile))
            fail(path, fmt::format("data file '{}' named by the header was not found",
                                   fs::path(stem + ".img").filename().string()));
        const std::string name = dataFile.filename().string();
        dataFile = confinedDataFile(path, name);
        where = fmt::format("data file '{}'", name);
    }
    const uint64_t need = n.voxOffset + n.bytes;
    if (startsWithGzipMagic(dataFile, 0)) {
        checkCompressedLength(path, where, compressedSize(dataFile, 0, need), need, n.shape);
    } else {
        checkLength(path, where, fileSize(dataFile).value_or(0), need, n.shape);
    }
}

// ---------------------------------------------------------------------------------------
// From ITK's header information to a validated Volume.

std::optional<VoxelType> voxelTypeOf(itk::IOComponentEnum t, size_t componentSize) {
    using C = itk::IOComponentEnum;
    switch (t) {
    case C::UCHAR: return VoxelType::UInt8;
    case C::CHAR: return VoxelType::Int8;
    case C::USHORT: return VoxelType::UInt16;
    case C::SHORT: return VoxelType::Int16;
    case C::UINT: return VoxelType::UInt32;
    case C::INT: return VoxelType::Int32;
    case C::ULONG: return componentSize == 4 ? std::optional(VoxelType::UInt32) : std::nullopt;
    case C::LONG: return componentSize == 4 ? std::optional(VoxelType::Int32) : std::nullopt;
    case C::FLOAT: return VoxelType::Float32;
    case C::DOUBLE: return VoxelType::Float64;
    default: return std::nullopt;
    }
}

itk::IOComponentEnum itkComponentOf(VoxelType t) {
    using C = itk::IOComponentEnum;
    switch (t) {
    case VoxelType::UInt8: return C::UCHAR;
    case VoxelType::Int8: return C::CHAR;
    case VoxelType::UInt16: return C::USHORT;
    case VoxelType::Int16: return C::SHORT;
    case VoxelType::UInt32: return C::UINT;
    case VoxelType::Int32: return C::INT;
    case VoxelType::Float32: return C::FLOAT;
    case VoxelType::Float64: return C::DOUBLE;
    }
    return C::UNKNOWNCOMPONENTTYPE;
}

// Calls f with a value of the C++ type that stores `t`.
template <typename F>
decltype(auto) withVoxelType(VoxelType t, F &&f) {
    switch (t) {
    case VoxelType::UInt8: return f(uint8_t{});
    case VoxelType::Int8: return f(int8_t{});
    case VoxelType::UInt16: return f(uint16_t{});
    case VoxelType::Int16: return f(int16_t{});
    case VoxelType::UInt32: return f(uint32_t{});
    case VoxelType::Int32: return f(int32_t{});
    case VoxelType::Float32: return f(float{});
    case VoxelType::Float64: return f(double{});
    }
    return f(float{});
}

VoxelType checkedVoxelType(const fs::path &path, const itk::ImageIOBase &io) {
    const auto components = io.GetNumberOfComponents();
    if (components != 1)
        fail(path, fmt::format("has {} components per voxel ({} data); only scalar volumes with one "
                               "component can be loaded",
                               components, itk::ImageIOBase::GetPixelTypeAsString(io.GetPixelType())));
    const auto componentType = io.GetComponentType();
    if (componentType == itk::IOComponentEnum::UNKNOWNCOMPONENTTYPE)
        fail(path, "voxel type is unknown or unsupported");
    const auto type = voxelTypeOf(componentType, io.GetComponentSize());
    if (!type)
        fail(path, fmt::format("voxel type '{}'{} is not supported (supported: int8, uint8, int16, uint16, "
                               "int32, uint32, float, double)",
                               itk::ImageIOBase::GetComponentTypeAsString(componentType),
                               io.GetComponentSize() == 8 ? " (64-bit integer)" : ""));
    return *type;
}

void checkShape(const fs::path &path, const Vec3i &dims, const LoadOptions &options) {
    const std::string sizes = fmt::format("{} x {} x {}", dims.x, dims.y, dims.z);
    for (int a = 0; a < 3; ++a) {
        if (dims[a] < 1)
            fail(path, fmt::format("size of axis {} is {} ({}); every size must be at least 1", a, dims[a], sizes));
        if (dims[a] > options.maxDimension)
            fail(path, fmt::format("size {} is absurd: axis {} has {} samples, more than the {} allowed per axis",
                                   sizes, a, dims[a], options.maxDimension));
    }
    std::optional<uint64_t> bytes = sizeof(float);
    for (int a = 0; a < 3; ++a) bytes = bytes ? checkedMul(*bytes, uint64_t(dims[a])) : std::nullopt;
    if (!bytes || *bytes > options.maxBytes)
        throw VolumeTooLarge(path.string() + ": " +
                                 fmt::format("volume of {} voxels needs {} as float32, more than the memory budget "
                                             "of {}",
                                             sizes, bytes ? humanBytes(*bytes) : std::string("more than 16 EiB"),
                                             humanBytes(options.maxBytes)),
                             bytes.value_or(std::numeric_limits<uint64_t>::max()));
}

// Spacing must be positive and finite, the direction matrix orthonormal; returns the
// direction re-orthonormalized exactly (same handedness), since Volume inverts it by transposing.
Mat3d checkedGeometry(const fs::path &path, const Vec3d &spacing, const Vec3d &origin, const Mat3d &direction) {
    for (int a = 0; a < 3; ++a) {
        if (!std::isfinite(spacing[a]) || spacing[a] <= 0)
            fail(path, fmt::format("spacing of axis {} is {}; spacings must be finite and greater than 0", a,
                                   spacing[a]));
        if (!std::isfinite(origin[a])) fail(path, fmt::format("origin of axis {} is {}", a, origin[a]));
    }
    std::array<Vec3d, 3> c;
    for (int a = 0; a < 3; ++a) c[size_t(a)] = {direction(0, a), direction(1, a), direction(2, a)};
    constexpr double kTolerance = 1e-3;
    const auto describe = [&] {
        std::string s;
        for (const auto &v : c) s += fmt::format(" ({:.6g}, {:.6g}, {:.6g})", v.x, v.y, v.z);
        return s;
    };
    for (int a = 0; a < 3; ++a) {
        const double len = length(c[size_t(a)]);
        if (!std::isfinite(len) || std::abs(len - 1) > kTolerance)
            fail(path, fmt::format("direction matrix is singular or not orthonormal: axis {} has length {:.6g} "
                                   "(axes:{})",
                                   a, len, describe()));
    }
    for (int a = 0; a < 3; ++a) {
        const int b = (a + 1) % 3;
        const double d = dot(c[size_t(a)], c[size_t(b)]);
        if (std::abs(d) > kTolerance)
            fail(path, fmt::format("direction matrix is not orthonormal: axes {} and {} are {:.3f} degrees apart, "
                                   "not 90 (axes:{})",
                                   a, b, std::acos(std::clamp(d, -1.0, 1.0)) * 180 / 3.14159265358979323846,
                                   describe()));
    }
    // Gram-Schmidt on the first two axes; the third follows from the handedness.
    const double det = dot(c[0], cross(c[1], c[2]));
    const Vec3d x = normalize(c[0]);
    const Vec3d y = normalize(c[1] - x * dot(c[1], x));
    const Vec3d z = cross(x, y) * (det < 0 ? -1.0 : 1.0);
    Mat3d out;
    for (int r = 0; r < 3; ++r) {
        out(r, 0) = x[r];
        out(r, 1) = y[r];
        out(r, 2) = z[r];
    }
    return out;
}

// NaN -> smallest finite, +Inf -> largest finite, -Inf -> smallest finite (see volume_io.hpp).
size_t replaceNonFinite(const fs::path &path, std::vector<float> &voxels) {
    float lo = std::numeric_limits<float>::max();
    float hi = std::numeric_limits<float>::lowest();
    size_t bad = 0;
    for (float x : voxels) {
        if (std::isfinite(x)) {
            lo = std::min(lo, x);
            hi = std::max(hi, x);
        } else {
            ++bad;
        }
    }
    if (bad == voxels.size())
        fail(path, fmt::format("has no finite voxel (all {} voxels are NaN or infinite)", voxels.size()));
    if (bad == 0) return 0;
    for (float &x : voxels)
        if (!std::isfinite(x)) x = (x > 0) ? hi : lo;  // NaN compares false, so it takes lo
    spdlog::warn("{}: replaced {} non-finite voxels (NaN and -Inf by the smallest finite value {}, +Inf by the "
                 "largest {})",
                 path.string(), bad, lo, hi);
    return bad;
}

std::string displayName(const fs::path &path) {
    const fs::path p = path.has_filename() ? path : path.parent_path();
    return p.filename().string();
}

// Reads all voxels of an IO whose header is read and validated into v: an 8- or 16-bit
// file's straight into the narrow store (unsigned as they are, signed with the sign bit
// flipped, which is adding 2^7 or 2^15: offset −2^7 or −2^15), so that a 16-bit scan never
// takes float32's bytes, even while loading; every other type converted to float32.
void readVoxels(const fs::path &path, itk::ImageIOBase &io, VoxelType type, Volume &v, LoadProgress &progress) {
    static_assert(std::endian::native == std::endian::little, "the narrow store is little-endian (narrow_samples.hpp)");
    itk::ImageIORegion region(io.GetNumberOfDimensions());
    for (unsigned d = 0; d < io.GetNumberOfDimensions(); ++d) {
        region.SetIndex(d, 0);
        region.SetSize(d, io.GetDimensions(d));
    }
    io.SetIORegion(region);
    const size_t count = v.voxelCount();
    size_t clamped = 0;
    try {
        withVoxelType(type, [&](auto tag) {
            using T = decltype(tag);
            if constexpr (std::is_same_v<T, float>) {
                v.voxels.resize(count);
                io.Read(v.voxels.data());
            } else if constexpr (std::is_integral_v<T> && sizeof(T) <= 2) {
                v.narrowVoxels.assign(count * sizeof(T) + kNarrowSlack, 0);
                io.Read(v.narrowVoxels.data());
                progress(0.8, "converting");
                if constexpr (std::is_signed_v<T>) {
                    // Little-endian: the sign bit is in each sample's last byte.
                    for (size_t i = sizeof(T) - 1; i < count * sizeof(T); i += sizeof(T)) v.narrowVoxels[i] ^= 0x80;
                }
                v.narrow = {int(sizeof(T)), std::is_signed_v<T> ? -std::ldexp(1.0f, 8 * int(sizeof(T)) - 1) : 0.0f};
            } else {
                v.voxels.resize(count);
                std::vector<T> native(count);
                io.Read(native.data());
                const size_t chunk = std::max<size_t>(count / 16, 1);
                for (size_t i = 0; i < count; ++i) {
                    if (i % chunk == 0) progress(0.8 + 0.1 * double(i) / double(count), "converting");
                    if constexpr (std::is_same_v<T, double>) {
                        // Finite doubles beyond float's range would become Inf; clamp them instead.
                        constexpr double kMax = std::numeric_limits<float>::max();
                        const double x = native[i];
                        if (std::isfinite(x) && std::abs(x) > kMax) {
                            v.voxels[i] = float(std::clamp(x, -kMax, kMax));
                            ++clamped;
                        } else {
                            v.voxels[i] = float(x);
                        }
                    } else {
                        v.voxels[i] = float(native[i]);
                    }
                }
            }
        });
    } catch (const itk::ExceptionObject &e) {
        const std::string message = cleanItkMessage(e);
        const bool shortData = message.find("fread got only") != std::string::npos ||
                               message.find("but received") != std::string::npos;
        fail(path, (shortData ? "data is truncated: " : "cannot read the voxel data: ") + message);
    }
    if (clamped > 0)
        spdlog::warn("{}: clamped {} float64 voxels beyond the float32 range", path.string(), clamped);
}

// A private temporary folder holding a link to the file being read; removed on scope exit.
struct TemporaryLink {
    fs::path folder;
    fs::path link;
    TemporaryLink() = default;
    TemporaryLink(const TemporaryLink &) = delete;
    TemporaryLink &operator=(const TemporaryLink &) = delete;
    ~TemporaryLink() {
        std::error_code ec;
        if (!folder.empty()) fs::remove_all(folder, ec);
    }
};

// niftilib looks for a single-file image's voxels in "x.nii" before "x.nii.gz", whatever
// name it was given: with both side by side, loading x.nii.gz would pair its header with
// x.nii's bytes. Such a file is read through a link in a folder of its own.
fs::path niftiReadPath(const fs::path &path, TemporaryLink &alias) {
    const std::string name = path.string();
    if (!lower(name).ends_with(".nii.gz")) return path;
    const fs::path sibling(name.substr(0, name.size() - 3));
    if (!fs::exists(sibling)) return path;
    std::random_device random;
    alias.folder = fs::temp_directory_path() / fmt::format("volcast_nifti_{:08x}{:08x}", random(), random());
    std::error_code ec;
    fs::create_directories(alias.folder, ec);
    if (!ec) fs::create_symlink(fs::absolute(path), alias.folder / path.filename(), ec);
    if (ec)
        fail(path, fmt::format("'{}' lies beside it and the NIfTI library would read that file's voxels instead; "
                               "move one of the two away",
                               sibling.filename().string()));
    alias.link = alias.folder / path.filename();
    spdlog::info("{}: '{}' lies beside it; reading through a link so that the NIfTI library takes the right voxels",
                 path.string(), sibling.filename().string());
    return alias.link;
}

// Every entry of a DICOM folder must be a regular file or a folder that stays inside it:
// GDCM opens each file to scan it, and a FIFO would block the loader.
void checkDicomFolderEntries(const fs::path &dir) {
    std::error_code ec;
    const fs::path folder = fs::canonical(dir, ec);
    if (ec) fail(dir, "folder cannot be resolved: " + ec.message());
    for (fs::directory_iterator it(folder, ec), end; !ec && it != end; it.increment(ec)) {
        const std::string name = it->path().filename().string();
        std::error_code ec2;
        const fs::path resolved = fs::weakly_canonical(it->path(), ec2);
        if (ec2 || !isInside(resolved, folder))
            fail(dir, fmt::format("'{}' in the folder is a symbolic link that leads out of it", name));
        const auto status = fs::status(resolved, ec2);
        if (!ec2 && !fs::is_regular_file(status) && !fs::is_directory(status))
            fail(dir, fmt::format("'{}' in the folder is not a regular file (a FIFO, socket or device)", name));
    }
}

// GDCM reads a slice whose pixel data is cut short as if the missing bytes were zero, so the
// loader compares each slice's file size with the length its pixel data element declares,
// and that length with what rows, columns and bits allocated need. Encapsulated
// (compressed) pixel data has no declared length and is left to GDCM's decoder.
// Where one slice of a series lies, as its header says (absent values stay empty).
struct SliceGeometry {
    std::string file;
    std::optional<Vec3d> position;                 // Image Position (Patient), mm
    std::optional<std::array<double, 6>> orientation;   // Image Orientation (Patient): row, then column cosines
    int64_t rows = 0, columns = 0;
};

// The numbers of a DS (decimal string) element, or nothing when it is absent or does not hold
// exactly `count` finite numbers. Parsed here rather than by GDCM's attribute classes, whose
// assertions a hostile value could reach.
template <size_t N>
std::optional<std::array<double, N>> decimalStrings(const gdcm::DataSet &ds, gdcm::Tag tag) {
    if (!ds.FindDataElement(tag)) return std::nullopt;
    const gdcm::ByteValue *value = ds.GetDataElement(tag).GetByteValue();
    if (!value || value->GetLength() == 0 || value->GetLength() > 1024) return std::nullopt;
    std::string text(value->GetPointer(), value->GetLength());
    std::array<double, N> out{};
    size_t count = 0, at = 0;
    while (at <= text.size()) {
        const size_t end = std::min(text.find('\\', at), text.size());
        std::string item = text.substr(at, end - at);
        item.erase(std::remove_if(item.begin(), item.end(), [](unsigned char c) { return c == ' ' || c == '\0'; }),
                   item.end());
        char *stop = nullptr;
        const double x = std::strtod(item.c_str(), &stop);
        if (item.empty() || *stop != '\0' || !std::isfinite(x) || count == N) return std::nullopt;
        out[count++] = x;
        at = end + 1;
    }
    if (count != N) return std::nullopt;
    return out;
}

int64_t unsignedShort(const gdcm::DataSet &ds, gdcm::Tag tag) {
    if (!ds.FindDataElement(tag)) return 0;
    const gdcm::ByteValue *value = ds.GetDataElement(tag).GetByteValue();
    if (!value || value->GetLength() != 2) return 0;
    const auto *b = reinterpret_cast<const unsigned char *>(value->GetPointer());
    return int64_t(b[0] | b[1] << 8);   // US in the little-endian transfer syntaxes GDCM reads here
}

SliceGeometry checkDicomSlice(const fs::path &dir, const fs::path &file, uint64_t need) {
    const std::string name = file.filename().string();
    const gdcm::Tag pixelData(0x7fe0, 0x0010);
    gdcm::Reader reader;
    reader.SetFileName(file.string().c_str());
    // The pixel data element as a tag to skip: its value is not read (a damaged header may
    // declare 4 GiB of it, which GDCM would allocate and fill before this check could refuse).
    if (!reader.ReadUpToTag(pixelData, {pixelData}))
        fail(dir, fmt::format("slice '{}' is not a readable DICOM file (its header is damaged or cut short)", name));
    // The pixel data element starts after the file meta header and every element before it.
    const gdcm::File &dicom = reader.GetFile();
    SliceGeometry geometry;
    geometry.file = name;
    {
        const gdcm::DataSet &ds = dicom.GetDataSet();
        if (const auto p = decimalStrings<3>(ds, gdcm::Tag(0x0020, 0x0032))) geometry.position = Vec3d{(*p)[0], (*p)[1], (*p)[2]};
        geometry.orientation = decimalStrings<6>(ds, gdcm::Tag(0x0020, 0x0037));
        geometry.rows = unsignedShort(ds, gdcm::Tag(0x0028, 0x0010));
        geometry.columns = unsignedShort(ds, gdcm::Tag(0x0028, 0x0011));
    }
    const bool implicitVr =
        dicom.GetHeader().GetDataSetTransferSyntax().GetNegociatedType() == gdcm::TransferSyntax::Implicit;
    uint64_t at = dicom.GetHeader().GetFullLength();
    for (const gdcm::DataElement &de : dicom.GetDataSet().GetDES()) {
        if (!(de.GetTag() < pixelData)) break;
        at += implicitVr ? uint64_t(static_cast<const gdcm::ImplicitDataElement &>(de).GetLength())
                         : uint64_t(static_cast<const gdcm::ExplicitDataElement &>(de).GetLength());
    }
    const uint64_t size = fileSize(file).value_or(0);
    std::array<unsigned char, 12> e{};
    std::ifstream in(file, std::ios::binary);
    in.seekg(std::streamoff(at));
    in.read(reinterpret_cast<char *>(e.data()), std::streamsize(e.size()));
    const bool bigEndian = e[0] == 0x7f && e[1] == 0xe0;
    const auto u16 = [&](size_t i) { return bigEndian ? uint16_t(e[i] << 8 | e[i + 1]) : uint16_t(e[i] | e[i + 1] << 8); };
    const auto u32 = [&](size_t i) {
        return bigEndian ? uint32_t(e[i]) << 24 | uint32_t(e[i + 1]) << 16 | uint32_t(e[i + 2]) << 8 | e[i + 3]
                         : uint32_t(e[i]) | uint32_t(e[i + 1]) << 8 | uint32_t(e[i + 2]) << 16 | uint32_t(e[i + 3]) << 24;
    };
    if (size < at + 8) fail(dir, fmt::format("slice '{}' is truncated: it ends before its pixel data", name));
    // A layout this count does not follow (no preamble, say) is left to GDCM.
    if (u16(0) != 0x7fe0 || u16(2) != 0x0010) return geometry;
    // Explicit VR (OB/OW/...: two letters, two reserved bytes, 32-bit length) or implicit.
    const bool explicitVr = !implicitVr && std::isupper(e[4]) && std::isupper(e[5]);
    if (explicitVr && size < at + 12)
        fail(dir, fmt::format("slice '{}' is truncated: it ends within its pixel data header", name));
    const uint32_t length = explicitVr ? u32(8) : u32(4);
    if (length == 0xffffffffu) return geometry;
    const uint64_t start = at + (explicitVr ? 12 : 8);
    const uint64_t have = size > start ? size - start : 0;
    if (have < length)
        fail(dir, fmt::format("slice '{}' is truncated: its pixel data holds {} bytes of the {} it declares", name,
                              withThousands(have), withThousands(length)));
    if (length < need)
        fail(dir, fmt::format("slice '{}' is truncated: its pixel data declares {} bytes, but its rows, columns "
                              "and type need {}",
                              name, withThousands(length), withThousands(need)));
    return geometry;
}

// The slices of one series must form one regular stack, as the volume that comes out of them
// assumes: the same size and orientation, positions along the slice normal with even gaps and
// none repeated, and no drift within the plane (a gantry tilt shears the stack, which an
// orthonormal direction matrix cannot hold). Otherwise the picture would be wrong without a
// word: a missing slice squeezes the anatomy, two stacks interleave. Slices are in the order
// GDCM's series reader will read them. The tolerance, 0.01 mm or 1 % of the gap if larger,
// is what 3D Slicer's DICOM import allows before it warns of irregular geometry (positions are
// decimal strings of at most 16 characters, so rounding alone stays far below it).
void checkSeriesGeometry(const fs::path &dir, const std::vector<SliceGeometry> &slices) {
    if (slices.size() < 2) return;
    const SliceGeometry &first = slices.front();
    for (const SliceGeometry &s : slices)
        if (s.rows != first.rows || s.columns != first.columns)
            fail(dir, fmt::format("slice '{}' is {} x {} pixels where slice '{}' is {} x {}: the folder mixes images "
                                  "of different sizes; it is not loaded",
                                  s.file, s.columns, s.rows, first.file, first.columns, first.rows));
    const auto located = std::count_if(slices.begin(), slices.end(),
                                       [](const SliceGeometry &s) { return s.position && s.orientation; });
    if (located == 0) return;   // no patient geometry at all (secondary capture): ITK's own spacing
    for (const SliceGeometry &s : slices)
        if (!s.position || !s.orientation)
            fail(dir, fmt::format("slice '{}' has no image position or orientation where the others have them; "
                                  "the stack cannot be placed, and it is not loaded",
                                  s.file));
    const auto &o = *first.orientation;
    const Vec3d row{o[0], o[1], o[2]}, column{o[3], o[4], o[5]};
    const Vec3d normal = cross(row, column);
    if (std::abs(length(normal) - 1) > 1e-3)
        fail(dir, fmt::format("slice '{}' has an image orientation whose row and column are not perpendicular unit "
                              "vectors; it is not loaded",
                              first.file));
    for (const SliceGeometry &s : slices)
        for (size_t i = 0; i < 6; ++i)
            if (std::abs((*s.orientation)[i] - o[i]) > 1e-4)
                fail(dir, fmt::format("slice '{}' is oriented differently from slice '{}': the folder mixes stacks "
                                      "(or a scout image); it is not loaded",
                                      s.file, first.file));
    std::vector<double> gaps;
    for (size_t i = 1; i < slices.size(); ++i) gaps.push_back(dot(*slices[i].position - *slices[i - 1].position, normal));
    std::vector<double> sorted = gaps;
    std::nth_element(sorted.begin(), sorted.begin() + ptrdiff_t(sorted.size() / 2), sorted.end());
    const double typical = sorted[sorted.size() / 2];
    const double tolerance = std::max(0.01, 0.01 * std::abs(typical));
    for (size_t i = 0; i < gaps.size(); ++i) {
        const SliceGeometry &a = slices[i], &b = slices[i + 1];
        if (std::abs(gaps[i]) <= tolerance)
            fail(dir, fmt::format("slices '{}' and '{}' lie at the same position: the folder holds a slice twice or "
                                  "two stacks; it is not loaded",
                                  a.file, b.file));
        if (std::abs(gaps[i] - typical) > tolerance)
            fail(dir, fmt::format("the gap between slices '{}' and '{}' is {:.4g} mm where the series' others are "
                                  "{:.4g} mm: a slice is missing or the stack is irregular; it is not loaded",
                                  a.file, b.file, std::abs(gaps[i]), std::abs(typical)));
        const Vec3d step = *b.position - *a.position;
        const Vec3d inPlane = step - normal * dot(step, normal);
        if (length(inPlane) > tolerance)
            fail(dir, fmt::format("slice '{}' is shifted {:.4g} mm within the plane from slice '{}': a tilted gantry "
                                  "or sheared stack, which is not supported; it is not loaded",
                                  b.file, length(inPlane), a.file));
    }
}

// Bytes of one stored DICOM pixel (before ITK applies the rescale slope and intercept).
uint64_t storedDicomSize(itk::GDCMImageIO &io) {
    using C = itk::IOComponentEnum;
    switch (io.GetInternalComponentType()) {
    case C::UCHAR: case C::CHAR: return 1;
    case C::USHORT: case C::SHORT: return 2;
    case C::UINT: case C::INT: case C::FLOAT: return 4;
    default: return 8;
    }
}

void readPatientSpace(const itk::ImageIOBase &io, Volume &v);

Volume loadImageFile(const fs::path &path, const LoadOptions &options, LoadProgress &progress) {
    {
        std::ifstream probe(path, std::ios::binary);
        if (!probe) fail(path, "cannot be opened (check its permissions)");
    }
    if (fileSize(path).value_or(0) == 0) fail(path, "is an empty file, not a volume");
    itk::ImageIOBase::Pointer io =
        itk::ImageIOFactory::CreateImageIO(path.string().c_str(), itk::IOFileModeEnum::ReadMode);
    if (!io)
        fail(path, "is not a volume file in a supported format (NRRD, MetaImage, NIfTI or DICOM): its "
                   "contents were not recognised");
    const std::string ioName = io->GetNameOfClass();

    // Every detached data file is confined to the header's folder and must be a regular
    // file, checked before ITK opens any of them (a missing one is named here too, before
    // ITK reports it in its own words).
    std::optional<NrrdLayout> nrrd;
    std::optional<MetaLayout> meta;
    std::optional<NiftiHeader> nifti;
    if (ioName == "NrrdImageIO") {
        nrrd = scanNrrdHeader(path);
        if (nrrd)
            for (const auto &name : nrrd->dataFiles) confinedDataFile(path, name);
    } else if (ioName == "MetaImageIO") {
        meta = scanMetaHeader(path);
        if (meta)
            for (const auto &name : meta->dataFiles) confinedDataFile(path, name);
    } else if (ioName == "NiftiImageIO") {
        nifti = readNiftiHeader(path);  // fields checked before niftilib trusts them
    }

    TemporaryLink alias;
    const fs::path readPath = ioName == "NiftiImageIO" ? niftiReadPath(path, alias) : path;
    io->SetFileName(readPath.string());
    try {
        io->ReadImageInformation();
    } catch (const itk::ExceptionObject &e) {
        fail(path, "cannot read the header: " + cleanItkMessage(e));
    }

    // Validate everything the header says before any voxel memory is allocated.
    const unsigned nd = io->GetNumberOfDimensions();
    if (nd < 2)
        fail(path, fmt::format("is a {}-D image; only 3-D volumes (or a 2-D image as one slice) can be loaded", nd));
    for (unsigned d = 3; d < nd; ++d)
        if (io->GetDimensions(d) != 1)
            fail(path, fmt::format("is a {}-D image (axis {} has size {}); only 3-D volumes can be loaded", nd, d,
                                   io->GetDimensions(d)));
    const VoxelType type = checkedVoxelType(path, *io);
    Volume v;
    for (unsigned a = 0; a < 3; ++a) {
        const uint64_t size = a < nd ? uint64_t(io->GetDimensions(a)) : 1;
        v.dims[int(a)] = size > uint64_t(std::numeric_limits<int64_t>::max()) ? -1 : int64_t(size);
    }
    if (nrrd)
        for (size_t a = 0; a < nrrd->sizes.size(); ++a) {
            const uint64_t itkSize = a < nd ? uint64_t(io->GetDimensions(unsigned(a))) : 1;
            if (nrrd->sizes[a] != itkSize)
                fail(path, fmt::format("NRRD header's sizes give axis {} {} samples, but ITK read {} (it keeps a "
                                       "size in 32 bits): the header is refused",
                                       a, nrrd->sizes[a], itkSize));
        }
    checkShape(path, v.dims, options);
    Mat3d direction;
    for (unsigned a = 0; a < 3 && a < nd; ++a) {
        v.spacing[int(a)] = io->GetSpacing(a);
        v.origin[int(a)] = io->GetOrigin(a);
        const std::vector<double> column = io->GetDirection(a);
        for (unsigned r = 0; r < 3 && r < column.size(); ++r) direction(int(r), int(a)) = column[r];
    }
    v.direction = checkedGeometry(path, v.spacing, v.origin, direction);
    v.sourceType = type;
    readPatientSpace(*io, v);

    if (auto *dicom = dynamic_cast<itk::GDCMImageIO *>(io.GetPointer()))
        checkDicomSlice(path, path, uint64_t(v.voxelCount()) * storedDicomSize(*dicom));

    // The data must hold exactly what the header promises (see the byte-count helpers).
    const uint64_t need = uint64_t(v.voxelCount()) * voxelTypeSize(type);
    const std::string shape =
        fmt::format("{} x {} x {} {}", v.dims.x, v.dims.y, v.dims.z, voxelTypeName(type));
    // Counting a gzip stream's bytes inflates it once: about half of what reading it costs.
    progress(0.02, "checking data");
    if (nrrd) checkNrrdData(path, *nrrd, need, shape);
    if (meta) checkMetaData(path, *meta, need, shape);
    if (nifti) checkNiftiData(path, *nifti);

    progress(0.35, "reading voxels");
    readVoxels(path, *io, type, v, progress);
    return v;
}

Volume loadDicomFolder(const fs::path &dir, const LoadOptions &options, LoadProgress &progress) {
    checkDicomFolderEntries(dir);
    auto names = itk::GDCMSeriesFileNames::New();
    names->SetUseSeriesDetails(true);
    names->SetDirectory(dir.string());
    const auto &uids = names->GetSeriesUIDs();
    if (uids.empty()) fail(dir, "folder holds no DICOM series (no DICOM image files were found in it)");
    const std::vector<std::string> files = names->GetFileNames(uids.front());
    if (files.empty()) fail(dir, "folder holds no DICOM image files");
    if (uids.size() > 1)
        spdlog::info("{}: folder holds {} DICOM series; loading the first ({}, {} files)", dir.string(), uids.size(),
                     uids.front(), files.size());
    // One file may be a multi-frame volume on its own.
    if (files.size() == 1) {
        try {
            return loadImageFile(fs::path(files.front()), options, progress);
        } catch (const VolumeLoadError &e) {
            fail(dir, e.what());  // keeps the promise that messages start with the path given
        }
    }

    auto io = itk::GDCMImageIO::New();
    io->SetFileName(files.front());
    try {
        io->ReadImageInformation();
    } catch (const itk::ExceptionObject &e) {
        fail(dir, fmt::format("cannot read the DICOM header of '{}': {}", fs::path(files.front()).filename().string(),
                              cleanItkMessage(e)));
    }
    if (io->GetNumberOfDimensions() > 2 && io->GetDimensions(2) != 1)
        fail(dir, "series of multi-frame DICOM files are not supported (each file holds several slices)");
    const VoxelType type = checkedVoxelType(dir, *io);
    Volume v;
    v.dims = {int64_t(io->GetDimensions(0)), int64_t(io->GetDimensions(1)), int64_t(files.size())};
    checkShape(dir, v.dims, options);
    // The stored pixels of one slice, before ITK's rescaling: rows x columns x stored size.
    const uint64_t sliceBytes = uint64_t(v.dims.x) * uint64_t(v.dims.y) * storedDicomSize(*io);
    progress(0.01, "checking slices");
    std::vector<SliceGeometry> geometry;
    for (const auto &file : files) geometry.push_back(checkDicomSlice(dir, fs::path(file), sliceBytes));
    checkSeriesGeometry(dir, geometry);

    using Image = itk::Image<float, 3>;
    auto reader = itk::ImageSeriesReader<Image>::New();
    reader->SetImageIO(io);
    reader->SetFileNames(files);
    auto observer = ItkProgress::New();
    observer->progress = &progress;
    observer->from = 0.02;
    observer->to = 0.9;
    observer->task = "reading slices";
    reader->AddObserver(itk::ProgressEvent(), observer);
    progress(0.02, "reading slices");
    try {
        reader->Update();
    } catch (const itk::ExceptionObject &e) {
        if (observer->stopped) std::rethrow_exception(observer->stopped);
        fail(dir, "cannot read the DICOM series: " + cleanItkMessage(e));
    }
    if (observer->stopped) std::rethrow_exception(observer->stopped);
    const Image *image = reader->GetOutput();
    const auto size = image->GetLargestPossibleRegion().GetSize();
    if (int64_t(size[0]) != v.dims.x || int64_t(size[1]) != v.dims.y || int64_t(size[2]) != v.dims.z)
        fail(dir, fmt::format("DICOM series came out {} x {} x {}, but its first slice and file count say {} x {} x {}",
                              size[0], size[1], size[2], v.dims.x, v.dims.y, v.dims.z));
    Mat3d direction;
    for (int a = 0; a < 3; ++a) {
        v.spacing[a] = image->GetSpacing()[unsigned(a)];
        v.origin[a] = image->GetOrigin()[unsigned(a)];
        for (int r = 0; r < 3; ++r) direction(r, a) = image->GetDirection()(unsigned(r), unsigned(a));
    }
    v.direction = checkedGeometry(dir, v.spacing, v.origin, direction);
    v.sourceType = type;
    readPatientSpace(*io, v);
    const float *buffer = image->GetBufferPointer();
    v.voxels.assign(buffer, buffer + v.voxelCount());
    return v;
}

// --- writing

template <typename T>
std::vector<T> convertForWriting(const SampleGrid &samples, size_t first, size_t count) {
    std::vector<T> out(count);
    for (size_t i = 0; i < count; ++i) {
        const float s = samples[first + i];
        if constexpr (std::is_floating_point_v<T>) {
            out[i] = T(s);
        } else {
            const double x = std::isnan(s) ? 0.0 : std::nearbyint(double(s));
            out[i] = T(std::clamp(x, double(std::numeric_limits<T>::lowest()), double(std::numeric_limits<T>::max())));
        }
    }
    return out;
}

std::string dicomNumber(double x) { return fmt::format("{:.10g}", x); }

// A header entry ITK keeps in the image IO's dictionary, as text whatever type ITK stored it
// as; empty when absent.
std::string headerText(const itk::MetaDataDictionary &dict, const std::string &key) {
    if (!dict.HasKey(key)) return {};
    std::string text;
    if (itk::ExposeMetaData<std::string>(dict, key, text)) {
        while (!text.empty() && (text.back() == ' ' || text.back() == '\0')) text.pop_back();
        return text;
    }
    int i = 0;  // ITK keeps NIfTI codes as int or short, by version
    if (itk::ExposeMetaData<int>(dict, key, i)) return std::to_string(i);
    short h = 0;
    if (itk::ExposeMetaData<short>(dict, key, h)) return std::to_string(h);
    return {};
}

// Longest modality statement kept (a description is cut there): what the checker hands back.
constexpr size_t kMaxStatedModalityBytes = 64;

// Whether the header names the patient space and which modality it states (see Volume).
// DICOM: image orientation (0020,0037) and modality (0008,0060). NRRD: a `space` field
// (ITK keeps it as NRRD_space). NIfTI: a qform or sform code other than 0 (unknown). A
// MetaImage without these, a NIfTI with both codes 0 or an NRRD without `space` keep their
// numbers as they are: ITK's direction is then no statement about the patient.
void readPatientSpace(const itk::ImageIOBase &io, Volume &v) {
    const itk::MetaDataDictionary &dict = io.GetMetaDataDictionary();
    const std::string ioName = io.GetNameOfClass();
    // The modality statement, fit for a sentence and the checker's hand-back: printable, short.
    const auto state = [&](const std::string &text, const char *field) {
        std::string said;
        for (char c : text)
            if (c >= 0x20 && c < 0x7f && said.size() < kMaxStatedModalityBytes) said += c;
        while (!said.empty() && said.back() == ' ') said.pop_back();
        if (said.empty() || !v.modality.empty()) return;
        v.modality = said;
        v.modalityField = field;
    };
    if (ioName == "GDCMImageIO") {
        v.orientationKnown = !headerText(dict, "0020|0037").empty();
        state(headerText(dict, "0008|0060"), "DICOM");
    } else if (ioName == "NrrdImageIO") {
        v.orientationKnown = !headerText(dict, "NRRD_space").empty();
        // A key-value pair `modality:=CT` (any case of the key) states it; else the `content`
        // field (ITK keeps it as NRRD_content) may name it in words.
        for (const std::string &key : dict.GetKeys())
            if (lower(key) == "modality") state(headerText(dict, key), "NRRD key");
        state(headerText(dict, "NRRD_content"), "NRRD content");
    } else if (ioName == "NiftiImageIO") {
        // NIfTI's 80-byte description; ITK 5.2 keeps it as ITK_FileNotes (later versions also as descrip).
        state(headerText(dict, "descrip"), "NIfTI descrip");
        state(headerText(dict, "ITK_FileNotes"), "NIfTI descrip");
        const auto coded = [&](const char *code, const char *name) {
            const std::string n = headerText(dict, name);
            if (!n.empty()) return n.find("UNKNOWN") == std::string::npos;
            const std::string c = headerText(dict, code);
            return !c.empty() && c != "0";
        };
        v.orientationKnown = coded("qform_code", "qform_code_name") || coded("sform_code", "sform_code_name");
    }
}

// A load that ran out of memory (std::bad_alloc): the DICOM checker tells it apart from
// every other refusal, since its memory limit, not the file's header, may be the cause.
struct LoadOutOfMemory : VolumeLoadError {
    using VolumeLoadError::VolumeLoadError;
};

// ---------------------------------------------------------------------------------------
// DICOM in a child process
//
// GDCM (Debian's build keeps its assertions) aborts the whole process on some damaged files,
// from inside ITK's CanReadFile, before any check of ours can look at the bytes (fuzz/README.md,
// finding 7); the next such assertion or crash would do the same. So every load that will reach
// GDCM runs first, whole, in a child process with its own memory and CPU limits; a child that
// dies by a signal or runs out of memory means the file is refused, and only a file the child
// loaded (or refused with an ordinary VolumeLoadError) is loaded here.

// The DICOM checker's exit statuses.
constexpr int kCheckLoaded = 0;
constexpr int kCheckRefused = 1;      // a VolumeLoadError: the load here repeats it, same words, same type
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

// Whether ITK's factory would ask GDCM about this file: only if none of the readers registered
// before it (registerItkFactories' order) claims it.
bool reachesGdcm(const fs::path &path) {
    const std::string name = path.string();
    return !itk::NrrdImageIO::New()->CanReadFile(name.c_str()) && !itk::MetaImageIO::New()->CanReadFile(name.c_str()) &&
           !itk::NiftiImageIO::New()->CanReadFile(name.c_str());
}

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

// What the checker hands back: the volume it loaded, so that the file is parsed once, in the
// child, and never again in the caller. A fixed header, the file's modality, then the samples
// as the volume holds them (narrow integers or float32). The caller reads it as it reads any
// file from outside: a child that a hostile file took over could have written anything here,
// so every field is checked and the statistics are computed again.
struct CheckedHeader {
    char magic[16] = "volcast-checked";
    uint32_t version = 2;
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
};
constexpr uint32_t kMaxCheckedModalityBytes = 64;

void writeCheckedVolume(const Volume &v, const fs::path &to) {
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
    // O_NOFOLLOW and no O_CREAT: the caller made the file, and only that file is written.
    const int fd = ::open(to.c_str(), O_WRONLY | O_TRUNC | O_NOFOLLOW | O_CLOEXEC);
    if (fd < 0) throw std::runtime_error("cannot open the result file: " + std::string(std::strerror(errno)));
    const auto put = [&](const void *data, size_t bytes) {
        const char *at = static_cast<const char *>(data);
        while (bytes > 0) {
            const ssize_t n = ::write(fd, at, std::min<size_t>(bytes, size_t(1) << 30));
            if (n < 0 && errno == EINTR) continue;
            if (n <= 0) {
                ::close(fd);
                throw std::runtime_error("cannot write the result file: " + std::string(std::strerror(errno)));
            }
            at += n;
            bytes -= size_t(n);
        }
    };
    put(&h, sizeof h);
    put(modality.data(), modality.size());
    put(modalityField.data(), modalityField.size());
    if (v.narrow.bytes == 4) put(v.voxels.data(), v.voxels.size() * sizeof(float));
    else put(v.narrowVoxels.data(), v.voxelCount() * size_t(v.narrow.bytes));
    ::close(fd);
}

// `samples` false: the header only (its fields and the file's size checked), for a caller that
// keeps the result to load later.
Volume readCheckedVolume(const fs::path &path, const fs::path &from, const LoadOptions &options, bool samples = true) {
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

// A result file of the caller's, removed however the load ends.
struct CheckedResultFile {
    fs::path path;
    CheckedResultFile() {
        std::string pattern = (fs::temp_directory_path() / "volcast-checked-XXXXXX").string();
        const int fd = ::mkostemp(pattern.data(), O_CLOEXEC);
        if (fd < 0) throw std::runtime_error("cannot create a file for the parser's result: " + std::string(std::strerror(errno)));
        ::close(fd);
        path = pattern;
    }
    ~CheckedResultFile() {
        std::error_code ec;
        fs::remove(path, ec);
    }
    CheckedResultFile(const CheckedResultFile &) = delete;
    CheckedResultFile &operator=(const CheckedResultFile &) = delete;
};

// Parses the file in the checker process, which writes what it loaded to `result` (a file the
// caller made): true when it did, false when it refused the file (the caller then repeats the
// load here for the refusal's own words); any other end of the child fails the load.
bool runChecker(const fs::path &path, const LoadOptions &options, LoadProgress &progress, bool dicom,
                const fs::path &result) {
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
    std::string said, line;
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
                    // steps, slice by slice), passed on; the rest is what it said, for the log.
                    for (ssize_t i = 0; i < n; ++i) {
                        line += buffer[i];
                        if (buffer[i] != '\n' && line.size() < 512) continue;
                        if (line.starts_with(kProgressMark)) {
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
                    if (said.size() > 4096) said.erase(0, said.size() - 4096);
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
    if (WIFEXITED(status) && WEXITSTATUS(status) == kCheckRefused) return false;
    if (WIFEXITED(status) && WEXITSTATUS(status) == kCheckLoaded) return true;
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

// A DICOM series packed as a .zip: unpacked into a fresh folder beside it (private to the
// caller: the upload folder), loaded as a folder, the folder removed whatever happens. The
// loader's messages name the archive, not the folder.
Volume loadZippedSeries(const fs::path &path, const LoadOptions &options, LoadProgress &progress);

Volume loadVolumeHere(const fs::path &path, const LoadOptions &options, bool dicomInChild) {
    registerItkFactories();
    std::error_code ec;
    const auto status = fs::status(path, ec);
    if (!fs::exists(status)) fail(path, "file not found");
    // stat() only: opening a FIFO would block the loader until someone writes to it.
    if (!fs::is_regular_file(status) && !fs::is_directory(status))
        fail(path, "is not a regular file or a folder (a FIFO, socket or device); it is not loaded");
    try {
        LoadProgress progress(options, path);
        progress(0, "reading header");
        const bool folder = fs::is_directory(status);
        const bool zip = !folder && isZipName(path);
        std::optional<Volume> checked;
        if (dicomInChild) {
            const bool dicom = folder || zip || (fileSize(path).value_or(0) > 0 && reachesGdcm(path));
            if (dicom || options.parseInChild) {
                const CheckedResultFile result;
                if (runChecker(path, options, progress, dicom, result.path)) {
                    progress(0.8, "reading the parsed volume");
                    checked = readCheckedVolume(path, result.path, options);
                }
            }
        }
        Volume v = checked ? std::move(*checked)
                   : folder ? loadDicomFolder(path, options, progress)
                   : zip    ? loadZippedSeries(path, options, progress)
                            : loadImageFile(path, options, progress);
        v.name = displayName(path);
        progress(0.9, "statistics");
        if (!checked && !v.voxels.empty()) v.nonFiniteReplaced = replaceNonFinite(path, v.voxels);
        // In the checker (dicomInChild false) they would be computed twice: its caller computes
        // them again from the hand-back, which it does not trust.
        if (dicomInChild) computeStatistics(v);
        holdNarrow(v); // a float file (or a DICOM series, rescaled) whose samples are 8- or 16-bit integers
        progress(1, "statistics");
        spdlog::debug("{}: loaded {} x {} x {} {} voxels, spacing {} {} {}, range {} .. {}", path.string(), v.dims.x,
                      v.dims.y, v.dims.z, voxelTypeName(v.sourceType), v.spacing.x, v.spacing.y, v.spacing.z,
                      v.range.min, v.range.max);
        return v;
    } catch (const VolumeLoadError &) {
        throw;
    } catch (const itk::ExceptionObject &e) {
        fail(path, "cannot be read: " + cleanItkMessage(e));
    } catch (const std::bad_alloc &) {
        throw LoadOutOfMemory(path.string() + ": not enough memory to load the volume");
    } catch (const std::exception &e) {
        fail(path, std::string("cannot be read: ") + e.what());
    }
}

Volume loadZippedSeries(const fs::path &path, const LoadOptions &options, LoadProgress &progress) {
    std::string pattern = (path.parent_path() / (path.filename().string() + ".unpacked-XXXXXX")).string();
    if (!::mkdtemp(pattern.data())) fail(path, fmt::format("cannot be unpacked: {}", std::strerror(errno)));
    const fs::path folder = pattern;
    struct Remove {
        fs::path folder;
        ~Remove() {
            std::error_code ec;
            fs::remove_all(folder, ec);
        }
    } remove{folder};
    progress(0, "unpacking the archive");
    ZipLimits limits;
    limits.maxBytes = options.maxArchiveBytes;
    try {
        extractZip(path, folder, limits, path.string());
    } catch (const ZipError &e) {
        throw VolumeLoadError(e.what());
    }
    // The series' messages name entries as archive/entry_00003.
    const auto named = [&](const std::string &message) {
        std::string out = message;
        for (size_t at; (at = out.find(folder.string())) != std::string::npos;)
            out.replace(at, folder.string().size(), path.string());
        return out;
    };
    try {
        return loadDicomFolder(folder, options, progress);
    } catch (const VolumeTooLarge &e) {
        throw VolumeTooLarge(named(e.what()), e.bytes);
    } catch (const VolumeLoadTimeout &e) {
        throw VolumeLoadTimeout(named(e.what()), e.limitSeconds);
    } catch (const LoadOutOfMemory &) {
        throw;
    } catch (const VolumeLoadError &e) {
        throw VolumeLoadError(named(e.what()));
    }
}

void setLimit(int resource, uint64_t value) {
    rlimit limit{};
    limit.rlim_cur = limit.rlim_max = rlim_t(value);
    if (::setrlimit(resource, &limit) != 0)
        std::fprintf(stderr, "%s: cannot set resource limit %d: %s\n", kCheckerName, resource, std::strerror(errno));
}

} // namespace

Volume loadVolume(const fs::path &path, const LoadOptions &options) {
    return loadVolumeHere(path, options, true);
}

ParsedVolumeSummary parseToKeep(const fs::path &path, const fs::path &keep, const LoadOptions &options) {
    // O_EXCL: the checker writes only into a file made here, never through a name that was there.
    const int fd = ::open(keep.c_str(), O_WRONLY | O_CREAT | O_EXCL | O_NOFOLLOW | O_CLOEXEC, 0600);
    if (fd < 0) fail(path, fmt::format("cannot make the file for its parsed volume: {}", std::strerror(errno)));
    ::close(fd);
    struct RemoveUnlessKept {
        const fs::path &keep;
        bool kept = false;
        ~RemoveUnlessKept() {
            std::error_code ec;
            if (!kept) fs::remove(keep, ec);
        }
    } guard{keep};
    try {
        LoadProgress progress(options, path);
        progress(0, "reading header");
        std::error_code ec;
        const auto status = fs::status(path, ec);
        if (!fs::exists(status)) fail(path, "file not found");
        if (!fs::is_regular_file(status) && !fs::is_directory(status))
            fail(path, "is not a regular file or a folder (a FIFO, socket or device); it is not loaded");
        const bool dicom = fs::is_directory(status) || isZipName(path) ||
                           (fileSize(path).value_or(0) > 0 && reachesGdcm(path));
        if (!runChecker(path, options, progress, dicom, keep)) {
            // The child refused it and survived: the same parse here gives the refusal's own words.
            loadVolumeHere(path, options, false);
            fail(path, "was refused by the parser in its separate process; it is not loaded");
        }
        const Volume v = readCheckedVolume(path, keep, options, false);
        progress(1, "parsed");
        guard.kept = true;
        return {{v.dims.x, v.dims.y, v.dims.z}, v.sourceType};
    } catch (const VolumeLoadError &) {
        throw;
    } catch (const std::bad_alloc &) {
        throw LoadOutOfMemory(path.string() + ": not enough memory to load the volume");
    } catch (const std::exception &e) {
        fail(path, std::string("cannot be read: ") + e.what());
    }
}

Volume loadParsedVolume(const fs::path &keep, const fs::path &shownAs, const LoadOptions &options) {
    try {
        LoadProgress progress(options, shownAs);
        progress(0.8, "reading the parsed volume");
        Volume v = readCheckedVolume(shownAs, keep, options);
        v.name = displayName(shownAs);
        progress(0.9, "statistics");
        computeStatistics(v);
        holdNarrow(v);
        progress(1, "statistics");
        return v;
    } catch (const VolumeLoadError &) {
        throw;
    } catch (const std::bad_alloc &) {
        throw LoadOutOfMemory(shownAs.string() + ": not enough memory to load the volume");
    } catch (const std::exception &e) {
        fail(shownAs, std::string("cannot be read: ") + e.what());
    }
}

int runDicomCheck(int argc, char **argv) {
    if (argc < 5 || argc > 7) {
        std::fprintf(stderr, "usage: %s FILE-OR-FOLDER MAX-BYTES MAX-DIMENSION TIME-LIMIT-S [MAX-ARCHIVE-BYTES [RESULT]]\n"
                             "Loads a volume as volcast's loader does, in this process (volcast runs it to parse "
                             "files from outside away from the server), and writes what it loaded to the existing "
                             "file RESULT; exit status 0 loaded, 1 refused, 3 out of memory.\n",
                     kCheckerName);
        return kCheckUsage;
    }
    LoadOptions options;
    try {
        options.maxBytes = std::stoull(argv[2]);
        options.maxDimension = std::stoll(argv[3]);
        options.timeLimitSeconds = std::stod(argv[4]);
        if (argc >= 6) options.maxArchiveBytes = std::stoull(argv[5]);
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
        const Volume v = loadVolumeHere(argv[1], options, false);
        if (argc == 7) writeCheckedVolume(v, argv[6]);
        return kCheckLoaded;
    } catch (const LoadOutOfMemory &e) {
        std::fprintf(stderr, "%s\n", e.what());
        return kCheckOutOfMemory;
    } catch (const VolumeLoadError &e) {
        std::fprintf(stderr, "%s\n", e.what());
        return kCheckRefused;
    } catch (const std::exception &e) {
        std::fprintf(stderr, "%s\n", e.what());
        return kCheckFailed;
    }
}

void saveVolume(const Volume &v, const fs::path &path, const SaveOptions &options) {
    registerItkFactories();
    const auto saveFail = [&](const std::string &problem) {
        throw VolumeSaveError(path.string() + ": " + problem);
    };
    if (v.voxelCount() == 0 || !v.hasSamples())
        saveFail("volume has no voxels, or fewer voxels than its dims say");
    const std::string name = lower(path.filename().string());
    const bool known = name.ends_with(".nrrd") || name.ends_with(".nhdr") || name.ends_with(".mha") ||
                       name.ends_with(".mhd") || name.ends_with(".nii") || name.ends_with(".nii.gz");
    if (!known) saveFail("unsupported extension (use .nrrd, .nhdr, .mha, .mhd, .nii or .nii.gz)");
    try {
        itk::ImageIOBase::Pointer io =
            itk::ImageIOFactory::CreateImageIO(path.string().c_str(), itk::IOFileModeEnum::WriteMode);
        if (!io) saveFail("no ITK writer accepts this file name");
        io->SetNumberOfDimensions(3);
        itk::ImageIORegion region(3);
        for (unsigned a = 0; a < 3; ++a) {
            io->SetDimensions(a, itk::SizeValueType(v.dims[int(a)]));
            io->SetSpacing(a, v.spacing[int(a)]);
            io->SetOrigin(a, v.origin[int(a)]);
            io->SetDirection(a, std::vector<double>{v.direction(0, int(a)), v.direction(1, int(a)),
                                                     v.direction(2, int(a))});
            region.SetIndex(a, 0);
            region.SetSize(a, itk::SizeValueType(v.dims[int(a)]));
        }
        io->SetPixelType(itk::IOPixelEnum::SCALAR);
        io->SetNumberOfComponents(1);
        io->SetComponentType(itkComponentOf(options.type));
        io->SetUseCompression(options.compress);
        io->SetFileName(path.string());
        io->SetIORegion(region);
        withVoxelType(options.type, [&](auto tag) {
            const auto buffer = convertForWriting<decltype(tag)>(v.samples(), 0, v.voxelCount());
            io->WriteImageInformation();
            io->Write(buffer.data());
        });
    } catch (const VolumeSaveError &) {
        throw;
    } catch (const itk::ExceptionObject &e) {
        saveFail(cleanItkMessage(e));
    } catch (const std::exception &e) {
        saveFail(e.what());
    }
}

void saveDicomSeries(const Volume &v, const fs::path &folder, VoxelType type) {
    registerItkFactories();
    const auto saveFail = [&](const std::string &problem) {
        throw VolumeSaveError(folder.string() + ": " + problem);
    };
    if (type == VoxelType::Float32 || type == VoxelType::Float64)
        saveFail("DICOM series are written with integer voxels; choose an integer type");
    if (v.voxelCount() == 0 || !v.hasSamples())
        saveFail("volume has no voxels, or fewer voxels than its dims say");
    try {
        fs::create_directories(folder);
        // One IO for every slice: it generates the study and series UIDs once and keeps them.
        auto io = itk::GDCMImageIO::New();
        const std::string orientation =
            fmt::format("{}\\{}\\{}\\{}\\{}\\{}", dicomNumber(v.direction(0, 0)), dicomNumber(v.direction(1, 0)),
                        dicomNumber(v.direction(2, 0)), dicomNumber(v.direction(0, 1)),
                        dicomNumber(v.direction(1, 1)), dicomNumber(v.direction(2, 1)));
        const size_t sliceCount = size_t(v.dims.x * v.dims.y);
        for (int64_t k = 0; k < v.dims.z; ++k) {
            const Vec3d position = v.worldFromIndex({0, 0, double(k)});
            itk::MetaDataDictionary dict;
            // CT Image Storage: GDCM ignores the position and orientation of secondary-capture
            // images, which is what it writes for other modalities.
            itk::EncapsulateMetaData<std::string>(dict, "0008|0060", "CT");
            itk::EncapsulateMetaData<std::string>(dict, "0028|0004", "MONOCHROME2");
            itk::EncapsulateMetaData<std::string>(dict, "0020|0013", std::to_string(k + 1));
            itk::EncapsulateMetaData<std::string>(
                dict, "0020|0032",
                fmt::format("{}\\{}\\{}", dicomNumber(position.x), dicomNumber(position.y), dicomNumber(position.z)));
            itk::EncapsulateMetaData<std::string>(dict, "0020|0037", orientation);
            itk::EncapsulateMetaData<std::string>(dict, "0018|0050", dicomNumber(v.spacing.z));
            itk::EncapsulateMetaData<std::string>(dict, "0018|0088", dicomNumber(v.spacing.z));
            io->SetMetaDataDictionary(dict);
            io->SetNumberOfDimensions(2);
            itk::ImageIORegion region(2);
            for (unsigned a = 0; a < 2; ++a) {
                io->SetDimensions(a, itk::SizeValueType(v.dims[int(a)]));
                io->SetSpacing(a, v.spacing[int(a)]);
                io->SetOrigin(a, position[int(a)]);
                region.SetIndex(a, 0);
                region.SetSize(a, itk::SizeValueType(v.dims[int(a)]));
            }
            io->SetPixelType(itk::IOPixelEnum::SCALAR);
            io->SetNumberOfComponents(1);
            io->SetComponentType(itkComponentOf(type));
            io->SetIORegion(region);
            io->SetFileName((folder / fmt::format("slice_{:04d}.dcm", k)).string());
            withVoxelType(type, [&](auto tag) {
                const auto buffer =
                    convertForWriting<decltype(tag)>(v.samples(), size_t(k) * sliceCount, sliceCount);
                io->WriteImageInformation();
                io->Write(buffer.data());
            });
        }
    } catch (const VolumeSaveError &) {
        throw;
    } catch (const itk::ExceptionObject &e) {
        saveFail(cleanItkMessage(e));
    } catch (const std::exception &e) {
        saveFail(e.what());
    }
}

} // namespace volcast
