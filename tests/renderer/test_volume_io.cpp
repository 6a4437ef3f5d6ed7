// Tests of the volume loader (renderer/io/volume_io.cpp): the real scans of MANIFEST.md, every
// format and voxel type written by the test itself, damaged files, and the NaN/Inf policy.

#include "renderer/io/volume_io.hpp"

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

namespace fs = std::filesystem;

// The real scans (MANIFEST.md there) live outside the repository: the CMake variable or
// environment variable VOLCAST_DATA_DIR names their folder (tests/README.md). Without it the
// tests that read them skip and say why; every other test here makes its files itself.
const fs::path kDataDir = VOLCAST_DATA_DIR;

#define SKIP_WITHOUT_SCANS()                                                                   \
    if (!fs::is_regular_file(kDataDir / "MANIFEST.md"))                                       \
    GTEST_SKIP() << "needs the real scans, and " << kDataDir.string() << " has no MANIFEST.md: " \
                 << "configure with -DVOLCAST_DATA_DIR=/path/to/scans (tests/README.md)"

static_assert(std::endian::native == std::endian::little, "the byte-order helpers assume a little-endian host");

// ---------------------------------------------------------------------------------------
// Helpers

std::string lowerCase(std::string s) {
    std::transform(s.begin(), s.end(), s.begin(), [](unsigned char c) { return char(std::tolower(c)); });
    return s;
}

std::string readFile(const fs::path &p) {
    std::ifstream in(p, std::ios::binary);
    std::ostringstream ss;
    ss << in.rdbuf();
    return ss.str();
}

void writeFile(const fs::path &p, const std::string &bytes) {
    std::ofstream out(p, std::ios::binary);
    out.write(bytes.data(), std::streamsize(bytes.size()));
}

// SHA-256 through coreutils' sha256sum (no home-made hash).
std::string sha256(const std::string &bytes) {
    const fs::path file = fs::temp_directory_path() / ("volcast_io_sha_" + std::to_string(getpid()));
    writeFile(file, bytes);
    std::string out;
    if (FILE *pipe = popen(("sha256sum '" + file.string() + "'").c_str(), "r")) {
        char buf[128] = {};
        if (std::fgets(buf, sizeof buf, pipe)) out = buf;
        pclose(pipe);
    }
    fs::remove(file);
    return out.substr(0, std::min<size_t>(64, out.size()));
}

// One gzip stream (zlib's deflate with a gzip wrapper), as NRRD's "encoding: gzip" wants.
std::string gzipBytes(const std::string &in) {
    z_stream zs{};
    EXPECT_EQ(deflateInit2(&zs, Z_DEFAULT_COMPRESSION, Z_DEFLATED, 15 + 16, 8, Z_DEFAULT_STRATEGY), Z_OK);
    std::string out(deflateBound(&zs, uLong(in.size())) + 64, '\0');
    zs.next_in = reinterpret_cast<Bytef *>(const_cast<char *>(in.data()));
    zs.avail_in = uInt(in.size());
    zs.next_out = reinterpret_cast<Bytef *>(out.data());
    zs.avail_out = uInt(out.size());
    EXPECT_EQ(deflate(&zs, Z_FINISH), Z_STREAM_END);
    out.resize(zs.total_out);
    deflateEnd(&zs);
    return out;
}

template <typename T>
void appendScalar(std::string &out, T value, bool bigEndian) {
    char b[sizeof(T)];
    std::memcpy(b, &value, sizeof(T));
    if (bigEndian) std::reverse(b, b + sizeof(T));
    out.append(b, sizeof(T));
}

template <typename F>
void withType(VoxelType t, F &&f) {
    switch (t) {
    case VoxelType::UInt8: f(uint8_t{}); break;
    case VoxelType::Int8: f(int8_t{}); break;
    case VoxelType::UInt16: f(uint16_t{}); break;
    case VoxelType::Int16: f(int16_t{}); break;
    case VoxelType::UInt32: f(uint32_t{}); break;
    case VoxelType::Int32: f(int32_t{}); break;
    case VoxelType::Float32: f(float{}); break;
    case VoxelType::Float64: f(double{}); break;
    }
}

// Values stored as `t`, in the given byte order.
std::string encode(VoxelType t, const std::vector<double> &values, bool bigEndian) {
    std::string out;
    withType(t, [&](auto tag) {
        using T = decltype(tag);
        for (double x : values) appendScalar(out, T(x), bigEndian);
    });
    return out;
}

// Loaded float voxels converted back to their native type, in the given byte order.
std::string nativeBytes(const Volume &v, bool bigEndian) {
    const std::vector<float> samples = v.samples().toFloats();
    return encode(v.sourceType, {samples.begin(), samples.end()}, bigEndian);
}

const char *nrrdTypeName(VoxelType t) {
    switch (t) {
    case VoxelType::UInt8: return "uint8";
    case VoxelType::Int8: return "int8";
    case VoxelType::UInt16: return "uint16";
    case VoxelType::Int16: return "int16";
    case VoxelType::UInt32: return "uint32";
    case VoxelType::Int32: return "int32";
    case VoxelType::Float32: return "float";
    case VoxelType::Float64: return "double";
    }
    return "?";
}

// Test values for a 5 x 4 x 3 volume of type t: the type's extremes first (sign and width
// handling), then a ramp inside the range; every value but float64's is exact in float32.
std::vector<double> testValues(VoxelType t, size_t count) {
    std::vector<double> v(count);
    for (size_t i = 0; i < count; ++i) {
        const double x = double(i);
        switch (t) {
        case VoxelType::Int8: v[i] = -30 + x; break;
        case VoxelType::UInt8: v[i] = 1 + 3 * x; break;
        case VoxelType::Int16: v[i] = -20000 + 601 * x; break;
        case VoxelType::UInt16: v[i] = 7 + 1000 * x; break;
        case VoxelType::Int32: v[i] = -1000000 + 33333 * x; break;
        case VoxelType::UInt32: v[i] = 16000000 + 3 * x; break;
        case VoxelType::Float32: v[i] = -1.5 + 0.25 * x; break;
        case VoxelType::Float64: v[i] = -2 + x / 3; break;
        }
    }
    withType(t, [&](auto tag) {
        using T = decltype(tag);
        if constexpr (std::is_integral_v<T>) {
            v[0] = double(std::numeric_limits<T>::lowest());
            v[1] = double(std::numeric_limits<T>::max());
        }
    });
    return v;
}

std::string joinDouble(const Vec3d &v, const char *sep = " ") {
    std::ostringstream ss;
    ss.precision(17);
    ss << v.x << sep << v.y << sep << v.z;
    return ss.str();
}

std::string nrrdVector(const Vec3d &v) { return "(" + joinDouble(v, ",") + ")"; }

// Each test gets a fresh temp folder; the shared data is only ever read or copied.
class VolumeIoTest : public ::testing::Test {
protected:
    fs::path dir;

    void SetUp() override {
        const auto *info = ::testing::UnitTest::GetInstance()->current_test_info();
        std::string name = std::string(info->test_suite_name()) + "_" + info->name();
        std::replace(name.begin(), name.end(), '/', '_');
        dir = fs::temp_directory_path() / ("volcast_io_" + std::to_string(getpid()) + "_" + name);
        fs::remove_all(dir);
        fs::create_directories(dir);
    }
    void TearDown() override { fs::remove_all(dir); }

    // A NRRD of dims with `payload` bytes; detached when dataName is set, gzip when asked.
    fs::path writeNrrd(const std::string &name, const std::string &type, const Vec3i &dims, const std::string &payload,
                       bool bigEndian, bool gzip, const std::string &dataName = "", const std::string &extra = "") {
        std::ostringstream h;
        h << "NRRD0004\n# written by test_volume_io\ntype: " << type << "\ndimension: 3\nsizes: " << dims.x << " "
          << dims.y << " " << dims.z << "\n"
          << extra << "endian: " << (bigEndian ? "big" : "little") << "\nencoding: " << (gzip ? "gzip" : "raw") << "\n";
        const std::string data = gzip ? gzipBytes(payload) : payload;
        const fs::path path = dir / name;
        if (dataName.empty()) {
            writeFile(path, h.str() + "\n" + data);
        } else {
            h << "data file: " << dataName << "\n";
            writeFile(path, h.str());
            writeFile(dir / dataName, data);
        }
        return path;
    }

