#pragma once
// Tests' edits of single DICOM files written by saveDicomSeries: one element's value set
// through GDCM (its reader, gdcm::Anonymizer's Replace, its writer), the rest of the file kept.
// For the identity and consistency tests of DICOM series (renderer/io/dicom_identity.hpp).

#include <gdcmAnonymizer.h>
#include <gdcmReader.h>
#include <gdcmWriter.h>
#include <gtest/gtest.h>

#include <cstdint>
#include <filesystem>
#include <string>
#include <utility>
#include <vector>

namespace volcast::dicom_tags {

// Sets each (group, element) to its value in `file` (added where it is absent).
inline void setTags(const std::filesystem::path &file,
                    const std::vector<std::pair<std::pair<uint16_t, uint16_t>, std::string>> &values) {
    gdcm::Reader reader;
    reader.SetFileName(file.string().c_str());
    ASSERT_TRUE(reader.Read()) << "GDCM cannot read " << file;
    gdcm::Anonymizer anonymizer;
    anonymizer.SetFile(reader.GetFile());
    for (const auto &[tag, value] : values)
        ASSERT_TRUE(anonymizer.Replace(gdcm::Tag(tag.first, tag.second), value.c_str()))
            << "GDCM cannot set (" << std::hex << tag.first << "," << tag.second << ") in " << file;
    gdcm::Writer writer;
    writer.SetFile(reader.GetFile());
    writer.SetFileName(file.string().c_str());
    ASSERT_TRUE(writer.Write()) << "GDCM cannot write " << file;
}

inline constexpr std::pair<uint16_t, uint16_t> kPatientId{0x0010, 0x0020};
inline constexpr std::pair<uint16_t, uint16_t> kPatientName{0x0010, 0x0010};
inline constexpr std::pair<uint16_t, uint16_t> kStudyUid{0x0020, 0x000d};
inline constexpr std::pair<uint16_t, uint16_t> kSeriesUid{0x0020, 0x000e};
inline constexpr std::pair<uint16_t, uint16_t> kSopInstanceUid{0x0008, 0x0018};
inline constexpr std::pair<uint16_t, uint16_t> kFrameOfReferenceUid{0x0020, 0x0052};
inline constexpr std::pair<uint16_t, uint16_t> kImageOrientation{0x0020, 0x0037};
inline constexpr std::pair<uint16_t, uint16_t> kImagePosition{0x0020, 0x0032};

// Another patient's instance, as a PACS or a folder might hold it: another PatientID and
// study, the same series.
inline void makeAnotherPatients(const std::filesystem::path &file) {
    setTags(file, {{kPatientId, "OTHER-PATIENT-7"}, {kPatientName, "Other^Patient"}, {kStudyUid, "1.2.826.0.1.3680043.2.1125.99.1"}});
}

} // namespace volcast::dicom_tags
