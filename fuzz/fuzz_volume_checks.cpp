// The loader's own checks on a volume file, without ITK: what renderer/io/ itself parses
// before and beside ITK's readers. fuzz_volume_header goes through ITK as well and runs at
// ~100 executions a second; this one runs the same functions of the loader alone, thousands
// of times faster, so they reach 1 M executions.
//
// The checks are internal to renderer/io/, so the loader's sources that hold them (and what
// those call) are included here whole: the target runs the very code the loader runs, with
// no copy and no change to the loader. This target is linked instead of volcast_renderer_io,
// never with it.
//
// One file per input in a folder in /dev/shm. Byte 0 picks the check, bytes 1-4 are the
// byte count the header's sizes would need (little-endian, below 1 MiB; ITK's part in the
// real loader), the rest is the file:
//   0 NRRD (in.nhdr)      scanNrrdHeader, confinedDataFile on every data file, checkNrrdData
//   1 MetaImage (in.mhd)  scanMetaHeader, confinedDataFile on every data file, checkMetaData
//   2 NIfTI (in.nii)      readNiftiHeader, checkNiftiData (single file, or with the n+1 magic off)
//   3 NIfTI pair (in.hdr) readNiftiHeader, checkNiftiData against in.img beside it
//   4 DICOM (in.dcm)      checkDicomSlice (GDCM reads up to the pixel data; our arithmetic after),
//                         only with VOLCAST_FUZZ_DICOM=1 in the environment: Debian's GDCM
//                         aborts on an assertion for some damaged files (README, finding 7),
//                         which the mutator finds within seconds; CI must not stop on that
//                         known, open finding, so plain runs skip these inputs.
//   5 a data file name    confinedDataFile on the rest as a name
// The folder beside the header holds data.raw (4 KiB), data.raw.gz, in.img, a subfolder,
// a FIFO, a link out of the folder, a link inside it and a dangling link; a file outside
// the folder (the "secret") must never be accepted as data.
// Invariants: only VolumeLoadError escapes and its message starts with the header's path
// and never names the folder's absolute path after it (client messages must not leak
// server paths); an accepted data file is a regular file inside the canonical folder; no
// check opens the FIFO (it would block: a libFuzzer timeout).

#include "renderer/io/dicom_identity.cpp"
#include "renderer/io/dicom_series.cpp"
#include "renderer/io/dicom_uncompressed.cpp"
#include "renderer/io/itk_reading.cpp"
#include "renderer/io/metaimage.cpp"
#include "renderer/io/nifti.cpp"
#include "renderer/io/nrrd.cpp"
#include "renderer/io/volume_checks.cpp"

#include "fuzz/fuzz_check.hpp"

#include <sys/stat.h>

#include <cstddef>
#include <cstdint>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <string>
#include <string_view>
#include <vector>

namespace {
namespace fs = std::filesystem;

constexpr std::array<const char *, 6> kNames = {"in.nhdr", "in.mhd", "in.nii", "in.hdr", "in.dcm", "in.nhdr"};

struct Folder {
    fs::path top;     // holds secret.raw, outside the header's folder
    fs::path folder;  // the header's folder (canonical)
    Folder() {
        const char *base = fs::is_directory("/dev/shm") ? "/dev/shm" : "/tmp";
        std::string pattern = std::string(base) + "/volcast-fuzz-checks-XXXXXX";
        if (!mkdtemp(pattern.data())) volcast::fuzz::fail("cannot create the temporary folder");
        top = fs::canonical(pattern);
        folder = top / "hdr";
        fs::create_directories(folder / "sub");
        std::vector<unsigned char> raw(4096);
        for (size_t i = 0; i < raw.size(); ++i) raw[i] = static_cast<unsigned char>(i * 7);
        const auto put = [&](const fs::path &p) {
            std::ofstream(p, std::ios::binary).write(reinterpret_cast<const char *>(raw.data()), std::streamsize(raw.size()));
        };
        put(folder / "data.raw");
        put(folder / "in.img");
        put(folder / "sub" / "data.raw");
        put(top / "secret.raw");
        gzFile gz = gzopen((folder / "data.raw.gz").c_str(), "wb");
        if (!gz) volcast::fuzz::fail("cannot write data.raw.gz");
        gzwrite(gz, raw.data(), unsigned(raw.size()));
        gzclose(gz);
        if (mkfifo((folder / "fifo.raw").c_str(), 0600) != 0) volcast::fuzz::fail("cannot make the FIFO");
        fs::create_symlink(top / "secret.raw", folder / "out.raw");
        fs::create_symlink("data.raw", folder / "in_link.raw");
        fs::create_symlink("missing.raw", folder / "dangling.raw");
    }
    ~Folder() {
        std::error_code ec;
        fs::remove_all(top, ec);
    }
};
const Folder &folder() {
    static const Folder f;
    return f;
}

// An accepted data file: a regular file inside the header's folder, never the secret.
void checkAccepted(const fs::path &resolved, const Folder &f) {
    volcast::fuzz::check(volcast::io::isInside(resolved, f.folder), "an accepted data file lies outside the header's folder",
                         resolved.string());
    volcast::fuzz::check(fs::is_regular_file(resolved), "an accepted data file is not a regular file", resolved.string());
}
} // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size) {
    using namespace volcast;
    using namespace volcast::io;
    if (size < 5) return 0;
    const Folder &f = folder();
    const unsigned pick = data[0] % kNames.size();
    const uint64_t need = (uint64_t(data[1]) | uint64_t(data[2]) << 8 | uint64_t(data[3]) << 16 |
                           uint64_t(data[4]) << 24) % (uint64_t(1) << 20);
    const std::string_view rest(reinterpret_cast<const char *>(data + 5), size - 5);
    static const bool dicom = [] {
        const char *v = std::getenv("VOLCAST_FUZZ_DICOM");
        return v && std::string_view(v) == "1";
    }();
    if (pick == 4 && !dicom) return 0;
    const fs::path header = f.folder / kNames[pick];
    if (pick != 5) {
        std::ofstream out(header, std::ios::binary | std::ios::trunc);
        out.write(rest.data(), std::streamsize(rest.size()));
    }
    const std::string shape = "fuzz shape";
    try {
        switch (pick) {
        case 0:
            if (const auto layout = scanNrrdHeader(header)) {
                for (const auto &name : layout->dataFiles) checkAccepted(confinedDataFile(header, name), f);
                checkNrrdData(header, *layout, need, shape);
            }
            break;
        case 1:
            if (const auto layout = scanMetaHeader(header)) {
                for (const auto &name : layout->dataFiles) checkAccepted(confinedDataFile(header, name), f);
                checkMetaData(header, *layout, need, shape);
            }
            break;
        case 2:
        case 3:
            checkNiftiData(header, readNiftiHeader(header));
            break;
        case 4:
            checkDicomSlice(f.folder, header, need);
            break;
        case 5:
            checkAccepted(confinedDataFile(header, std::string(rest)), f);
            break;
        }
    } catch (const VolumeLoadError &e) {
        const std::string_view message = e.what();
        const std::string_view prefix = pick == 4 ? std::string_view(f.folder.native()) : std::string_view(header.native());
        fuzz::check(message.starts_with(prefix), "a check's error does not start with the path", message);
        // A header may quote anything, the folder's name included: only a name the input lacks counts.
        fuzz::check(message.substr(prefix.size()).find(f.top.native()) == std::string_view::npos ||
                        rest.find(f.top.native()) != std::string_view::npos,
                    "a check's error names the server's absolute folder", message);
    }
    return 0;
}
