// A volume file as the loader reads it (loadVolume, through ITK), one file per input in a
// temporary folder. The first input byte picks the format, the rest is the file's bytes:
//   0 .nrrd  NRRD, header and data in one file
//   1 .nhdr  detached NRRD header; the folder holds data.raw (4 KiB) and data.raw.gz for it
//   2 .nii   NIfTI-1, header bytes and voxels
//   3 .mhd   MetaImage header; the folder holds data.raw for it
//   4 .mha   MetaImage, header and data in one file
// maxBytes is 1 MiB, so no input can make the loader allocate much.
// A file no other reader claims goes to the DICOM checker child process (volume_io.cpp); an
// ASan-built child costs ~0.3 s to start, and most mutated inputs are such files, which held
// the target at 30-140 runs a second. So DICOM fails closed here (the checker is pointed at a
// path that does not exist) unless VOLCAST_FUZZ_DICOM=1, as in fuzz_volume_checks; the child
// has tests of its own (tests/server/test_dicom_isolation.cpp).
// Invariants: only VolumeLoadError escapes, its message starts with the path; a loaded
// volume has positive dims within the limits, as many voxels as its dims say, all finite,
// finite positive spacings, an orthonormal direction, and a range and histogram that
// cover its voxels.

#include "fuzz/fuzz_check.hpp"
#include "renderer/io/volume_io.hpp"

#include <zlib.h>

#include <array>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <numeric>
#include <string>
#include <string_view>
#include <vector>

namespace fs = std::filesystem;
using namespace volcast;

namespace {
constexpr uint64_t kMaxBytes = 1 << 20;
constexpr std::array<const char *, 5> kNames = {"in.nrrd", "in.nhdr", "in.nii", "in.mhd", "in.mha"};

struct Folder {
    fs::path path;
    Folder() {
        // /dev/shm: one file written per input; keep it off the disk.
        const char *base = fs::is_directory("/dev/shm") ? "/dev/shm" : "/tmp";
        std::string pattern = std::string(base) + "/volcast-fuzz-volume-XXXXXX";
        if (!mkdtemp(pattern.data())) fuzz::fail("cannot create the temporary folder");
        path = pattern;
        std::vector<unsigned char> raw(4096);
        for (size_t i = 0; i < raw.size(); ++i) raw[i] = static_cast<unsigned char>(i * 7);
        std::ofstream(path / "data.raw", std::ios::binary).write(reinterpret_cast<const char *>(raw.data()), std::streamsize(raw.size()));
        gzFile gz = gzopen((path / "data.raw.gz").c_str(), "wb");
        if (!gz) fuzz::fail("cannot write data.raw.gz");
        gzwrite(gz, raw.data(), unsigned(raw.size()));
        gzclose(gz);
    }
    ~Folder() {
        std::error_code ec;
        fs::remove_all(path, ec);
    }
};
const Folder &folder() {
    static const Folder f;
    return f;
}
} // namespace

extern "C" int LLVMFuzzerInitialize(int *, char ***) {
    const char *dicom = std::getenv("VOLCAST_FUZZ_DICOM");
    if (!dicom || std::string_view(dicom) != "1") ::setenv("VOLCAST_DICOM_CHECK", "/nonexistent/volcast-dicom-check", 1);
    return 0;
}

extern "C" int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size) {
    if (size < 1) return 0;
    const fs::path file = folder().path / kNames[data[0] % kNames.size()];
    {
        std::ofstream out(file, std::ios::binary | std::ios::trunc);
        out.write(reinterpret_cast<const char *>(data + 1), std::streamsize(size - 1));
    }
    LoadOptions options;
    options.maxBytes = kMaxBytes;
    options.maxDimension = 4096;
    Volume v;
    try {
        v = loadVolume(file, options);
    } catch (const VolumeLoadError &e) {
        fuzz::check(std::string_view(e.what()).starts_with(file.string()), "a load error does not start with the path",
                    e.what());
        return 0;
    }
    fuzz::check(v.dims.x > 0 && v.dims.y > 0 && v.dims.z > 0, "a loaded volume has a non-positive dimension");
    fuzz::check(v.voxelCount() * sizeof(float) <= kMaxBytes, "a loaded volume is over maxBytes");
    fuzz::check(v.hasSamples(), "a loaded volume's sample count differs from its dims");
    const SampleGrid samples = v.samples();
    for (size_t i = 0; i < samples.count(); ++i)
        fuzz::check(std::isfinite(samples[i]), "a loaded volume holds a non-finite voxel");
    for (int a = 0; a < 3; ++a) {
        fuzz::check(std::isfinite(v.spacing[a]) && v.spacing[a] > 0, "a loaded volume has a bad spacing");
        fuzz::check(std::isfinite(v.origin[a]), "a loaded volume has a non-finite origin");
        for (int b = 0; b < 3; ++b) {
            double dot = 0;
            for (int r = 0; r < 3; ++r) dot += v.direction(r, a) * v.direction(r, b);
            // Re-orthonormalized exactly by the loader; 1e-9 is rounding of a 3x3 product.
            fuzz::check(std::abs(dot - (a == b ? 1.0 : 0.0)) < 1e-9, "a loaded volume's direction is not orthonormal");
        }
    }
    fuzz::check(v.range.min <= v.range.max, "a loaded volume's range is inverted");
    const uint64_t counted = std::accumulate(v.histogram.counts.begin(), v.histogram.counts.end(), uint64_t(0));
    fuzz::check(counted == v.voxelCount(), "a loaded volume's histogram does not count every voxel");
    return 0;
}