    // A copy of a real scan's header and data in the temp folder, with header lines replaced.
    fs::path copyScan(const std::string &scan, const std::string &newName,
                      std::initializer_list<std::pair<std::string, std::string>> replace, size_t keepDataBytes = 0) {
        std::string header = readFile(kDataDir / (scan + ".nhdr"));
        std::istringstream lines(header);
        std::string line, out, dataFile;
        while (std::getline(lines, line)) {
            if (line.starts_with("data file: ")) dataFile = line.substr(11);
            for (const auto &[key, value] : replace)
                if (line.starts_with(key + ":")) line = key + ": " + value;
            out += line + "\n";
        }
        std::string data = readFile(kDataDir / dataFile);
        if (keepDataBytes > 0) data.resize(keepDataBytes);
        writeFile(dir / dataFile, data);
        writeFile(dir / newName, out);
        return dir / newName;
    }
};

// The load must fail with a message that starts with the path, names the file, and
// contains every word (lower case) that names the problem after the path.
void expectLoadError(const fs::path &path, std::initializer_list<const char *> words, const LoadOptions &options = {}) {
    try {
        const Volume v = loadVolume(path, options);
        ADD_FAILURE() << path << " loaded (" << v.dims.x << " x " << v.dims.y << " x " << v.dims.z
                      << ") but should have been rejected";
    } catch (const VolumeLoadError &e) {
        const std::string message = e.what();
        EXPECT_TRUE(message.starts_with(path.string())) << message;
        EXPECT_NE(message.find(path.filename().string()), std::string::npos) << message;
        // The words must name the problem, so they are looked for after the path (which
        // holds the test's own name).
        const std::string problem = lowerCase(message.substr(std::min(message.size(), path.string().size())));
        for (const char *word : words)
            EXPECT_NE(problem.find(word), std::string::npos) << "no '" << word << "' in: " << message;
    } catch (const std::exception &e) {
        ADD_FAILURE() << path << " threw something other than VolumeLoadError: " << e.what();
    }
}

// ---------------------------------------------------------------------------------------
// 1. The real scans of MANIFEST.md

struct ScanExpectation {
    const char *header;
    Vec3i dims;
    VoxelType type;
    Vec3d spacing;
    float min, max;
    const char *littleEndianSha256;  // sha256 of the voxels as native little-endian bytes
};

// Dims, type and spacing are MANIFEST.md's table. min/max came from an independent reader
// (a python3 script with gzip + struct that decodes each data file by its header, run once
// when these tests were written) and agree with MANIFEST.md's "Stats" where it gives them
// (iguana_microct and head_mr_volume have no stats there). Values are integers or exact
// float32 values, so they are compared exactly.
Volume checkScan(const ScanExpectation &e) {
    const Volume v = loadVolume(kDataDir / e.header);
    EXPECT_EQ(v.name, e.header);
    EXPECT_EQ(v.dims, e.dims);
    EXPECT_EQ(v.sourceType, e.type) << voxelTypeName(v.sourceType);
    // The headers' decimal spacings parse to the same doubles here and in ITK/teem; 4 ULPs
    // (EXPECT_DOUBLE_EQ) only allows for a differently rounding parser.
    EXPECT_DOUBLE_EQ(v.spacing.x, e.spacing.x);
    EXPECT_DOUBLE_EQ(v.spacing.y, e.spacing.y);
    EXPECT_DOUBLE_EQ(v.spacing.z, e.spacing.z);
    // The headers carry no space origin or directions.
    EXPECT_EQ(v.origin, Vec3d(0, 0, 0));
    EXPECT_EQ(v.direction, Mat3d::identity());
    EXPECT_EQ(v.range.min, e.min);
    EXPECT_EQ(v.range.max, e.max);
    EXPECT_EQ(v.nonFiniteReplaced, 0u);
    EXPECT_TRUE(v.hasSamples());
    EXPECT_EQ(v.voxelCount(), size_t(e.dims.x * e.dims.y * e.dims.z));
    // Voxels back in their native type, little-endian: the exact decoded bytes.
    EXPECT_EQ(sha256(nativeBytes(v, false)), e.littleEndianSha256);
    return v;
}

// "voxel sha256" of MANIFEST.md (decoded little-endian or 1-byte voxel bytes).
TEST(VolumeIoRealScans, CraniumCt) {
    SKIP_WITHOUT_SCANS();
    checkScan({"cranium_ct.nhdr", {256, 256, 108}, VoxelType::Int16, {0.9570312, 0.9570312, 1.5}, -1024, 2986,
               "d87fd5e6aaf2c4fdf4f3fe28ee3335192fc2464ed8e9682fc78530cb837938da"});
}

TEST(VolumeIoRealScans, Headsq) {
    SKIP_WITHOUT_SCANS();
    checkScan({"headsq.nhdr", {64, 64, 93}, VoxelType::Int16, {3.2, 3.2, 1.5}, 0, 3926,
               "35b0a0101e612dc83ff56295b09e1ac95c8462198def11a8db1297f8aed3e5f6"});
}

TEST(VolumeIoRealScans, Lidc2ChestCt) {
    SKIP_WITHOUT_SCANS();
    checkScan({"lidc2_chest_ct.nhdr", {256, 256, 133}, VoxelType::UInt8, {1.40625, 1.40625, 2.5}, 0, 255,
               "d697a46dadafc1b2e08b9c088e7e78b905c3ddfa602f397992f54cd593ec8b25"});
}

TEST(VolumeIoRealScans, Aneurism) {
    SKIP_WITHOUT_SCANS();
    checkScan({"aneurism.nhdr", {256, 256, 256}, VoxelType::UInt8, {1, 1, 1}, 0, 255,
               "2826a66db406f19bdd9e38cfe42a80b861fbce34a947c24ce511f07f1c160b83"});
}

TEST(VolumeIoRealScans, AvmCta) {
    SKIP_WITHOUT_SCANS();
    checkScan({"avm_cta.nhdr", {337, 319, 154}, VoxelType::UInt8, {0.5469, 0.5469, 1}, 0, 255,
               "11a92b60abc4cc56e1a4e994d49bbf986607860ac4bb835efb2d83d82d70516c"});
}

TEST(VolumeIoRealScans, StentCt) {
    SKIP_WITHOUT_SCANS();
    checkScan({"stent_ct.nhdr", {128, 128, 256}, VoxelType::Int16, {1, 1, 1}, 0, 2000,
               "8431cfdc59600c1a6e2b68adeac61a8535d01cfdba236150b92101f984454da1"});
}

TEST(VolumeIoRealScans, Bonsai) {
    SKIP_WITHOUT_SCANS();
    checkScan({"bonsai.nhdr", {256, 256, 256}, VoxelType::UInt8, {1, 1, 1}, 0, 255,
               "d5c346c6c7507e88ba2bb93700d1223188f0566a93956ede73ea2df9559c2e4e"});
}

TEST(VolumeIoRealScans, Engine) {
    SKIP_WITHOUT_SCANS();
    checkScan({"engine.nhdr", {256, 256, 128}, VoxelType::UInt8, {1, 1, 1}, 0, 255,
               "0824611d5656143ee2d6fb4ad5cec3b6f64e1736b34e66217f5375da9fb63575"});
}

TEST(VolumeIoRealScans, IguanaMicroCt) {
    SKIP_WITHOUT_SCANS();
    checkScan({"iguana_microct.nhdr", {210, 256, 179}, VoxelType::UInt8, {0.1018, 0.1018, 0.1018}, 0, 229,
               "eeaf934b88e1032fb85c4e6b1d309d933fb215d23ba8fe7e682abe01435826c7"});
}

TEST(VolumeIoRealScans, Colin27MrT1) {
    SKIP_WITHOUT_SCANS();
    checkScan({"colin27_mr_t1.nhdr", {181, 217, 181}, VoxelType::UInt8, {1, 1, 1}, 0, 254,
               "38e1383cfd10824abc62dd61c9597f83ff899c82e2a84eb37737bdc83bfc9d7d"});
}

