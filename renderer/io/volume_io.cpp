// Loading volumes (volume_io.hpp): which way a file or folder goes. Each format lies in its
// own file (nrrd, metaimage, nifti, dicom_series), read through the ITK glue they share
// (itk_reading), after the checks that need no ITK (volume_checks); a file from outside is
// parsed first in the checker process (dicom_child). Writing: volume_write.cpp.

#include "renderer/io/volume_io.hpp"
#include "renderer/io/dicom_child.hpp"
#include "renderer/io/dicom_series.hpp"
#include "renderer/io/itk_reading.hpp"
#include "renderer/io/volume_checks.hpp"
#include "renderer/io/zip_extract.hpp"

#include <itkMacro.h>
#include <spdlog/fmt/fmt.h>
#include <spdlog/spdlog.h>

#include <fcntl.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>
#include <new>
#include <optional>

namespace volcast {
namespace io {

Volume loadVolumeHere(const fs::path &path, const LoadOptions &options, bool dicomInChild) {
    registerItkFactories();
    std::error_code ec;
    const auto status = fs::status(path, ec);
    if (!fs::exists(status)) fail(path, "file not found");
    // stat() only: opening a FIFO would block the loader until someone writes to it.
    if (!fs::is_regular_file(status) && !fs::is_directory(status))
        fail(path, "is not a regular file or a folder (a FIFO, socket or device); it is not loaded");
    try {
        LoadProgress progress(options, path);
        progress(0, "reading header");
        const bool folder = fs::is_directory(status);
        const bool zip = !folder && isZipName(path);
        if (options.seriesStack && !folder && !zip)
            fail(path, fmt::format("is not a DICOM series: a stack (#stack={}) is chosen only within a series",
                                   *options.seriesStack));
        std::optional<Volume> checked;
        if (dicomInChild) {
            // A file from outside is not even sniffed here (ITK's CanReadFile reads, and for a
            // .nii.gz inflates, its start): it goes to the checker whatever it is.
            const bool dicom = folder || zip ||
                               (!options.parseInChild && fileSize(path).value_or(0) > 0 && reachesGdcm(path));
            if (dicom || options.parseInChild) {
                const CheckedResultFile result;
                // A folder's uncompressed series may come back as a plan: its pixels copied
                // here from the files, straight into the volume. A refusal throws the
                // checker's own words: the file is never parsed in this process.
                runChecker(path, options, progress, dicom, result.path, folder);
                progress(0.8, "reading the parsed volume");
                checked = readCheckedVolume(path, result.path, options, true, &progress);
            }
        }
        Volume v = checked ? std::move(*checked)
                   : folder ? loadDicomFolder(path, options, progress)
                   : zip    ? loadZippedSeries(path, options, progress)
                            : loadImageFile(path, options, progress);
        v.name = displayName(path);
        progress(0.9, "statistics");
        if (!checked && !v.voxels.empty()) v.nonFiniteReplaced = replaceNonFinite(path, v.voxels);
        // In the checker (dicomInChild false) they would be computed twice: its caller computes
        // them again from the hand-back, which it does not trust.
        if (dicomInChild) computeStatistics(v);
        holdNarrow(v); // a float file (or a DICOM series, rescaled) whose samples are 8- or 16-bit integers
        // The checker's hand-back would outgrow the room its caller has: refused before any of it is written.
        if (const uint64_t needed = checkedResultBytes(v); needed > options.maxResultBytes)
            throw VolumeOverResultLimit(
                fmt::format("{}: would need {} of upload storage once parsed; {} left; it is not loaded", path.string(),
                            humanBytes(needed), humanBytes(options.maxResultBytes)),
                needed, options.maxResultBytes);
        progress(1, "statistics");
        spdlog::debug("{}: loaded {} x {} x {} {} voxels, spacing {} {} {}, range {} .. {}", path.string(), v.dims.x,
                      v.dims.y, v.dims.z, voxelTypeName(v.sourceType), v.spacing.x, v.spacing.y, v.spacing.z,
                      v.range.min, v.range.max);
        return v;
    } catch (const VolumeLoadError &) {
        throw;
    } catch (const itk::ExceptionObject &e) {
        fail(path, "cannot be read: " + cleanItkMessage(e));
    } catch (const std::bad_alloc &) {
        throw LoadOutOfMemory(path.string() + ": not enough memory to load the volume");
    } catch (const std::exception &e) {
        fail(path, std::string("cannot be read: ") + e.what());
    }
}

} // namespace io

using namespace io; // the loader's internals (renderer/io/*.hpp)

Volume loadVolume(const fs::path &path, const LoadOptions &options) {
    return loadVolumeHere(path, options, true);
}

ParsedVolumeSummary parseToKeep(const fs::path &path, const fs::path &keep, const LoadOptions &options) {
    // O_EXCL: the checker writes only into a file made here, never through a name that was there.
    const int fd = ::open(keep.c_str(), O_WRONLY | O_CREAT | O_EXCL | O_NOFOLLOW | O_CLOEXEC, 0600);
    if (fd < 0) fail(path, fmt::format("cannot make the file for its parsed volume: {}", std::strerror(errno)));
    ::close(fd);
    struct RemoveUnlessKept {
        const fs::path &keep;
        bool kept = false;
        ~RemoveUnlessKept() {
            std::error_code ec;
            if (!kept) fs::remove(keep, ec);
        }
    } guard{keep};
    try {
        LoadProgress progress(options, path);
        progress(0, "reading header");
        std::error_code ec;
        const auto status = fs::status(path, ec);
        if (!fs::exists(status)) fail(path, "file not found");
        if (!fs::is_regular_file(status) && !fs::is_directory(status))
            fail(path, "is not a regular file or a folder (a FIFO, socket or device); it is not loaded");
        // Not sniffed here (see loadVolumeHere): only a folder or a .zip is taken for DICOM.
        const bool dicom = fs::is_directory(status) || isZipName(path);
        // A refusal throws the checker's own words: the file is never parsed in this process.
        runChecker(path, options, progress, dicom, keep);
        const Volume v = readCheckedVolume(path, keep, options, false);
        progress(1, "parsed");
        guard.kept = true;
        return {{v.dims.x, v.dims.y, v.dims.z}, v.sourceType};
    } catch (const VolumeLoadError &) {
        throw;
    } catch (const std::bad_alloc &) {
        throw LoadOutOfMemory(path.string() + ": not enough memory to load the volume");
    } catch (const std::exception &e) {
        fail(path, std::string("cannot be read: ") + e.what());
    }
}

Volume loadParsedVolume(const fs::path &keep, const fs::path &shownAs, const LoadOptions &options) {
    try {
        LoadProgress progress(options, shownAs);
        progress(0.8, "reading the parsed volume");
        Volume v = readCheckedVolume(shownAs, keep, options);
        v.name = displayName(shownAs);
        progress(0.9, "statistics");
        computeStatistics(v);
        holdNarrow(v);
        progress(1, "statistics");
        return v;
    } catch (const VolumeLoadError &) {
        throw;
    } catch (const std::bad_alloc &) {
        throw LoadOutOfMemory(shownAs.string() + ": not enough memory to load the volume");
    } catch (const std::exception &e) {
        fail(shownAs, std::string("cannot be read: ") + e.what());
    }
}

} // namespace volcast
