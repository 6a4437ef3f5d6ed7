// Uncompressed DICOM series read straight from their files (dicom_uncompressed.hpp).
//
// A Part 10 file: a 128-byte preamble, "DICM", the file meta group (explicit VR little-endian)
// naming the transfer syntax, then the data set in it. Each element: group, element, then in
// explicit VR two letters and a 16-bit length (or two reserved bytes and a 32-bit length for
// the VRs listed below), in implicit VR a 32-bit length. A length of 0xFFFFFFFF is undefined:
// a sequence whose items end with delimiters. Pixel Data (7FE0,0010) is the last element read.

#include "renderer/io/dicom_uncompressed.hpp"

#include <spdlog/fmt/fmt.h>

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <bit>
#include <cerrno>
#include <cmath>
#include <cstring>
#include <limits>

namespace volcast::io {
namespace {

constexpr const char *kImplicitLittleEndian = "1.2.840.10008.1.2";
constexpr const char *kExplicitLittleEndian = "1.2.840.10008.1.2.1";
constexpr const char *kCtImageStorage = "1.2.840.10008.5.1.4.1.1.2";
constexpr const char *kMrImageStorage = "1.2.840.10008.5.1.4.1.1.4";

constexpr uint32_t kUndefinedLength = 0xffffffffu;
// Nested sequences deeper than this are not taken (GDCM reads them; a hostile file could
// nest without end).
constexpr int kMaxSequenceDepth = 16;
// A slice's header is read in its first kHeaderBytes (CT and MR headers take a few KiB), and
// again in its first kLongHeaderBytes where that was not enough; a longer one is not taken.
constexpr size_t kHeaderBytes = 16 * 1024;
constexpr size_t kLongHeaderBytes = 256 * 1024;

constexpr uint32_t tagOf(uint16_t group, uint16_t element) { return uint32_t(group) << 16 | element; }
constexpr uint32_t kPixelData = tagOf(0x7fe0, 0x0010);
constexpr uint32_t kItem = tagOf(0xfffe, 0xe000);
constexpr uint32_t kItemEnd = tagOf(0xfffe, 0xe00d);
constexpr uint32_t kSequenceEnd = tagOf(0xfffe, 0xe0dd);

// Thrown within the parse when the file is not one this reader takes; caught at its edge.
struct NotTaken {
    std::string why;
};

struct Cursor {
    std::span<const unsigned char> bytes;
    size_t at = 0;
    bool explicitVr = true;

