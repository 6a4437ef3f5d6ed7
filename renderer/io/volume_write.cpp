// Writing volumes through ITK (volume_io.hpp: saveVolume, saveDicomSeries).

#include "renderer/io/volume_io.hpp"
#include "renderer/io/itk_reading.hpp"

#include <itkGDCMImageIO.h>
#include <itkImageIOFactory.h>
#include <itkMetaDataObject.h>
#include <spdlog/fmt/fmt.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <type_traits>
#include <vector>

namespace volcast {
namespace io {
namespace {

template <typename T>
std::vector<T> convertForWriting(const SampleGrid &samples, size_t first, size_t count) {
    std::vector<T> out(count);
    for (size_t i = 0; i < count; ++i) {
        const float s = samples[first + i];
        if constexpr (std::is_floating_point_v<T>) {
            out[i] = T(s);
        } else {
            const double x = std::isnan(s) ? 0.0 : std::nearbyint(double(s));
            out[i] = T(std::clamp(x, double(std::numeric_limits<T>::lowest()), double(std::numeric_limits<T>::max())));
        }
    }
    return out;
}

std::string dicomNumber(double x) { return fmt::format("{:.10g}", x); }

} // namespace
} // namespace io

using namespace io; // the loader's internals (itk_reading.hpp)

void saveVolume(const Volume &v, const fs::path &path, const SaveOptions &options) {
    registerItkFactories();
    const auto saveFail = [&](const std::string &problem) {
        throw VolumeSaveError(path.string() + ": " + problem);
    };
    if (v.voxelCount() == 0 || !v.hasSamples())
        saveFail("volume has no voxels, or fewer voxels than its dims say");
    const std::string name = lower(path.filename().string());
    const bool known = name.ends_with(".nrrd") || name.ends_with(".nhdr") || name.ends_with(".mha") ||
                       name.ends_with(".mhd") || name.ends_with(".nii") || name.ends_with(".nii.gz");
    if (!known) saveFail("unsupported extension (use .nrrd, .nhdr, .mha, .mhd, .nii or .nii.gz)");
    try {
        itk::ImageIOBase::Pointer io =
            itk::ImageIOFactory::CreateImageIO(path.string().c_str(), itk::IOFileModeEnum::WriteMode);
        if (!io) saveFail("no ITK writer accepts this file name");
        io->SetNumberOfDimensions(3);
        itk::ImageIORegion region(3);
        for (unsigned a = 0; a < 3; ++a) {
            io->SetDimensions(a, itk::SizeValueType(v.dims[int(a)]));
            io->SetSpacing(a, v.spacing[int(a)]);
            io->SetOrigin(a, v.origin[int(a)]);
            io->SetDirection(a, std::vector<double>{v.direction(0, int(a)), v.direction(1, int(a)),
                                                     v.direction(2, int(a))});
            region.SetIndex(a, 0);
            region.SetSize(a, itk::SizeValueType(v.dims[int(a)]));
        }
        io->SetPixelType(itk::IOPixelEnum::SCALAR);
        io->SetNumberOfComponents(1);
        io->SetComponentType(itkComponentOf(options.type));
        io->SetUseCompression(options.compress);
        io->SetFileName(path.string());
        io->SetIORegion(region);
        withVoxelType(options.type, [&](auto tag) {
            const auto buffer = convertForWriting<decltype(tag)>(v.samples(), 0, v.voxelCount());
            io->WriteImageInformation();
            io->Write(buffer.data());
        });
    } catch (const VolumeSaveError &) {
        throw;
    } catch (const itk::ExceptionObject &e) {
        saveFail(cleanItkMessage(e));
    } catch (const std::exception &e) {
        saveFail(e.what());
    }
}

void saveDicomSeries(const Volume &v, const fs::path &folder, VoxelType type) {
    registerItkFactories();
    const auto saveFail = [&](const std::string &problem) {
        throw VolumeSaveError(folder.string() + ": " + problem);
    };
    if (type == VoxelType::Float32 || type == VoxelType::Float64)
        saveFail("DICOM series are written with integer voxels; choose an integer type");
    if (v.voxelCount() == 0 || !v.hasSamples())
        saveFail("volume has no voxels, or fewer voxels than its dims say");
    try {
        fs::create_directories(folder);
        // One IO for every slice: it generates the study and series UIDs once and keeps them.
        auto io = itk::GDCMImageIO::New();
        const std::string orientation =
            fmt::format("{}\\{}\\{}\\{}\\{}\\{}", dicomNumber(v.direction(0, 0)), dicomNumber(v.direction(1, 0)),
                        dicomNumber(v.direction(2, 0)), dicomNumber(v.direction(0, 1)),
                        dicomNumber(v.direction(1, 1)), dicomNumber(v.direction(2, 1)));
        const size_t sliceCount = size_t(v.dims.x * v.dims.y);
        for (int64_t k = 0; k < v.dims.z; ++k) {
            const Vec3d position = v.worldFromIndex({0, 0, double(k)});
            itk::MetaDataDictionary dict;
            // CT Image Storage: GDCM ignores the position and orientation of secondary-capture
            // images, which is what it writes for other modalities.
            itk::EncapsulateMetaData<std::string>(dict, "0008|0060", "CT");
            itk::EncapsulateMetaData<std::string>(dict, "0028|0004", "MONOCHROME2");
            itk::EncapsulateMetaData<std::string>(dict, "0020|0013", std::to_string(k + 1));
            itk::EncapsulateMetaData<std::string>(
                dict, "0020|0032",
                fmt::format("{}\\{}\\{}", dicomNumber(position.x), dicomNumber(position.y), dicomNumber(position.z)));
            itk::EncapsulateMetaData<std::string>(dict, "0020|0037", orientation);
            itk::EncapsulateMetaData<std::string>(dict, "0018|0050", dicomNumber(v.spacing.z));
            itk::EncapsulateMetaData<std::string>(dict, "0018|0088", dicomNumber(v.spacing.z));
            io->SetMetaDataDictionary(dict);
            io->SetNumberOfDimensions(2);
            itk::ImageIORegion region(2);
            for (unsigned a = 0; a < 2; ++a) {
                io->SetDimensions(a, itk::SizeValueType(v.dims[int(a)]));
                io->SetSpacing(a, v.spacing[int(a)]);
                io->SetOrigin(a, position[int(a)]);
                region.SetIndex(a, 0);
                region.SetSize(a, itk::SizeValueType(v.dims[int(a)]));
            }
            io->SetPixelType(itk::IOPixelEnum::SCALAR);
            io->SetNumberOfComponents(1);
            io->SetComponentType(itkComponentOf(type));
            io->SetIORegion(region);
            io->SetFileName((folder / fmt::format("slice_{:04d}.dcm", k)).string());
            withVoxelType(type, [&](auto tag) {
                const auto buffer =
                    convertForWriting<decltype(tag)>(v.samples(), size_t(k) * sliceCount, sliceCount);
                io->WriteImageInformation();
                io->Write(buffer.data());
            });
        }
    } catch (const VolumeSaveError &) {
        throw;
    } catch (const itk::ExceptionObject &e) {
        saveFail(cleanItkMessage(e));
    } catch (const std::exception &e) {
        saveFail(e.what());
    }
}

} // namespace volcast