// A 1-byte raw file: MANIFEST.md's "data sha256 (= source sha256)" is of the voxel bytes.
TEST(VolumeIoRealScans, HeadMrVolume) {
    SKIP_WITHOUT_SCANS();
    checkScan({"head_mr_volume.nhdr", {48, 62, 42}, VoxelType::UInt8, {4, 4, 4}, 0, 255,
               "714ff5b2db59d3867675d0f2419c24a71ed234985b39dc1ea83ee7d72110de4b"});
}

// Big-endian raw scans. The little-endian sha256 was computed by the same python reader
// (struct '>H' / '>f', re-packed '<'); on top of it the test decodes the raw file itself
// with explicit byte swapping and compares voxel by voxel, and re-encodes the loaded
// voxels big-endian, which must reproduce MANIFEST.md's "data sha256" of the file.
template <typename T>
void checkBigEndianScan(const Volume &v, const char *dataFile, const char *fileSha256) {
    const std::string raw = readFile(kDataDir / dataFile);
    const std::vector<float> samples = v.samples().toFloats();
    ASSERT_EQ(raw.size(), samples.size() * sizeof(T));
    size_t mismatches = 0;
    for (size_t i = 0; i < samples.size(); ++i) {
        char b[sizeof(T)];
        std::memcpy(b, raw.data() + i * sizeof(T), sizeof(T));
        std::reverse(b, b + sizeof(T));
        T value;
        std::memcpy(&value, b, sizeof(T));
        if (float(value) != samples[i]) ++mismatches;
    }
    EXPECT_EQ(mismatches, 0u);
    EXPECT_EQ(sha256(nativeBytes(v, true)), fileSha256);
}

TEST(VolumeIoRealScans, ToothBigEndian) {
    SKIP_WITHOUT_SCANS();
    const Volume v = checkScan({"tooth.nhdr", {103, 94, 161}, VoxelType::UInt16, {1, 1, 1}, 0, 1300,
                                "0149b5fa6dc38d5314bae74f2644b4f76b6da98129b0156a967960b450735a74"});
    checkBigEndianScan<uint16_t>(v, "tooth.raw", "a0bbab299083a4a11155bd5142397b2c9a7910ecb6e04c43f1a315f9494ad688");
}

TEST(VolumeIoRealScans, CarotidFloatBigEndian) {
    SKIP_WITHOUT_SCANS();
    const Volume v = checkScan({"carotid_float.nhdr", {76, 49, 45}, VoxelType::Float32, {1, 1, 1}, 0, 580,
                                "9a675d4040f6ce60e8b37deda7d615912c1567c9a2d9d82e9ea5c5fcb03d8d54"});
    checkBigEndianScan<float>(v, "carotid_float.raw",
                              "a34434396659c45f3e7449d91f625b42b2aae5803cf7a65a1e960be105e51c20");
}

// ---------------------------------------------------------------------------------------
// 2. Formats written by the test

constexpr Vec3i kDims{5, 4, 3};  // small, and different per axis so a swapped axis shows
constexpr size_t kCount = 5 * 4 * 3;

void expectVoxels(const Volume &v, VoxelType type, const std::vector<double> &values) {
    ASSERT_EQ(v.dims, kDims);
    EXPECT_EQ(v.sourceType, type) << voxelTypeName(v.sourceType);
    const std::vector<float> samples = v.samples().toFloats();
    ASSERT_EQ(samples.size(), values.size());
    // The loader converts each native value with a plain float cast (or, 8 and 16 bits, holds
    // it narrow, which widens to the same float), so the expectation is the same cast of the
    // written value: exact equality.
    for (size_t i = 0; i < values.size(); ++i) EXPECT_EQ(samples[i], float(values[i])) << "voxel " << i;
}

class VolumeIoNrrdTypes : public VolumeIoTest, public ::testing::WithParamInterface<VoxelType> {};

// Every voxel type, both byte orders, attached raw / attached gzip / detached raw / detached gzip.
TEST_P(VolumeIoNrrdTypes, RoundTripsValuesDimsAndSpacing) {
    const VoxelType type = GetParam();
    const std::vector<double> values = testValues(type, kCount);
    const std::string spacings = "spacings: 0.5 0.75 2.25\n";
    for (bool bigEndian : {false, true}) {
        for (int layout = 0; layout < 4; ++layout) {
            const bool gzip = layout % 2 == 1;
            const bool detached = layout >= 2;
            const std::string base =
                std::string(nrrdTypeName(type)) + (bigEndian ? "_be" : "_le") + (gzip ? "_gz" : "_raw");
            SCOPED_TRACE(base + (detached ? " detached" : " attached"));
            const fs::path path = writeNrrd(base + (detached ? ".nhdr" : ".nrrd"), nrrdTypeName(type), kDims,
                                            encode(type, values, bigEndian), bigEndian, gzip,
                                            detached ? base + (gzip ? ".raw.gz" : ".raw") : "", spacings);
            const Volume v = loadVolume(path);
            expectVoxels(v, type, values);
            EXPECT_EQ(v.spacing, Vec3d(0.5, 0.75, 2.25));  // exact binary fractions
        }
    }
}

INSTANTIATE_TEST_SUITE_P(VolumeIo, VolumeIoNrrdTypes,
                         ::testing::Values(VoxelType::Int8, VoxelType::UInt8, VoxelType::Int16, VoxelType::UInt16,
                                           VoxelType::Int32, VoxelType::UInt32, VoxelType::Float32,
                                           VoxelType::Float64),
                         [](const auto &param) { return std::string(voxelTypeName(param.param)); });

// Geometry read back from text written with 17 significant digits: equal within 1e-12
// (ITK normalizes each space direction, which costs a few ULPs).
void expectGeometry(const Volume &v, const Vec3d &spacing, const Vec3d &origin, const Mat3d &direction,
                    double tolerance = 1e-12) {
    for (int a = 0; a < 3; ++a) {
        EXPECT_NEAR(v.spacing[a], spacing[a], tolerance * std::max(1.0, spacing[a])) << "spacing " << a;
        EXPECT_NEAR(v.origin[a], origin[a], tolerance * std::max(1.0, std::abs(origin[a]))) << "origin " << a;
        for (int r = 0; r < 3; ++r)
            EXPECT_NEAR(v.direction(r, a), direction(r, a), tolerance) << "direction " << r << "," << a;
    }
}

// Rotation by `degrees` about a unit axis (Rodrigues), an oblique orientation.
Mat3d rotation(Vec3d axis, double degrees) {
    axis = normalize(axis);
    const double t = degrees * std::numbers::pi / 180, c = std::cos(t), s = std::sin(t);
    Mat3d m;
    const double k[3][3] = {{0, -axis.z, axis.y}, {axis.z, 0, -axis.x}, {-axis.y, axis.x, 0}};
    for (int r = 0; r < 3; ++r)
        for (int q = 0; q < 3; ++q) {
            double kk = 0;
            for (int i = 0; i < 3; ++i) kk += k[r][i] * k[i][q];
            m(r, q) = (r == q ? 1.0 : 0.0) + s * k[r][q] + (1 - c) * kk;
        }
    return m;
}

Vec3d column(const Mat3d &m, int c) { return {m(0, c), m(1, c), m(2, c)}; }

std::string spaceDirections(const Mat3d &d, const Vec3d &spacing) {
    return "space directions: " + nrrdVector(column(d, 0) * spacing.x) + " " + nrrdVector(column(d, 1) * spacing.y) +
           " " + nrrdVector(column(d, 2) * spacing.z) + "\n";
}

TEST_F(VolumeIoTest, NrrdObliqueSpaceDirectionsAndOrigin) {
    const Mat3d d = rotation({1, 2, 3}, 30);
    const Vec3d spacing{0.7, 1.3, 2.1}, origin{-12.5, 40.25, 7};
    const std::vector<double> values = testValues(VoxelType::Int16, kCount);
    // An LPS space is ITK's own, so the numbers come through unchanged.
    const fs::path path = writeNrrd("oblique.nhdr", "int16", kDims, encode(VoxelType::Int16, values, false), false,
                                    true, "oblique.raw.gz",
                                    "space: left-posterior-superior\n" + spaceDirections(d, spacing) +
                                        "space origin: " + nrrdVector(origin) + "\n");
    const Volume v = loadVolume(path);
    expectVoxels(v, VoxelType::Int16, values);
    expectGeometry(v, spacing, origin, d);
    // World position of voxel (1, 2, 3) = origin + D (1 sx, 2 sy, 3 sz), docs/design.md's contract.
    const Vec3d expected = origin + d * Vec3d(1 * spacing.x, 2 * spacing.y, 3 * spacing.z);
    const Vec3d world = v.worldFromIndex({1, 2, 3});
    // Both sides are a handful of double operations on values of size ~50: 1e-9 is loose.
    for (int a = 0; a < 3; ++a) EXPECT_NEAR(world[a], expected[a], 1e-9);
}

