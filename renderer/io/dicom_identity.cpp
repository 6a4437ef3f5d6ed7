// One series of one patient, one stack (dicom_identity.hpp).

#include "renderer/io/dicom_identity.hpp"
#include "renderer/io/dicom_uncompressed.hpp"

#include <gdcmReader.h>
#include <spdlog/fmt/fmt.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <set>

namespace volcast::io {

namespace {

// A value as stored, without the padding DICOM allows (trailing spaces and NULs, leading
// spaces), or nothing when the element is absent or holds no bytes.
std::optional<std::string> storedValue(const gdcm::DataSet &ds, uint16_t group, uint16_t element) {
    const gdcm::Tag tag(group, element);
    if (!ds.FindDataElement(tag)) return std::nullopt;
    const gdcm::ByteValue *value = ds.GetDataElement(tag).GetByteValue();
    if (!value || value->GetLength() == 0) return std::nullopt;
    std::string s(value->GetPointer(), value->GetLength());
    while (!s.empty() && (s.back() == ' ' || s.back() == '\0')) s.pop_back();
    const size_t first = s.find_first_not_of(' ');
    return first == std::string::npos ? std::string() : s.substr(first);
}

int64_t storedUnsignedShort(const gdcm::DataSet &ds, uint16_t group, uint16_t element) {
    const gdcm::Tag tag(group, element);
    if (!ds.FindDataElement(tag)) return 0;
    const gdcm::ByteValue *value = ds.GetDataElement(tag).GetByteValue();
    if (!value || value->GetLength() != 2) return 0;
    const auto *b = reinterpret_cast<const unsigned char *>(value->GetPointer());
    return int64_t(b[0] | b[1] << 8);   // US in the little-endian transfer syntaxes GDCM reads here
}

constexpr const char *kMediaStorageDirectory = "1.2.840.10008.1.3.10";   // a DICOMDIR

// "instance 117 ('slice_0116.dcm')", or the file alone where it states no instance number.
std::string instanceName(const InstanceHeader &h) {
    const std::string number = statedText(h.instanceNumber);
    return number.empty() ? fmt::format("'{}'", h.file) : fmt::format("instance {} ('{}')", number, h.file);
}

// One stack: a size and an orientation (nothing where none is stated), and how many slices.
struct Stack {
    int64_t rows = 0, columns = 0;
    std::optional<std::array<double, 6>> orientation;
    size_t slices = 0;
    std::vector<std::string> files;
    bool holds(const InstanceHeader &h, const std::optional<std::array<double, 6>> &o) const {
        if (h.rows != rows || h.columns != columns || o.has_value() != orientation.has_value()) return false;
        if (!o) return true;
        // The tolerance of checkSeriesGeometry (dicom_series.cpp) for one orientation.
        for (size_t i = 0; i < 6; ++i)
            if (std::abs((*o)[i] - (*orientation)[i]) > 1e-4) return false;
        return true;
    }
};

size_t mostSlices(const std::vector<Stack> &stacks) {
    size_t largest = 0;
    for (const Stack &s : stacks) largest = std::max(largest, s.slices);
    return largest;
}

// A scout image beside the series' stack: one to three slices where another stack has more.
bool looksLikeLocalizer(const Stack &s, size_t largest) { return s.slices <= 3 && s.slices < largest; }

std::string describeStacks(const std::vector<Stack> &stacks) {
    const size_t largest = mostSlices(stacks);
    bool oneSize = true;
    for (const Stack &s : stacks) oneSize = oneSize && s.rows == stacks.front().rows && s.columns == stacks.front().columns;
    std::string said;
    for (size_t i = 0; i < stacks.size(); ++i) {
        const Stack &s = stacks[i];
        if (i > 0) said += i + 1 == stacks.size() ? " and " : ", ";
        said += fmt::format("stack {} has {} slice{} {} x {}", i + 1, s.slices, s.slices == 1 ? "" : "s", s.columns, s.rows);
        if (oneSize) {
            if (s.orientation) {
                const auto &o = *s.orientation;
                said += fmt::format(" oriented ({:.3g}, {:.3g}, {:.3g} / {:.3g}, {:.3g}, {:.3g})", o[0], o[1], o[2],
                                    o[3], o[4], o[5]);
            } else {
                said += " without an orientation";
            }
        }
        if (looksLikeLocalizer(s, largest)) said += " (a localizer?)";
    }
    return said;
}

// Where the slices face: the axis their normal lies within 30 degrees of (cos 30 = 0.866), in
// the patient's LPS axes (x: sagittal, y: coronal, z: axial).
std::string orientationName(const std::optional<std::array<double, 6>> &o) {
    if (!o) return "unknown";
    const auto &r = *o;
    const std::array<double, 3> normal{r[1] * r[5] - r[2] * r[4], r[2] * r[3] - r[0] * r[5], r[0] * r[4] - r[1] * r[3]};
    const double length = std::sqrt(normal[0] * normal[0] + normal[1] * normal[1] + normal[2] * normal[2]);
    if (!(length > 0)) return "oblique";
    constexpr std::array<const char *, 3> kAxes{"sagittal", "coronal", "axial"};
    for (size_t a = 0; a < 3; ++a)
        if (std::abs(normal[a]) / length >= 0.866) return kAxes[a];
    return "oblique";
}

// The stacks in the order that numbers them (SeriesStack): most slices first, then rows,
// columns and orientation, which tell any two stacks apart.
void numberStacks(std::vector<Stack> &stacks) {
    std::sort(stacks.begin(), stacks.end(), [](const Stack &a, const Stack &b) {
        if (a.slices != b.slices) return a.slices > b.slices;
        if (a.rows != b.rows) return a.rows > b.rows;
        if (a.columns != b.columns) return a.columns > b.columns;
        return a.orientation < b.orientation;
    });
}

std::vector<SeriesStack> listedStacks(const std::vector<Stack> &stacks) {
    const size_t largest = mostSlices(stacks);
    std::vector<SeriesStack> listed;
    for (size_t i = 0; i < stacks.size() && i < SeriesHoldsStacks::kMaxListed; ++i) {
        const Stack &s = stacks[i];
        listed.push_back({uint32_t(i + 1), uint32_t(s.slices), s.rows, s.columns, orientationName(s.orientation),
                          looksLikeLocalizer(s, largest)});
    }
    return listed;
}

} // namespace

std::vector<InstanceHeader> readInstanceHeaders(const fs::path &dir, LoadProgress &progress) {
    std::vector<fs::path> files;
    std::error_code ec;
    for (fs::directory_iterator it(dir, ec), end; !ec && it != end; it.increment(ec))
        if (it->is_regular_file(ec)) files.push_back(it->path());
    std::sort(files.begin(), files.end());
    std::vector<InstanceHeader> headers;
    for (const fs::path &file : files) {
        progress(0, "checking the series");
        gdcm::Reader reader;
        reader.SetFileName(file.string().c_str());
        // Every element the check needs lies before (0028,0012); the pixel data, and a
        // scanner's long private groups after it, are not read.
        if (!reader.ReadUpToTag(gdcm::Tag(0x0028, 0x0012), {gdcm::Tag(0x7fe0, 0x0010)})) continue;
        const gdcm::File &dicom = reader.GetFile();
        const gdcm::DataSet &meta = dicom.GetHeader();
        if (storedValue(meta, 0x0002, 0x0002).value_or("") == kMediaStorageDirectory) continue;
        const gdcm::DataSet &ds = dicom.GetDataSet();
        InstanceHeader h;
        h.file = file.filename().string();
        h.instanceNumber = storedValue(ds, 0x0020, 0x0013).value_or("");
        h.patientId = storedValue(ds, 0x0010, 0x0020).value_or("");
        h.patientName = storedValue(ds, 0x0010, 0x0010).value_or("");
        h.issuerOfPatientId = storedValue(ds, 0x0010, 0x0021).value_or("");
        h.studyUid = storedValue(ds, 0x0020, 0x000d).value_or("");
        h.seriesUid = storedValue(ds, 0x0020, 0x000e).value_or("");
        h.sopInstanceUid = storedValue(ds, 0x0008, 0x0018).value_or("");
        h.frameOfReferenceUid = storedValue(ds, 0x0020, 0x0052).value_or("");
        h.rows = storedUnsignedShort(ds, 0x0028, 0x0010);
        h.columns = storedUnsignedShort(ds, 0x0028, 0x0011);
        h.orientation = storedValue(ds, 0x0020, 0x0037);
        h.position = storedValue(ds, 0x0020, 0x0032);
        headers.push_back(std::move(h));
    }
    return headers;
}

std::optional<std::vector<std::string>> checkSeriesIdentity(const fs::path &dir,
                                                            const std::vector<InstanceHeader> &instances,
                                                            const std::optional<SeriesIdentity> &expected,
                                                            std::optional<uint32_t> selected) {
    if (instances.empty()) {
        if (selected && *selected != 1) fail(dir, fmt::format("holds no DICOM instances, so no stack {}", *selected));
        return std::nullopt;
    }
    const InstanceHeader &first = instances.front();
    const auto refuse = [&](const InstanceHeader &h, const std::string &problem) {
        fail(dir, fmt::format("{} {}; the series is not loaded", instanceName(h), problem));
    };
    const auto differs = [&](const InstanceHeader &h, const std::string &field, const std::string &what,
                             const std::string &more = "") {
        refuse(h, fmt::format("belongs to {} ({} differs from the series' first instance, {}){}", what, field,
                              instanceName(first), more));
    };
    // Where the instances of several series lie in one folder, how many of each.
    const auto seriesCounts = [&] {
        std::vector<std::pair<std::string, size_t>> counts;
        for (const InstanceHeader &h : instances) {
            auto it = std::find_if(counts.begin(), counts.end(), [&](const auto &c) { return c.first == h.seriesUid; });
            if (it == counts.end()) counts.emplace_back(h.seriesUid, 1);
            else ++it->second;
        }
        std::string said;
        for (size_t i = 0; i < counts.size(); ++i)
            said += fmt::format("{}{} instance{}", i == 0 ? "" : i + 1 == counts.size() ? " and " : ", ",
                                counts[i].second, counts[i].second == 1 ? "" : "s");
        return fmt::format(": the files hold {} series ({}), and one volume shows one series", counts.size(), said);
    };
    std::set<std::string> sopInstances;
    std::vector<Stack> stacks;
    const InstanceHeader *firstOfAnotherStack = nullptr;
    for (const InstanceHeader &h : instances) {
        if (expected && h.studyUid != expected->studyUid)
            refuse(h, "is not of the requested study (its StudyInstanceUID is another): the source answered with "
                      "another study's images");
        if (expected && h.seriesUid != expected->seriesUid)
            refuse(h, "is not of the requested series (its SeriesInstanceUID is another): the source answered with "
                      "another series' images");
        if (h.patientId != first.patientId) differs(h, "PatientID", "another patient");
        if (!h.issuerOfPatientId.empty() && !first.issuerOfPatientId.empty() &&
            h.issuerOfPatientId != first.issuerOfPatientId)
            differs(h, "IssuerOfPatientID", "another patient");
        if (!h.patientName.empty() && !first.patientName.empty() && h.patientName != first.patientName)
            differs(h, "PatientName", "another patient");
        const std::string several = h.seriesUid != first.seriesUid ? seriesCounts() : "";
        if (h.studyUid != first.studyUid) differs(h, "StudyInstanceUID", "another study", several);
        if (h.seriesUid != first.seriesUid) differs(h, "SeriesInstanceUID", "another series", several);
        if (h.frameOfReferenceUid != first.frameOfReferenceUid)
            differs(h, "FrameOfReferenceUID", "another frame of reference", ": its positions lie in another space");
        if (!h.sopInstanceUid.empty() && !sopInstances.insert(h.sopInstanceUid).second) {
            const auto same = std::find_if(instances.begin(), instances.end(),
                                           [&](const InstanceHeader &o) { return o.sopInstanceUid == h.sopInstanceUid; });
            refuse(h, fmt::format("is the same instance as {} (their SOPInstanceUID is the same): the series holds "
                                  "an image twice",
                                  instanceName(*same)));
        }
        std::optional<std::array<double, 6>> orientation;
        if (h.orientation) {
            orientation = decimalStrings<6>(*h.orientation);
            if (!orientation)
                refuse(h, "has an image orientation (ImageOrientationPatient) that is not six finite numbers: "
                          "where its image lies in the patient is unknown");
        }
        if (h.position && !decimalStrings<3>(*h.position))
            refuse(h, "has an image position (ImagePositionPatient) that is not three finite numbers: where its "
                      "image lies in the patient is unknown");
        auto stack = std::find_if(stacks.begin(), stacks.end(), [&](const Stack &s) { return s.holds(h, orientation); });
        if (stack == stacks.end()) {
            if (!stacks.empty() && !firstOfAnotherStack) firstOfAnotherStack = &h;
            stacks.push_back({h.rows, h.columns, orientation, 0, {}});
            stack = stacks.end() - 1;
        }
        ++stack->slices;
        stack->files.push_back(h.file);
    }
    numberStacks(stacks);
    const auto refuseStacks = [&](const std::string &problem) {
        throw SeriesHoldsStacks(fmt::format("{}: {}", dir.string(), problem), listedStacks(stacks));
    };
    if (selected) {
        // Only the split into stacks is resolved by the selection: every check above held for
        // the whole series.
        if (*selected < 1 || *selected > stacks.size())
            refuseStacks(fmt::format("the series holds {} stack{}, so no stack {}; it is not loaded", stacks.size(),
                                     stacks.size() == 1 ? "" : "s", *selected));
        std::vector<std::string> files = std::move(stacks[*selected - 1].files);
        std::sort(files.begin(), files.end());   // StackFiles: sorted for the read paths' lookups
        return files;
    }
    if (firstOfAnotherStack) {
        const InstanceHeader &h = *firstOfAnotherStack;
        const std::string how = h.rows != first.rows || h.columns != first.columns
                                    ? fmt::format("is {} x {} pixels where the series' first instance, {}, is {} x {}",
                                                  h.columns, h.rows, instanceName(first), first.columns, first.rows)
                                    : fmt::format("is oriented otherwise (ImageOrientationPatient) than the series' "
                                                  "first instance, {}",
                                                  instanceName(first));
        const std::string found = fmt::format("{} {}: the series holds {} stacks: {}", instanceName(h), how,
                                              stacks.size(), describeStacks(stacks));
        // Exactly one stack of several slices beside single-slice images: the stack meant is
        // plain, and said first, but still only loaded when asked for by its number.
        const bool oneStackBesideLocalizers =
            stacks[0].slices > 1 &&
            std::all_of(stacks.begin() + 1, stacks.end(), [](const Stack &s) { return s.slices == 1; });
        if (oneStackBesideLocalizers)
            refuseStacks(fmt::format("the series holds {} besides {} {} slices: open stack 1 for the {} slices ({}); "
                                     "one volume shows one stack, and the series is not loaded",
                                     stacks.size() == 2 ? "a localizer"
                                                        : fmt::format("{} localizers", stacks.size() - 1),
                                     stacks[0].slices, orientationName(stacks[0].orientation), stacks[0].slices,
                                     found));
        refuseStacks(fmt::format("{}; one volume shows one stack, and the series is not loaded: open one of its "
                                 "stacks",
                                 found));
    }
    return std::nullopt;
}

} // namespace volcast::io
