#pragma once
// The ITK glue every format shares: the readers registered once, ITK's messages cleaned,
// voxel types in both directions, the voxels read into a Volume, the patient space a header
// states, and the load of one image file (NRRD, MetaImage, NIfTI or a single DICOM file)
// with each format's own checks before ITK reads it. Internal to renderer/io/.

#include "renderer/io/volume_checks.hpp"

#include <itkCommand.h>
#include <itkImageIOBase.h>
#include <itkProcessObject.h>

#include <exception>
#include <string>

namespace volcast::io {

// Forwards an ITK filter's ProgressEvent (a DICOM series: one per slice) into [from, to].
class ItkProgress : public itk::Command {
  public:
    using Self = ItkProgress;
    using Superclass = itk::Command;
    using Pointer = itk::SmartPointer<Self>;
    itkNewMacro(Self)

    LoadProgress *progress = nullptr;
    double from = 0, to = 1;
    std::string task;
    // What stopped the load (time limit, stop request): ITK may send progress from a
    // destructor, so nothing is thrown through it; the filter is aborted and the loader
    // rethrows this once Update() returns.
    std::exception_ptr stopped;

    void Execute(itk::Object *caller, const itk::EventObject &event) override {
        auto *filter = dynamic_cast<itk::ProcessObject *>(caller);
        if (!progress || !filter || stopped || !itk::ProgressEvent().CheckEvent(&event)) return;
        try {
            (*progress)(from + (to - from) * double(filter->GetProgress()), task);
        } catch (...) {
            stopped = std::current_exception();
            filter->AbortGenerateDataOn();
        }
    }
    void Execute(const itk::Object *, const itk::EventObject &) override {}

  protected:
    ItkProgress() = default;
};

// ITK's IO factories (NRRD, MetaImage, NIfTI, then GDCM), registered once.
void registerItkFactories();

// The lines of an ITK exception that say what went wrong.
std::string cleanItkMessage(const itk::ExceptionObject &e);

itk::IOComponentEnum itkComponentOf(VoxelType t);

// Calls f with a value of the C++ type that stores `t`.
template <typename F>
decltype(auto) withVoxelType(VoxelType t, F &&f) {
    switch (t) {
    case VoxelType::UInt8: return f(uint8_t{});
    case VoxelType::Int8: return f(int8_t{});
    case VoxelType::UInt16: return f(uint16_t{});
    case VoxelType::Int16: return f(int16_t{});
    case VoxelType::UInt32: return f(uint32_t{});
    case VoxelType::Int32: return f(int32_t{});
    case VoxelType::Float32: return f(float{});
    case VoxelType::Float64: return f(double{});
    }
    return f(float{});
}

// The header's voxel type, if one component of a supported type; else fails.
VoxelType checkedVoxelType(const fs::path &path, const itk::ImageIOBase &io);

// Reads all voxels of an IO whose header is read and validated into v (narrow or float32).
void readVoxels(const fs::path &path, itk::ImageIOBase &io, VoxelType type, Volume &v, LoadProgress &progress);

// Volume::orientationKnown, modality and modalityField from the header ITK read.
void readPatientSpace(const itk::ImageIOBase &io, Volume &v);

// One image file through ITK's image IO, every check of its format first.
Volume loadImageFile(const fs::path &path, const LoadOptions &options, LoadProgress &progress);

} // namespace volcast::io