TEST_F(VolumeIoTest, NrrdPermutedSpaceDirections) {
    // Index axis x runs along world y, y along z, z along x: a permutation, not a rotation
    // about one axis, and without a named space (so no LPS conversion).
    const std::string payload = encode(VoxelType::UInt8, testValues(VoxelType::UInt8, kCount), false);
    const fs::path path = writeNrrd("permuted.nrrd", "uint8", kDims, payload, false, false, "",
                                    "space dimension: 3\nspace directions: (0,2,0) (0,0,3) (1.5,0,0)\n"
                                    "space origin: (1,2,3)\n");
    const Volume v = loadVolume(path);
    Mat3d d;
    d.m = {0, 0, 1, 1, 0, 0, 0, 1, 0};
    expectGeometry(v, {2, 3, 1.5}, {1, 2, 3}, d);
    const Vec3d world = v.worldFromIndex({1, 1, 1});
    EXPECT_EQ(world, Vec3d(1 + 1.5, 2 + 2, 3 + 3));  // exact: small binary fractions
}

TEST_F(VolumeIoTest, NrrdRasSpaceComesOutInLps) {
    // ITK's convention: a right-anterior-superior space is turned into LPS (x and y negated).
    const std::string payload = encode(VoxelType::UInt8, testValues(VoxelType::UInt8, kCount), false);
    const fs::path path = writeNrrd("ras.nrrd", "uint8", kDims, payload, false, false, "",
                                    "space: right-anterior-superior\nspace directions: (2,0,0) (0,3,0) (0,0,4)\n"
                                    "space origin: (10,20,30)\n");
    const Volume v = loadVolume(path);
    Mat3d d;
    d.m = {-1, 0, 0, 0, -1, 0, 0, 0, 1};
    expectGeometry(v, {2, 3, 4}, {-10, -20, 30}, d);
}

TEST_F(VolumeIoTest, Nrrd2DImageIsOneSlice) {
    writeFile(dir / "slice.nrrd",
              "NRRD0004\ntype: uint8\ndimension: 2\nsizes: 3 2\nspacings: 0.5 0.25\nencoding: raw\n\n" +
                  encode(VoxelType::UInt8, {1, 2, 3, 4, 5, 6}, false));
    const Volume v = loadVolume(dir / "slice.nrrd");
    EXPECT_EQ(v.dims, Vec3i(3, 2, 1));
    EXPECT_EQ(v.spacing, Vec3d(0.5, 0.25, 1));  // z spacing 1 by the documented convention
    EXPECT_EQ(v.samples().toFloats(), std::vector<float>({1, 2, 3, 4, 5, 6}));
}

TEST_F(VolumeIoTest, MetaImageDetachedMhdAndAttachedMha) {
    const std::vector<double> values = testValues(VoxelType::Int16, kCount);
    // .mhd + raw, little-endian, with an axis permutation (TransformMatrix lists the index
    // axes' world directions one after another, as ITK reads it) and an offset.
    writeFile(dir / "vol.mhd", "ObjectType = Image\nNDims = 3\nDimSize = 5 4 3\nElementType = MET_SHORT\n"
                               "ElementSpacing = 0.5 0.75 2.25\nTransformMatrix = 0 1 0 0 0 1 1 0 0\n"
                               "Offset = 1 2 3\nElementByteOrderMSB = False\nElementDataFile = vol.raw\n");
    writeFile(dir / "vol.raw", encode(VoxelType::Int16, values, false));
    const Volume mhd = loadVolume(dir / "vol.mhd");
    expectVoxels(mhd, VoxelType::Int16, values);
    Mat3d d;
    d.m = {0, 0, 1, 1, 0, 0, 0, 1, 0};
    expectGeometry(mhd, {0.5, 0.75, 2.25}, {1, 2, 3}, d);

    // .mha with the data attached, big-endian.
    writeFile(dir / "vol.mha", "ObjectType = Image\nNDims = 3\nDimSize = 5 4 3\nElementType = MET_SHORT\n"
                               "ElementSpacing = 0.5 0.75 2.25\nElementByteOrderMSB = True\nElementDataFile = LOCAL\n" +
                                   encode(VoxelType::Int16, values, true));
    const Volume mha = loadVolume(dir / "vol.mha");
    expectVoxels(mha, VoxelType::Int16, values);
    EXPECT_EQ(mha.spacing, Vec3d(0.5, 0.75, 2.25));
}

// A NIfTI-1 single-file header (348 bytes + 4 bytes of empty extension flag).
std::string niftiHeader(const Vec3i &dims, int16_t datatype, int16_t bitpix, const float sform[3][4],
                        float slope = 1, float intercept = 0) {
    std::string h(352, '\0');
    auto put = [&](size_t offset, auto value) { std::memcpy(h.data() + offset, &value, sizeof value); };
    put(0, int32_t(348));
    const int16_t dim[8] = {3, int16_t(dims.x), int16_t(dims.y), int16_t(dims.z), 1, 1, 1, 1};
    for (size_t i = 0; i < 8; ++i) put(40 + 2 * i, dim[i]);
    put(70, datatype);
    put(72, bitpix);
    const float pixdim[8] = {1, std::hypot(sform[0][0], sform[1][0], sform[2][0]),
                             std::hypot(sform[0][1], sform[1][1], sform[2][1]),
                             std::hypot(sform[0][2], sform[1][2], sform[2][2]), 1, 1, 1, 1};
    for (size_t i = 0; i < 8; ++i) put(76 + 4 * i, pixdim[i]);
    put(108, 352.0f);  // vox_offset
    put(112, slope);
    put(116, intercept);
    put(252, int16_t(0));  // qform_code: unused
    put(254, int16_t(2));  // sform_code: aligned
    for (size_t r = 0; r < 3; ++r)
        for (size_t c = 0; c < 4; ++c) put(280 + 16 * r + 4 * c, sform[r][c]);
    std::memcpy(h.data() + 344, "n+1", 4);
    return h;
}

// sform columns: index x along world y (spacing 2), y along z (3), z along x (4); origin
// (10, 20, 30) in RAS, which ITK turns into LPS.
constexpr float kSform[3][4] = {{0, 0, 4, 10}, {2, 0, 0, 20}, {0, 3, 0, 30}};
const Mat3d kSformLps = [] {
    Mat3d d;
    d.m = {0, 0, -1, -1, 0, 0, 0, 1, 0};
    return d;
}();

// vol.nii and vol.nii.gz side by side on purpose: niftilib, asked for vol.nii.gz, takes its
// header but looks for the voxels in vol.nii first; the loader must not mix the two.
TEST_F(VolumeIoTest, NiftiNiAndNiiGz) {
    const std::vector<double> shorts = testValues(VoxelType::Int16, kCount);
    writeFile(dir / "vol.nii", niftiHeader(kDims, 4, 16, kSform) + encode(VoxelType::Int16, shorts, false));
    const Volume nii = loadVolume(dir / "vol.nii");
    expectVoxels(nii, VoxelType::Int16, shorts);
    expectGeometry(nii, {2, 3, 4}, {-10, -20, 30}, kSformLps, 1e-6);  // float32 header fields

    const std::vector<double> floats = testValues(VoxelType::Float32, kCount);
    writeFile(dir / "vol.nii.gz",
              gzipBytes(niftiHeader(kDims, 16, 32, kSform) + encode(VoxelType::Float32, floats, false)));
    const Volume gz = loadVolume(dir / "vol.nii.gz");
    expectVoxels(gz, VoxelType::Float32, floats);
    expectGeometry(gz, {2, 3, 4}, {-10, -20, 30}, kSformLps, 1e-6);
}

