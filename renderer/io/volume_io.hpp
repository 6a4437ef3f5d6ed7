#pragma once
// Loading volumes from files through ITK's image IO: NRRD (.nrrd, detached .nhdr; raw or
// gzip; either byte order), MetaImage (.mhd, .mha), NIfTI-1 (.nii, .nii.gz) and a DICOM
// series given as a folder.
//
// Non-finite voxels policy: NaN becomes the smallest finite value of the volume, +Inf the
// largest and -Inf the smallest; the count is kept in Volume::nonFiniteReplaced and a
// warning is logged. A volume with no finite voxel is rejected.
//
// What is accepted:
// - Scalar images only (exactly one component per voxel); RGB, vector, tensor and complex
//   images are rejected.
// - 3-D images; a 2-D image is a volume of one slice (dims.z = 1, z spacing 1); images of
//   more dimensions only when every axis beyond the third has size 1.
// - Voxel types int8/uint8/int16/uint16/int32/uint32/float32/float64. 64-bit integers are
//   rejected. int32/uint32 values above 2^24 and float64 values lose precision in float32;
//   float64 values beyond the float32 range are clamped to it (and logged). ITK applies
//   NIfTI scl_slope/scl_inter and DICOM rescale slope/intercept itself; sourceType is then
//   the type ITK reports for the rescaled values (float32 for a scaled NIfTI).
// - Detached data files (NRRD `data file:` in each of its forms, MetaImage
//   `ElementDataFile`, a NIfTI .img) must lie in the header's folder once symbolic links
//   are resolved (no absolute name, no `..`, no link out), be regular files and not the
//   header's own file; a file from outside (parseInChild) may name none at all. The file or
//   folder given must be a regular file or a folder. This is checked with stat() before
//   anything is opened, so a FIFO never blocks the loader.
// - NIfTI headers are checked against the specification (sizeof_hdr, dim, datatype and
//   bitpix, vox_offset, pixdim); each DICOM slice must hold all the pixel data its header
//   promises.
// - Geometry is ITK's: files that name a patient space (NRRD `space` RAS/LAS/LPS, NIfTI,
//   DICOM) come out in LPS world coordinates; files without one keep their numbers. The
//   direction matrix must be orthonormal within 1e-3 (it is then re-orthonormalized
//   exactly, keeping its handedness); spacings must be finite and > 0.
// - The data on disk must hold exactly what the header promises: ITK silently accepts a
//   raw or gzip NRRD longer than its header says, and reads truncated MetaImage and NIfTI
//   files into garbage, so the loader checks the byte counts itself before reading.
// - x.nii.gz lying beside an x.nii is read through a temporary link: niftilib, given
//   x.nii.gz, would take its header but x.nii's voxels.
// - A folder is read as a DICOM series, and it must hold one series of one patient that one
//   volume can show (dicom_identity.hpp), else it is refused naming the first instance that
//   differs and the field: one PatientID (and PatientName, IssuerOfPatientID where stated), one
//   study, one series, one frame of reference, no SOPInstanceUID twice, one size and
//   orientation (a localizer or a second stack is refused with SeriesHoldsStacks, listing
//   the stacks, never a subset loaded unasked), finite image orientation and position where
//   stated; with LoadOptions::expectedSeries, every instance of the requested study and
//   series. A folder holding several series is refused naming how many. With
//   LoadOptions::seriesStack, the series (checked whole as above) is read as that one of its
//   stacks, which must itself be one regular stack.
// - A .zip file is a DICOM series packed: unpacked (zip_extract.hpp: entry names ignored,
//   links refused, entries, bytes and ratio bounded) into a fresh folder beside it, loaded as
//   a folder, and the folder removed. Like every folder it is parsed first in the checker.

#include "renderer/model/volume.hpp"

#include <array>
#include <cstdint>
#include <filesystem>
#include <functional>
#include <optional>
#include <string>
#include <string_view>
#include <stdexcept>
#include <vector>

