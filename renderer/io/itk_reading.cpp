// The ITK glue every format shares (itk_reading.hpp).

#include "renderer/io/itk_reading.hpp"
#include "renderer/io/dicom_series.hpp"
#include "renderer/io/metaimage.hpp"
#include "renderer/io/nifti.hpp"
#include "renderer/io/nrrd.hpp"

#include <itkGDCMImageIO.h>
#include <itkGDCMImageIOFactory.h>
#include <itkImageIOFactory.h>
#include <itkMetaDataObject.h>
#include <itkMetaImageIOFactory.h>
#include <itkNiftiImageIOFactory.h>
#include <itkNrrdImageIOFactory.h>
#include <spdlog/fmt/fmt.h>
#include <spdlog/spdlog.h>

#include <algorithm>
#include <bit>
#include <cmath>
#include <fstream>
#include <limits>
#include <optional>
#include <regex>
#include <type_traits>
#include <vector>

namespace volcast::io {
namespace {

// ---------------------------------------------------------------------------------------
// From ITK's header information to a validated Volume.

std::optional<VoxelType> voxelTypeOf(itk::IOComponentEnum t, size_t componentSize) {
    using C = itk::IOComponentEnum;
    switch (t) {
    case C::UCHAR: return VoxelType::UInt8;
    case C::CHAR: return VoxelType::Int8;
    case C::USHORT: return VoxelType::UInt16;
    case C::SHORT: return VoxelType::Int16;
    case C::UINT: return VoxelType::UInt32;
    case C::INT: return VoxelType::Int32;
    case C::ULONG: return componentSize == 4 ? std::optional(VoxelType::UInt32) : std::nullopt;
    case C::LONG: return componentSize == 4 ? std::optional(VoxelType::Int32) : std::nullopt;
    case C::FLOAT: return VoxelType::Float32;
    case C::DOUBLE: return VoxelType::Float64;
    default: return std::nullopt;
    }
}

// A header entry ITK keeps in the image IO's dictionary, as text whatever type ITK stored it
// as; empty when absent.
std::string headerText(const itk::MetaDataDictionary &dict, const std::string &key) {
    if (!dict.HasKey(key)) return {};
    std::string text;
    if (itk::ExposeMetaData<std::string>(dict, key, text)) {
        while (!text.empty() && (text.back() == ' ' || text.back() == '\0')) text.pop_back();
        return text;
    }
    int i = 0;  // ITK keeps NIfTI codes as int or short, by version
    if (itk::ExposeMetaData<int>(dict, key, i)) return std::to_string(i);
    short h = 0;
    if (itk::ExposeMetaData<short>(dict, key, h)) return std::to_string(h);
    return {};
}

} // namespace

// ITK's IO factories are registered explicitly (we do not use ITK_USE_FILE's generated
// registration); a function-local static makes it happen once, thread-safely.
void registerItkFactories() {
    static const bool registered = [] {
        itk::NrrdImageIOFactory::RegisterOneFactory();
        itk::MetaImageIOFactory::RegisterOneFactory();
        itk::NiftiImageIOFactory::RegisterOneFactory();
        itk::GDCMImageIOFactory::RegisterOneFactory();
        return true;
    }();
    (void)registered;
}

// ITK's messages carry the source location, the object address and teem's whole error
// stack; keep the lines that say what went wrong.
std::string cleanItkMessage(const itk::ExceptionObject &e) {
    static const std::regex itkPrefix(R"(^(itk::ERROR|ITK ERROR): \w+\(0x[0-9a-fA-F]+\): )");
    static const std::regex biffPrefix(R"(^\[\w+\] \w+:\s?)");
    std::string description = e.GetDescription();
    std::vector<std::string> kept;
    size_t start = 0;
    while (start <= description.size()) {
        size_t end = description.find('\n', start);
        if (end == std::string::npos) end = description.size();
        std::string line = trim(description.substr(start, end - start));
        start = end + 1;
        line = std::regex_replace(line, itkPrefix, "");
        line = trim(std::regex_replace(line, biffPrefix, ""));
        // Headlines ("Read: Error reading x:") and teem's "trouble" breadcrumbs say nothing.
        if (line.empty() || line.back() == ':' || line == "trouble" || line.starts_with("trouble reading"))
            continue;
        kept.push_back(line);
    }
    std::string out;
    for (const auto &line : kept) out += (out.empty() ? "" : "; ") + line;
    if (out.empty()) out = trim(description);
    if (out.size() > 400) out = out.substr(0, 400) + "...";
    return out;
}

itk::IOComponentEnum itkComponentOf(VoxelType t) {
    using C = itk::IOComponentEnum;
    switch (t) {
    case VoxelType::UInt8: return C::UCHAR;
    case VoxelType::Int8: return C::CHAR;
    case VoxelType::UInt16: return C::USHORT;
    case VoxelType::Int16: return C::SHORT;
    case VoxelType::UInt32: return C::UINT;
    case VoxelType::Int32: return C::INT;
    case VoxelType::Float32: return C::FLOAT;
    case VoxelType::Float64: return C::DOUBLE;
    }
    return C::UNKNOWNCOMPONENTTYPE;
}

VoxelType checkedVoxelType(const fs::path &path, const itk::ImageIOBase &io) {
    const auto components = io.GetNumberOfComponents();
    if (components != 1)
        fail(path, fmt::format("has {} components per voxel ({} data); only scalar volumes with one "
                               "component can be loaded",
                               components, itk::ImageIOBase::GetPixelTypeAsString(io.GetPixelType())));
    const auto componentType = io.GetComponentType();
    if (componentType == itk::IOComponentEnum::UNKNOWNCOMPONENTTYPE)
        fail(path, "voxel type is unknown or unsupported");
    const auto type = voxelTypeOf(componentType, io.GetComponentSize());
    if (!type)
        fail(path, fmt::format("voxel type '{}'{} is not supported (supported: int8, uint8, int16, uint16, "
                               "int32, uint32, float, double)",
                               itk::ImageIOBase::GetComponentTypeAsString(componentType),
                               io.GetComponentSize() == 8 ? " (64-bit integer)" : ""));
    return *type;
}

// Reads all voxels of an IO whose header is read and validated into v: an 8- or 16-bit
// file's straight into the narrow store (unsigned as they are, signed with the sign bit
// flipped, which is adding 2^7 or 2^15: offset −2^7 or −2^15), so that a 16-bit scan never
// takes float32's bytes, even while loading; every other type converted to float32.
void readVoxels(const fs::path &path, itk::ImageIOBase &io, VoxelType type, Volume &v, LoadProgress &progress) {
    static_assert(std::endian::native == std::endian::little, "the narrow store is little-endian (narrow_samples.hpp)");
    itk::ImageIORegion region(io.GetNumberOfDimensions());
    for (unsigned d = 0; d < io.GetNumberOfDimensions(); ++d) {
        region.SetIndex(d, 0);
        region.SetSize(d, io.GetDimensions(d));
    }
    io.SetIORegion(region);
    const size_t count = v.voxelCount();
    size_t clamped = 0;
    try {
        withVoxelType(type, [&](auto tag) {
            using T = decltype(tag);
            if constexpr (std::is_same_v<T, float>) {
                v.voxels.resize(count);
                io.Read(v.voxels.data());
            } else if constexpr (std::is_integral_v<T> && sizeof(T) <= 2) {
                v.narrowVoxels.assign(count * sizeof(T) + kNarrowSlack, 0);
                io.Read(v.narrowVoxels.data());
                progress(0.8, "converting");
                if constexpr (std::is_signed_v<T>) {
                    // Little-endian: the sign bit is in each sample's last byte.
                    for (size_t i = sizeof(T) - 1; i < count * sizeof(T); i += sizeof(T)) v.narrowVoxels[i] ^= 0x80;
                }
                v.narrow = {int(sizeof(T)), std::is_signed_v<T> ? -std::ldexp(1.0f, 8 * int(sizeof(T)) - 1) : 0.0f};
            } else {
                v.voxels.resize(count);
                std::vector<T> native(count);
                io.Read(native.data());
                const size_t chunk = std::max<size_t>(count / 16, 1);
                for (size_t i = 0; i < count; ++i) {
                    if (i % chunk == 0) progress(0.8 + 0.1 * double(i) / double(count), "converting");
                    if constexpr (std::is_same_v<T, double>) {
                        // Finite doubles beyond float's range would become Inf; clamp them instead.
                        constexpr double kMax = std::numeric_limits<float>::max();
                        const double x = native[i];
                        if (std::isfinite(x) && std::abs(x) > kMax) {
                            v.voxels[i] = float(std::clamp(x, -kMax, kMax));
                            ++clamped;
                        } else {
                            v.voxels[i] = float(x);
                        }
                    } else {
                        v.voxels[i] = float(native[i]);
                    }
                }
            }
        });
    } catch (const itk::ExceptionObject &e) {
        const std::string message = cleanItkMessage(e);
        const bool shortData = message.find("fread got only") != std::string::npos ||
                               message.find("but received") != std::string::npos;
        fail(path, (shortData ? "data is truncated: " : "cannot read the voxel data: ") + message);
    }
    if (clamped > 0)
        spdlog::warn("{}: clamped {} float64 voxels beyond the float32 range", path.string(), clamped);
}

// Whether the header names the patient space and which modality it states (see Volume).
// DICOM: image orientation (0020,0037) and modality (0008,0060). NRRD: a `space` field
// (ITK keeps it as NRRD_space). NIfTI: a qform or sform code other than 0 (unknown). A
// MetaImage without these, a NIfTI with both codes 0 or an NRRD without `space` keep their
// numbers as they are: ITK's direction is then no statement about the patient.
void readPatientSpace(const itk::ImageIOBase &io, Volume &v) {
    const itk::MetaDataDictionary &dict = io.GetMetaDataDictionary();
    const std::string ioName = io.GetNameOfClass();
    // The modality statement, fit for a sentence and the checker's hand-back: printable, short.
    const auto state = [&](const std::string &text, const char *field) {
        const std::string said = statedText(text);
        if (said.empty() || !v.modality.empty()) return;
        v.modality = said;
        v.modalityField = field;
    };
    if (ioName == "GDCMImageIO") {
        v.orientationKnown = !headerText(dict, "0020|0037").empty();
        state(headerText(dict, "0008|0060"), "DICOM");
    } else if (ioName == "NrrdImageIO") {
        v.orientationKnown = !headerText(dict, "NRRD_space").empty();
        // A key-value pair `modality:=CT` (any case of the key) states it; else the `content`
        // field (ITK keeps it as NRRD_content) may name it in words.
        for (const std::string &key : dict.GetKeys())
            if (lower(key) == "modality") state(headerText(dict, key), "NRRD key");
        state(headerText(dict, "NRRD_content"), "NRRD content");
    } else if (ioName == "NiftiImageIO") {
        // NIfTI's 80-byte description; ITK 5.2 keeps it as ITK_FileNotes (later versions also as descrip).
        state(headerText(dict, "descrip"), "NIfTI descrip");
        state(headerText(dict, "ITK_FileNotes"), "NIfTI descrip");
        const auto coded = [&](const char *code, const char *name) {
            const std::string n = headerText(dict, name);
            if (!n.empty()) return n.find("UNKNOWN") == std::string::npos;
            const std::string c = headerText(dict, code);
            return !c.empty() && c != "0";
        };
        v.orientationKnown = coded("qform_code", "qform_code_name") || coded("sform_code", "sform_code_name");
    }
}

Volume loadImageFile(const fs::path &path, const LoadOptions &options, LoadProgress &progress) {
    {
        std::ifstream probe(path, std::ios::binary);
        if (!probe) fail(path, "cannot be opened (check its permissions)");
    }
    if (fileSize(path).value_or(0) == 0) fail(path, "is an empty file, not a volume");
    itk::ImageIOBase::Pointer io =
        itk::ImageIOFactory::CreateImageIO(path.string().c_str(), itk::IOFileModeEnum::ReadMode);
    if (!io)
        fail(path, "is not a volume file in a supported format (NRRD, MetaImage, NIfTI or DICOM): its "
                   "contents were not recognised");
    const std::string ioName = io->GetNameOfClass();

    // Every detached data file is confined to the header's folder and must be a regular
    // file, checked before ITK opens any of them (a missing one is named here too, before
    // ITK reports it in its own words).
    std::optional<NrrdLayout> nrrd;
    std::optional<MetaLayout> meta;
    std::optional<NiftiHeader> nifti;
    // A file from outside (LoadOptions::parseInChild) comes alone: nothing beside it is its data.
    const auto carried = [&](const std::string &name) {
        if (options.parseInChild)
            fail(path, fmt::format("an upload must carry its data: the header names a separate data file '{}'; "
                                   "send one file that holds its voxels (.nrrd, .mha or .nii)",
                                   name));
    };
    if (ioName == "NrrdImageIO") {
        nrrd = scanNrrdHeader(path);
        if (nrrd)
            for (const auto &name : nrrd->dataFiles) {
                carried(name);
                confinedDataFile(path, name);
            }
    } else if (ioName == "MetaImageIO") {
        meta = scanMetaHeader(path);
        if (meta)
            for (const auto &name : meta->dataFiles) {
                carried(name);
                confinedDataFile(path, name);
            }
    } else if (ioName == "NiftiImageIO") {
        nifti = readNiftiHeader(path);  // fields checked before niftilib trusts them
        if (!nifti->singleFile) carried(path.stem().string() + ".img");
    }

    TemporaryLink alias;
    const fs::path readPath = ioName == "NiftiImageIO" ? niftiReadPath(path, alias) : path;
    io->SetFileName(readPath.string());
    try {
        io->ReadImageInformation();
    } catch (const itk::ExceptionObject &e) {
        fail(path, "cannot read the header: " + cleanItkMessage(e));
    }

    // Validate everything the header says before any voxel memory is allocated.
    const unsigned nd = io->GetNumberOfDimensions();
    if (nd < 2)
        fail(path, fmt::format("is a {}-D image; only 3-D volumes (or a 2-D image as one slice) can be loaded", nd));
    for (unsigned d = 3; d < nd; ++d)
        if (io->GetDimensions(d) != 1)
            fail(path, fmt::format("is a {}-D image (axis {} has size {}); only 3-D volumes can be loaded", nd, d,
                                   io->GetDimensions(d)));
    const VoxelType type = checkedVoxelType(path, *io);
    Volume v;
    for (unsigned a = 0; a < 3; ++a) {
        const uint64_t size = a < nd ? uint64_t(io->GetDimensions(a)) : 1;
        v.dims[int(a)] = size > uint64_t(std::numeric_limits<int64_t>::max()) ? -1 : int64_t(size);
    }
    if (nrrd)
        for (size_t a = 0; a < nrrd->sizes.size(); ++a) {
            const uint64_t itkSize = a < nd ? uint64_t(io->GetDimensions(unsigned(a))) : 1;
            if (nrrd->sizes[a] != itkSize)
                fail(path, fmt::format("NRRD header's sizes give axis {} {} samples, but ITK read {} (it keeps a "
                                       "size in 32 bits): the header is refused",
                                       a, nrrd->sizes[a], itkSize));
        }
    checkShape(path, v.dims, options);
    Mat3d direction;
    for (unsigned a = 0; a < 3 && a < nd; ++a) {
        v.spacing[int(a)] = io->GetSpacing(a);
        v.origin[int(a)] = io->GetOrigin(a);
        const std::vector<double> column = io->GetDirection(a);
        for (unsigned r = 0; r < 3 && r < column.size(); ++r) direction(int(r), int(a)) = column[r];
    }
    v.direction = checkedGeometry(path, v.spacing, v.origin, direction);
    v.sourceType = type;
    readPatientSpace(*io, v);

    if (auto *dicom = dynamic_cast<itk::GDCMImageIO *>(io.GetPointer()))
        checkDicomSlice(path, path, uint64_t(v.voxelCount()) * storedDicomSize(*dicom));

    // The data must hold exactly what the header promises (see the byte-count helpers).
    const uint64_t need = uint64_t(v.voxelCount()) * voxelTypeSize(type);
    const std::string shape =
        fmt::format("{} x {} x {} {}", v.dims.x, v.dims.y, v.dims.z, voxelTypeName(type));
    // Counting a gzip stream's bytes inflates it once: about half of what reading it costs.
    progress(0.02, "checking data");
    if (nrrd) checkNrrdData(path, *nrrd, need, shape);
    if (meta) checkMetaData(path, *meta, need, shape);
    if (nifti) checkNiftiData(path, *nifti);

    progress(0.35, "reading voxels");
    readVoxels(path, *io, type, v, progress);
    return v;
}

} // namespace volcast::io