TEST_F(VolumeIoTest, NiftiScaleSlopeIsApplied) {
    // uint8 stored values 0..59 with scl_slope 2.5, scl_inter -1: ITK hands back float32
    // physical values (exact here: multiples of 0.5).
    std::vector<double> stored(kCount);
    for (size_t i = 0; i < kCount; ++i) stored[i] = double(i);
    writeFile(dir / "scaled.nii",
              niftiHeader(kDims, 2, 8, kSform, 2.5f, -1.0f) + encode(VoxelType::UInt8, stored, false));
    const Volume v = loadVolume(dir / "scaled.nii");
    std::vector<double> physical(kCount);
    for (size_t i = 0; i < kCount; ++i) physical[i] = 2.5 * stored[i] - 1;
    expectVoxels(v, VoxelType::Float32, physical);
}

// ITK's writers (saveVolume) and the loader agree on every format, oblique geometry included.
TEST_F(VolumeIoTest, SaveVolumeRoundTripsEveryFormat) {
    Volume src;
    src.dims = kDims;
    src.spacing = {0.6, 0.9, 1.75};
    src.origin = {-20, 5.5, 100};
    src.direction = rotation({0.3, -1, 0.5}, 40);
    const std::vector<double> values = testValues(VoxelType::Int16, kCount);
    src.voxels.assign(values.begin(), values.end());
    for (const char *name : {"w.nrrd", "w.nhdr", "w.mha", "w.mhd", "w.nii", "w.nii.gz"}) {
        for (bool compress : {false, true}) {
            SCOPED_TRACE(std::string(name) + (compress ? " compressed" : ""));
            fs::remove_all(dir);
            fs::create_directories(dir);
            saveVolume(src, dir / name, {VoxelType::Int16, compress});
            const Volume v = loadVolume(dir / name);
            expectVoxels(v, VoxelType::Int16, values);
            // NIfTI stores geometry as float32 (about 1e-7 relative); the others as decimal text.
            expectGeometry(v, src.spacing, src.origin, src.direction, 1e-5);
        }
    }
}

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

// Progress as the server streams it: from 0 to 1, never backwards, each step named.
struct ProgressLog {
    std::vector<std::pair<double, std::string>> steps;
    LoadOptions options() {
        LoadOptions o;
        o.progress = [this](double f, std::string_view task) { steps.emplace_back(f, std::string(task)); };
        return o;
    }
    void expectWellFormed() const {
        ASSERT_GE(steps.size(), 3u);
        EXPECT_EQ(steps.front().first, 0.0);
        EXPECT_EQ(steps.back().first, 1.0);
        for (size_t i = 1; i < steps.size(); ++i) EXPECT_GE(steps[i].first, steps[i - 1].first) << i;
        for (const auto &[f, task] : steps) EXPECT_FALSE(task.empty()) << f;
    }
    size_t count(const std::string &task) const {
        return size_t(std::count_if(steps.begin(), steps.end(), [&](const auto &s) { return s.second == task; }));
    }
};

