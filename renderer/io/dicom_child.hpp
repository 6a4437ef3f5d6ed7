#pragma once
// The caller's side of the checker process (dicom_check.hpp): the file parsed whole in
// `volcast-dicom-check`, under its own limits, which hands back the volume it loaded; the
// hand-back read as untrusted. Internal to renderer/io/.

#include "renderer/io/volume_checks.hpp"

#include <fcntl.h>
#include <stdlib.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>
#include <stdexcept>

namespace volcast::io {

// Whether ITK's factory would ask GDCM about this file (no other reader claims it).
bool reachesGdcm(const fs::path &path);

// The checker's hand-back in `from`, every field checked again; messages name `path`.
// `samples` false: the header only (its fields and the file's size checked). A plan's
// pixels are read from the files in the folder `path`, with `progress` where given.
Volume readCheckedVolume(const fs::path &path, const fs::path &from, const LoadOptions &options,
                         bool samples = true, LoadProgress *progress = nullptr);

// The bytes of the checker's hand-back of v as samples (what LoadOptions::maxResultBytes bounds).
uint64_t checkedResultBytes(const Volume &v);

// A result file of the caller's, removed however the load ends.
struct CheckedResultFile {
    fs::path path;
    CheckedResultFile() {
        std::string pattern = (fs::temp_directory_path() / "volcast-checked-XXXXXX").string();
        const int fd = ::mkostemp(pattern.data(), O_CLOEXEC);
        if (fd < 0) throw std::runtime_error("cannot create a file for the parser's result: " + std::string(std::strerror(errno)));
        ::close(fd);
        path = pattern;
    }
    ~CheckedResultFile() {
        std::error_code ec;
        fs::remove(path, ec);
    }
    CheckedResultFile(const CheckedResultFile &) = delete;
    CheckedResultFile &operator=(const CheckedResultFile &) = delete;
};

// The checker's refusal line (its mark, kind letter, number and message; without the newline)
// as the error a load throws, read as hostile (runChecker below). Internal; fuzzed by
// fuzz/fuzz_checker_refusal.cpp.
[[noreturn]] void throwRefusal(const fs::path &path, const LoadOptions &options, const std::string &line);

// Parses the file in the checker process. Returns when it loaded it (its volume, or with
// planAllowed and a folder it reads directly, its plan, is in `result`). When it refused it,
// throws the checker's own refusal: its words (read as hostile: one line, bounded, control
// characters and invalid UTF-8 replaced) and its kind (VolumeTooLarge, VolumeLoadTimeout,
// VolumeOverResultLimit or VolumeLoadError); the file is never parsed here. Any other end of
// the child (a signal, its memory limit) throws a VolumeLoadError saying so. planAllowed only
// where the folder outlives the reading of the result (never for a kept parse or an unpacked
// archive).
void runChecker(const fs::path &path, const LoadOptions &options, LoadProgress &progress, bool dicom,
                const fs::path &result, bool planAllowed = false);

// The load in this process (volume_io.cpp): the checker's own load, with dicomInChild false.
Volume loadVolumeHere(const fs::path &path, const LoadOptions &options, bool dicomInChild);

} // namespace volcast::io
