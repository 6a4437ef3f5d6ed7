// The volume registry on its own (server/volume_registry.cpp): the memory budget's edges,
// the load time limit, and the messages clients get. Built-in volumes (64³: 1.2 MiB counted
// each, float32 plus 20 %) and small files the tests write; budgets of a few MiB.

#include "renderer/cpu/cpu_renderer.hpp"
#include "renderer/io/volume_io.hpp"
#include "renderer/common/mip_pyramid.hpp"
#include "server/volume_registry.hpp"
#include "tests/dicom_tags.hpp"
#include "tests/server/registry_fixture.hpp"

#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>

namespace {

namespace fs = std::filesystem;
using volcast::test::kMiB;
using volcast::test::entryOf;
using volcast::test::loadFailure;
using volcast::test::openNow;

class VolumeRegistryTest : public volcast::test::RegistryTest {
  protected:
    // A uint8 NRRD of dims x*y*z: counted as about 2.7 * x*y*z*4 bytes once loaded (float32
    // voxels, mips, the renderer's padded copies, level 0's in 8 bits, and coefficients:
    // CpuRenderer::plannedBytes).
    void writeVolume(const std::string &name, int x, int y, int z) {
        volcast::Volume v;
        v.dims = {x, y, z};
        v.voxels.resize(v.voxelCount());
        for (size_t i = 0; i < v.voxels.size(); ++i) v.voxels[i] = float(i % 251);
        volcast::saveVolume(v, data / name, {volcast::VoxelType::UInt8, false});
    }
};

TEST_F(VolumeRegistryTest, VolumeLargerThanTheWholeBudgetIsRefusedSayingSo) {
    auto r = registry(1 * kMiB);
    // builtin:sphere (64³, float32) counts 2.5 MiB.
    const std::string builtin = loadFailure(openNow(*r, "builtin:sphere"));
    for (const char *words : {"needs 3 MiB", "whole memory budget of 1 MiB", "--memory-budget-mib"})
        EXPECT_NE(builtin.find(words), std::string::npos) << "no '" << words << "' in: " << builtin;
    // A file is refused from its header: its data file here holds 10 bytes of the 16 MiB the
    // header promises, and the message is about the budget, not the truncated data (64 MiB
    // of float32 voxels, times 1.5: the least an 8-bit scan and the renderer's copies take).
    std::ofstream(data / "big.nhdr") << "NRRD0004\ntype: uint8\ndimension: 3\nsizes: 256 256 256\nencoding: raw\n"
                                        "data file: big.raw\n";
    std::ofstream(data / "big.raw") << "0123456789";
    const std::string file = loadFailure(openNow(*r, "big.nhdr"));
    for (const char *words : {"big.nhdr", "needs 96 MiB", "whole memory budget of 1 MiB", "--memory-budget-mib"})
        EXPECT_NE(file.find(words), std::string::npos) << "no '" << words << "' in: " << file;
    EXPECT_EQ(file.find("truncated"), std::string::npos) << file;
}

TEST_F(VolumeRegistryTest, FailedLoadEvictsNothing) {
    auto r = registry(10 * kMiB);
    const auto held = entryOf(openNow(*r, "builtin:sphere"));   // 2.5 MiB, held
    entryOf(openNow(*r, "builtin:gaussian_blob"));                // 2.5 MiB, unused at once
    ASSERT_TRUE(r->isLoaded("builtin:gaussian_blob"));
    // 128 x 128 x 80 uint8 voxels count 8.3 MiB: it would fit only by evicting both, and the
    // sphere is held, so it fails, and the unused blob must still be there.
    writeVolume("wide.nrrd", 128, 128, 80);
    const std::string message = loadFailure(openNow(*r, "wide.nrrd"));
    EXPECT_NE(message.find("cannot be evicted"), std::string::npos) << message;
    EXPECT_TRUE(r->isLoaded("builtin:gaussian_blob")) << "a failed load evicted an unused volume";
    // A file that fails to load evicts nothing either.
    std::ofstream(data / "broken.nrrd") << "NRRD0004\ntype: float\n";
    loadFailure(openNow(*r, "broken.nrrd"));
    EXPECT_TRUE(r->isLoaded("builtin:gaussian_blob"));
    EXPECT_TRUE(r->isLoaded("builtin:sphere"));
}

TEST_F(VolumeRegistryTest, SwitchingSessionMayHaveItsOwnVolumeEvicted) {
    auto r = registry(10 * kMiB);
    writeVolume("wide.nrrd", 128, 128, 80);   // 8.3 MiB: fits only once the sphere (2.5) is gone
    auto current = entryOf(openNow(*r, "builtin:sphere"));
    ASSERT_TRUE(current);
    // Without saying that it gives the sphere up, the session's own hold blocks the load.
    loadFailure(openNow(*r, "wide.nrrd"));
    EXPECT_TRUE(r->isLoaded("builtin:sphere"));
    // Another session holding the sphere too keeps it, whatever this one releases.
    {
        auto other = entryOf(openNow(*r, "builtin:sphere"));
        loadFailure(openNow(*r, "wide.nrrd", current));
        EXPECT_TRUE(r->isLoaded("builtin:sphere"));
    }
    // Released by its only holder, the sphere makes room; the session still has it until it
    // drops its hold, and then its memory goes.
    auto next = entryOf(openNow(*r, "wide.nrrd", current));
    ASSERT_TRUE(next);
    EXPECT_FALSE(r->isLoaded("builtin:sphere"));
    EXPECT_TRUE(r->isLoaded("wide.nrrd"));
    EXPECT_EQ(current->volume->dims, volcast::Vec3i(64, 64, 64)) << "the session's old volume stays usable";
    EXPECT_LE(r->usedBytes(), 10 * kMiB);
}

// The budget counts the bytes a volume really takes: a 16-bit scan is held in 16 bits (its
// file's 2 bytes a sample, narrow_samples.hpp), sampled there with no copy, and its renderer
// adds mip levels, B-spline coefficients and brick grids as frames ask
// for them. After frames that build all of them, what the registry counted must cover what is
// held, and not by much more.
TEST_F(VolumeRegistryTest, ASixteenBitVolumeCountsEveryByteItsRendererBuilds) {
    volcast::Volume v;
    v.dims = {48, 40, 36};
    v.voxels.resize(v.voxelCount());
    for (size_t i = 0; i < v.voxels.size(); ++i) v.voxels[i] = float(int(i % 3001) - 1000);
    volcast::saveVolume(v, data / "ct16.nrrd", {volcast::VoxelType::Int16, true});
    auto r = registry(64 * kMiB);
    const auto entry = entryOf(openNow(*r, "ct16.nrrd"));
    ASSERT_TRUE(entry);
    EXPECT_EQ(entry->volume->sourceType, volcast::VoxelType::Int16);
    const auto *cpu = dynamic_cast<const volcast::CpuRenderer *>(entry->renderer.get());
    ASSERT_NE(cpu, nullptr) << entry->renderer->description();
    const uint64_t voxelBytes = uint64_t(v.voxelCount()) * 2 + volcast::kNarrowSlack;
    EXPECT_EQ(entry->volume->narrow.bytes, 2);
    EXPECT_EQ(entry->volume->sampleBytes(), voxelBytes) << "16-bit samples are held in 16 bits";
    const uint64_t openedBytes = cpu->memoryBytes();
    EXPECT_EQ(openedBytes, 0) << "level 0 is sampled in place: opening copies nothing";

    // Every mip level, trilinear and cubic, with skipping and the adaptive step: everything
    // the renderer can build.
    volcast::TransferFunction tf;
    tf.points = {{-1000, 0, 0, 0, 0}, {0, 0, 0, 0, 0}, {2000, 1, 1, 1, 0.5}};
    volcast::Camera camera;
    camera.target = entry->volume->center();
    camera.eye = camera.target + volcast::Vec3d(20, 30, 3 * volcast::length(entry->volume->extent()));
    int maxLevel = 0;
    while (!(volcast::mipLevelDims(v.dims, maxLevel) == volcast::Vec3i(1, 1, 1))) ++maxLevel;
    for (int level = 0; level <= maxLevel; ++level)
        for (auto interpolation : {volcast::Interpolation::Linear, volcast::Interpolation::Cubic}) {
            volcast::Quality q;
            q.mipLevel = level;
            q.interpolation = interpolation;
            q.emptySpaceSkipping = true;
            q.adaptiveStep = true;
            entry->renderer->render({tf, camera, 16, 16, q, {}});
        }
    const uint64_t held = voxelBytes + cpu->memoryBytes();
    EXPECT_GE(entry->bytes, held) << "the budget counted " << entry->bytes << " bytes; the volume and its renderer hold "
                                  << held;
    EXPECT_LE(double(entry->bytes), 1.01 * double(held)) << "the budget counts far more than is ever held";
    // Level 0's padded coefficients alone take over 5 bytes a sample here (51·43·39 / 48·40·36).
    EXPECT_GT(double(cpu->memoryBytes()), 5.0 * double(v.voxelCount())) << "the renderer's copies were not all built";
    EXPECT_EQ(r->usedBytes(), entry->bytes);
}

TEST_F(VolumeRegistryTest, LoadPastItsTimeLimitFailsNamingTheFlag) {
    // 64 DICOM slices take GDCM far more than 1 ms to scan; the limit is checked at the
    // loader's next step after that.
    volcast::Volume v;
    v.dims = {8, 8, 64};
    v.voxels.assign(v.voxelCount(), 10.0f);
    volcast::saveDicomSeries(v, data / "series");
    auto r = registry(64 * kMiB, 0.001);
    const std::string message = loadFailure(openNow(*r, "series"));
    for (const char *words : {"series", "time limit", "--load-timeout-s"})
        EXPECT_NE(message.find(words), std::string::npos) << "no '" << words << "' in: " << message;
}

TEST_F(VolumeRegistryTest, ClientMessagesNameNoServerPath) {
    fs::create_directories(data / "ct");
    std::ofstream(data / "ct" / "missing.nhdr") << "NRRD0004\ntype: uint8\ndimension: 3\nsizes: 2 2 2\n"
                                                   "encoding: raw\ndata file: gone.raw\n";
    std::ofstream(data / "ct" / "broken.nrrd") << "NRRD0004\ntype: float\n";
    std::ofstream(data / "ct" / "escape.nhdr") << "NRRD0004\ntype: uint8\ndimension: 3\nsizes: 2 2 2\n"
                                                  "encoding: raw\ndata file: ../../outside.raw\n";
    auto r = registry(64 * kMiB);
    for (const char *name : {"ct/missing.nhdr", "ct/broken.nrrd", "ct/escape.nhdr"}) {
        const std::string message = loadFailure(openNow(*r, name));
        EXPECT_EQ(message.find(data.string()), std::string::npos) << message;
        EXPECT_EQ(message.find(fs::canonical(data).string()), std::string::npos) << message;
        EXPECT_EQ(message.find(fs::temp_directory_path().string()), std::string::npos) << message;
        EXPECT_TRUE(message.starts_with(name)) << message;
    }
}

// A data-folder DICOM folder holding an axial stack and a localizer: refused offering each
// stack by the name that opens it; NAME#stack=N opens that stack alone.
TEST_F(VolumeRegistryTest, ADicomFolderOfSeveralStacksOffersEachAndOpensOneByItsName) {
    const auto slices = [](int64_t size, int64_t count, const fs::path &folder) {
        volcast::Volume v;
        v.dims = {size, size, count};
        v.spacing = {1, 1, 2};
        v.voxels.assign(v.voxelCount(), 10.0f);
        volcast::saveDicomSeries(v, folder, volcast::VoxelType::Int16);
    };
    slices(16, 6, data / "ct" / "series");
    slices(32, 1, data / "scout");
    fs::rename(data / "scout" / "slice_0000.dcm", data / "ct" / "series" / "slice_scout.dcm");
    fs::remove_all(data / "scout");
    for (const auto &e : fs::directory_iterator(data / "ct" / "series"))
        volcast::dicom_tags::setTags(e.path(), {{volcast::dicom_tags::kStudyUid, "1.2.826.0.1.3680043.2.1125.1"},
                                                {volcast::dicom_tags::kSeriesUid, "1.2.826.0.1.3680043.2.1125.1.2"},
                                                {volcast::dicom_tags::kFrameOfReferenceUid, "1.2.826.0.1.3680043.2.1125.1.3"}});
    writeVolume("head.nrrd", 4, 4, 4);
    auto r = registry(64 * kMiB);
    const auto refused = openNow(*r, "ct/series");
    const auto *error = std::get_if<volcast::protocol::ProtocolError>(&refused);
    ASSERT_NE(error, nullptr) << "a series of two stacks is not opened unasked";
    EXPECT_EQ(error->code, volcast::protocol::ErrorCode::LoadFailed);
    EXPECT_TRUE(error->message.starts_with("ct/series: the series holds a localizer besides 6 axial slices"))
        << error->message;
    EXPECT_EQ(error->stacks, (std::vector<volcast::protocol::StackOffer>{{"ct/series#stack=1", 6, 16, 16, "axial", false},
                                                                        {"ct/series#stack=2", 1, 32, 32, "axial", true}}));
    const auto stack = entryOf(openNow(*r, "ct/series#stack=1"));
    ASSERT_NE(stack, nullptr);
    EXPECT_EQ(stack->name, "ct/series#stack=1");
    EXPECT_EQ(stack->volume->dims.z, 6) << "the axial stack alone";
    EXPECT_EQ(stack->volume->dims.x, 16);
    const std::string none = loadFailure(openNow(*r, "ct/series#stack=3"));
    EXPECT_NE(none.find("holds 2 stacks, so no stack 3"), std::string::npos) << none;
    const std::string file = loadFailure(openNow(*r, "head.nrrd#stack=1"));
    EXPECT_NE(file.find("is not a DICOM series"), std::string::npos) << file;
}

} // namespace