TEST_F(VolumeIoTest, ProgressOfAFileRunsFromZeroToOneThroughItsSteps) {
    Volume src;
    src.dims = {40, 30, 20};
    src.voxels.assign(src.voxelCount(), 7.0f);
    saveVolume(src, dir / "p.nrrd", {VoxelType::Int32, true});
    ProgressLog log;
    loadVolume(dir / "p.nrrd", log.options());
    log.expectWellFormed();
    for (const char *task : {"reading header", "checking data", "reading voxels", "statistics"})
        EXPECT_GE(log.count(task), 1u) << task;
    // int32 to float in 16 chunks or more (8- and 16-bit files are read straight into the
    // narrow store and say "converting" once).
    EXPECT_GE(log.count("converting"), 16u);
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

TEST_F(VolumeIoTest, DicomFolderWithTwoSeriesLoadsOne) {
    // Two series of different sizes in one folder: the loader takes one of them whole (the
    // first GDCM lists, logged) rather than mixing slices of both.
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
    const Volume v = loadVolume(dir / "both");
    const Volume &expected = v.dims == a.dims ? a : b;
    EXPECT_EQ(v.dims, expected.dims);
    EXPECT_EQ(v.samples().toFloats(), expected.voxels);
}

// ---------------------------------------------------------------------------------------
// 3. Damaged files (copies in the temp folder)

// ITK 5.2 keeps a NRRD size in 32 bits: 4294967298 samples reached the loader's checks as 2
// while NrrdIO allocated for the real count (343 GB in fuzz finding 13). The header's sizes
// are read by the loader too, and must be whole numbers that ITK read alike.
TEST_F(VolumeIoTest, NrrdSizesItkWrapsOrCannotReadAreRefused) {
    writeFile(dir / "wraps.nrrd", "NRRD0004\ntype: uint8\ndimension: 3\nsizes: 2 2 4294967298\nencoding: raw\n\n" +
                                      std::string(8, '\1'));
    expectLoadError(dir / "wraps.nrrd", {"sizes", "4294967298", "read 2"});
    writeFile(dir / "garbled.nrrd", "NRRD0004\ntype: uint8\ndimension: 3\nsizes: 2 2\xa6" "6 2\nencoding: raw\n\n" +
                                        std::string(8, '\1'));
    expectLoadError(dir / "garbled.nrrd", {"sizes", "not a whole number"});
}

TEST_F(VolumeIoTest, TruncatedRawData) {
    SKIP_WITHOUT_SCANS();
    // head_mr_volume.raw holds 124,992 bytes; keep 100,000. teem reports a short fread.
    expectLoadError(copyScan("head_mr_volume", "trunc_raw.nhdr", {}, 100000), {"truncated"});
}

TEST_F(VolumeIoTest, TruncatedGzipData) {
    SKIP_WITHOUT_SCANS();
    // headsq.raw.gz cut to about half its 424,639 bytes.
    expectLoadError(copyScan("headsq", "trunc_gz.nhdr", {}, 200000), {"truncated"});
}

TEST_F(VolumeIoTest, RawSizesBiggerThanData) {
    SKIP_WITHOUT_SCANS();
    expectLoadError(copyScan("head_mr_volume", "big.nhdr", {{"sizes", "48 62 43"}}), {"truncated", "size"});
}

TEST_F(VolumeIoTest, RawSizesSmallerThanData) {
    SKIP_WITHOUT_SCANS();
    // ITK reads the first 48*62*41 bytes and says nothing; the loader compares file sizes.
    expectLoadError(copyScan("head_mr_volume", "small.nhdr", {{"sizes", "48 62 41"}}), {"size", "disagree"});
}

TEST_F(VolumeIoTest, GzipSizesBiggerThanData) {
    SKIP_WITHOUT_SCANS();
    expectLoadError(copyScan("headsq", "big_gz.nhdr", {{"sizes", "64 64 94"}}), {"truncated", "size"});
}

TEST_F(VolumeIoTest, GzipSizesSmallerThanData) {
    SKIP_WITHOUT_SCANS();
    // ITK accepts this silently too; the loader counts the decompressed bytes.
    expectLoadError(copyScan("headsq", "small_gz.nhdr", {{"sizes", "64 64 92"}}), {"size", "disagree"});
}

TEST_F(VolumeIoTest, AttachedRawLongerThanHeader) {
    const fs::path p = writeNrrd("long.nrrd", "uint8", {2, 2, 2}, std::string(12, '\1'), false, false);
    expectLoadError(p, {"size", "disagree"});
}

TEST_F(VolumeIoTest, UnknownTypeInHeader) {
    SKIP_WITHOUT_SCANS();
    expectLoadError(copyScan("headsq", "badtype.nhdr", {{"type", "complex"}}), {"type"});
}

TEST_F(VolumeIoTest, UnsupportedInt64Type) {
    SKIP_WITHOUT_SCANS();
    expectLoadError(copyScan("headsq", "int64.nhdr", {{"type", "int64"}}), {"type", "not supported"});
}

TEST_F(VolumeIoTest, ZeroSize) {
    SKIP_WITHOUT_SCANS();
    expectLoadError(copyScan("headsq", "zero.nhdr", {{"sizes", "0 64 93"}}), {"size"});
}

TEST_F(VolumeIoTest, AbsurdSize) {
    SKIP_WITHOUT_SCANS();
    expectLoadError(copyScan("headsq", "huge.nhdr", {{"sizes", "1000000 1000000 1000000"}}), {"size", "absurd"});
}

TEST_F(VolumeIoTest, MoreVoxelsThanMemoryBudget) {
    SKIP_WITHOUT_SCANS();
    LoadOptions small;
    small.maxBytes = 100000;  // head_mr_volume needs 124,992 x 4 bytes as float32
    expectLoadError(kDataDir / "head_mr_volume.nhdr", {"budget"}, small);
}

TEST_F(VolumeIoTest, MissingDataFile) {
    SKIP_WITHOUT_SCANS();
    const fs::path p = copyScan("headsq", "missing_data.nhdr", {{"data file", "nothere.raw.gz"}});
    expectLoadError(p, {"nothere.raw.gz", "not found"});
}

TEST_F(VolumeIoTest, MissingHeaderFile) { expectLoadError(dir / "nothere.nhdr", {"not found"}); }

TEST_F(VolumeIoTest, FolderWithoutDicom) {
    fs::create_directories(dir / "empty_series");
    writeFile(dir / "empty_series" / "readme.txt", "no images here\n");
    expectLoadError(dir / "empty_series", {"no dicom"});
}

TEST_F(VolumeIoTest, TextFileNamedNrrd) {
    writeFile(dir / "text.nrrd", "hello, I am not a volume\n");
    expectLoadError(dir / "text.nrrd", {"format"});
}

TEST_F(VolumeIoTest, FourComponentImage) {
    writeFile(dir / "rgba.nrrd", "NRRD0004\ntype: uint8\ndimension: 4\nsizes: 4 2 2 2\n"
                                 "kinds: RGBA-color domain domain domain\nencoding: raw\n\n" + std::string(32, '\0'));
    expectLoadError(dir / "rgba.nrrd", {"4 components", "scalar"});
}

TEST_F(VolumeIoTest, TimeSeriesIsNotAVolume) {
    writeFile(dir / "4d.nrrd",
              "NRRD0004\ntype: uint8\ndimension: 4\nsizes: 2 2 2 3\nencoding: raw\n\n" + std::string(24, '\0'));
    expectLoadError(dir / "4d.nrrd", {"4-d", "3-d"});
}

TEST_F(VolumeIoTest, NonOrthonormalDirections) {
    const fs::path p = writeNrrd("skew.nrrd", "uint8", {2, 2, 2}, std::string(8, '\0'), false, false, "",
                                 "space: left-posterior-superior\nspace directions: (1,0,0) (1,1,0) (0,0,1)\n");
    expectLoadError(p, {"direction", "orthonormal"});
}

TEST_F(VolumeIoTest, ZeroOrNegativeSpacing) {
    // A zero space direction gives ITK spacing 0 and a NaN direction; "spacings: -2" passes ITK.
    const fs::path zero = writeNrrd("zero_dir.nrrd", "uint8", {2, 2, 2}, std::string(8, '\0'), false, false, "",
                                    "space: left-posterior-superior\nspace directions: (1,0,0) (0,0,0) (0,0,1)\n");
    expectLoadError(zero, {"spacing"});
    const fs::path negative =
        writeNrrd("neg.nrrd", "uint8", {2, 2, 2}, std::string(8, '\0'), false, false, "", "spacings: -2 1 1\n");
    expectLoadError(negative, {"spacing"});
}

// MetaIO copies a field name into a 255-byte buffer without a check: a name of 255 bytes or
// more aborted the process in MetaIO's fortified strcpy (fuzz finding 9), with or without
// an '=' on its line. 254 is the longest it takes.
TEST_F(VolumeIoTest, MetaImageFieldNameLongerThanMetaIoTakesIsRefusedNotACrash) {
    const std::string tail = "NDims = 3\nDimSize = 2 2 2\nElementType = MET_UCHAR\nElementDataFile = LOCAL\n" +
                             std::string(8, '\1');
    writeFile(dir / "long_name.mha", "ObjectType = Image\n" + std::string(255, 'K') + " = 1\n" + tail);
    expectLoadError(dir / "long_name.mha", {"line 2", "255 bytes", "at most 254"});
    writeFile(dir / "long_line.mha", std::string(300, 'K') + "\n" + tail);
    expectLoadError(dir / "long_line.mha", {"line 1", "300 bytes"});
    // The longest name MetaIO takes loads as before (an unknown field, ignored).
    writeFile(dir / "ok_name.mha", "ObjectType = Image\n" + std::string(254, 'K') + " = 1\n" + tail);
    EXPECT_EQ(loadVolume(dir / "ok_name.mha").dims, Vec3i(2, 2, 2));
}

// MetaIO loops NDims times reading the header's per-axis values into arrays of 10: a huge
// NDims kept the loader reading for good (fuzz finding 10).
TEST_F(VolumeIoTest, MetaImageNDimsOutsideOneToTenIsRefusedBeforeMetaIoLoopsOnIt) {
    const std::string rest = "DimSize = 2 2 2\nElementType = MET_UCHAR\nElementDataFile = LOCAL\n" + std::string(8, '\1');
    writeFile(dir / "huge_ndims.mha", "ObjectType = Image\nNDims = " + std::string(120, '9') + "\n" + rest);
    expectLoadError(dir / "huge_ndims.mha", {"ndims", "1 to 10"});
    writeFile(dir / "eleven.mha", "ObjectType = Image\nNDims = 11\n" + rest);
    expectLoadError(dir / "eleven.mha", {"ndims is '11'"});
    writeFile(dir / "zero.mha", "ObjectType = Image\nNDims = 0\n" + rest);
    expectLoadError(dir / "zero.mha", {"ndims is '0'"});
}

// MetaIO reads "Name: value" as "Name = value", and a NUL ends a name: both spellings of
// ElementDataFile reached its LIST reader without the loader's data-file checks (a crash;
// fuzz finding 12). The colon form is now checked like the other; a NUL is refused.
TEST_F(VolumeIoTest, MetaImageColonSeparatorIsCheckedAndANulIsRefused) {
    const std::string head = "ObjectType = Image\nNDims = 3\nDimSize = 2 2 2\nElementType = MET_UCHAR\n";
    writeFile(dir / "colon.mha", head + "ElementDataFile: LIST\nmissing_a.raw\nmissing_b.raw\n");
    expectLoadError(dir / "colon.mha", {"missing_a.raw"});
    writeFile(dir / "nul.mha", head + std::string("ElementDataFile\0x: LIST\n", 24) + "a.raw\n");
    expectLoadError(dir / "nul.mha", {"line 5", "nul"});
    // The colon form of a sound header loads as the '=' form does.
    writeFile(dir / "colon_ok.mha", head + "ElementDataFile: LOCAL\n" + std::string(8, '\1'));
    EXPECT_EQ(loadVolume(dir / "colon_ok.mha").dims, Vec3i(2, 2, 2));
}

TEST_F(VolumeIoTest, TruncatedMetaImage) {
    // MetaIO prints "data not read completely" and ITK returns garbage; the loader refuses.
    writeFile(dir / "short.mha", "ObjectType = Image\nNDims = 3\nDimSize = 2 2 2\nElementType = MET_UCHAR\n"
                                 "ElementDataFile = LOCAL\n" + std::string(5, '\1'));
    expectLoadError(dir / "short.mha", {"truncated"});
    writeFile(dir / "short.mhd", "ObjectType = Image\nNDims = 3\nDimSize = 2 2 2\nElementType = MET_UCHAR\n"
                                 "ElementDataFile = short.raw\n");
    writeFile(dir / "short.raw", std::string(7, '\1'));
    expectLoadError(dir / "short.mhd", {"truncated"});
    // Compressed: ITK prints "Uncompress failed" and carries on.
    const std::string z = gzipBytes(std::string(8, '\1'));
    writeFile(dir / "short_z.mha", "ObjectType = Image\nNDims = 3\nDimSize = 2 2 2\nElementType = MET_UCHAR\n"
                                   "CompressedData = True\nElementDataFile = LOCAL\n" + z.substr(0, z.size() / 2));
    expectLoadError(dir / "short_z.mha", {"truncated"});
}

TEST_F(VolumeIoTest, TruncatedNifti) {
    // NiftiImageIO reads a short .nii or a cut .nii.gz without any error.
    const std::string full =
        niftiHeader(kDims, 4, 16, kSform) + encode(VoxelType::Int16, testValues(VoxelType::Int16, kCount), false);
    writeFile(dir / "short.nii", full.substr(0, full.size() - 10));
    expectLoadError(dir / "short.nii", {"truncated"});
    const std::string gz = gzipBytes(full);
    writeFile(dir / "cut.nii.gz", gz.substr(0, gz.size() - 30));
    expectLoadError(dir / "cut.nii.gz", {"truncated"});
    writeFile(dir / "long.nii", full + "extra bytes");
    expectLoadError(dir / "long.nii", {"size", "disagree"});
}

TEST_F(VolumeIoTest, NiftiZeroSize) {
    // NiftiImageIO reports a size of 0 as 1; the loader reads the header's own dims.
    writeFile(dir / "zero.nii", niftiHeader({5, 0, 3}, 2, 8, kSform) + std::string(15, '\0'));
    expectLoadError(dir / "zero.nii", {"size"});
}

// ---------------------------------------------------------------------------------------
// 3b. Damaged NIfTI headers: each breaks one rule of the NIfTI-1 specification, which ITK
// would read into a zero-filled or shifted volume. The refusal names the field.

template <typename T>
std::string patched(std::string bytes, size_t offset, T value) {
    std::memcpy(bytes.data() + offset, &value, sizeof value);
    return bytes;
}

class VolumeIoNiftiHeader : public VolumeIoTest {
  protected:
    // A valid int16 .nii of kDims with one header field replaced.
    template <typename T>
    fs::path writeWith(const std::string &name, size_t offset, T value) {
        const std::string good =
            niftiHeader(kDims, 4, 16, kSform) + encode(VoxelType::Int16, testValues(VoxelType::Int16, kCount), false);
        writeFile(dir / name, patched(good, offset, value));
        return dir / name;
    }
};

TEST_F(VolumeIoNiftiHeader, ValidHeaderLoads) {  // the baseline the others break
    EXPECT_EQ(loadVolume(writeWith("ok.nii", 70, int16_t(4))).dims, kDims);
}
TEST_F(VolumeIoNiftiHeader, SizeofHdrNot348) {
    expectLoadError(writeWith("header_size.nii", 0, int32_t(350)), {"sizeof_hdr", "348"});
}
TEST_F(VolumeIoNiftiHeader, DimZeroOutsideOneToSeven) {
    expectLoadError(writeWith("rank_zero.nii", 40, int16_t(0)), {"dim[0]"});
    expectLoadError(writeWith("rank_eight.nii", 40, int16_t(8)), {"dim[0]"});
}
TEST_F(VolumeIoNiftiHeader, NegativeDim) {
    expectLoadError(writeWith("negative_size.nii", 44, int16_t(-4)), {"dim[2]", "-4"});
}
TEST_F(VolumeIoNiftiHeader, BitpixNotMatchingDatatype) {
    // int16 data (datatype 4) declared with 8 bits per voxel.
    expectLoadError(writeWith("bits.nii", 72, int16_t(8)), {"bitpix", "datatype 4"});
}
TEST_F(VolumeIoNiftiHeader, UnknownDatatype) {
    expectLoadError(writeWith("type3.nii", 70, int16_t(3)), {"datatype 3"});
}
TEST_F(VolumeIoNiftiHeader, VoxOffsetInsideTheHeader) {
    expectLoadError(writeWith("early_data.nii", 108, 100.0f), {"vox_offset", "100"});
}
TEST_F(VolumeIoNiftiHeader, ZeroPixdim) {
    expectLoadError(writeWith("zero_spacing.nii", 80, 0.0f), {"pixdim[1]"});
}
TEST_F(VolumeIoNiftiHeader, NegativePixdim) {
    expectLoadError(writeWith("negative_spacing.nii", 84, -3.0f), {"pixdim[2]"});
}
TEST_F(VolumeIoNiftiHeader, NanPixdim) {
    expectLoadError(writeWith("nan_spacing.nii", 88, std::numeric_limits<float>::quiet_NaN()), {"pixdim[3]"});
}
// ITK's orientation SVD never ended on a NaN in the affine rows (fuzz finding 8): the load
// must fail at once, naming the field, not spin the loader (ctest's timeout caught it before).
TEST_F(VolumeIoNiftiHeader, NanInTheSformRowsIsRefusedBeforeItkLoopsOnIt) {
    expectLoadError(writeWith("nan_srow.nii", 280 + 16 * 1 + 4 * 2, std::numeric_limits<float>::quiet_NaN()),
                    {"srow_y[2]", "finite"});
    expectLoadError(writeWith("inf_srow.nii", 280, std::numeric_limits<float>::infinity()), {"srow_x[0]"});
}
// Finite but huge affine rows overflowed inside the single-precision SVD, which then never
// ended either (fuzz finding 11: -1.7e38 beside 1.5e26).
TEST_F(VolumeIoNiftiHeader, HugeAffineRowsAndSpacingsAreRefused) {
    expectLoadError(writeWith("huge_srow.nii", 280 + 16 * 1 + 4 * 1, -1.7e38f), {"srow_y[1]", "at most 1e+09"});
    expectLoadError(writeWith("huge_offset.nii", 280 + 16 * 2 + 4 * 3, 2e9f), {"srow_z[3]"});
    expectLoadError(writeWith("huge_spacing.nii", 80, 1e12f), {"pixdim[1]", "at most 1e+09"});
}
TEST_F(VolumeIoNiftiHeader, NanInTheQuaternionIsRefused) {
    const std::string good =
        niftiHeader(kDims, 4, 16, kSform) + encode(VoxelType::Int16, testValues(VoxelType::Int16, kCount), false);
    std::string bad = patched(good, 252, int16_t(1));  // qform_code: scanner
    const float nan = std::numeric_limits<float>::quiet_NaN();
    bad.replace(260, sizeof nan, reinterpret_cast<const char *>(&nan), sizeof nan);  // quatern_c
    writeFile(dir / "nan_quatern.nii", bad);
    expectLoadError(dir / "nan_quatern.nii", {"quatern_c", "finite"});
}
TEST_F(VolumeIoNiftiHeader, TransformCodesOutsideTheSpecificationAreRefused) {
    expectLoadError(writeWith("sform_code.nii", 254, int16_t(18789)), {"sform_code", "18789"});
    expectLoadError(writeWith("qform_code.nii", 252, int16_t(-1)), {"qform_code", "-1"});
}

// ---------------------------------------------------------------------------------------
// 3c. Damaged DICOM series

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
    expectLoadError(dir / "series", {"same position"});
}

