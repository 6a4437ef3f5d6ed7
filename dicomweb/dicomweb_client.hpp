#pragma once
// A DICOMweb client: QIDO-RS search of studies and series, a series' size from its instances'
// metadata, and WADO-RS retrieval of a series as DICOM files, streamed to a folder. Knows
// nothing of the renderer or the protocol. Every failure is a DicomWebError (errors.hpp), its
// message scrubbed of the source's credentials (credential_scrubber.hpp).
//
// A Client holds only its configuration: its calls may run on several threads at once (each
// call makes its own HTTP connection).

#include "dicomweb/credential_scrubber.hpp"
#include "dicomweb/errors.hpp"

#include <cstdint>
#include <filesystem>
#include <functional>
#include <string>
#include <string_view>
#include <vector>

namespace volcast::dicomweb {

struct SourceConfig {
    std::string name;            // for messages
    std::string baseUrl;         // the DICOMweb root, e.g. https://pacs.example.org/dicom-web
    std::string authorization;   // "" or the Authorization value ("Basic …", "Bearer …"); never logged
    double connectTimeoutSeconds = 5;
    double requestTimeoutSeconds = 30;  // per QIDO request
    double lowSpeedSeconds = 15;        // retrieval (and QIDO) fail if < 1 KiB/s for this long
    uint64_t maxQueryBytes = 16 << 20;  // one QIDO answer
};

// Empty fields are not sent. patientName may use DICOM wildcards '*' and '?'; studyDate is
// YYYYMMDD or a range YYYYMMDD-YYYYMMDD where either end may be empty.
struct StudyQuery {
    std::string patientName, patientId, studyDate, modality, accessionNumber;
    int limit = 100;  // 1..1000
};

struct SeriesRecord {
    std::string seriesUid, modality, description;
    int64_t instances = 0;  // 0 when the PACS did not say
};

struct StudyRecord {
    std::string studyUid, patientName, patientId, studyDate, description, accessionNumber;
    std::vector<std::string> modalities;
    std::vector<SeriesRecord> series;
};

// From QIDO-RS metadata, before retrieval: the series' instance count and its first
// instance's size (every instance's, largest and summed, where the source gives no count).
struct SeriesSize {
    int64_t instances = 0;
    int64_t rows = 0, columns = 0;
    uint64_t float32Bytes = 0;      // frames × rows × columns × 4 of an instance, times the count
};

struct RetrieveProgress {
    int64_t instancesDone = 0;
    int64_t instancesTotal = 0;  // 0: not known
    uint64_t bytes = 0;          // DICOM bytes received so far
};

class Client {
  public:
    // Throws BadQuery if the base URL is not http(s)://host/... or the Authorization value
    // holds a line break.
    explicit Client(SourceConfig config);

    // QIDO-RS: the matching studies (at most query.limit), then each one's series. Studies
    // whose UID is missing or malformed are left out; other missing attributes are empty.
    std::vector<StudyRecord> findStudies(const StudyQuery &query);

    // QIDO-RS of the series (Number of Series Related Instances) and of its first instance
    // (Rows, Columns, NumberOfFrames); of every instance where the series record has no count.
    // NotFound when the series has no instance; BadResponse when an instance asked has no
    // usable Rows or Columns.
    SeriesSize seriesSize(const std::string &studyUid, const std::string &seriesUid);

    // WADO-RS multipart/related; type="application/dicom": each instance is written, as it
    // arrives, to folder/instance_NNNNN.dcm (00000 first). The folder must be empty or missing
    // (it is then created); otherwise Storage.
    // At most maxBytes of DICOM data (past it: TooLarge); `progress` after each instance;
    // `cancelled` asked between chunks and while the transfer waits. With expectedInstances > 0
    // (from seriesSize), a series that arrives with a different count is BadResponse: never a
    // silently incomplete series. On any failure the files this call wrote are removed.
    RetrieveProgress retrieveSeries(const std::string &studyUid, const std::string &seriesUid,
                                    const std::filesystem::path &folder, uint64_t maxBytes,
                                    const std::function<void(const RetrieveProgress &)> &progress,
                                    const std::function<bool()> &cancelled, int64_t expectedInstances = 0);

    const SourceConfig &config() const { return config_; }

  private:
    // The calls above, whose errors those wrap in scrubbingErrors.
    std::vector<StudyRecord> searchStudies(const StudyQuery &query);
    SeriesSize measureSeries(const std::string &studyUid, const std::string &seriesUid);
    RetrieveProgress retrieve(const std::string &studyUid, const std::string &seriesUid,
                              const std::filesystem::path &folder, uint64_t maxBytes,
                              const std::function<void(const RetrieveProgress &)> &progress,
                              const std::function<bool()> &cancelled, int64_t expectedInstances);

    SourceConfig config_;
    CredentialScrubber scrubber_;
    std::string base_;  // baseUrl without its trailing '/'
};

// A DICOM UID as this library puts it in a URL: [0-9.]{1,64}, no leading, trailing or double dot.
bool isUid(std::string_view text);

// The query string of a QIDO-RS studies search ("PatientName=...&limit=N&includefield=..."),
// values percent-encoded. Throws BadQuery naming the field: control characters, a backslash,
// invalid UTF-8, a value longer than DICOM allows (64, accession number 16, modality 16),
// a malformed date or range, a limit outside 1..1000.
std::string studyQueryString(const StudyQuery &query);

} // namespace volcast::dicomweb
