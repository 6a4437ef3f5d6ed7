// DICOM series: the folder, the slices, the stack (dicom_series.hpp).

#include "renderer/io/dicom_series.hpp"
#include "renderer/io/dicom_identity.hpp"
#include "renderer/io/dicom_uncompressed.hpp"
#include "renderer/io/itk_reading.hpp"
#include "renderer/io/zip_extract.hpp"

#include <itkGDCMSeriesFileNames.h>
#include <itkImage.h>
#include <itkImageSeriesReader.h>
#include <spdlog/fmt/fmt.h>
#include <spdlog/spdlog.h>
#include <gdcmExplicitDataElement.h>
#include <gdcmImplicitDataElement.h>
#include <gdcmReader.h>

#include <stdlib.h>

#include <algorithm>
#include <cctype>
#include <cerrno>
#include <cmath>
#include <cstdlib>
#include <cstring>
#include <exception>
#include <fstream>
#include <vector>

namespace volcast::io {

// Every entry of a DICOM folder must be a regular file or a folder that stays inside it:
// GDCM opens each file to scan it, and a FIFO would block the loader.
void checkDicomFolderEntries(const fs::path &dir) {
    std::error_code ec;
    const fs::path folder = fs::canonical(dir, ec);
    if (ec) fail(dir, "folder cannot be resolved: " + ec.message());
    for (fs::directory_iterator it(folder, ec), end; !ec && it != end; it.increment(ec)) {
        const std::string name = it->path().filename().string();
        std::error_code ec2;
        const fs::path resolved = fs::weakly_canonical(it->path(), ec2);
        if (ec2 || !isInside(resolved, folder))
            fail(dir, fmt::format("'{}' in the folder is a symbolic link that leads out of it", name));
        const auto status = fs::status(resolved, ec2);
        if (!ec2 && !fs::is_regular_file(status) && !fs::is_directory(status))
            fail(dir, fmt::format("'{}' in the folder is not a regular file (a FIFO, socket or device)", name));
    }
}

StackFiles checkDicomFolder(const fs::path &dir, const LoadOptions &options, LoadProgress &progress) {
    checkDicomFolderEntries(dir);
    return checkSeriesIdentity(dir, readInstanceHeaders(dir, progress), options.expectedSeries, options.seriesStack);
}

namespace {

// The numbers of a DS (decimal string) element, or nothing when it is absent or does not hold
// exactly N finite numbers (decimalStrings).
template <size_t N>
std::optional<std::array<double, N>> elementDecimals(const gdcm::DataSet &ds, gdcm::Tag tag) {
    if (!ds.FindDataElement(tag)) return std::nullopt;
    const gdcm::ByteValue *value = ds.GetDataElement(tag).GetByteValue();
    if (!value) return std::nullopt;
    return decimalStrings<N>(std::string_view(value->GetPointer(), value->GetLength()));
}

int64_t unsignedShort(const gdcm::DataSet &ds, gdcm::Tag tag) {
    if (!ds.FindDataElement(tag)) return 0;
    const gdcm::ByteValue *value = ds.GetDataElement(tag).GetByteValue();
    if (!value || value->GetLength() != 2) return 0;
    const auto *b = reinterpret_cast<const unsigned char *>(value->GetPointer());
    return int64_t(b[0] | b[1] << 8);   // US in the little-endian transfer syntaxes GDCM reads here
}

// The slices of one series must form one regular stack, as the volume that comes out of them
// assumes: the same size and orientation, positions along the slice normal with even gaps and
// none repeated, and no drift within the plane (a gantry tilt shears the stack, which an
// orthonormal direction matrix cannot hold). Otherwise the picture would be wrong without a
// word: a missing slice squeezes the anatomy, two stacks interleave. Slices are in the order
// GDCM's series reader will read them. The tolerance, 0.01 mm or 1 % of the gap if larger,
// is what 3D Slicer's DICOM import allows before it warns of irregular geometry (positions are
// decimal strings of at most 16 characters, so rounding alone stays far below it).
void checkSeriesGeometry(const fs::path &dir, const std::vector<SliceGeometry> &slices) {
    if (slices.size() < 2) return;
    const SliceGeometry &first = slices.front();
    for (const SliceGeometry &s : slices)
        if (s.rows != first.rows || s.columns != first.columns)
            fail(dir, fmt::format("slice '{}' is {} x {} pixels where slice '{}' is {} x {}: the folder mixes images "
                                  "of different sizes; it is not loaded",
                                  s.file, s.columns, s.rows, first.file, first.columns, first.rows));
    const auto located = std::count_if(slices.begin(), slices.end(),
                                       [](const SliceGeometry &s) { return s.position && s.orientation; });
    if (located == 0) return;   // no patient geometry at all (secondary capture): ITK's own spacing
    for (const SliceGeometry &s : slices)
        if (!s.position || !s.orientation)
            fail(dir, fmt::format("slice '{}' has no image position or orientation where the others have them; "
                                  "the stack cannot be placed, and it is not loaded",
                                  s.file));
    const auto &o = *first.orientation;
    const Vec3d row{o[0], o[1], o[2]}, column{o[3], o[4], o[5]};
    const Vec3d normal = cross(row, column);
    if (std::abs(length(normal) - 1) > 1e-3)
        fail(dir, fmt::format("slice '{}' has an image orientation whose row and column are not perpendicular unit "
                              "vectors; it is not loaded",
                              first.file));
    for (const SliceGeometry &s : slices)
        for (size_t i = 0; i < 6; ++i)
            if (std::abs((*s.orientation)[i] - o[i]) > 1e-4)
                fail(dir, fmt::format("slice '{}' is oriented differently from slice '{}': the folder mixes stacks "
                                      "(or a scout image); it is not loaded",
                                      s.file, first.file));
    std::vector<double> gaps;
    for (size_t i = 1; i < slices.size(); ++i) gaps.push_back(dot(*slices[i].position - *slices[i - 1].position, normal));
    std::vector<double> sorted = gaps;
    std::nth_element(sorted.begin(), sorted.begin() + ptrdiff_t(sorted.size() / 2), sorted.end());
    const double typical = sorted[sorted.size() / 2];
    const double tolerance = std::max(0.01, 0.01 * std::abs(typical));
    for (size_t i = 0; i < gaps.size(); ++i) {
        const SliceGeometry &a = slices[i], &b = slices[i + 1];
        if (std::abs(gaps[i]) <= tolerance)
            fail(dir, fmt::format("slices '{}' and '{}' lie at the same position: the folder holds a slice twice or "
                                  "two stacks; it is not loaded",
                                  a.file, b.file));
        if (std::abs(gaps[i] - typical) > tolerance)
            fail(dir, fmt::format("the gap between slices '{}' and '{}' is {:.4g} mm where the series' others are "
                                  "{:.4g} mm: a slice is missing or the stack is irregular; it is not loaded",
                                  a.file, b.file, std::abs(gaps[i]), std::abs(typical)));
        const Vec3d step = *b.position - *a.position;
        const Vec3d inPlane = step - normal * dot(step, normal);
        if (length(inPlane) > tolerance)
            fail(dir, fmt::format("slice '{}' is shifted {:.4g} mm within the plane from slice '{}': a tilted gantry "
                                  "or sheared stack, which is not supported; it is not loaded",
                                  b.file, length(inPlane), a.file));
    }
}

// The files (and their geometry) ascending along the first slice's normal, as GDCM's series
// scan orders one stack; left as they are where a slice is not located.
void sortAlongNormal(std::vector<std::string> &files, std::vector<SliceGeometry> &geometry) {
    for (const SliceGeometry &s : geometry)
        if (!s.position || !s.orientation) return;
    const auto &o = *geometry.front().orientation;
    const Vec3d normal = cross(Vec3d{o[0], o[1], o[2]}, Vec3d{o[3], o[4], o[5]});
    std::vector<size_t> order(files.size());
    for (size_t i = 0; i < order.size(); ++i) order[i] = i;
    std::stable_sort(order.begin(), order.end(), [&](size_t a, size_t b) {
        return dot(*geometry[a].position, normal) < dot(*geometry[b].position, normal);
    });
    std::vector<std::string> sortedFiles;
    std::vector<SliceGeometry> sortedGeometry;
    for (const size_t i : order) {
        sortedFiles.push_back(std::move(files[i]));
        sortedGeometry.push_back(std::move(geometry[i]));
    }
    files = std::move(sortedFiles);
    geometry = std::move(sortedGeometry);
}

} // namespace

std::optional<UncompressedSeries> placedUncompressedSeries(const fs::path &dir, const LoadOptions &options,
                                                          LoadProgress &progress, Volume &v, const StackFiles &only) {
    std::string why;
    auto series = scanUncompressedSeries(dir, why, only);
    if (!series) {
        spdlog::debug("{}: read through GDCM ({})", dir.string(), why);
        return std::nullopt;
    }
    placeUncompressedSeries(dir, *series, v);
    checkShape(dir, v.dims, options);
    progress(0.01, "checking slices");
    std::vector<SliceGeometry> geometry;
    for (const UncompressedSlice &s : series->slices)
        geometry.push_back({s.file, s.position, s.orientation, s.rows, s.columns});
    checkSeriesGeometry(dir, geometry);
    return series;
}

// GDCM reads a slice whose pixel data is cut short as if the missing bytes were zero, so the
// loader compares each slice's file size with the length its pixel data element declares,
// and that length with what rows, columns and bits allocated need. Encapsulated
// (compressed) pixel data has no declared length and is left to GDCM's decoder.
SliceGeometry checkDicomSlice(const fs::path &dir, const fs::path &file, uint64_t need) {
    const std::string name = file.filename().string();
    const gdcm::Tag pixelData(0x7fe0, 0x0010);
    gdcm::Reader reader;
    reader.SetFileName(file.string().c_str());
    // The pixel data element as a tag to skip: its value is not read (a damaged header may
    // declare 4 GiB of it, which GDCM would allocate and fill before this check could refuse).
    if (!reader.ReadUpToTag(pixelData, {pixelData}))
        fail(dir, fmt::format("slice '{}' is not a readable DICOM file (its header is damaged or cut short)", name));
    // The pixel data element starts after the file meta header and every element before it.
    const gdcm::File &dicom = reader.GetFile();
    SliceGeometry geometry;
    geometry.file = name;
    {
        const gdcm::DataSet &ds = dicom.GetDataSet();
        if (const auto p = elementDecimals<3>(ds, gdcm::Tag(0x0020, 0x0032))) geometry.position = Vec3d{(*p)[0], (*p)[1], (*p)[2]};
        geometry.orientation = elementDecimals<6>(ds, gdcm::Tag(0x0020, 0x0037));
        geometry.rows = unsignedShort(ds, gdcm::Tag(0x0028, 0x0010));
        geometry.columns = unsignedShort(ds, gdcm::Tag(0x0028, 0x0011));
    }
    const bool implicitVr =
        dicom.GetHeader().GetDataSetTransferSyntax().GetNegociatedType() == gdcm::TransferSyntax::Implicit;
    uint64_t at = dicom.GetHeader().GetFullLength();
    for (const gdcm::DataElement &de : dicom.GetDataSet().GetDES()) {
        if (!(de.GetTag() < pixelData)) break;
        at += implicitVr ? uint64_t(static_cast<const gdcm::ImplicitDataElement &>(de).GetLength())
                         : uint64_t(static_cast<const gdcm::ExplicitDataElement &>(de).GetLength());
    }
    const uint64_t size = fileSize(file).value_or(0);
    std::array<unsigned char, 12> e{};
    std::ifstream in(file, std::ios::binary);
    in.seekg(std::streamoff(at));
    in.read(reinterpret_cast<char *>(e.data()), std::streamsize(e.size()));
    const bool bigEndian = e[0] == 0x7f && e[1] == 0xe0;
    const auto u16 = [&](size_t i) { return bigEndian ? uint16_t(e[i] << 8 | e[i + 1]) : uint16_t(e[i] | e[i + 1] << 8); };
    const auto u32 = [&](size_t i) {
        return bigEndian ? uint32_t(e[i]) << 24 | uint32_t(e[i + 1]) << 16 | uint32_t(e[i + 2]) << 8 | e[i + 3]
                         : uint32_t(e[i]) | uint32_t(e[i + 1]) << 8 | uint32_t(e[i + 2]) << 16 | uint32_t(e[i + 3]) << 24;
    };
    if (size < at + 8) fail(dir, fmt::format("slice '{}' is truncated: it ends before its pixel data", name));
    // A layout this count does not follow (no preamble, say) is left to GDCM.
    if (u16(0) != 0x7fe0 || u16(2) != 0x0010) return geometry;
    // Explicit VR (OB/OW/...: two letters, two reserved bytes, 32-bit length) or implicit.
    const bool explicitVr = !implicitVr && std::isupper(e[4]) && std::isupper(e[5]);
    if (explicitVr && size < at + 12)
        fail(dir, fmt::format("slice '{}' is truncated: it ends within its pixel data header", name));
    const uint32_t length = explicitVr ? u32(8) : u32(4);
    if (length == 0xffffffffu) return geometry;
    const uint64_t start = at + (explicitVr ? 12 : 8);
    const uint64_t have = size > start ? size - start : 0;
    if (have < length)
        fail(dir, fmt::format("slice '{}' is truncated: its pixel data holds {} bytes of the {} it declares", name,
                              withThousands(have), withThousands(length)));
    if (length < need)
        fail(dir, fmt::format("slice '{}' is truncated: its pixel data declares {} bytes, but its rows, columns "
                              "and type need {}",
                              name, withThousands(length), withThousands(need)));
    return geometry;
}

// Bytes of one stored DICOM pixel (before ITK applies the rescale slope and intercept).
uint64_t storedDicomSize(itk::GDCMImageIO &io) {
    using C = itk::IOComponentEnum;
    switch (io.GetInternalComponentType()) {
    case C::UCHAR: case C::CHAR: return 1;
    case C::USHORT: case C::SHORT: return 2;
    case C::UINT: case C::INT: case C::FLOAT: return 4;
    default: return 8;
    }
}

// Reads the series' samples as T into v (its dims already set from the first slice), with
// the geometry ITK computed from the slice positions.
template <class T>
void readSeriesSamples(const fs::path &dir, itk::GDCMImageIO *io, const std::vector<std::string> &files,
                       LoadProgress &progress, Volume &v) {
    using Image = itk::Image<T, 3>;
    auto reader = itk::ImageSeriesReader<Image>::New();
    reader->SetImageIO(io);
    reader->SetFileNames(files);
    auto observer = ItkProgress::New();
    observer->progress = &progress;
    observer->from = 0.02;
    observer->to = 0.9;
    observer->task = "reading slices";
    reader->AddObserver(itk::ProgressEvent(), observer);
    progress(0.02, "reading slices");
    try {
        reader->Update();
    } catch (const itk::ExceptionObject &e) {
        if (observer->stopped) std::rethrow_exception(observer->stopped);
        fail(dir, "cannot read the DICOM series: " + cleanItkMessage(e));
    }
    if (observer->stopped) std::rethrow_exception(observer->stopped);
    const Image *image = reader->GetOutput();
    const auto size = image->GetLargestPossibleRegion().GetSize();
    if (int64_t(size[0]) != v.dims.x || int64_t(size[1]) != v.dims.y || int64_t(size[2]) != v.dims.z)
        fail(dir, fmt::format("DICOM series came out {} x {} x {}, but its first slice and file count say {} x {} x {}",
                              size[0], size[1], size[2], v.dims.x, v.dims.y, v.dims.z));
    Mat3d direction;
    for (int a = 0; a < 3; ++a) {
        v.spacing[a] = image->GetSpacing()[unsigned(a)];
        v.origin[a] = image->GetOrigin()[unsigned(a)];
        for (int r = 0; r < 3; ++r) direction(r, a) = image->GetDirection()(unsigned(r), unsigned(a));
    }
    v.direction = checkedGeometry(dir, v.spacing, v.origin, direction);
    // Narrow as holdNarrow keeps them (8- and 16-bit integers always are), without a float
    // copy of the whole volume first.
    storeSamples(v, image->GetBufferPointer());
}

Volume loadDicomFolder(const fs::path &dir, const LoadOptions &options, LoadProgress &progress) {
    const StackFiles only = checkDicomFolder(dir, options, progress);
    // Uncompressed slices of one series are read straight from their files; any other
    // series through ITK and GDCM, below.
    Volume v;
    if (const auto series = placedUncompressedSeries(dir, options, progress, v, only)) {
        readUncompressedSamples(dir, *series, progress, 0.02, 0.9, v);
        return v;
    }
    auto names = itk::GDCMSeriesFileNames::New();
    names->SetUseSeriesDetails(true);
    names->SetDirectory(dir.string());
    // GDCM's parts of the folder, each the files of the selected stack alone where one is.
    std::vector<std::vector<std::string>> parts;
    for (const std::string &uid : names->GetSeriesUIDs()) {
        std::vector<std::string> part = names->GetFileNames(uid);
        if (only)
            std::erase_if(part, [&](const std::string &file) {
                return !std::binary_search(only->begin(), only->end(), fs::path(file).filename().string());
            });
        if (!part.empty()) parts.push_back(std::move(part));
    }
    if (parts.empty()) fail(dir, "folder holds no DICOM series (no DICOM image files were found in it)");
    std::vector<std::string> files = parts.front();
    // checkDicomFolder let one series through; GDCM's scan splits it further by series
    // number, sequence name and slice thickness, and loading one part would be a silent subset.
    if (parts.size() > 1)
        fail(dir, fmt::format("the series' slices differ in series number, sequence name or slice thickness, "
                              "which splits them into {} stacks; one volume shows one stack, and it is not loaded",
                              parts.size()));
    // One file may be a multi-frame volume on its own.
    if (files.size() == 1) {
        try {
            return loadImageFile(fs::path(files.front()), options, progress);
        } catch (const VolumeLoadError &e) {
            fail(dir, e.what());  // keeps the promise that messages start with the path given
        }
    }

    auto io = itk::GDCMImageIO::New();
    io->SetFileName(files.front());
    try {
        io->ReadImageInformation();
    } catch (const itk::ExceptionObject &e) {
        fail(dir, fmt::format("cannot read the DICOM header of '{}': {}", fs::path(files.front()).filename().string(),
                              cleanItkMessage(e)));
    }
    if (io->GetNumberOfDimensions() > 2 && io->GetDimensions(2) != 1)
        fail(dir, "series of multi-frame DICOM files are not supported (each file holds several slices)");
    const VoxelType type = checkedVoxelType(dir, *io);
    v.dims = {int64_t(io->GetDimensions(0)), int64_t(io->GetDimensions(1)), int64_t(files.size())};
    checkShape(dir, v.dims, options);
    // The stored pixels of one slice, before ITK's rescaling: rows x columns x stored size.
    const uint64_t sliceBytes = uint64_t(v.dims.x) * uint64_t(v.dims.y) * storedDicomSize(*io);
    progress(0.01, "checking slices");
    std::vector<SliceGeometry> geometry;
    for (const auto &file : files) geometry.push_back(checkDicomSlice(dir, fs::path(file), sliceBytes));
    // GDCM orders a part by position only where all its files share an orientation; a stack
    // taken out of a part with another stack is ordered here, along its own normal.
    if (only) sortAlongNormal(files, geometry);
    checkSeriesGeometry(dir, geometry);

    // Read as the type GDCM gives after rescaling: asking ITK for floats made it convert every
    // sample (half the checker's time on a 16-bit series), and a float copy had to be narrowed
    // again. Integers of 8 or 16 bits go straight to the narrow store; anything else as float.
    using C = itk::IOComponentEnum;
    switch (io->GetComponentType()) {
    case C::CHAR: readSeriesSamples<int8_t>(dir, io, files, progress, v); break;
    case C::UCHAR: readSeriesSamples<uint8_t>(dir, io, files, progress, v); break;
    case C::SHORT: readSeriesSamples<int16_t>(dir, io, files, progress, v); break;
    case C::USHORT: readSeriesSamples<uint16_t>(dir, io, files, progress, v); break;
    default: readSeriesSamples<float>(dir, io, files, progress, v); break;
    }
    v.sourceType = type;
    readPatientSpace(*io, v);
    return v;
}

Volume loadZippedSeries(const fs::path &path, const LoadOptions &options, LoadProgress &progress) {
    std::string pattern = (path.parent_path() / (path.filename().string() + ".unpacked-XXXXXX")).string();
    if (!::mkdtemp(pattern.data())) fail(path, fmt::format("cannot be unpacked: {}", std::strerror(errno)));
    const fs::path folder = pattern;
    struct Remove {
        fs::path folder;
        ~Remove() {
            std::error_code ec;
            fs::remove_all(folder, ec);
        }
    } remove{folder};
    progress(0, "unpacking the archive");
    ZipLimits limits;
    limits.maxBytes = options.maxArchiveBytes;
    try {
        extractZip(path, folder, limits, path.string());
    } catch (const ZipError &e) {
        throw VolumeLoadError(e.what());
    }
    // The series' messages name entries as archive/entry_00003.
    const auto named = [&](const std::string &message) {
        std::string out = message;
        for (size_t at; (at = out.find(folder.string())) != std::string::npos;)
            out.replace(at, folder.string().size(), path.string());
        return out;
    };
    try {
        return loadDicomFolder(folder, options, progress);
    } catch (const VolumeTooLarge &e) {
        throw VolumeTooLarge(named(e.what()), e.bytes);
    } catch (const VolumeLoadTimeout &e) {
        throw VolumeLoadTimeout(named(e.what()), e.limitSeconds);
    } catch (const LoadOutOfMemory &) {
        throw;
    } catch (const SeriesHoldsStacks &e) {
        throw SeriesHoldsStacks(named(e.what()), e.stacks);
    } catch (const VolumeLoadError &e) {
        throw VolumeLoadError(named(e.what()));
    }
}

} // namespace volcast::io