// ---------------------------------------------------------------------------------------
// 3d. Detached data files stay in the header's folder and are regular files

class VolumeIoDataFiles : public VolumeIoTest {
  protected:
    void SetUp() override {
        VolumeIoTest::SetUp();
        fs::create_directories(dir / "sub");
    }
    // dir/sub/NAME, a 2x2x2 uint8 header naming `dataFile`; dir/x.raw lies outside sub/.
    fs::path header(const std::string &name, const std::string &dataFile) {
        fs::create_directories(dir / "sub");
        writeFile(dir / "x.raw", std::string(8, '\1'));
        writeFile(dir / "sub" / name, "NRRD0004\ntype: uint8\ndimension: 3\nsizes: 2 2 2\nencoding: raw\n"
                                      "data file: " + dataFile + "\n");
        return dir / "sub" / name;
    }
    fs::path metaHeader(const std::string &name, const std::string &dataFile) {
        fs::create_directories(dir / "sub");
        writeFile(dir / "x.raw", std::string(8, '\1'));
        writeFile(dir / "sub" / name, "ObjectType = Image\nNDims = 3\nDimSize = 2 2 2\nElementType = MET_UCHAR\n"
                                      "ElementDataFile = " + dataFile + "\n");
        return dir / "sub" / name;
    }
    // No server path in the message: the data file as the header names it, nothing more.
    void expectNoOutsidePath(const fs::path &p) {
        try {
            loadVolume(p);
        } catch (const VolumeLoadError &e) {
            EXPECT_EQ(std::string(e.what()).find((dir / "x.raw").string()), std::string::npos) << e.what();
        }
    }
    // Loads on another thread: a loader that opened a FIFO would wait for a writer forever.
    // If it does, the test writes nothing, closes the FIFO's write end to free it, and fails.
    void expectRefusedWithoutBlocking(const fs::path &p, const fs::path &fifo,
                                      std::initializer_list<const char *> words) {
        auto result = std::async(std::launch::async, [p, words] { expectLoadError(p, words); });
        if (result.wait_for(std::chrono::seconds(10)) != std::future_status::ready) {
            ADD_FAILURE() << "loading " << p << " blocked on the FIFO " << fifo;
            const int fd = ::open(fifo.c_str(), O_WRONLY | O_NONBLOCK);
            if (fd >= 0) ::close(fd);
        }
        result.wait();
    }
};

