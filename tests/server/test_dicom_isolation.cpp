// DICOM is parsed in a child process before the server loads it (renderer/io/dicom_check.hpp):
// a file on which GDCM aborts (fuzz/README.md, finding 7) fails its load with a clear message,
// and the process that asked — the server's volume registry here, in this test's process —
// carries on and serves the next volume. Before the fix, GDCM's assertion aborted this whole
// test executable.

#include "renderer/io/volume_io.hpp"
#include "server/volume_registry.hpp"
#include "tests/server/registry_fixture.hpp"

#include <gtest/gtest.h>

#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <iterator>

namespace {

namespace fs = std::filesystem;
using volcast::server::VolumeRegistry;
using volcast::test::kMiB;
using volcast::test::loadFailure;
using volcast::test::openNow;
namespace protocol = volcast::protocol;

class DicomIsolationTest : public volcast::test::RegistryTest {
  protected:
    std::unique_ptr<VolumeRegistry> registry() { return RegistryTest::registry(64 * kMiB); }
    // The 223-byte DICOM file of finding 7: the committed fuzz input less its first byte (the
    // fuzz target's choice of file name).
    void writeAbortingDicom(const fs::path &to) {
        std::ifstream in(VOLCAST_GDCM_ASSERT_INPUT, std::ios::binary);
        ASSERT_TRUE(in) << "cannot read " << VOLCAST_GDCM_ASSERT_INPUT;
        std::string bytes((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
        ASSERT_EQ(bytes.size(), 224u) << "the finding's input changed";
        std::ofstream(to, std::ios::binary).write(bytes.data() + 1, std::streamsize(bytes.size() - 1));
    }
    void writeVolume(const fs::path &to, int n) {
        volcast::Volume v;
        v.dims = {n, n, n};
        v.voxels.resize(v.voxelCount());
        for (size_t i = 0; i < v.voxels.size(); ++i) v.voxels[i] = float(i % 97);
        volcast::saveVolume(v, to, {volcast::VoxelType::Int16, false});
    }
};

void expectLoaded(const VolumeRegistry::Result &r, int n) {
    if (const auto entry = volcast::test::entryOf(r)) {
        EXPECT_EQ(entry->volume->dims.z, n);
    }
}

TEST_F(DicomIsolationTest, FileOnWhichGdcmAbortsFailsItsLoadAndTheServerServesTheNextVolume) {
    writeAbortingDicom(data / "upload.dcm");
    fs::create_directories(data / "series");
    writeAbortingDicom(data / "series" / "slice0001.dcm");   // the same file as a DICOM folder
    writeVolume(data / "good.nrrd", 8);
    auto r = registry();
    for (const std::string name : {"upload.dcm", "series"}) {
        const std::string message = loadFailure(openNow(*r, name));
        EXPECT_TRUE(message.starts_with(name + ":")) << "the message does not name the volume first: " << message;
        EXPECT_NE(message.find("rejected by the DICOM parser"), std::string::npos) << message;
        EXPECT_NE(message.find("SIGABRT"), std::string::npos) << "the message does not say how GDCM ended: " << message;
        EXPECT_EQ(message.find(data.string()), std::string::npos) << "a server path in: " << message;
        EXPECT_FALSE(r->isLoaded(name));
    }
    // The process that asked is still here (this test), and its registry still loads.
    expectLoaded(openNow(*r, "good.nrrd"), 8);
    EXPECT_TRUE(r->isLoaded("good.nrrd"));
}

TEST_F(DicomIsolationTest, SoundDicomSeriesAndFileStillLoadThroughTheChildProcess) {
    volcast::Volume v;
    v.dims = {6, 5, 4};
    v.voxels.resize(v.voxelCount());
    for (size_t i = 0; i < v.voxels.size(); ++i) v.voxels[i] = float(i);
    volcast::saveDicomSeries(v, data / "ct", volcast::VoxelType::Int16);
    auto r = registry();
    expectLoaded(openNow(*r, "ct"), 4);
    // One slice of it on its own, as a file (no other reader claims .dcm: GDCM is asked).
    const auto slice = fs::directory_iterator(data / "ct")->path();
    fs::copy_file(slice, data / "one.dcm");
    expectLoaded(openNow(*r, "one.dcm"), 1);
}

TEST_F(DicomIsolationTest, WithoutTheCheckerDicomIsRefusedNotParsedInProcess) {
    writeAbortingDicom(data / "upload.dcm");
    writeVolume(data / "good.nrrd", 8);
    // A checker that is named but absent: the load must fail closed, never fall back to GDCM
    // in this process (which would abort it).
    ::setenv("VOLCAST_DICOM_CHECK", (data / "no-such-checker").c_str(), 1);
    auto r = registry();
    const std::string message = loadFailure(openNow(*r, "upload.dcm"));
    const std::string nrrd = [&] {
        auto result = openNow(*r, "good.nrrd");   // NRRD never needs the checker
        auto *e = std::get_if<protocol::ProtocolError>(&result);
        return e ? e->message : std::string();
    }();
    ::unsetenv("VOLCAST_DICOM_CHECK");
    EXPECT_TRUE(message.starts_with("upload.dcm:")) << message;
    EXPECT_NE(message.find("DICOM checker 'volcast-dicom-check' was not found"), std::string::npos) << message;
    EXPECT_EQ(nrrd, "") << "a NRRD file failed without the DICOM checker: " << nrrd;
}

} // namespace
