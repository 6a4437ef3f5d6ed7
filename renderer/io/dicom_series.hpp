#pragma once
// A DICOM series given as a folder (or packed as a .zip): the folder's entries, each slice's
// pixel data length, the stack's geometry, then ITK's series reader. Internal to renderer/io/.

#include "renderer/io/dicom_uncompressed.hpp"
#include "renderer/io/volume_checks.hpp"

#include <itkGDCMImageIO.h>

#include <array>
#include <optional>

namespace volcast::io {

// Where one slice of a series lies, as its header says (absent values stay empty).
struct SliceGeometry {
    std::string file;
    std::optional<Vec3d> position;                 // Image Position (Patient), mm
    std::optional<std::array<double, 6>> orientation;   // Image Orientation (Patient): row, then column cosines
    int64_t rows = 0, columns = 0;
};

// The slice holds the pixel data its header declares, and at least `need` bytes of it; else
// fails naming the slice. Returns where the slice lies.
SliceGeometry checkDicomSlice(const fs::path &dir, const fs::path &file, uint64_t need);

// Every entry of the folder a regular file or a folder inside it (GDCM would block on a FIFO).
void checkDicomFolderEntries(const fs::path &dir);

// What every DICOM folder meets before either read path: its entries (checkDicomFolderEntries),
// then its instances' headers, one series of one patient in one stack, of the requested
// series where LoadOptions::expectedSeries names one (dicom_identity.hpp). Where
// LoadOptions::seriesStack selects a stack, the names of its files (sorted: the lookups of the
// read paths are binary searches), which alone are read.
using StackFiles = std::optional<std::vector<std::string>>;
StackFiles checkDicomFolder(const fs::path &dir, const LoadOptions &options, LoadProgress &progress);

// The folder's series when the direct reader takes it (dicom_uncompressed.hpp), checked as
// any series is (its shape against the budget, its slices' geometry) and v placed; no
// samples yet. Nothing when the series goes through GDCM. `only`: checkDicomFolder's answer.
std::optional<UncompressedSeries> placedUncompressedSeries(const fs::path &dir, const LoadOptions &options,
                                                          LoadProgress &progress, Volume &v, const StackFiles &only);

// Bytes of one stored DICOM pixel (before ITK applies the rescale slope and intercept).
uint64_t storedDicomSize(itk::GDCMImageIO &io);

// The folder's one series (checkDicomFolder), every check first.
Volume loadDicomFolder(const fs::path &dir, const LoadOptions &options, LoadProgress &progress);

// A DICOM series packed as a .zip: unpacked into a fresh folder beside it (private to the
// caller: the upload folder), loaded as a folder, the folder removed whatever happens. The
// loader's messages name the archive, not the folder.
Volume loadZippedSeries(const fs::path &path, const LoadOptions &options, LoadProgress &progress);

} // namespace volcast::io