TEST_F(VolumeIoDataFiles, ValidDetachedDataFileLoads) {  // the baseline the others break
    writeFile(dir / "sub" / "in.raw", std::string(8, '\2'));
    const fs::path p = header("ok.nhdr", "in.raw");
    EXPECT_EQ(loadVolume(p).samples().toFloats(), std::vector<float>(8, 2.0f));
}
TEST_F(VolumeIoDataFiles, NrrdDataFileWithDotDotIsRefused) {
    const fs::path p = header("dotdot.nhdr", "../x.raw");
    expectLoadError(p, {"../x.raw", "outside"});
    expectNoOutsidePath(p);
}
TEST_F(VolumeIoDataFiles, NrrdAbsoluteDataFileIsRefused) {
    expectLoadError(header("rooted.nhdr", "/etc/passwd"), {"/etc/passwd", "absolute"});
}
TEST_F(VolumeIoDataFiles, NrrdDataFileLinkLeadingOutIsRefused) {
    const fs::path p = header("link.nhdr", "link.raw");
    fs::create_symlink(dir / "x.raw", dir / "sub" / "link.raw");
    expectLoadError(p, {"link.raw", "outside"});
    expectNoOutsidePath(p);
}
TEST_F(VolumeIoDataFiles, NrrdDataFileThatIsAFolderIsRefused) {
    fs::create_directories(dir / "sub" / "inner");
    expectLoadError(header("dir.nhdr", "inner"), {"inner", "folder"});
}
TEST_F(VolumeIoDataFiles, NrrdDataFileThatIsAFifoIsRefusedBeforeOpening) {
    const fs::path p = header("fifo.nhdr", "fifo.raw");
    ASSERT_EQ(::mkfifo((dir / "sub" / "fifo.raw").c_str(), 0600), 0) << std::strerror(errno);
    expectRefusedWithoutBlocking(p, dir / "sub" / "fifo.raw", {"fifo.raw", "regular file"});
}
TEST_F(VolumeIoDataFiles, NrrdListDataFilesAreConfined) {
    writeFile(dir / "sub" / "a.raw", std::string(4, '\1'));
    const fs::path p = header("list.nhdr", "LIST\na.raw\n../x.raw");
    expectLoadError(p, {"../x.raw", "outside"});
}
TEST_F(VolumeIoDataFiles, NrrdPatternDataFilesAreConfined) {
    writeFile(dir / "s1.raw", std::string(4, '\1'));
    writeFile(dir / "s2.raw", std::string(4, '\1'));
    expectLoadError(header("pattern.nhdr", "../s%d.raw 1 2 1"), {"../s1.raw", "outside"});
}
TEST_F(VolumeIoDataFiles, NrrdListAndPatternInsideTheFolderLoad) {
    // Two files of one z slice (4 bytes) each, in both multi-file forms.
    writeFile(dir / "sub" / "s01.raw", std::string(4, '\1'));
    writeFile(dir / "sub" / "s02.raw", std::string(4, '\2'));
    const std::vector<float> expected = {1, 1, 1, 1, 2, 2, 2, 2};
    EXPECT_EQ(loadVolume(header("list_ok.nhdr", "LIST\ns01.raw\ns02.raw")).samples().toFloats(), expected);
    EXPECT_EQ(loadVolume(header("pattern_ok.nhdr", "s%02d.raw 1 2 1")).samples().toFloats(), expected);
}
TEST_F(VolumeIoDataFiles, MetaImageDataFileOutsideOrAbsoluteOrFifoIsRefused) {
    expectLoadError(metaHeader("dotdot.mhd", "../x.raw"), {"../x.raw", "outside"});
    expectLoadError(metaHeader("rooted.mhd", "/etc/passwd"), {"/etc/passwd", "absolute"});
    ASSERT_EQ(::mkfifo((dir / "sub" / "fifo.raw").c_str(), 0600), 0) << std::strerror(errno);
    expectRefusedWithoutBlocking(metaHeader("fifo.mhd", "fifo.raw"), dir / "sub" / "fifo.raw",
                                 {"fifo.raw", "regular file"});
}
TEST_F(VolumeIoDataFiles, HeaderThatIsAFifoIsRefusedBeforeOpening) {
    ASSERT_EQ(::mkfifo((dir / "pipe.nrrd").c_str(), 0600), 0) << std::strerror(errno);
    expectRefusedWithoutBlocking(dir / "pipe.nrrd", dir / "pipe.nrrd", {"regular file"});
}
TEST_F(VolumeIoDataFiles, DicomFolderHoldingAFifoIsRefusedBeforeScanning) {
    Volume src;
    src.dims = {4, 4, 2};
    src.voxels.assign(src.voxelCount(), 5.0f);
    saveDicomSeries(src, dir / "series", VoxelType::Int16);
    ASSERT_EQ(::mkfifo((dir / "series" / "pipe.dcm").c_str(), 0600), 0) << std::strerror(errno);
    expectRefusedWithoutBlocking(dir / "series", dir / "series" / "pipe.dcm", {"pipe.dcm", "regular file"});
}

// ---------------------------------------------------------------------------------------
// 3e. Time limit and stop request, checked at every progress step

TEST_F(VolumeIoTest, LoadPastItsTimeLimitFailsNamingTheLimit) {
    Volume src;
    src.dims = {8, 8, 12};
    src.voxels.assign(src.voxelCount(), 100.0f);
    saveDicomSeries(src, dir / "slow", VoxelType::Int16);
    LoadOptions slow;
    slow.timeLimitSeconds = 0.2;
    // Each step takes 50 ms: the 12 slices alone take 0.6 s, three times the limit.
    slow.progress = [](double, std::string_view) { std::this_thread::sleep_for(std::chrono::milliseconds(50)); };
    EXPECT_THROW(loadVolume(dir / "slow", slow), VolumeLoadTimeout);
    expectLoadError(dir / "slow", {"time limit", "0.2 s"}, slow);
    // Without the limit the same load completes.
    slow.timeLimitSeconds = 0;
    EXPECT_EQ(loadVolume(dir / "slow", slow).dims, src.dims);
}

TEST_F(VolumeIoTest, StopRequestEndsTheLoad) {
    Volume src;
    src.dims = {8, 8, 4};
    src.voxels.assign(src.voxelCount(), 1.0f);
    saveVolume(src, dir / "s.nrrd");
    LoadOptions stopping;
    stopping.stopRequested = [] { return true; };
    expectLoadError(dir / "s.nrrd", {"stopped"}, stopping);
}

// ---------------------------------------------------------------------------------------
// 4. NaN / Inf policy

TEST_F(VolumeIoTest, NonFiniteVoxelsAreReplaced) {
    const float nan = std::numeric_limits<float>::quiet_NaN(), inf = std::numeric_limits<float>::infinity();
    const std::vector<double> values = {nan, inf, -inf, 1, 2, 3, -5, 7};
    const fs::path p =
        writeNrrd("nan.nrrd", "float", {2, 2, 2}, encode(VoxelType::Float32, values, false), false, false);
    const Volume v = loadVolume(p);
    // NaN and -Inf take the smallest finite value (-5), +Inf the largest (7).
    EXPECT_EQ(v.samples().toFloats(), std::vector<float>({-5, 7, -5, 1, 2, 3, -5, 7}));
    EXPECT_EQ(v.nonFiniteReplaced, 3u);
    EXPECT_EQ(v.range.min, -5.0f);
    EXPECT_EQ(v.range.max, 7.0f);
}

TEST_F(VolumeIoTest, AllNanVolumeIsRejected) {
    const std::vector<double> values(8, std::numeric_limits<double>::quiet_NaN());
    // Big-endian gzip double, so the NaN bit patterns go through the whole decoding path.
    const fs::path p =
        writeNrrd("allnan.nrrd", "double", {2, 2, 2}, encode(VoxelType::Float64, values, true), true, true);
    expectLoadError(p, {"finite"});
}

} // namespace
} // namespace volcast
