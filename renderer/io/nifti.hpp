#pragma once
// NIfTI-1/2 (.nii, .nii.gz, .hdr/.img): the header read and checked against the
// specification by the loader itself, the data's byte count, and the read through a link
// when x.nii lies beside x.nii.gz. Internal to renderer/io/.

#include "renderer/io/volume_checks.hpp"

#include <array>

namespace volcast::io {

struct NiftiHeader {
    std::array<int64_t, 8> dim{};
    int bitpix = 0;
    uint64_t voxOffset = 0;
    bool singleFile = false;
    uint64_t bytes = 0;   // voxel bytes the dims and bitpix promise
    std::string shape;
};

// The header's fields, each checked before niftilib trusts it; else fails naming the field.
NiftiHeader readNiftiHeader(const fs::path &path);

// The data (in the file, or the .img beside a .hdr) holds what the header promises.
void checkNiftiData(const fs::path &path, const NiftiHeader &n);

// A private temporary folder holding a link to the file being read; removed on scope exit.
struct TemporaryLink {
    fs::path folder;
    fs::path link;
    TemporaryLink() = default;
    TemporaryLink(const TemporaryLink &) = delete;
    TemporaryLink &operator=(const TemporaryLink &) = delete;
    ~TemporaryLink() {
        std::error_code ec;
        if (!folder.empty()) fs::remove_all(folder, ec);
    }
};

// The path to hand niftilib: `path`, or a link to it in `alias` when x.nii lies beside x.nii.gz.
fs::path niftiReadPath(const fs::path &path, TemporaryLink &alias);

} // namespace volcast::io
