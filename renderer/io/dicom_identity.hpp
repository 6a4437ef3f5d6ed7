#pragma once
// Whether the DICOM files of a folder are one series of one patient that one volume can show:
// a series from a PACS, a folder of the data folders or an uploaded .zip is shown as one
// patient's images, so an instance of another patient, study or series merged into it, or a
// second stack silently dropped, would be a wrong picture with no word of it. The check runs
// over the headers of every file before either read path (the direct reader of uncompressed
// series and ITK's series reader), in the checker process. Internal to renderer/io/.

#include "renderer/io/volume_checks.hpp"

#include <cstdint>
#include <optional>
#include <string>
#include <vector>

namespace volcast::io {

// What the check needs of one instance's header, values as stored (trailing spaces and NULs
// removed); an absent element is empty (or nullopt where absence differs from an empty value).
struct InstanceHeader {
    std::string file;                  // the name within the folder
    std::string instanceNumber;        // (0020,0013), to name the instance
    std::string patientId;             // (0010,0020)
    std::string patientName;           // (0010,0010)
    std::string issuerOfPatientId;     // (0010,0021)
    std::string studyUid;              // (0020,000D)
    std::string seriesUid;             // (0020,000E)
    std::string sopInstanceUid;        // (0008,0018)
    std::string frameOfReferenceUid;   // (0020,0052)
    int64_t rows = 0, columns = 0;     // (0028,0010), (0028,0011); 0 when absent or not one US
    std::optional<std::string> orientation;   // (0020,0037) Image Orientation (Patient)
    std::optional<std::string> position;      // (0020,0032) Image Position (Patient)
};

// Every header of a DICOM file in the folder (read with GDCM up to the pixel data, which is
// not read), in the order of the files' names. Files GDCM cannot read as DICOM, and a
// DICOMDIR, are passed over, as GDCM's series scan passes over them. Progress steps (without
// advancing) let the time limit end a long scan.
std::vector<InstanceHeader> readInstanceHeaders(const fs::path &dir, LoadProgress &progress);

// Fails naming the first instance (in the order given) and the field that keeps the
// instances from being one volume of one patient: the requested study and series (where
// `expected` is given), one patient (ID, and name and issuer where both state them), one
// study, one series, one frame of reference, no instance twice, one stack (one size and
// orientation: a localizer or a second stack is named, with the stacks' slice counts), and an
// orientation and position that are finite numbers where stated. Messages never quote a
// patient's name or ID: they say which field differs. Nothing to check without instances.
// Several stacks are refused with SeriesHoldsStacks unless `selected` selects one of them
// (SeriesStack::number); then the names of that stack's files are returned, for the read
// paths to read only those. Nothing is returned without a selection.
std::optional<std::vector<std::string>> checkSeriesIdentity(const fs::path &dir,
                                                            const std::vector<InstanceHeader> &instances,
                                                            const std::optional<SeriesIdentity> &expected,
                                                            std::optional<uint32_t> selected = std::nullopt);

} // namespace volcast::io