    bool atEnd() const { return at >= bytes.size(); }
    void need(size_t n) const {
        if (bytes.size() - std::min(at, bytes.size()) < n) throw NotTaken{"its header does not end within its first bytes"};
    }
    uint16_t u16() {
        need(2);
        const uint16_t v = uint16_t(bytes[at] | bytes[at + 1] << 8);
        at += 2;
        return v;
    }
    uint32_t u32() {
        need(4);
        const uint32_t v = uint32_t(bytes[at]) | uint32_t(bytes[at + 1]) << 8 | uint32_t(bytes[at + 2]) << 16 |
                           uint32_t(bytes[at + 3]) << 24;
        at += 4;
        return v;
    }
};

struct ElementHead {
    uint32_t tag = 0;
    char vr[3] = {0, 0, 0};   // empty in implicit VR
    uint32_t length = 0;
};

// VRs whose explicit form has two reserved bytes and a 32-bit length (PS3.5 7.1.2).
bool longFormVr(const char *vr) {
    static constexpr const char *kLong[] = {"OB", "OD", "OF", "OL", "OV", "OW", "SQ", "SV", "UC", "UN", "UR", "UT", "UV"};
    for (const char *l : kLong)
        if (vr[0] == l[0] && vr[1] == l[1]) return true;
    return false;
}

ElementHead readHead(Cursor &c) {
    ElementHead h;
    const uint16_t group = c.u16(), element = c.u16();
    h.tag = tagOf(group, element);
    // Items and delimiters have no VR in either syntax.
    if (!c.explicitVr || group == 0xfffe) {
        h.length = c.u32();
        return h;
    }
    c.need(2);
    h.vr[0] = char(c.bytes[c.at]);
    h.vr[1] = char(c.bytes[c.at + 1]);
    c.at += 2;
    if (!std::isupper(static_cast<unsigned char>(h.vr[0])) || !std::isupper(static_cast<unsigned char>(h.vr[1])))
        throw NotTaken{fmt::format("element ({:04x},{:04x}) has no valid VR", group, element)};
    if (longFormVr(h.vr)) {
        c.u16();
        h.length = c.u32();
    } else {
        h.length = c.u16();
    }
    return h;
}

std::span<const unsigned char> value(Cursor &c, uint32_t length) {
    c.need(length);
    const auto v = c.bytes.subspan(c.at, length);
    c.at += length;
    return v;
}

void skipUndefinedSequence(Cursor &c, int depth);

// The data set of one item whose length is undefined, up to its delimiter.
void skipUndefinedItem(Cursor &c, int depth) {
    for (;;) {
        const ElementHead h = readHead(c);
        if (h.tag == kItemEnd) return;
        if (h.tag == kItem || h.tag == kSequenceEnd)
            throw NotTaken{"a sequence item is not closed where its data set ends"};
        if (h.length == kUndefinedLength) skipUndefinedSequence(c, depth + 1);
        else value(c, h.length);
    }
}

void skipUndefinedSequence(Cursor &c, int depth) {
    if (depth > kMaxSequenceDepth) throw NotTaken{"sequences nest too deep"};
    for (;;) {
        const ElementHead h = readHead(c);
        if (h.tag == kSequenceEnd) return;
        if (h.tag != kItem) throw NotTaken{"a sequence holds something other than items"};
        if (h.length == kUndefinedLength) skipUndefinedItem(c, depth);
        else value(c, h.length);
    }
}

std::string text(std::span<const unsigned char> v) {
    std::string s(reinterpret_cast<const char *>(v.data()), v.size());
    while (!s.empty() && (s.back() == ' ' || s.back() == '\0')) s.pop_back();
    while (!s.empty() && s.front() == ' ') s.erase(0, 1);
    return s;
}

// A decimal string's N numbers, or the slice is not taken.
template <size_t N>
std::array<double, N> decimals(std::span<const unsigned char> v, const char *what) {
    const auto numbers = decimalStrings<N>(std::string_view(reinterpret_cast<const char *>(v.data()), v.size()));
    if (!numbers) throw NotTaken{fmt::format("its {} is not {} finite numbers", what, N)};
    return *numbers;
}

int unsignedShortValue(std::span<const unsigned char> v, const char *what) {
    if (v.size() != 2) throw NotTaken{fmt::format("its {} is not one 16-bit number", what)};
    return v[0] | v[1] << 8;
}

} // namespace

std::optional<UncompressedSlice> parseUncompressedSlice(std::span<const unsigned char> bytes, std::string &why) {
    try {
        if (bytes.size() < 132 || std::memcmp(bytes.data() + 128, "DICM", 4) != 0)
            throw NotTaken{"it has no DICOM Part 10 preamble"};
        Cursor c{bytes, 132, true};
        UncompressedSlice s;
        std::string transferSyntax, sopClassInDataSet;
        // The file meta group, always explicit VR little-endian.
        while (!c.atEnd()) {
            c.need(2);
            if (uint16_t(c.bytes[c.at] | c.bytes[c.at + 1] << 8) != 0x0002) break;
            const ElementHead h = readHead(c);
            if (h.length == kUndefinedLength) throw NotTaken{"its file meta group has an element of undefined length"};
            const auto v = value(c, h.length);
            if (h.tag == tagOf(0x0002, 0x0002)) s.sopClass = text(v);
            if (h.tag == tagOf(0x0002, 0x0010)) transferSyntax = text(v);
        }
        if (transferSyntax == kImplicitLittleEndian) c.explicitVr = false;
        else if (transferSyntax != kExplicitLittleEndian)
            throw NotTaken{fmt::format("its transfer syntax is '{}', not uncompressed little-endian", statedText(transferSyntax))};

        bool rows = false, columns = false, bitsAllocated = false, bitsStored = false, highBitSeen = false,
             representation = false, position = false, orientation = false, spacing = false, photometric = false;
        int highBit = -1;
        double slope = 1;
        std::string details;
        uint32_t previous = 0;
        for (;;) {
            const ElementHead h = readHead(c);
            if (h.tag <= previous) throw NotTaken{"its elements are not in ascending order"};
            previous = h.tag;
            if ((h.tag >> 16) == 0xfffe) throw NotTaken{"an item or delimiter stands outside a sequence"};
            if (h.tag == kPixelData) {
                if (h.length == kUndefinedLength) throw NotTaken{"its pixel data is encapsulated (compressed)"};
                s.pixelOffset = c.at;
                s.pixelLength = h.length;
                break;
            }
            if (h.length == kUndefinedLength) {
                if (c.explicitVr && !(h.vr[0] == 'S' && h.vr[1] == 'Q') && !(h.vr[0] == 'U' && h.vr[1] == 'N'))
                    throw NotTaken{"an element other than a sequence has an undefined length"};
                skipUndefinedSequence(c, 1);
                continue;
            }
            const auto v = value(c, h.length);
            switch (h.tag) {
            case tagOf(0x0008, 0x0016): sopClassInDataSet = text(v); break;
            case tagOf(0x0008, 0x0060): s.modality = std::string(reinterpret_cast<const char *>(v.data()), v.size()); break;
            // What GDCM's series scan splits a series by besides its UID (with rows and columns):
            // series number, sequence name, slice thickness.
            case tagOf(0x0020, 0x0011): case tagOf(0x0018, 0x0024): case tagOf(0x0018, 0x0050):
                details += fmt::format("{:08x}={};", h.tag, text(v));
                break;
            case tagOf(0x0020, 0x000e): s.seriesUid = text(v); break;
            case tagOf(0x0020, 0x0032): {
                const auto p = decimals<3>(v, "image position");
                s.position = {p[0], p[1], p[2]};
                position = true;
                break;
            }
            case tagOf(0x0020, 0x0037): s.orientation = decimals<6>(v, "image orientation"); orientation = true; break;
            case tagOf(0x0028, 0x0002):
                if (unsignedShortValue(v, "samples per pixel") != 1) throw NotTaken{"it has more than one sample per pixel"};
                break;
            case tagOf(0x0028, 0x0004):
                if (text(v) != "MONOCHROME2") throw NotTaken{fmt::format("its photometric interpretation is '{}'", statedText(text(v)))};
                photometric = true;
                break;
            case tagOf(0x0028, 0x0008):
                if (text(v) != "1") throw NotTaken{"it holds several frames"};
                break;
            case tagOf(0x0028, 0x0010): s.rows = unsignedShortValue(v, "rows"); rows = true; break;
            case tagOf(0x0028, 0x0011): s.columns = unsignedShortValue(v, "columns"); columns = true; break;
            case tagOf(0x0028, 0x0030): s.pixelSpacing = decimals<2>(v, "pixel spacing"); spacing = true; break;
            case tagOf(0x0028, 0x0100): s.bitsAllocated = unsignedShortValue(v, "bits allocated"); bitsAllocated = true; break;
            case tagOf(0x0028, 0x0101): s.bitsStored = unsignedShortValue(v, "bits stored"); bitsStored = true; break;
            case tagOf(0x0028, 0x0102): highBit = unsignedShortValue(v, "high bit"); highBitSeen = true; break;
            case tagOf(0x0028, 0x0103): {
                const int r = unsignedShortValue(v, "pixel representation");
                if (r > 1) throw NotTaken{"its pixel representation is neither 0 nor 1"};
                s.isSigned = r == 1;
                representation = true;
                break;
            }
            case tagOf(0x0028, 0x1052): s.intercept = decimals<1>(v, "rescale intercept")[0]; break;
            case tagOf(0x0028, 0x1053): slope = decimals<1>(v, "rescale slope")[0]; break;
            case tagOf(0x0028, 0x3000): throw NotTaken{"it has a modality LUT"};
            default:
                // Philips' private rescale, which GDCM applies to MR in place of the standard one.
                if ((h.tag >> 16) == 0x2005) throw NotTaken{"it has Philips private MR elements"};
                break;
            }
        }
        if (!(rows && columns && bitsAllocated && bitsStored && highBitSeen && representation && photometric))
            throw NotTaken{"its image pixel module is incomplete"};
        if (!(position && orientation && spacing)) throw NotTaken{"it does not state its position, orientation and spacing"};
        if (s.rows < 1 || s.columns < 1) throw NotTaken{"it has no pixels"};
        if (s.bitsAllocated != 8 && s.bitsAllocated != 16) throw NotTaken{"its pixels are neither 8 nor 16 bits"};
        // Below 9 stored bits in 16, GDCM's type after rescaling is 8-bit where the stored one
        // is not; left to it.
        if (s.bitsStored < (s.bitsAllocated == 16 ? 9 : 1) || s.bitsStored > s.bitsAllocated || highBit != s.bitsStored - 1)
            throw NotTaken{"its stored bits are not the low bits of its pixels"};
        if (!sopClassInDataSet.empty() && sopClassInDataSet != s.sopClass)
            throw NotTaken{"its meta header and data set name different SOP classes"};
        if (s.sopClass != kCtImageStorage && s.sopClass != kMrImageStorage)
            throw NotTaken{fmt::format("its SOP class '{}' is neither CT nor MR Image Storage", statedText(s.sopClass))};
        // A rescale GDCM gives as integers: slope 1 (0 it reads as 1), an integer intercept, and
        // none at all for MR, where GDCM may ignore the standard one.
        if (slope == 0) slope = 1;
        if (slope != 1 || s.intercept != std::trunc(s.intercept) || std::abs(s.intercept) > double(1 << 20))
            throw NotTaken{"its rescale is not an integer shift"};
        if (s.sopClass == kMrImageStorage && s.intercept != 0) throw NotTaken{"it is MR with a rescale"};
        s.details = details + fmt::format("{}x{}", s.columns, s.rows);
        return s;
    } catch (const NotTaken &e) {
        why = e.why;
        return std::nullopt;
    }
}

namespace {

// The type GDCM gives the samples after rescaling by slope 1 and an integer intercept: the
// smallest that holds every value the stored bits allow, shifted.
VoxelType rescaledType(const UncompressedSlice &s) {
    const double lowest = s.isSigned ? -std::ldexp(1.0, s.bitsStored - 1) : 0.0;
    const double highest = s.isSigned ? std::ldexp(1.0, s.bitsStored - 1) - 1 : std::ldexp(1.0, s.bitsStored) - 1;
    const double lo = lowest + s.intercept, hi = highest + s.intercept;
    if (lo >= 0) return hi <= 255 ? VoxelType::UInt8 : hi <= 65535 ? VoxelType::UInt16 : VoxelType::UInt32;
    if (lo >= -128 && hi <= 127) return VoxelType::Int8;
    if (lo >= -32768 && hi <= 32767) return VoxelType::Int16;
    return VoxelType::Int32;
}

// Every byte of `size` at `offset`, or false.
bool readAt(int fd, unsigned char *to, size_t size, uint64_t offset) {
    while (size > 0) {
        const ssize_t n = ::pread(fd, to, size, off_t(offset));
        if (n < 0 && errno == EINTR) continue;
        if (n <= 0) return false;
        to += n;
        size -= size_t(n);
        offset += uint64_t(n);
    }
    return true;
}

struct File {
    int fd = -1;
    // Non-blocking: a FIFO in its place is refused by fstat, never waited on.
    explicit File(const fs::path &p) : fd(::open(p.c_str(), O_RDONLY | O_CLOEXEC | O_NOFOLLOW | O_NONBLOCK)) {}
    ~File() {
        if (fd >= 0) ::close(fd);
    }
    File(const File &) = delete;
    File &operator=(const File &) = delete;
};

} // namespace

std::optional<UncompressedSeries> scanUncompressedSeries(const fs::path &dir, std::string &why,
                                                         const std::optional<std::vector<std::string>> &only) {
    std::vector<fs::path> files;
    std::error_code ec;
    for (fs::directory_iterator it(dir, ec), end; !ec && it != end; it.increment(ec)) {
        if (only && !std::binary_search(only->begin(), only->end(), it->path().filename().string())) continue;
        if (!it->is_regular_file(ec) || it->is_symlink(ec)) {
            why = fmt::format("'{}' is not a regular file", it->path().filename().string());
            return std::nullopt;
        }
        files.push_back(it->path());
    }
    if (ec) {
        why = "the folder cannot be listed: " + ec.message();
        return std::nullopt;
    }
    if (files.size() < 2) {
        why = "the folder holds fewer than two files";
        return std::nullopt;
    }
    std::sort(files.begin(), files.end());
    UncompressedSeries series;
    std::vector<unsigned char> head;
    for (const fs::path &path : files) {
        const std::string name = path.filename().string();
        const File file(path);
        struct stat st {};
        if (file.fd < 0 || ::fstat(file.fd, &st) != 0 || !S_ISREG(st.st_mode)) {
            why = fmt::format("'{}' cannot be opened", name);
            return std::nullopt;
        }
        std::optional<UncompressedSlice> slice;
        for (const size_t limit : {kHeaderBytes, kLongHeaderBytes}) {
            head.resize(std::min<uint64_t>(uint64_t(st.st_size), limit));
            if (!readAt(file.fd, head.data(), head.size(), 0)) {
                why = fmt::format("'{}' cannot be read", name);
                return std::nullopt;
            }
            slice = parseUncompressedSlice(head, why);
            if (slice || head.size() == uint64_t(st.st_size)) break;   // the whole file was read
        }
        if (!slice) {
            why = fmt::format("'{}': {}", name, why);
            return std::nullopt;
        }
        const uint64_t need = uint64_t(slice->rows) * uint64_t(slice->columns) * uint64_t(slice->bitsAllocated / 8);
        if (slice->pixelLength < need || uint64_t(st.st_size) < slice->pixelOffset + need) {
            why = fmt::format("'{}' holds fewer pixel bytes than its rows and columns need", name);
            return std::nullopt;
        }
        slice->file = name;
        series.slices.push_back(std::move(*slice));
    }
    const UncompressedSlice &first = series.slices.front();
    for (const UncompressedSlice &s : series.slices)
        if (s.seriesUid != first.seriesUid || s.sopClass != first.sopClass || s.details != first.details ||
            s.bitsAllocated != first.bitsAllocated || s.bitsStored != first.bitsStored || s.isSigned != first.isSigned ||
            s.orientation != first.orientation || s.pixelSpacing != first.pixelSpacing || s.intercept != first.intercept ||
            s.modality != first.modality) {
            why = fmt::format("'{}' and '{}' differ in series, pixel format, orientation, spacing or rescale", first.file,
                              s.file);
            return std::nullopt;
        }
    // Ascending along the normal of the first slice's rows and columns, as GDCM's series scan
    // orders them; a tie it would break by other means, so one is not taken.
    const auto &o = first.orientation;
    const Vec3d normal = cross(Vec3d{o[0], o[1], o[2]}, Vec3d{o[3], o[4], o[5]});
    std::vector<std::pair<double, size_t>> order;
    for (size_t i = 0; i < series.slices.size(); ++i) order.emplace_back(dot(series.slices[i].position, normal), i);
    std::sort(order.begin(), order.end());
    for (size_t i = 1; i < order.size(); ++i)
        if (order[i].first == order[i - 1].first) {
            why = "two slices lie at the same distance along the normal";
            return std::nullopt;
        }
    std::vector<UncompressedSlice> sorted;
    for (const auto &[distance, i] : order) sorted.push_back(std::move(series.slices[i]));
    series.slices = std::move(sorted);
    series.type = rescaledType(series.slices.front());
    return series;
}

namespace {

// Stored pixels (Code: uint8_t or uint16_t) to the narrow store in place: the value is the
// low bitsStored bits (sign-extended when signed) plus the intercept; the store holds value −
// lowest in 1 or 2 bytes, as narrowWidth and packNarrow would choose and write. The store's
// bytes are read and written as Code through a may_alias type (the host is little-endian,
// as the store), so that both passes vectorise.
template <class Code>
void packInPlace(Volume &v, const UncompressedSlice &format) {
    static_assert(std::endian::native == std::endian::little, "the narrow store is little-endian");
    using Aliased [[gnu::may_alias]] = Code;
    const size_t count = v.voxelCount();
    Aliased *codes = reinterpret_cast<Aliased *>(v.narrowVoxels.data());
    const unsigned bits = unsigned(format.bitsStored);
    const uint32_t mask = (uint32_t(1) << bits) - 1;
    const uint32_t sign = format.isSigned ? uint32_t(1) << (bits - 1) : 0;
    // Two's complement of the low bits: flipping the sign bit and subtracting it extends it.
    const auto valueOf = [mask, sign](Code c) { return int32_t((uint32_t(c) & mask) ^ sign) - int32_t(sign); };
    int32_t lo = std::numeric_limits<int32_t>::max(), hi = std::numeric_limits<int32_t>::lowest();
    for (size_t i = 0; i < count; ++i) {
        const int32_t x = valueOf(codes[i]);
        lo = std::min(lo, x);
        hi = std::max(hi, x);
    }
    const int bytes = hi - lo < 256 ? 1 : 2;
    if (size_t(bytes) == sizeof(Code)) {
        for (size_t i = 0; i < count; ++i) codes[i] = Code(uint32_t(valueOf(codes[i]) - lo));
    } else {
        // 16-bit pixels spanning fewer than 256 values: each byte lands at or before the
        // sample it comes from, which is read first.
        unsigned char *store = v.narrowVoxels.data();
        for (size_t i = 0; i < count; ++i) store[i] = uint8_t(uint32_t(valueOf(codes[i]) - lo));
    }
    v.narrow = {bytes, float(double(lo) + format.intercept)};
    if (size_t(bytes) < sizeof(Code)) {
        v.narrowVoxels.resize(count * size_t(bytes) + kNarrowSlack);
        v.narrowVoxels.shrink_to_fit();
    }
    std::fill(v.narrowVoxels.end() - kNarrowSlack, v.narrowVoxels.end(), 0);
}

} // namespace

void placeUncompressedSeries(const fs::path &dir, const UncompressedSeries &series, Volume &v) {
    // As ITK's series reader computes it: x and y spacing from Pixel Spacing (between
    // columns, between rows), the origin at the first slice, the z spacing and the third axis
    // from the first slice to the last.
    const UncompressedSlice &first = series.slices.front(), &last = series.slices.back();
    v.dims = {first.columns, first.rows, int64_t(series.slices.size())};
    const Vec3d span = last.position - first.position;
    const auto &o = first.orientation;
    v.spacing = {first.pixelSpacing[1], first.pixelSpacing[0], length(span) / double(series.slices.size() - 1)};
    v.origin = first.position;
    const Vec3d z = span / length(span);
    Mat3d direction;
    for (int r = 0; r < 3; ++r) {
        direction(r, 0) = o[size_t(r)];
        direction(r, 1) = o[size_t(3 + r)];
        direction(r, 2) = z[r];
    }
    v.direction = checkedGeometry(dir, v.spacing, v.origin, direction);
    v.sourceType = series.type;
    v.orientationKnown = true;
    v.modality = statedText(first.modality);
    v.modalityField = v.modality.empty() ? "" : "DICOM";
}

void readUncompressedSamples(const fs::path &dir, const UncompressedSeries &series, LoadProgress &progress,
                             double from, double to, Volume &v) {
    const UncompressedSlice &first = series.slices.front();
    const size_t stored = size_t(first.bitsAllocated / 8);
    const size_t sliceBytes = size_t(first.rows) * size_t(first.columns) * stored;
    v.narrowVoxels.assign(sliceBytes * series.slices.size() + kNarrowSlack, 0);
    progress(from, "reading slices");
    for (size_t k = 0; k < series.slices.size(); ++k) {
        const UncompressedSlice &s = series.slices[k];
        const File file(dir / s.file);
        struct stat st {};
        if (file.fd < 0 || ::fstat(file.fd, &st) != 0 || !S_ISREG(st.st_mode) ||
            uint64_t(st.st_size) < sliceBytes || s.pixelOffset > uint64_t(st.st_size) - sliceBytes ||
            !readAt(file.fd, v.narrowVoxels.data() + k * sliceBytes, sliceBytes, s.pixelOffset))
            fail(dir, fmt::format("slice '{}' no longer holds its pixel data", s.file));
        progress(from + (to - from) * double(k + 1) / double(series.slices.size()), "reading slices");
    }
    if (stored == 1) packInPlace<uint8_t>(v, first);
    else packInPlace<uint16_t>(v, first);
}

} // namespace volcast::io