namespace volcast {

// The study and series a series was asked for by (a PACS's answer is checked against them).
struct SeriesIdentity {
    std::string studyUid;    // (0020,000D) StudyInstanceUID
    std::string seriesUid;   // (0020,000E) SeriesInstanceUID
};

// One stack of a DICOM series (one size and orientation): what SeriesHoldsStacks lists and
// LoadOptions::seriesStack selects. Stacks are numbered from 1 by their slice count, largest
// first (then rows, columns and orientation), so a number names the same stack however the
// files are named or ordered.
struct SeriesStack {
    uint32_t number = 0;
    uint32_t slices = 0;
    int64_t rows = 0, columns = 0;
    // "axial", "coronal" or "sagittal" where the slices' normal lies within 30 degrees of that
    // axis, "oblique" otherwise, "unknown" where the slices state no orientation.
    std::string orientation;
    bool localizer = false;   // one to three slices beside a larger stack: a scout image
    bool operator==(const SeriesStack &) const = default;
};

struct LoadOptions {
    uint64_t maxBytes = uint64_t(8) << 30;  // in-memory size (float32 voxels) allowed, bytes
    int64_t maxDimension = 32768;           // samples per axis allowed
    // Called on the loading thread as the load advances: the fraction done in [0, 1], never
    // decreasing, ending at 1, and what is happening now ("checking data", "reading voxels",
    // "reading slices", "converting", "statistics"). The fractions weigh the steps by their
    // usual share of the time; a DICOM series advances slice by slice.
    std::function<void(double fraction, std::string_view task)> progress;
    // A load still running after this many seconds fails with VolumeLoadTimeout at its next
    // progress step (between steps, and slice by slice in a DICOM series; one read of the
    // voxels is not interrupted, and every file read is a regular file, so none blocks
    // forever). 0: no limit.
    double timeLimitSeconds = 0;
    // Asked at every progress step; true ends the load with VolumeLoadError (a server
    // shutting down).
    std::function<bool()> stopRequested;
    // Every file, whatever its format, is parsed in the checker process only, not only what
    // reaches GDCM (dicom_check.hpp): for bytes from a browser or a PACS, hostile until a parse
    // has survived. A crash or runaway parse then ends the child and the load fails saying so;
    // a file the checker refuses fails with the checker's own words, and this process never
    // parses it (nor sniffs its format). A header naming a separate data file is refused.
    bool parseInChild = false;
    // A .zip (a DICOM series) unpacks to at most this many bytes (zip_extract.hpp).
    uint64_t maxArchiveBytes = uint64_t(8) << 30;
    // A DICOM folder retrieved as this study and series: every instance must belong to them,
    // or the load is refused (a PACS that answered another series, or mixed one in).
    std::optional<SeriesIdentity> expectedSeries;
    // The one stack of a DICOM series to read (SeriesStack::number), asked for by name; the
    // whole series is still checked as one series of one patient. Anything but a DICOM series
    // is refused with it.
    std::optional<uint32_t> seriesStack;
    // The checker's hand-back (parseToKeep's kept file) may be at most this many bytes: the
    // room left in the caller's storage. A volume needing more is refused with
    // VolumeOverResultLimit once its size is known, before any of it is written.
    uint64_t maxResultBytes = UINT64_MAX;
};

// Every failure to load: the message starts with the file's path and names the problem.
struct VolumeLoadError : std::runtime_error {
    using std::runtime_error::runtime_error;
};

// The header's sizes need more than LoadOptions::maxBytes (refused before any voxel is read).
struct VolumeTooLarge : VolumeLoadError {
    VolumeTooLarge(const std::string &message, uint64_t float32Bytes)
        : VolumeLoadError(message), bytes(float32Bytes) {}
    uint64_t bytes;   // the volume's size as float32 voxels
};

// The parsed volume needs more than LoadOptions::maxResultBytes.
struct VolumeOverResultLimit : VolumeLoadError {
    VolumeOverResultLimit(const std::string &message, uint64_t neededBytes, uint64_t limitBytes)
        : VolumeLoadError(message), needed(neededBytes), limit(limitBytes) {}
    uint64_t needed, limit;
};

// A DICOM series holding more than one stack, without LoadOptions::seriesStack (or with one
// it does not hold): the stacks it holds, the largest SeriesHoldsStacks::kMaxListed of them.
struct SeriesHoldsStacks : VolumeLoadError {
    static constexpr size_t kMaxListed = 32;
    SeriesHoldsStacks(const std::string &message, std::vector<SeriesStack> held)
        : VolumeLoadError(message), stacks(std::move(held)) {}
    std::vector<SeriesStack> stacks;
};

// The load ran past LoadOptions::timeLimitSeconds.
struct VolumeLoadTimeout : VolumeLoadError {
    VolumeLoadTimeout(const std::string &message, double limit) : VolumeLoadError(message), limitSeconds(limit) {}
    double limitSeconds;
};

Volume loadVolume(const std::filesystem::path &path, const LoadOptions &options = {});

// A file from outside parsed once however often it is opened (an upload): parseToKeep parses
// it in the checker process only, as LoadOptions::parseInChild does, and keeps what the child
// handed back in the new file `keep` (made here, 0600; removed again when the parse fails),
// reading back only its header; loadParsedVolume loads that file later, checking every field
// again (the child that wrote it parsed hostile bytes) and computing the statistics. Both
// throw as loadVolume does; `shownAs` is the path the messages and the volume's name use.
struct ParsedVolumeSummary {
    std::array<int64_t, 3> dims{};
    VoxelType sourceType = VoxelType::Float32;
};
ParsedVolumeSummary parseToKeep(const std::filesystem::path &path, const std::filesystem::path &keep,
                                const LoadOptions &options = {});
Volume loadParsedVolume(const std::filesystem::path &keep, const std::filesystem::path &shownAs,
                        const LoadOptions &options = {});

// Writing volumes through ITK, for exports and for building test fixtures in every format
// the loader reads. Voxels are converted to `type` (integers: rounded and clamped to the
// type's range, NaN as 0). Geometry (spacing, origin, direction) is written as ITK does.
struct SaveOptions {
    VoxelType type = VoxelType::Float32;
    bool compress = false;  // gzip/zlib where the format allows it (.nii.gz always is)
};

// Every failure to save: the message starts with the file's path.
struct VolumeSaveError : std::runtime_error {
    using std::runtime_error::runtime_error;
};

// Format from the extension: .nrrd, .nhdr, .mha, .mhd, .nii, .nii.gz.
void saveVolume(const Volume &v, const std::filesystem::path &path, const SaveOptions &options = {});

// One DICOM file per z slice (slice_0000.dcm, ...) in `folder` (created if missing), all in
// one new series, with image position/orientation so that loading the folder gives back
// the volume's geometry. `type` must be an integer type.
void saveDicomSeries(const Volume &v, const std::filesystem::path &folder,
                     VoxelType type = VoxelType::Int16);

} // namespace volcast
