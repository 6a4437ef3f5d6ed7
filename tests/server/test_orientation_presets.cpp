// Patient orientation and modality-aware presets, end to end through the loader:
//
// - Files the tests write (DICOM series, NIfTI, NRRD) with identity, flipped and permuted
//   direction matrices hold a head-like body and a bright marker on the patient's
//   left-anterior-superior side. Loaded, framed by the server's starting camera and drawn by
//   the native CPU renderer, the marker must land on the image's right (patient's left) and
//   upper half (superior), and, seen from the patient's left, on the image's left
//   (anterior) — whatever the file's voxel order.
// - The loader says whether a file names its patient space, and reads DICOM's modality.
// - The modality and default preset chosen for synthetic volumes and for the 13 scans in
//   VOLCAST_DATA_DIR (their MANIFEST.md says what each is).

#include "protocol/server_messages.hpp"
#include "renderer/io/volume_io.hpp"
#include "renderer/make_frame_renderer.hpp"
#include "renderer/model/presets.hpp"
#include "server/session_scene.hpp"
#include "server/volume_registry.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <map>
#include <random>
#include <set>
#include <string>

namespace volcast {
namespace {

namespace fs = std::filesystem;

// A temporary folder removed at the end of the test.
struct TempDir {
    fs::path path;
    TempDir() {
        std::random_device rd;
        path = fs::temp_directory_path() / ("volcast-orient-" + std::to_string(rd()) + std::to_string(rd()));
        fs::create_directories(path);
    }
    ~TempDir() {
        std::error_code ec;
        fs::remove_all(path, ec);
    }
};

// Where the marker sits, as a fraction of the body's half-size along each patient axis:
// left (+x), anterior (−y), superior (+z) in LPS.
const Vec3d kMarkerOffset{0.45, -0.45, 0.45};
const Vec3d kBodyHalf{40, 45, 50};   // mm: the body's half-size along x, y, z (patient axes)

// Hounsfield-like values at a world (LPS) position: air, a soft-tissue ellipsoid, and the
// marker ball of bone inside it.
float valueAt(const Vec3d &p) {
    const Vec3d m{kMarkerOffset.x * kBodyHalf.x, kMarkerOffset.y * kBodyHalf.y, kMarkerOffset.z * kBodyHalf.z};
    const Vec3d d = p - m;
    if (d.x * d.x + d.y * d.y + d.z * d.z < 8.0 * 8.0) return 1500;
    const double e = (p.x / kBodyHalf.x) * (p.x / kBodyHalf.x) + (p.y / kBodyHalf.y) * (p.y / kBodyHalf.y) +
                     (p.z / kBodyHalf.z) * (p.z / kBodyHalf.z);
    return e < 1 ? 40.f : -1000.f;
}

// A volume whose index axes are `direction`'s columns (a signed permutation), centred on the
// world origin, sampled from valueAt in world space: the same patient whatever the order.
Volume patientVolume(const Mat3d &direction) {
    Volume v;
    v.spacing = {2, 2, 2};
    v.direction = direction;
    // Samples per index axis: enough to cover the body along the world axis it maps to.
    const Vec3d extent{2 * kBodyHalf.x + 12, 2 * kBodyHalf.y + 12, 2 * kBodyHalf.z + 12};
    for (int a = 0; a < 3; ++a) {
        const Vec3d column{direction(0, a), direction(1, a), direction(2, a)};
        const double along = std::abs(column.x) * extent.x + std::abs(column.y) * extent.y + std::abs(column.z) * extent.z;
        v.dims[a] = int64_t(std::ceil(along / v.spacing[a]));
    }
    v.origin = {0, 0, 0};
    v.origin = Vec3d{0, 0, 0} - (v.worldFromIndex(Vec3d(v.dims - Vec3i{1, 1, 1}) * 0.5));
    v.voxels.resize(v.voxelCount());
    for (int64_t k = 0; k < v.dims.z; ++k)
        for (int64_t j = 0; j < v.dims.y; ++j)
            for (int64_t i = 0; i < v.dims.x; ++i)
                v.voxels[v.index(i, j, k)] = valueAt(v.worldFromIndex({double(i), double(j), double(k)}));
    v.sourceType = VoxelType::Int16;
    computeStatistics(v);
    return v;
}

Mat3d matrix(std::array<double, 9> rows) {
    Mat3d m;
    m.m = rows;
    return m;
}

const std::map<std::string, Mat3d> kDirections = {
    {"identity", Mat3d::identity()},
    // x and z reversed (a scan stored right-to-left and feet-first): determinant +1.
    {"flipped", matrix({-1, 0, 0, 0, 1, 0, 0, 0, -1})},
    // index x along world z (superior), y along x (left), z along y (posterior): det +1.
    {"permuted", matrix({0, 1, 0, 0, 0, 1, 1, 0, 0})},
    // x reversed alone: a left-handed grid, as radiological NIfTI files often are (det −1).
    {"left_handed", matrix({-1, 0, 0, 0, 1, 0, 0, 0, 1})},
};

struct Centroid {
    double x = 0, y = 0, weight = 0;   // image fractions in [0, 1], x right, y down
};

// Where the marker is in the image: the opacity-weighted centre of what the transfer
// function shows (only the bone marker: the body and the air are transparent).
Centroid markerInImage(const Volume &v, const Camera &camera) {
    auto renderer = makeFrameRenderer(DeviceChoice::parse("cpu"), std::make_shared<const Volume>(v));
    TransferFunction tf;
    tf.points = {{0, 0, 0, 0, 0}, {800, 1, 1, 1, 0}, {1200, 1, 1, 1, 1}};
    constexpr int kSide = 64;
    const Image image = renderer->render({tf, camera, kSide, kSide, Quality{}, {}});
    Centroid c;
    for (int y = 0; y < kSide; ++y)
        for (int x = 0; x < kSide; ++x) {
            const double a = image.pixel(x, y)[3];
            c.x += a * (x + 0.5) / kSide;
            c.y += a * (y + 0.5) / kSide;
            c.weight += a;
        }
    if (c.weight > 0) {
        c.x /= c.weight;
        c.y /= c.weight;
    }
    return c;
}

// From the patient's left (+x), head up: anterior (−y) is on the image's left.
Camera fromPatientsLeft(const Camera &start) {
    Camera c = start;
    const Vec3d d = start.eye - start.target;
    const double distance = std::sqrt(d.x * d.x + d.y * d.y + d.z * d.z);
    c.eye = start.target + Vec3d{distance, 0, 0};
    c.up = {0, 0, 1};
    return c;
}

// The checks of the file's description, for every format and direction.
void expectMarkerOnPatientsLeftAnteriorSuperior(const Volume &loaded, const std::string &what) {
    SCOPED_TRACE(what);
    ASSERT_TRUE(loaded.orientationKnown) << what << ": the loader lost the patient space";
    const Camera start = server::defaultCamera(loaded, false);
    const Centroid front = markerInImage(loaded, start);
    // The marker ball (8 mm radius in a body about 100 mm across, in a view framing the
    // whole volume) covers about 20 pixels of the 64² image; 5 pixels' worth of opacity
    // means it was hit, and nothing else in the volume is visible to give opacity.
    ASSERT_GT(front.weight, 5) << "the marker is not in the starting view";
    // Patient's left on the image's right (radiology's anterior view), superior up. The
    // marker sits 0.45 of the half-size off-centre: its image offset is about 0.15 of the
    // image, so 0.05 leaves room for the perspective and the slightly oblique start.
    EXPECT_GT(front.x, 0.55) << "marker (patient's left) should be right of centre; at x " << front.x;
    EXPECT_LT(front.y, 0.45) << "marker (superior) should be above the centre; at y " << front.y;
    const Centroid side = markerInImage(loaded, fromPatientsLeft(start));
    ASSERT_GT(side.weight, 5) << "the marker is not in the view from the patient's left";
    EXPECT_LT(side.x, 0.45) << "from the patient's left, the marker (anterior) should be left of centre; at x "
                            << side.x;
    EXPECT_LT(side.y, 0.45) << "from the patient's left, the marker (superior) should be up; at y " << side.y;
}

TEST(PatientOrientation, NrrdNiftiAndDicomOpenFacingThePatientWhateverTheVoxelOrder) {
    TempDir dir;
    for (const auto &[name, direction] : kDirections) {
        const Volume v = patientVolume(direction);
        const fs::path nrrd = dir.path / (name + ".nrrd"), nifti = dir.path / (name + ".nii.gz"),
                       dicom = dir.path / (name + "_dicom");
        saveVolume(v, nrrd, {VoxelType::Int16, false});
        saveVolume(v, nifti, {VoxelType::Int16, false});
        saveDicomSeries(v, dicom, VoxelType::Int16);
        for (const fs::path &file : {nrrd, nifti, dicom}) {
            const Volume loaded = loadVolume(file);
            expectMarkerOnPatientsLeftAnteriorSuperior(loaded, file.filename().string() + " (" + name + ")");
        }
    }
}

TEST(PatientOrientation, TheStartingViewIsTheSameForEveryVoxelOrder) {
    // The rendered images of one patient stored three ways agree: the starting camera is a
    // function of the patient, not of the file's index axes.
    std::map<std::string, Centroid> seen;
    for (const auto &[name, direction] : kDirections) {
        Volume v = patientVolume(direction);
        v.orientationKnown = true;
        seen[name] = markerInImage(v, server::defaultCamera(v, false));
    }
    for (const auto &[name, c] : seen) {
        // One 64-pixel image: the centroids agree within a pixel's width (the voxel grids
        // sample the ball at different points).
        EXPECT_NEAR(c.x, seen["identity"].x, 1.0 / 64) << name;
        EXPECT_NEAR(c.y, seen["identity"].y, 1.0 / 64) << name;
    }
}

TEST(PatientOrientation, TheLoaderSaysWhetherTheFileNamesItsPatientSpace) {
    TempDir dir;
    const Volume v = patientVolume(Mat3d::identity());
    saveVolume(v, dir.path / "a.nrrd", {VoxelType::Int16, false});
    saveVolume(v, dir.path / "a.nii", {VoxelType::Int16, false});
    saveVolume(v, dir.path / "a.mha", {VoxelType::Int16, false});
    saveDicomSeries(v, dir.path / "dicom", VoxelType::Int16);
    EXPECT_TRUE(loadVolume(dir.path / "a.nrrd").orientationKnown) << "ITK writes NRRD with `space`";
    EXPECT_TRUE(loadVolume(dir.path / "a.nii").orientationKnown) << "ITK writes NIfTI with a qform code";
    EXPECT_FALSE(loadVolume(dir.path / "a.mha").orientationKnown) << "a MetaImage names no patient space";
    const Volume dicom = loadVolume(dir.path / "dicom");
    EXPECT_TRUE(dicom.orientationKnown);
    EXPECT_EQ(dicom.modality, "CT") << "saveDicomSeries writes CT Image Storage";

    // An NRRD header without `space` (as every scan in the shared data folder is).
    {
        std::ofstream raw(dir.path / "plain.raw", std::ios::binary);
        const std::vector<int16_t> zeros(8 * 8 * 8, 0);
        raw.write(reinterpret_cast<const char *>(zeros.data()), std::streamsize(zeros.size() * 2));
        std::ofstream(dir.path / "plain.nhdr") << "NRRD0004\ntype: int16\ndimension: 3\nsizes: 8 8 8\n"
                                                  "spacings: 1 1 1\nendian: little\nencoding: raw\n"
                                                  "data file: plain.raw\n\n";
    }
    const Volume plain = loadVolume(dir.path / "plain.nhdr");
    EXPECT_FALSE(plain.orientationKnown) << "no `space` field: the axes are the file's own";
    EXPECT_EQ(plain.modality, "");
}

TEST(PatientOrientation, TheVolumeInfoCarriesTheDirectionMatrix) {
    // Clients place the volume's box from dims, spacing, origin and direction (the clip
    // slider's range): without the direction, a flipped or permuted file's box lies elsewhere.
    Mat3d permuted;   // index i runs along −z, j along +x, k along −y
    permuted.m = {0, 1, 0, 0, 0, -1, -1, 0, 0};
    server::VolumeEntry entry;
    entry.name = "permuted";
    entry.volume = std::make_shared<const Volume>(patientVolume(permuted));
    const protocol::VolumeInfo info = entry.info();
    ASSERT_TRUE(info.direction.has_value());
    for (int r = 0; r < 3; ++r)
        for (int c = 0; c < 3; ++c) EXPECT_EQ((*info.direction)[size_t(r)][size_t(c)], permuted(r, c)) << r << "," << c;
}

TEST(PatientOrientation, TheVolumeInfoTellsTheClient) {
    TempDir dir;
    const Volume v = patientVolume(Mat3d::identity());
    saveVolume(v, dir.path / "a.mha", {VoxelType::Int16, false});
    saveDicomSeries(v, dir.path / "dicom", VoxelType::Int16);
    for (const auto &[file, known] : {std::pair{"a.mha", false}, std::pair{"dicom", true}}) {
        server::VolumeEntry entry;
        entry.name = file;
        entry.volume = std::make_shared<const Volume>(loadVolume(dir.path / file));
        const protocol::VolumeInfo info = entry.info();
        ASSERT_TRUE(info.orientationKnown.has_value()) << file;
        EXPECT_EQ(*info.orientationKnown, known) << file;
        ASSERT_TRUE(info.modality.has_value()) << file;
        EXPECT_EQ(info.modality->name, "CT") << file << ": " << info.modality->reason;
        // The JSON form round-trips through the protocol's reader (what scripted clients read).
        protocol::StateMessage state;
        state.volume = info;
        const std::string json = protocol::toJsonText(state);
        const auto back = std::get<protocol::StateMessage>(protocol::parseServerMessage(json));
        EXPECT_EQ(back.volume, info) << json;
    }
}

// --- modality and presets -----------------------------------------------------------------

Volume synthetic(VoxelType type, std::vector<float> values) {
    Volume v;
    v.dims = {int64_t(values.size()), 1, 1};
    v.voxels = std::move(values);
    v.sourceType = type;
    computeStatistics(v);
    return v;
}

TEST(ModalityPresets, DicomModalityWinsOverInference) {
    Volume v = synthetic(VoxelType::UInt8, {0, 10, 200, 255});
    v.modality = "MR";
    const ModalityChoice c = chooseModality(v, "series");
    EXPECT_EQ(c.modality, "MR");
    EXPECT_EQ(c.source, "file");
    EXPECT_EQ(c.defaultPreset, "mr.t1_brain");
    EXPECT_NE(c.reason.find("DICOM"), std::string::npos) << c.reason;
    v.modality = "PT";
    EXPECT_EQ(chooseModality(v, "series").modality, "micro-CT") << "a modality without presets of its own";
}

TEST(ModalityPresets, SignedValuesWithAirNearMinus1000AreCtInHounsfieldUnits) {
    std::vector<float> values(1000, -1000.f);
    for (size_t i = 0; i < 600; ++i) values[i] = float(i % 3 == 0 ? 40 : (i % 3 == 1 ? 700 : -100));
    const Volume ct = synthetic(VoxelType::Int16, values);
    const ModalityChoice c = chooseModality(ct, "scan.nrrd");
    EXPECT_EQ(c.modality, "CT") << c.reason;
    EXPECT_EQ(c.source, "inferred");
    EXPECT_EQ(c.defaultPreset, "ct.bone");
    EXPECT_NE(c.reason.find("-1000"), std::string::npos) << "the reason names the air: " << c.reason;
    // The same values, unsigned and shifted (a raw CT without its rescale), are not HU.
    std::vector<float> shifted = values;
    for (float &x : shifted) x += 1024;
    EXPECT_NE(chooseModality(synthetic(VoxelType::UInt16, shifted), "scan.nrrd").modality, "CT");
}

TEST(ModalityPresets, CtPresetsCarryTheRadiologyWindowsAndShading) {
    std::vector<float> values(1000, -1000.f);
    for (size_t i = 0; i < 500; ++i) values[i] = 1000;
    const Volume ct = synthetic(VoxelType::Int16, values);
    const auto presets = presetsFor(ct, chooseModality(ct, "head"));
    std::map<std::string, ResolvedPreset> byName;
    for (const auto &p : presets) byName[p.name] = p;
    ASSERT_EQ(presets.front().name, "ct.bone") << "the default comes first";
    const std::map<std::string, std::pair<double, double>> windows = {
        {"ct.bone", {2000, 400}}, {"ct.soft_tissue", {400, 40}}, {"ct.lung", {1500, -600}}, {"ct.angiography", {600, 300}}};
    for (const auto &[name, wl] : windows) {
        ASSERT_TRUE(byName.count(name)) << name;
        const ResolvedPreset &p = byName[name];
        EXPECT_EQ(p.window, wl.first) << name;
        EXPECT_EQ(p.level, wl.second) << name;
        // The points span exactly the window (what the web client reads as window/level).
        EXPECT_DOUBLE_EQ(p.points.front()[0], wl.second - wl.first / 2) << name;
        EXPECT_DOUBLE_EQ(p.points.back()[0], wl.second + wl.first / 2) << name;
        TransferFunction tf;
        for (const auto &q : p.points) tf.points.push_back({q[0], q[1], q[2], q[3], q[4]});
        EXPECT_NO_THROW(tf.validate()) << name;
        // Air is never visible: the opacity at -1000 HU is 0 in every CT preset.
        EXPECT_EQ(tf.evaluate(-1000).a, 0) << name;
    }
    EXPECT_TRUE(byName["ct.bone"].shading);
    EXPECT_TRUE(byName["ct.angiography"].shading);
}

TEST(ModalityPresets, GreyValuePresetsSitOnTheRobustRangeAboveTheBackground) {
    // 90 % background zeros, tissue 20 … 120, one hot voxel at 4000: the robust range is the
    // tissue's, not [0, 4000].
    std::vector<float> values(10000, 0.f);
    for (size_t i = 0; i < 1000; ++i) values[i] = float(20 + i % 101);
    values[5000] = 4000;
    const Volume mr = synthetic(VoxelType::UInt16, values);
    const ValueRange r = robustRange(mr);
    // Histogram bins are 4000/256 ≈ 15.6 wide: the percentiles are within a bin of 20 and 120.
    EXPECT_NEAR(r.min, 20, 16);
    EXPECT_NEAR(r.max, 120, 16);
    const ModalityChoice c = chooseModality(mr, "subject01_t1.nii");
    EXPECT_EQ(c.modality, "MR") << c.reason;
    EXPECT_NE(c.reason.find("'t1'"), std::string::npos) << c.reason;
    const auto presets = presetsFor(mr, c);
    ASSERT_FALSE(presets.empty());
    EXPECT_EQ(presets.front().name, "mr.t1_brain");
    EXPECT_LT(presets.front().points.back()[0], 200) << "placed on the robust range, not the hot voxel";
}

TEST(ModalityPresets, TheNameMayAskForAngiography) {
    const Volume v = synthetic(VoxelType::UInt8, {0, 0, 0, 10, 100, 200, 255});
    const ModalityChoice c = chooseModality(v, "head_cta.nrrd");
    EXPECT_EQ(c.modality, "CT") << c.reason;
    EXPECT_FALSE(c.hounsfield) << "8-bit values are grey values";
    EXPECT_EQ(c.defaultPreset, "ct.angiography") << c.reason;
    EXPECT_NE(c.reason.find("'cta'"), std::string::npos) << c.reason;
    const Volume unnamed = synthetic(VoxelType::UInt8, {0, 0, 0, 10, 100, 200, 255});
    EXPECT_EQ(chooseModality(unnamed, "head_aneurysm.nrrd").defaultPreset, "micro_ct.vessels")
        << "angiography without a modality word: the grey-value vessels preset";
}

// Points of a preset as a transfer function (what the client sends).
TransferFunction curveOf(const ResolvedPreset &p) {
    TransferFunction tf;
    for (const auto &q : p.points) tf.points.push_back({q[0], q[1], q[2], q[3], q[4]});
    return tf;
}

TEST(ModalityPresets, EveryPresetOfEveryModalityIsResolvedTheDefaultFirst) {
    std::vector<float> values(1000, -1000.f);
    for (size_t i = 0; i < 500; ++i) values[i] = float(i % 2 ? 40 : 1000);
    const Volume ct = synthetic(VoxelType::Int16, values);
    const ModalityChoice c = chooseModality(ct, "head");
    ASSERT_TRUE(c.hounsfield) << c.reason;
    const auto presets = presetsFor(ct, c);
    const std::vector<std::string> all = {"ct.bone",     "ct.soft_tissue", "ct.lung",         "ct.angiography",
                                          "mr.t1_brain", "mr.t2_brain",    "mr.angiography",  "micro_ct.default",
                                          "micro_ct.vessels"};
    std::set<std::string> names;
    for (const auto &p : presets) names.insert(p.name);
    EXPECT_EQ(names, std::set<std::string>(all.begin(), all.end())) << "every preset, whatever the modality";
    EXPECT_EQ(presets.size(), all.size()) << "each once";
    EXPECT_EQ(presets.front().name, c.defaultPreset);
    EXPECT_EQ(modalitiesFor(c), (std::vector<std::string>{"CT", "MR", "micro-CT"}));
    // Grouped by modality, the chosen one first, each modality's default first of its own.
    std::vector<std::string> order;
    for (const auto &p : presets) {
        EXPECT_FALSE(p.modality.empty()) << p.name;
        if (order.empty() || order.back() != p.modality) order.push_back(p.modality);
    }
    EXPECT_EQ(order, modalitiesFor(c)) << "one block per modality";
    // The MR presets of a CT sit on its robust range (grey values), the CT ones in HU.
    for (const auto &p : presets) {
        EXPECT_NO_THROW(curveOf(p).validate()) << p.name;
        if (p.modality == "CT") {
            EXPECT_EQ(p.label.find("grey"), std::string::npos) << p.label;
        }
    }

    // An MR volume lists MR first and still reaches the CT presets, in its grey values.
    const Volume mr = synthetic(VoxelType::UInt8, {0, 0, 0, 30, 60, 90, 120, 150});
    const ModalityChoice m = chooseModality(mr, "subject_t2.nii");
    EXPECT_EQ(m.modality, "MR");
    EXPECT_EQ(modalitiesFor(m), (std::vector<std::string>{"MR", "CT", "micro-CT"}));
    const auto mrPresets = presetsFor(mr, m);
    EXPECT_EQ(mrPresets.size(), all.size());
    EXPECT_EQ(mrPresets.front().modality, "MR");
    for (const auto &p : mrPresets) {
        if (p.modality == "CT") {
            EXPECT_NE(p.label.find("grey values"), std::string::npos) << p.label;
        }
    }
}

TEST(ModalityPresets, GreyValueCtGetsTheCtWindowsOnItsRobustRange) {
    // 8-bit CT: background zeros, tissue 1 … 250. The robust range maps onto −1000 … +1000 HU
    // (presets.hpp), so each CT window lands at a closed-form place.
    std::vector<float> values(20000, 0.f);
    for (size_t i = 0; i < 10000; ++i) values[i] = float(1 + i % 250);
    const Volume v = synthetic(VoxelType::UInt8, values);
    const ModalityChoice c = chooseModality(v, "chest_ct.nrrd");
    EXPECT_EQ(c.modality, "CT") << c.reason;
    EXPECT_FALSE(c.hounsfield);
    EXPECT_EQ(c.defaultPreset, "ct.bone");
    const ValueRange r = robustRange(v);
    const double span = double(r.max) - double(r.min);
    std::map<std::string, ResolvedPreset> byName;
    for (const auto &p : presetsFor(v, c)) byName[p.name] = p;
    const std::map<std::string, std::pair<double, double>> windows = {
        {"ct.bone", {2000, 400}}, {"ct.soft_tissue", {400, 40}}, {"ct.lung", {1500, -600}}, {"ct.angiography", {600, 300}}};
    for (const auto &[name, wl] : windows) {
        const ResolvedPreset &p = byName.at(name);
        // Doubles of one linear map: equal to rounding (1e-9 relative).
        EXPECT_NEAR(p.window, wl.first / 2000 * span, 1e-9 * span) << name;
        EXPECT_NEAR(p.level, r.min + (wl.second + 1000) / 2000 * span, 1e-9 * span) << name;
        EXPECT_NE(p.label.find("grey values"), std::string::npos) << p.label;
        EXPECT_EQ(curveOf(p).evaluate(0).a, 0) << name << ": the background (air) is never visible";
    }
}

// An NRRD header over 8³ int16 zeros but for a bright cube, with `extra` header lines.
// `attached`: one .nrrd holding its data, as a file from outside must (an upload).
fs::path writeNrrd(const fs::path &dir, const std::string &name, const std::string &extra, bool attached = false) {
    std::vector<int16_t> values(8 * 8 * 8, 0);
    for (size_t i = 0; i < values.size(); i += 3) values[i] = 200;
    const fs::path file = dir / (name + (attached ? ".nrrd" : ".nhdr"));
    std::ofstream(file) << "NRRD0004\ntype: int16\ndimension: 3\nsizes: 8 8 8\n"
                           "spacings: 1 1 1\nendian: little\nencoding: raw\n"
                        << extra << (attached ? "" : "data file: " + name + ".raw\n") << "\n";
    const auto dataMode = std::ios::binary | (attached ? std::ios::app : std::ios::trunc);
    std::ofstream(attached ? file : dir / (name + ".raw"), dataMode)
        .write(reinterpret_cast<const char *>(values.data()), std::streamsize(values.size() * 2));
    return file;
}

TEST(ModalityPresets, TheFileStatesTheModalityBeforeAnyGuess) {
    TempDir dir;
    // The names say nothing or the opposite: the header wins.
    const Volume keyed = loadVolume(writeNrrd(dir.path, "scan_ct", "modality:=MR\n"));
    EXPECT_EQ(keyed.modality, "MR");
    EXPECT_EQ(keyed.modalityField, "NRRD key");
    ModalityChoice c = chooseModality(keyed, "scan_ct.nhdr");
    EXPECT_EQ(c.modality, "MR") << c.reason;
    EXPECT_EQ(c.source, "file");
    EXPECT_NE(c.reason.find("NRRD"), std::string::npos) << c.reason;

    const Volume content = loadVolume(writeNrrd(dir.path, "scan_mr", "content: CT angiography of the head\n"));
    EXPECT_EQ(content.modalityField, "NRRD content");
    c = chooseModality(content, "scan_mr.nhdr");
    EXPECT_EQ(c.modality, "CT") << c.reason;
    EXPECT_EQ(c.source, "file");
    EXPECT_FALSE(c.hounsfield) << "no air near -1000: grey values";
    EXPECT_EQ(c.defaultPreset, "ct.angiography") << c.reason;
    EXPECT_NE(c.reason.find("content"), std::string::npos) << c.reason;

    // A description naming no modality leaves the choice to the name and statistics.
    const Volume vague = loadVolume(writeNrrd(dir.path, "plain", "content: volume 3\n"));
    EXPECT_EQ(chooseModality(vague, "plain.nhdr").source, "inferred");

    // NIfTI: the 80-byte `descrip` at byte 148 of the header (NIfTI-1).
    const Volume v = patientVolume(Mat3d::identity());
    saveVolume(v, dir.path / "a.nii", {VoxelType::Int16, false});
    {
        std::fstream f(dir.path / "a.nii", std::ios::in | std::ios::out | std::ios::binary);
        char descrip[80] = {};
        std::snprintf(descrip, sizeof descrip, "T1 MPRAGE sagittal");
        f.seekp(148);
        f.write(descrip, sizeof descrip);
    }
    const Volume nifti = loadVolume(dir.path / "a.nii");
    EXPECT_EQ(nifti.modalityField, "NIfTI descrip");
    EXPECT_EQ(nifti.modality, "T1 MPRAGE sagittal");
    c = chooseModality(nifti, "a.nii");
    EXPECT_EQ(c.modality, "MR") << c.reason;
    EXPECT_EQ(c.source, "file");
}

TEST(ModalityPresets, TheModalityTravelsThroughTheParserProcess) {
    // A file parsed in the separate checker process hands its modality statement back.
    TempDir dir;
    const fs::path file = writeNrrd(dir.path, "checked", "content: MRI of the knee\n", true);
    LoadOptions options;
    options.parseInChild = true;
    const Volume checked = loadVolume(file, options);
    EXPECT_EQ(checked.modality, "MRI of the knee");
    EXPECT_EQ(checked.modalityField, "NRRD content");
}

// The 13 scans of the shared data folder (MANIFEST.md): what each is and what it should
// open on. None carries a modality or a patient space, so all of it is inferred.
TEST(ModalityPresets, TheSharedScansOpenOnTheirModalitysPreset) {
    const char *dataDir = std::getenv("VOLCAST_DATA_DIR");
    if (!dataDir || !fs::is_directory(dataDir)) GTEST_SKIP() << "VOLCAST_DATA_DIR is not set to the scans' folder";
    const std::map<std::string, std::pair<std::string, std::string>> expected = {
        {"cranium_ct.nhdr", {"CT", "ct.bone"}},               // int16 HU, air at -1024
        {"headsq.nhdr", {"micro-CT", "micro_ct.default"}},    // int16 from 0: not HU, the name says nothing
        {"lidc2_chest_ct.nhdr", {"CT", "ct.bone"}},           // 8-bit windowed CT: CT presets in grey values
        {"aneurism.nhdr", {"micro-CT", "micro_ct.vessels"}},  // rotational angiography, 8-bit
        {"avm_cta.nhdr", {"CT", "ct.angiography"}},           // 8-bit CT angiography
        {"stent_ct.nhdr", {"CT", "ct.bone"}},                 // int16 0 … 2000, not HU
        {"bonsai.nhdr", {"micro-CT", "micro_ct.default"}},
        {"engine.nhdr", {"micro-CT", "micro_ct.default"}},
        {"tooth.nhdr", {"micro-CT", "micro_ct.default"}},
        {"iguana_microct.nhdr", {"micro-CT", "micro_ct.default"}},
        {"colin27_mr_t1.nhdr", {"MR", "mr.t1_brain"}},
        {"head_mr_volume.nhdr", {"MR", "mr.t1_brain"}},
        {"carotid_float.nhdr", {"MR", "mr.angiography"}},    // float flow data, "carotid"
    };
    for (const auto &[file, want] : expected) {
        const Volume v = loadVolume(fs::path(dataDir) / file);
        const ModalityChoice c = chooseModality(v, file);
        std::cout << file << ": " << c.modality << ", " << c.defaultPreset << " — " << c.reason << "\n";
        EXPECT_FALSE(v.orientationKnown) << file << ": no header in the folder has `space`";
        EXPECT_EQ(c.modality, want.first) << file << ": " << c.reason;
        EXPECT_EQ(c.defaultPreset, want.second) << file << ": " << c.reason;
        const auto presets = presetsFor(v, c);
        ASSERT_FALSE(presets.empty()) << file;
        for (const auto &p : presets) EXPECT_NO_THROW(curveOf(p).validate()) << file << " " << p.name;
    }
}

TEST(ModalityPresets, TheLungPresetShowsTheLungsOfTheEightBitChestCt) {
    // lidc2_chest_ct (MANIFEST.md): air is 0, the lungs the histogram's peak between 1 and 60,
    // soft tissue its peak between 100 and 160. The lung preset makes the lungs visible and
    // leaves air and soft tissue clear.
    const char *dataDir = std::getenv("VOLCAST_DATA_DIR");
    if (!dataDir || !fs::is_directory(dataDir)) GTEST_SKIP() << "VOLCAST_DATA_DIR is not set to the scans' folder";
    const Volume v = loadVolume(fs::path(dataDir) / "lidc2_chest_ct.nhdr");
    const ModalityChoice c = chooseModality(v, "lidc2_chest_ct.nhdr");
    ASSERT_EQ(c.modality, "CT") << c.reason;
    const auto peak = [&](int lo, int hi) {   // bins are one grey value wide (range 0 … 255)
        int best = lo;
        for (int i = lo; i <= hi; ++i)
            if (v.histogram.counts[size_t(i)] > v.histogram.counts[size_t(best)]) best = i;
        return double(best);
    };
    const double lung = peak(1, 60), soft = peak(100, 160);
    ResolvedPreset lungPreset;
    for (const auto &p : presetsFor(v, c))
        if (p.name == "ct.lung") lungPreset = p;
    ASSERT_FALSE(lungPreset.points.empty());
    const TransferFunction tf = curveOf(lungPreset);
    std::cout << "lung peak " << lung << ", soft-tissue peak " << soft << ", lung window " << lungPreset.window
              << " / " << lungPreset.level << "\n";
    EXPECT_GT(tf.evaluate(lung).a, 0.02) << "the lungs are visible";
    EXPECT_EQ(tf.evaluate(0).a, 0) << "air is clear";
    EXPECT_EQ(tf.evaluate(soft).a, 0) << "soft tissue is clear";
}

} // namespace
} // namespace volcast
