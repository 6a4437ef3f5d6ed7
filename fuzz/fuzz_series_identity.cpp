// The identity and consistency check of a DICOM series (renderer/io/dicom_identity.hpp,
// checkSeriesIdentity) over headers the input states: one instance a line, its fields
// separated by '|' in InstanceHeader's order (file, instance number, PatientID, PatientName,
// IssuerOfPatientID, study, series, SOP instance, frame of reference, rows, columns,
// orientation, position; a missing orientation or position field is an absent element). A
// first line starting with "expect|" names the requested study and series. The headers come
// from GDCM in the loader, which this target leaves out (an open assertion in GDCM, README
// finding 7): what is fuzzed is the check itself, with hostile values in every field.
// Invariants: only VolumeLoadError escapes, its message starting with the folder; the same
// headers give the same answer twice; the answer stays word for word the same with every
// PatientID and PatientName replaced by other values that are equal where they were (so no
// message quotes them).

#include "renderer/io/dicom_identity.hpp"

#include "fuzz/fuzz_check.hpp"

#include <cstddef>
#include <cstdint>
#include <map>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

using namespace volcast;

namespace {

std::vector<std::string> split(std::string_view text, char by, size_t most) {
    std::vector<std::string> out;
    size_t at = 0;
    while (out.size() < most) {
        const size_t end = text.find(by, at);
        out.emplace_back(text.substr(at, end == std::string_view::npos ? std::string_view::npos : end - at));
        if (end == std::string_view::npos) break;
        at = end + 1;
    }
    return out;
}

int64_t number(const std::string &s) {
    int64_t n = 0;
    for (char c : s.substr(0, 6))
        if (c >= '0' && c <= '9') n = n * 10 + (c - '0');
    return n;
}

// The refusal, or "" where the headers pass.
std::string verdict(const std::vector<io::InstanceHeader> &headers, const std::optional<SeriesIdentity> &expected) {
    try {
        io::checkSeriesIdentity("/fuzz/series", headers, expected);
        return "";
    } catch (const VolumeLoadError &e) {
        const std::string message = e.what();
        fuzz::check(!message.empty(), "a refusal without a message");
        return message;
    }
}

} // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size) {
    const std::string_view text(reinterpret_cast<const char *>(data), size);
    std::vector<std::string> lines = split(text, '\n', 257);
    std::optional<SeriesIdentity> expected;
    if (!lines.empty() && lines.front().starts_with("expect|")) {
        const auto f = split(lines.front(), '|', 3);
        expected = SeriesIdentity{f.size() > 1 ? f[1] : "", f.size() > 2 ? f[2] : ""};
        lines.erase(lines.begin());
    }
    std::vector<io::InstanceHeader> headers;
    for (const std::string &line : lines) {
        const auto f = split(line, '|', 13);
        const auto field = [&](size_t i) { return i < f.size() ? f[i] : std::string(); };
        io::InstanceHeader h;
        h.file = field(0);
        h.instanceNumber = field(1);
        h.patientId = field(2);
        h.patientName = field(3);
        h.issuerOfPatientId = field(4);
        h.studyUid = field(5);
        h.seriesUid = field(6);
        h.sopInstanceUid = field(7);
        h.frameOfReferenceUid = field(8);
        h.rows = number(field(9));
        h.columns = number(field(10));
        if (f.size() > 11) h.orientation = f[11];
        if (f.size() > 12) h.position = f[12];
        headers.push_back(std::move(h));
    }
    const std::string message = verdict(headers, expected);
    fuzz::check(message == verdict(headers, expected), "the same headers give another answer twice");
    // The check only compares them: with every PatientID and PatientName replaced by another
    // value (equal where they were equal, empty where empty), the answer must be the same
    // words, so no message can quote them.
    std::map<std::string, std::string> others;
    std::vector<io::InstanceHeader> renamed = headers;
    for (io::InstanceHeader &h : renamed)
        for (std::string *identifying : {&h.patientId, &h.patientName})
            if (!identifying->empty())
                *identifying = others.try_emplace(*identifying, "substitute-" + std::to_string(others.size())).first->second;
    fuzz::check(verdict(renamed, expected) == message, "a refusal depends on a patient's ID or name, not only on "
                                                       "whether they differ", message);
    if (message.empty()) return 0;
    fuzz::check(message.starts_with("/fuzz/series: "), "a refusal that does not start with the folder", message);
    fuzz::check(!headers.empty(), "a refusal without instances", message);
    return 0;
}
