#pragma once
// What the volume loader's tests (test_volume_io_*.cpp) share: the real scans' folder, files
// written byte by byte, the fixture that gives each test a fresh temp folder, and the checks
// of a refusal's message, of voxels and of geometry.

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

namespace volcast::volume_io_test {

namespace fs = std::filesystem;

// The real scans (MANIFEST.md there) live outside the repository: the CMake variable or
// environment variable VOLCAST_DATA_DIR names their folder (tests/README.md). Without it the
// tests that read them skip and say why; every other test makes its files itself. Defined in
// test_volume_io_real_scans.cpp, the one file compiled with VOLCAST_DATA_DIR.
extern const fs::path kDataDir;

#define SKIP_WITHOUT_SCANS()                                                                   \
    if (!fs::is_regular_file(kDataDir / "MANIFEST.md"))                                       \
    GTEST_SKIP() << "needs the real scans, and " << kDataDir.string() << " has no MANIFEST.md: " \
                 << "configure with -DVOLCAST_DATA_DIR=/path/to/scans (tests/README.md)"

static_assert(std::endian::native == std::endian::little, "the byte-order helpers assume a little-endian host");

// ---------------------------------------------------------------------------------------
// Helpers

inline std::string lowerCase(std::string s) {
    std::transform(s.begin(), s.end(), s.begin(), [](unsigned char c) { return char(std::tolower(c)); });
    return s;
}

inline std::string readFile(const fs::path &p) {
    std::ifstream in(p, std::ios::binary);
    std::ostringstream ss;
    ss << in.rdbuf();
    return ss.str();
}

inline void writeFile(const fs::path &p, const std::string &bytes) {
    std::ofstream out(p, std::ios::binary);
    out.write(bytes.data(), std::streamsize(bytes.size()));
}

// One gzip stream (zlib's deflate with a gzip wrapper), as NRRD's "encoding: gzip" wants.
inline std::string gzipBytes(const std::string &in) {
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
inline void appendScalar(std::string &out, T value, bool bigEndian) {
    char b[sizeof(T)];
    std::memcpy(b, &value, sizeof(T));
    if (bigEndian) std::reverse(b, b + sizeof(T));
    out.append(b, sizeof(T));
}

template <typename F>
inline void withType(VoxelType t, F &&f) {
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
inline std::string encode(VoxelType t, const std::vector<double> &values, bool bigEndian) {
    std::string out;
    withType(t, [&](auto tag) {
        using T = decltype(tag);
        for (double x : values) appendScalar(out, T(x), bigEndian);
    });
    return out;
}

// Test values for a 5 x 4 x 3 volume of type t: the type's extremes first (sign and width
// handling), then a ramp inside the range; every value but float64's is exact in float32.
inline std::vector<double> testValues(VoxelType t, size_t count) {
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
inline void expectLoadError(const fs::path &path, std::initializer_list<const char *> words, const LoadOptions &options = {}) {
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

constexpr Vec3i kDims{5, 4, 3};  // small, and different per axis so a swapped axis shows
constexpr size_t kCount = 5 * 4 * 3;

inline void expectVoxels(const Volume &v, VoxelType type, const std::vector<double> &values) {
    ASSERT_EQ(v.dims, kDims);
    EXPECT_EQ(v.sourceType, type) << voxelTypeName(v.sourceType);
    const std::vector<float> samples = v.samples().toFloats();
    ASSERT_EQ(samples.size(), values.size());
    // The loader converts each native value with a plain float cast (or, 8 and 16 bits, holds
    // it narrow, which widens to the same float), so the expectation is the same cast of the
    // written value: exact equality.
    for (size_t i = 0; i < values.size(); ++i) EXPECT_EQ(samples[i], float(values[i])) << "voxel " << i;
}

// Geometry read back from text written with 17 significant digits: equal within 1e-12
// (ITK normalizes each space direction, which costs a few ULPs).
inline void expectGeometry(const Volume &v, const Vec3d &spacing, const Vec3d &origin, const Mat3d &direction,
                    double tolerance = 1e-12) {
    for (int a = 0; a < 3; ++a) {
        EXPECT_NEAR(v.spacing[a], spacing[a], tolerance * std::max(1.0, spacing[a])) << "spacing " << a;
        EXPECT_NEAR(v.origin[a], origin[a], tolerance * std::max(1.0, std::abs(origin[a]))) << "origin " << a;
        for (int r = 0; r < 3; ++r)
            EXPECT_NEAR(v.direction(r, a), direction(r, a), tolerance) << "direction " << r << "," << a;
    }
}

// Rotation by `degrees` about a unit axis (Rodrigues), an oblique orientation.
inline Mat3d rotation(Vec3d axis, double degrees) {
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

} // namespace volcast::volume_io_test
