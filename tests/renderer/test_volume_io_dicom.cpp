// Tests of DICOM series loading (renderer/io/dicom_series.*, dicom_uncompressed.*): a series
// written by saveDicomSeries, a single slice, progress slice by slice, two series in one
// folder, damaged series, uncompressed series read straight from their files against the
// same series read through GDCM, and series whose instances are not one series of one
// patient in one stack (tags altered with GDCM, tests/dicom_tags.hpp).

#include "volume_io_test_helpers.hpp"

#include "renderer/io/dicom_child.hpp"
#include "renderer/io/dicom_uncompressed.hpp"
#include "renderer/io/volume_io.hpp"
#include "tests/dicom_tags.hpp"

#include <gtest/gtest.h>
#include <zlib.h>

#include <algorithm>
#include <bit>
#include <cctype>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstring>
#include <chrono>
#include <filesystem>
#include <future>
#include <thread>
#include <fstream>
#include <initializer_list>
#include <limits>
#include <numbers>
#include <sstream>
#include <string>
#include <vector>

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

namespace volcast {
namespace {

using namespace volume_io_test;

TEST_F(VolumeIoTest, DicomSeriesFolder) {
    Volume src;
    src.dims = {6, 5, 4};
    src.spacing = {0.7, 0.8, 2.5};
    src.origin = {-100, -120.5, 50};
    src.voxels.resize(src.voxelCount());
    for (size_t i = 0; i < src.voxels.size(); ++i) src.voxels[i] = float(int(i) * 37 - 1024);  // CT-like int16
    saveDicomSeries(src, dir / "series", VoxelType::Int16);
    size_t files = 0;
    for (const auto &entry : fs::directory_iterator(dir / "series")) files += entry.path().extension() == ".dcm";
    EXPECT_EQ(files, 4u);

    const Volume v = loadVolume(dir / "series");
    EXPECT_EQ(v.name, "series");
    EXPECT_EQ(v.dims, src.dims);
    EXPECT_EQ(v.sourceType, VoxelType::Int16);
    EXPECT_EQ(v.samples().toFloats(), src.voxels);  // int16 values, exact
    EXPECT_EQ(v.narrow.bytes, 2) << "held in 16 bits";
    // DICOM stores decimal strings (10 significant digits here), the z spacing is the
    // distance between slice positions: 1e-6 covers both.
    expectGeometry(v, src.spacing, src.origin, Mat3d::identity(), 1e-6);

    // One file of the series on its own is a one-slice volume at that slice's position.
    const Volume slice = loadVolume(dir / "series" / "slice_0002.dcm");
    EXPECT_EQ(slice.dims, Vec3i(6, 5, 1));
    EXPECT_EQ(slice.samples().toFloats(),
              std::vector<float>(src.voxels.begin() + 60, src.voxels.begin() + 90));
    EXPECT_NEAR(slice.origin.z, 50 + 2 * 2.5, 1e-6);  // decimal string in the file, as above
}

TEST_F(VolumeIoTest, ProgressOfADicomSeriesAdvancesSliceBySlice) {
    Volume src;
    src.dims = {8, 8, 12};
    src.voxels.assign(src.voxelCount(), 100.0f);
    saveDicomSeries(src, dir / "slices", VoxelType::Int16);
    ProgressLog log;
    loadVolume(dir / "slices", log.options());
    log.expectWellFormed();
    std::vector<double> slices;
    for (const auto &[f, task] : log.steps)
        if (task == "reading slices" && (slices.empty() || f > slices.back())) slices.push_back(f);
    EXPECT_GE(slices.size(), 6u) << "12 slices should advance the bar in several steps";
}

TEST_F(VolumeIoTest, DicomFolderWithTwoSeriesIsRefusedCountingThem) {
    // Two series of different sizes in one folder: loading one of them would show a subset of
    // what the folder holds without a word, so the folder is refused, counting the series.
    Volume a, b;
    a.dims = {6, 5, 4};
    b.dims = {3, 3, 2};
    for (Volume *v : {&a, &b}) {
        v->spacing = {1, 1, 2};
        v->voxels.resize(v->voxelCount());
        for (size_t i = 0; i < v->voxels.size(); ++i) v->voxels[i] = float(i) + (v == &a ? 0.0f : 1000.0f);
    }
    saveDicomSeries(a, dir / "both", VoxelType::Int16);
    saveDicomSeries(b, dir / "b", VoxelType::Int16);
    for (const auto &entry : fs::directory_iterator(dir / "b"))
        fs::rename(entry.path(), dir / "both" / ("b_" + entry.path().filename().string()));
    expectLoadError(dir / "both", {"2 series", "2 instances and 4 instances", "one volume shows one series"});
}

TEST_F(VolumeIoTest, FolderWithoutDicom) {
    fs::create_directories(dir / "empty_series");
    writeFile(dir / "empty_series" / "readme.txt", "no images here\n");
    expectLoadError(dir / "empty_series", {"no dicom"});
}

// ---------------------------------------------------------------------------------------
// Damaged DICOM series

// A slice cut short: GDCM would read the missing pixels as zeros.
TEST_F(VolumeIoTest, DicomSeriesWithATruncatedSlice) {
    Volume src;
    src.dims = {6, 5, 4};
    src.voxels.resize(src.voxelCount());
    for (size_t i = 0; i < src.voxels.size(); ++i) src.voxels[i] = float(int(i) * 37 - 1024);
    saveDicomSeries(src, dir / "series", VoxelType::Int16);
    const fs::path slice = dir / "series" / "slice_0002.dcm";
    fs::resize_file(slice, fs::file_size(slice) - 10);
    expectLoadError(dir / "series", {"slice_0002.dcm", "truncated"});
    // The same file on its own, as a one-slice volume.
    expectLoadError(slice, {"truncated"});
}

// A series whose slices do not form one regular stack would load as a picture with the wrong
// geometry and no word of it; the loader refuses it, naming the slices.
Volume obliqueSeriesVolume() {
    Volume src;
    src.dims = {6, 5, 7};
    src.spacing = {0.7, 0.7, 2.5};
    src.origin = {10, -20, 30};
    const double c = std::cos(0.4), s = std::sin(0.4);
    src.direction.m = {c, 0, s, 0, 1, 0, -s, 0, c};
    src.voxels.resize(src.voxelCount());
    for (size_t i = 0; i < src.voxels.size(); ++i) src.voxels[i] = float(int(i) * 37 - 1024);
    return src;
}

TEST_F(VolumeIoTest, DicomSeriesWithAMissingSliceIsRefusedNamingTheGap) {
    saveDicomSeries(obliqueSeriesVolume(), dir / "series", VoxelType::Int16);
    EXPECT_EQ(loadVolume(dir / "series").dims.z, 7) << "the whole oblique stack loads";
    fs::remove(dir / "series" / "slice_0003.dcm");
    expectLoadError(dir / "series", {"slice_0002.dcm", "slice_0004.dcm", "5 mm", "2.5 mm", "missing"});
}

TEST_F(VolumeIoTest, DicomSeriesWithASliceTwiceIsRefused) {
    saveDicomSeries(obliqueSeriesVolume(), dir / "series", VoxelType::Int16);
    fs::copy_file(dir / "series" / "slice_0004.dcm", dir / "series" / "slice_0004_again.dcm");
    expectLoadError(dir / "series", {"instance 5 ('slice_0004_again.dcm')", "same instance as instance 5 ('slice_0004.dcm')",
                                     "sopinstanceuid", "twice"});
}

// ---------------------------------------------------------------------------------------
// Uncompressed series read straight from their files, against GDCM

// The same series through ITK and GDCM: a copy of its folder with a text file beside the
// slices, which GDCM's series scan passes over and the direct reader does not take.
Volume loadThroughGdcm(const fs::path &series, const fs::path &copy) {
    fs::copy(series, copy);
    writeFile(copy / "notes.txt", "not DICOM\n");
    std::string why;
    EXPECT_FALSE(io::scanUncompressedSeries(copy, why)) << "the copy must go through GDCM";
    return loadVolume(copy);
}

// Everything a loaded volume holds but its name. Geometry to 1e-9: both come from the same
// decimal strings, through a few double operations in a different order.
void expectSameVolume(const Volume &direct, const Volume &gdcm, const std::string &what) {
    EXPECT_EQ(direct.dims, gdcm.dims) << what;
    EXPECT_EQ(direct.sourceType, gdcm.sourceType) << what;
    EXPECT_EQ(direct.narrow.bytes, gdcm.narrow.bytes) << what;
    EXPECT_EQ(direct.narrow.offset, gdcm.narrow.offset) << what;
    EXPECT_TRUE(direct.narrowVoxels == gdcm.narrowVoxels) << what << ": the narrow stores differ";
    EXPECT_EQ(direct.voxels, gdcm.voxels) << what;
    expectGeometry(direct, gdcm.spacing, gdcm.origin, gdcm.direction, 1e-9);
    EXPECT_EQ(direct.range.min, gdcm.range.min) << what;
    EXPECT_EQ(direct.range.max, gdcm.range.max) << what;
    EXPECT_EQ(direct.histogram.counts, gdcm.histogram.counts) << what;
    EXPECT_EQ(direct.orientationKnown, gdcm.orientationKnown) << what;
    EXPECT_EQ(direct.modality, gdcm.modality) << what;
    EXPECT_EQ(direct.modalityField, gdcm.modalityField) << what;
    EXPECT_EQ(direct.nonFiniteReplaced, gdcm.nonFiniteReplaced) << what;
}

TEST_F(VolumeIoTest, UncompressedSeriesReadDirectlyEqualsGdcmsRead) {
    struct Case {
        const char *what;
        Volume volume;
        VoxelType type;
    };
    const auto filled = [](Vec3i dims, Vec3d spacing, Mat3d direction, auto value) {
        Volume v;
        v.dims = dims;
        v.spacing = spacing;
        v.origin = {-100.25, 30, 12.5};
        v.direction = direction;
        v.voxels.resize(v.voxelCount());
        for (size_t i = 0; i < v.voxels.size(); ++i) v.voxels[i] = float(value(i));
        return v;
    };
    Mat3d flipX;
    flipX.m = {-1, 0, 0, 0, 1, 0, 0, 0, 1};
    Mat3d flipZ;
    flipZ.m = {1, 0, 0, 0, 1, 0, 0, 0, -1};
    const std::vector<Case> cases = {
        {"CT-like int16, anisotropic pixels",
         filled({6, 5, 4}, {0.7, 0.8, 2.5}, Mat3d::identity(), [](size_t i) { return int(i) * 37 - 1024; }),
         VoxelType::Int16},
        {"oblique int16", obliqueSeriesVolume(), VoxelType::Int16},
        {"rotated about a skew axis, uint16",
         filled({7, 5, 4}, {0.5, 0.5, 1.25}, rotation({0.6, 0.0, 0.8}, 30), [](size_t i) { return int(i) * 523 % 65536; }),
         VoxelType::UInt16},
        {"x flipped (stacked against the normal), int16",
         filled({6, 8, 3}, {1, 1, 2}, flipX, [](size_t i) { return int(i) * 11 - 300; }), VoxelType::Int16},
        {"z flipped, uint8", filled({5, 4, 6}, {1, 1, 1}, flipZ, [](size_t i) { return int(i * 7) % 256; }),
         VoxelType::UInt8},
        {"int16 spanning fewer than 256 values: one byte held",
         filled({6, 5, 4}, {1, 1, 3}, Mat3d::identity(), [](size_t i) { return int(i % 200) - 1000; }),
         VoxelType::Int16},
    };
    int k = 0;
    for (const Case &c : cases) {
        const fs::path series = dir / ("series_" + std::to_string(k)), copy = dir / ("gdcm_" + std::to_string(k));
        ++k;
        saveDicomSeries(c.volume, series, c.type);
        std::string why;
        ASSERT_TRUE(io::scanUncompressedSeries(series, why)) << c.what << ": the direct reader did not take it: " << why;
        const Volume direct = loadVolume(series);
        const Volume gdcm = loadThroughGdcm(series, copy);
        expectSameVolume(direct, gdcm, c.what);
        EXPECT_EQ(direct.samples().toFloats().size(), c.volume.voxelCount()) << c.what;
    }
}

// Gives every slice of a series written by saveDicomSeries a Rescale Intercept: ITK writes
// it as "0" in implicit VR little-endian (tag, a 32-bit length of 2, "0 "), which is replaced.
void setRescaleIntercept(const fs::path &series, std::string value) {
    if (value.size() % 2) value += ' ';   // DICOM values have even lengths
    const std::string written("\x28\x00\x52\x10\x02\x00\x00\x00\x30\x20", 10);
    std::string replaced("\x28\x00\x52\x10", 4);
    replaced += char(value.size());
    replaced += std::string(3, '\0');
    replaced += value;
    for (const auto &entry : fs::directory_iterator(series)) {
        std::string bytes = readFile(entry.path());
        const size_t at = bytes.find(written);
        ASSERT_NE(at, std::string::npos) << entry.path() << " has no Rescale Intercept of 0 where it was expected";
        bytes.replace(at, written.size(), replaced);
        writeFile(entry.path(), bytes);
    }
}

// A CT's stored pixels shifted by its Rescale Intercept (-1024 in most scanners' files): the
// values and the type after rescaling are GDCM's, from 16-bit stored pixels signed or not.
TEST_F(VolumeIoTest, UncompressedSeriesWithAnInterceptEqualsGdcmsRead) {
    for (const VoxelType type : {VoxelType::UInt16, VoxelType::Int16}) {
        Volume v;
        v.dims = {6, 5, 4};
        v.spacing = {0.6, 0.6, 1.5};
        v.voxels.resize(v.voxelCount());
        for (size_t i = 0; i < v.voxels.size(); ++i) v.voxels[i] = float(int(i) * 37 % 4096);
        const std::string name(voxelTypeName(type));
        saveDicomSeries(v, dir / name, type);
        setRescaleIntercept(dir / name, "-1024");
        std::string why;
        ASSERT_TRUE(io::scanUncompressedSeries(dir / name, why)) << name << ": the direct reader did not take it: " << why;
        const Volume direct = loadVolume(dir / name);
        const Volume gdcm = loadThroughGdcm(dir / name, dir / (name + "_gdcm"));
        expectSameVolume(direct, gdcm, name);
        EXPECT_EQ(direct.range.min, -1024.0f) << name;
        EXPECT_EQ(direct.sourceType, VoxelType::Int32) << name << ": 16 stored bits shifted by -1024 fit no 16-bit type";
    }
}

// A header longer than the reader's first read of a file (16 KiB; here a 20 KiB private
// element before the pixel data, as some scanners write) is read again whole and still taken;
// one longer than the second read (256 KiB) goes to GDCM, whose read is the same.
TEST_F(VolumeIoTest, UncompressedSeriesWithLongHeadersEqualsGdcmsRead) {
    for (const uint32_t extra : {20u * 1024u, 300u * 1024u}) {
        const std::string name = "long_" + std::to_string(extra);
        saveDicomSeries(obliqueSeriesVolume(), dir / name, VoxelType::Int16);
        std::string element("\x29\x00\x10\x10", 4);   // (0029,1010), implicit VR: the length follows
        for (int b = 0; b < 4; ++b) element += char((extra >> (8 * b)) & 0xff);
        element += std::string(extra, 'x');
        for (const auto &entry : fs::directory_iterator(dir / name)) {
            std::string bytes = readFile(entry.path());
            const size_t pixels = bytes.rfind(std::string("\xe0\x7f\x10\x00", 4));
            ASSERT_NE(pixels, std::string::npos) << entry.path();
            bytes.insert(pixels, element);
            writeFile(entry.path(), bytes);
        }
        std::string why;
        EXPECT_EQ(bool(io::scanUncompressedSeries(dir / name, why)), extra < 256u * 1024u) << name << ": " << why;
        const Volume read = loadVolume(dir / name);
        expectSameVolume(read, loadThroughGdcm(dir / name, dir / (name + "_gdcm")), name);
    }
}

// 12 of 16 bits stored, as most CT scanners write them: the sample is the low 12 bits,
// sign-extended when signed, whatever the high bits hold; GDCM reads it so, and so must the
// direct reader. ITK writes 16 bits stored, so Bits Stored and High Bit are rewritten.
TEST_F(VolumeIoTest, UncompressedSeriesOfTwelveStoredBitsEqualsGdcmsRead) {
    for (const VoxelType type : {VoxelType::Int16, VoxelType::UInt16}) {
        Volume v;
        v.dims = {6, 5, 4};
        v.voxels.resize(v.voxelCount());
        // Mostly within 12 bits; every seventh sample has high bits set beyond them.
        for (size_t i = 0; i < v.voxels.size(); ++i)
            v.voxels[i] = float(int(i) * 97 % 4096 - (type == VoxelType::Int16 ? 2048 : 0) + (i % 7 == 0 ? 8192 : 0));
        const std::string name(voxelTypeName(type));
        saveDicomSeries(v, dir / name, type);
        const std::string stored("\x28\x00\x01\x01\x02\x00\x00\x00\x10\x00", 10);
        const std::string high("\x28\x00\x02\x01\x02\x00\x00\x00\x0f\x00", 10);
        for (const auto &entry : fs::directory_iterator(dir / name)) {
            std::string bytes = readFile(entry.path());
            const size_t a = bytes.find(stored), b = bytes.find(high);
            ASSERT_TRUE(a != std::string::npos && b != std::string::npos) << entry.path() << ": bits not where expected";
            bytes[a + 8] = 12;
            bytes[b + 8] = 11;
            writeFile(entry.path(), bytes);
        }
        std::string why;
        ASSERT_TRUE(io::scanUncompressedSeries(dir / name, why)) << name << ": " << why;
        const Volume direct = loadVolume(dir / name);
        const Volume gdcm = loadThroughGdcm(dir / name, dir / (name + "_gdcm"));
        expectSameVolume(direct, gdcm, name);
        EXPECT_LE(direct.range.max, 4095.0f) << name << ": 12 bits hold no more";
    }
}

// The checker hands an uncompressed series in a folder back as a plan: where each slice's
// pixels lie, which the caller copies from the files itself. The caller reads a plan as
// untrusted (a checker a hostile file took over could write anything): a slice named outside
// the folder, a FIFO in a slice's place or an offset past a file's end is refused, naming
// the damage, and nothing blocks.
TEST_F(VolumeIoTest, ASeriesPlanFromTheCheckerIsReadAsUntrusted) {
    const fs::path series = dir / "series", plan = dir / "plan.bin";
    saveDicomSeries(obliqueSeriesVolume(), series, VoxelType::Int16);
    writeFile(plan, "");
    const std::string command = std::string("'") + VOLCAST_DICOM_CHECK_BUILD_PATH + "' '" + series.string() +
                                "' 4000000000 4096 60 4000000000 '" + plan.string() + "' plan";
    ASSERT_EQ(std::system(command.c_str()), 0) << command;
    EXPECT_LT(fs::file_size(plan), 1024u) << "a plan of 7 slices, not their samples";
    const std::string original = readFile(plan);
    Volume fromPlan = io::readCheckedVolume(series, plan, LoadOptions{});
    computeStatistics(fromPlan);   // as the load does after reading a hand-back
    expectSameVolume(fromPlan, loadThroughGdcm(series, dir / "gdcm"), "read from the plan");

    const auto refused = [&](const std::string &bytes, const fs::path &folder, bool samples,
                             std::initializer_list<const char *> words) {
        writeFile(plan, bytes);
        try {
            io::readCheckedVolume(folder, plan, LoadOptions{}, samples);
            ADD_FAILURE() << "a damaged plan was read";
        } catch (const VolumeLoadError &e) {
            for (const char *word : words) EXPECT_NE(std::string(e.what()).find(word), std::string::npos) << e.what();
        }
    };
    const auto replaced = [&](const std::string &from, const std::string &to) {
        std::string bytes = original;
        const size_t at = bytes.find(from);
        EXPECT_NE(at, std::string::npos) << from;
        return bytes.replace(at, from.size(), to);
    };
    refused(replaced("slice_0003.dcm", "../outside.dcm"), series, true, {"damaged plan", "outside the folder"});
    ASSERT_EQ(::mkfifo((series / "fifo_xx_03.dcm").c_str(), 0600), 0);
    refused(replaced("slice_0003.dcm", "fifo_xx_03.dcm"), series, true, {"fifo_xx_03.dcm", "no longer holds"});
    // Slice 3's offset: the 8 bytes before its name's length.
    std::string far = original;
    const size_t name = far.find("slice_0003.dcm");
    for (size_t i = name - 12; i < name - 4; ++i) far[i] = char(0xff);
    refused(far, series, true, {"slice_0003.dcm", "no longer holds"});
    refused(original.substr(0, original.size() - 1), series, true, {"damaged plan"});
    refused(original, series, false, {"damaged plan", "samples"});
}

// ---------------------------------------------------------------------------------------
// One series of one patient, one stack (renderer/io/dicom_identity.hpp): checked in the checker
// before either read path, the direct reader's plan and ITK's series reader.

// A series of `slices` slices of `size` x `size` pixels, 2 mm apart from z = z0.
void writeSeries(const fs::path &folder, int64_t slices, int64_t size = 16, double z0 = 0) {
    Volume v;
    v.dims = {size, size, slices};
    v.spacing = {1, 1, 2};
    v.origin = {0, 0, z0};
    v.voxels.resize(v.voxelCount());
    for (size_t i = 0; i < v.voxels.size(); ++i) v.voxels[i] = float(int(i % 500) - 250);
    saveDicomSeries(v, folder, VoxelType::Int16);
}

// Every file of the folder given one study, series and frame of reference (saveDicomSeries
// makes new ones each time), as one series that PACS or scanner put together.
void makeOneSeries(const fs::path &folder) {
    using namespace dicom_tags;
    for (const auto &e : fs::directory_iterator(folder))
        setTags(e.path(), {{kStudyUid, "1.2.826.0.1.3680043.2.1125.1"}, {kSeriesUid, "1.2.826.0.1.3680043.2.1125.1.2"},
                           {kFrameOfReferenceUid, "1.2.826.0.1.3680043.2.1125.1.3"}});
}

// The refusal's message, which must not quote the other patient's name or ID.
void expectNoPatientQuoted(const fs::path &series) {
    try {
        loadVolume(series);
    } catch (const VolumeLoadError &e) {
        const std::string message = e.what();
        EXPECT_EQ(message.find("OTHER-PATIENT-7"), std::string::npos) << "quotes a PatientID: " << message;
        EXPECT_EQ(message.find("Other^Patient"), std::string::npos) << "quotes a PatientName: " << message;
    }
}

TEST_F(VolumeIoTest, ASeriesWithAnotherPatientsInstanceIsRefusedNamingIt) {
    writeSeries(dir / "series", 8);
    ASSERT_EQ(loadVolume(dir / "series").dims.z, 8) << "the clean series loads";
    dicom_tags::makeAnotherPatients(dir / "series" / "slice_0004.dcm");
    expectLoadError(dir / "series", {"instance 5 ('slice_0004.dcm') belongs to another patient",
                                     "patientid differs from the series' first instance, instance 1 ('slice_0000.dcm')"});
    expectNoPatientQuoted(dir / "series");
    // Through ITK's series reader as well (a file beside the slices that the direct reader
    // does not take): the same check, before it.
    fs::copy(dir / "series", dir / "gdcm");
    writeFile(dir / "gdcm" / "notes.txt", "not DICOM\n");
    expectLoadError(dir / "gdcm", {"instance 5 ('slice_0004.dcm') belongs to another patient", "patientid differs"});
}

TEST_F(VolumeIoTest, ASeriesWithAnotherPatientNameOnlyIsRefusedNamingTheField) {
    writeSeries(dir / "series", 4);
    dicom_tags::setTags(dir / "series" / "slice_0000.dcm", {{dicom_tags::kPatientName, "First^Patient"}});
    dicom_tags::setTags(dir / "series" / "slice_0002.dcm", {{dicom_tags::kPatientName, "Other^Patient"}});
    expectLoadError(dir / "series", {"instance 3 ('slice_0002.dcm') belongs to another patient", "patientname differs"});
    expectNoPatientQuoted(dir / "series");
}

TEST_F(VolumeIoTest, ASeriesOfAnotherSeriesThanRequestedIsRefusedNamingIt) {
    writeSeries(dir / "series", 4);
    makeOneSeries(dir / "series");
    LoadOptions asked;
    asked.expectedSeries = SeriesIdentity{"1.2.826.0.1.3680043.2.1125.1", "1.2.826.0.1.3680043.2.1125.1.2"};
    ASSERT_EQ(loadVolume(dir / "series", asked).dims.z, 4) << "the series requested loads";
    asked.expectedSeries->seriesUid = "1.2.826.0.1.3680043.2.1125.1.9";
    expectLoadError(dir / "series", {"instance 1 ('slice_0000.dcm') is not of the requested series",
                                     "seriesinstanceuid"}, asked);
    asked.expectedSeries = SeriesIdentity{"1.2.826.0.1.3680043.2.1125.7", "1.2.826.0.1.3680043.2.1125.1.2"};
    expectLoadError(dir / "series", {"instance 1 ('slice_0000.dcm') is not of the requested study",
                                     "studyinstanceuid"}, asked);
}

TEST_F(VolumeIoTest, ASeriesAlternatingTwoSizesIsRefusedNamingTheStacks) {
    // Slices of 16 x 16 at z = 0, 2, 4, 6 and of 32 x 32 at z = 1, 3, 5, 7, all in one series.
    writeSeries(dir / "series", 4, 16, 0);
    writeSeries(dir / "large", 4, 32, 1);
    for (const auto &e : fs::directory_iterator(dir / "large"))
        fs::rename(e.path(), dir / "series" / ("slice_1" + e.path().filename().string().substr(7)));
    makeOneSeries(dir / "series");
    expectLoadError(dir / "series", {"('slice_1000.dcm') is 32 x 32 pixels where the series' first instance",
                                     "is 16 x 16",
                                     "holds 2 stacks: stack 1 has 4 slices 32 x 32 and stack 2 has 4 slices 16 x 16"});
}

TEST_F(VolumeIoTest, ASeriesWithALocalizerIsRefusedNamingIt) {
    writeSeries(dir / "series", 6, 16);
    writeSeries(dir / "scout", 1, 32);
    fs::rename(dir / "scout" / "slice_0000.dcm", dir / "series" / "slice_scout.dcm");
    makeOneSeries(dir / "series");
    expectLoadError(dir / "series", {"('slice_scout.dcm') is 32 x 32", "2 stacks", "1 slice 32 x 32 (a localizer?)", "6 slices 16 x 16"});
}

// The stacks a refusal offers (SeriesHoldsStacks), or a failure saying why there are none.
std::vector<SeriesStack> offeredStacks(const fs::path &series, const LoadOptions &options = {}) {
    try {
        const Volume v = loadVolume(series, options);
        ADD_FAILURE() << series << " loaded (" << v.dims.z << " slices) but holds several stacks";
    } catch (const SeriesHoldsStacks &e) {
        return e.stacks;
    } catch (const std::exception &e) {
        ADD_FAILURE() << series << " was refused without the stacks it holds: " << e.what();
    }
    return {};
}

std::array<int64_t, 3> dimsOf(const Volume &v) { return {v.dims.x, v.dims.y, v.dims.z}; }

LoadOptions stack(uint32_t number) {
    LoadOptions options;
    options.seriesStack = number;
    return options;
}

TEST_F(VolumeIoTest, ASeriesWithALocalizerOffersItsStacksAndLoadsEachByNumberOnly) {
    writeSeries(dir / "series", 6, 16, 10);
    writeSeries(dir / "scout", 1, 32);
    fs::rename(dir / "scout" / "slice_0000.dcm", dir / "series" / "slice_scout.dcm");
    makeOneSeries(dir / "series");
    EXPECT_EQ(offeredStacks(dir / "series"),
              (std::vector<SeriesStack>{{1, 6, 16, 16, "axial", false}, {2, 1, 32, 32, "axial", true}}));
    expectLoadError(dir / "series", {"holds a localizer besides 6 axial slices: open stack 1 for the 6 slices"});
    const Volume axial = loadVolume(dir / "series", stack(1));
    EXPECT_EQ(dimsOf(axial), (std::array<int64_t, 3>{16, 16, 6})) << "stack 1 is the 6 slices of 16 x 16 and nothing else";
    EXPECT_DOUBLE_EQ(axial.spacing[2], 2) << "their own gap, as written";
    EXPECT_DOUBLE_EQ(axial.origin[2], 10) << "their own first position, as written";
    const Volume scout = loadVolume(dir / "series", stack(2));
    EXPECT_EQ(dimsOf(scout), (std::array<int64_t, 3>{32, 32, 1})) << "stack 2 is the localizer alone";
    // A stack the series does not hold: refused naming how many it holds, offering them again.
    expectLoadError(dir / "series", {"holds 2 stacks, so no stack 3"}, stack(3));
    EXPECT_EQ(offeredStacks(dir / "series", stack(3)).size(), 2u);
    // A volume that is no series has no stacks to choose.
    writeSeries(dir / "single", 4);
    saveVolume(loadVolume(dir / "single"), dir / "head.nrrd");
    expectLoadError(dir / "head.nrrd", {"is not a dicom series"}, stack(1));
}

TEST_F(VolumeIoTest, ASeriesOfTwoOrientationsLoadsEachStackWithItsGeometryOnBothReadPaths) {
    // 6 axial slices (normal +z) and 4 coronal ones (rows along x, columns along -z: normal
    // +y) at y = 0, 3, 6, 9 mm, all of one size in one series.
    writeSeries(dir / "series", 6, 16, 0);
    writeSeries(dir / "coronal", 4, 16, 0);
    int y = 0;
    for (const auto &e : fs::directory_iterator(dir / "coronal")) {
        dicom_tags::setTags(e.path(), {{dicom_tags::kImageOrientation, "1\\0\\0\\0\\0\\-1"},
                                       {dicom_tags::kImagePosition, "0\\" + std::to_string(3 * y++) + "\\0"}});
        fs::rename(e.path(), dir / "series" / ("slice_1" + e.path().filename().string().substr(7)));
    }
    makeOneSeries(dir / "series");
    EXPECT_EQ(offeredStacks(dir / "series"),
              (std::vector<SeriesStack>{{1, 6, 16, 16, "axial", false}, {2, 4, 16, 16, "coronal", false}}));
    expectLoadError(dir / "series", {"is oriented otherwise", "holds 2 stacks", "open one of its stacks"});
    // The direct reader's plan, then ITK's series reader (a file beside the slices that the
    // direct reader does not take).
    fs::copy(dir / "series", dir / "gdcm");
    writeFile(dir / "gdcm" / "notes.txt", "not DICOM\n");
    for (const char *folder : {"series", "gdcm"}) {
        SCOPED_TRACE(folder);
        const Volume axial = loadVolume(dir / folder, stack(1));
        EXPECT_EQ(dimsOf(axial), (std::array<int64_t, 3>{16, 16, 6}));
        EXPECT_NEAR(std::abs(axial.direction(2, 2)), 1, 1e-9) << "stacked along z";
        const Volume coronal = loadVolume(dir / folder, stack(2));
        EXPECT_EQ(dimsOf(coronal), (std::array<int64_t, 3>{16, 16, 4}));
        EXPECT_NEAR(std::abs(coronal.direction(1, 2)), 1, 1e-9) << "stacked along y";
        EXPECT_NEAR(coronal.spacing[2], 3, 1e-9) << "the coronal slices' own gap";
    }
}

TEST_F(VolumeIoTest, AStackOfASeriesIsRefusedWhenAnotherStackBreaksTheSeriesIdentity) {
    writeSeries(dir / "series", 6, 16);
    writeSeries(dir / "scout", 1, 32);
    fs::rename(dir / "scout" / "slice_0000.dcm", dir / "series" / "slice_scout.dcm");
    makeOneSeries(dir / "series");
    ASSERT_EQ(loadVolume(dir / "series", stack(1)).dims.z, 6) << "stack 1 of the clean series loads";
    // The localizer, which stack 1 does not read, is another patient's: the whole series is refused.
    dicom_tags::makeAnotherPatients(dir / "series" / "slice_scout.dcm");
    expectLoadError(dir / "series", {"('slice_scout.dcm') belongs to another patient", "patientid differs"}, stack(1));
    // A selected stack must itself be regular: a slice missing from it is refused as before.
    writeSeries(dir / "gap", 6, 16);
    writeSeries(dir / "scout2", 1, 32);
    fs::rename(dir / "scout2" / "slice_0000.dcm", dir / "gap" / "slice_scout.dcm");
    fs::remove(dir / "gap" / "slice_0003.dcm");
    makeOneSeries(dir / "gap");
    expectLoadError(dir / "gap", {"a slice is missing"}, stack(1));
}

TEST_F(VolumeIoTest, ASeriesWithoutAFiniteOrientationOrPositionIsRefused) {
    writeSeries(dir / "series", 4);
    for (const auto &e : fs::directory_iterator(dir / "series"))
        dicom_tags::setTags(e.path(), {{dicom_tags::kImageOrientation, "NaN\\NaN\\NaN\\NaN\\NaN\\NaN"}});
    expectLoadError(dir / "series", {"instance 1 ('slice_0000.dcm')", "imageorientationpatient",
                                     "not six finite numbers"});
    writeSeries(dir / "placed", 4);
    dicom_tags::setTags(dir / "placed" / "slice_0001.dcm", {{dicom_tags::kImagePosition, "0\\NaN\\2"}});
    expectLoadError(dir / "placed", {"instance 2 ('slice_0001.dcm')", "imagepositionpatient", "not three finite numbers"});
}

TEST_F(VolumeIoTest, ASeriesWithOneSopInstanceUidTwiceIsRefused) {
    writeSeries(dir / "series", 8);
    for (const auto &e : fs::directory_iterator(dir / "series"))
        dicom_tags::setTags(e.path(), {{dicom_tags::kSopInstanceUid, "1.2.826.0.1.3680043.2.1125.5"}});
    expectLoadError(dir / "series", {"instance 2 ('slice_0001.dcm') is the same instance as instance 1",
                                     "sopinstanceuid", "twice"});
}

TEST_F(VolumeIoTest, ASeriesInAnotherFrameOfReferenceIsRefused) {
    writeSeries(dir / "series", 4);
    dicom_tags::setTags(dir / "series" / "slice_0003.dcm",
                        {{dicom_tags::kFrameOfReferenceUid, "1.2.826.0.1.3680043.2.1125.8"}});
    expectLoadError(dir / "series", {"instance 4 ('slice_0003.dcm')", "frameofreferenceuid differs"});
}

// GDCM's series scan splits one series by slice thickness (among others): a series it split
// was loaded as its first part, a silent subset; now it is refused.
TEST_F(VolumeIoTest, ASeriesThatGdcmSplitsIsRefusedRatherThanLoadedInPart) {
    writeSeries(dir / "series", 6);
    dicom_tags::setTags(dir / "series" / "slice_0005.dcm", {{{0x0018, 0x0050}, "9"}});
    expectLoadError(dir / "series", {"slice thickness", "2 stacks"});
}

} // namespace
} // namespace volcast
