// Tests of the data files a header names (renderer/io/volume_checks.*): inside the header's
// folder, regular files, checked before anything is opened.

#include "volume_io_test_helpers.hpp"

#include "renderer/io/volume_io.hpp"

#include <gtest/gtest.h>
#include <zlib.h>

#include <algorithm>
#include <bit>
#include <cctype>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstring>
#include <chrono>
#include <filesystem>
#include <future>
#include <thread>
#include <fstream>
#include <initializer_list>
#include <limits>
#include <numbers>
#include <sstream>
#include <string>
#include <vector>

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

namespace volcast {
namespace {

using namespace volume_io_test;

// ---------------------------------------------------------------------------------------
// Detached data files stay in the header's folder and are regular files

class VolumeIoDataFiles : public VolumeIoTest {
  protected:
    void SetUp() override {
        VolumeIoTest::SetUp();
        fs::create_directories(dir / "sub");
    }
    // dir/sub/NAME, a 2x2x2 uint8 header naming `dataFile`; dir/x.raw lies outside sub/.
    fs::path header(const std::string &name, const std::string &dataFile) {
        fs::create_directories(dir / "sub");
        writeFile(dir / "x.raw", std::string(8, '\1'));
        writeFile(dir / "sub" / name, "NRRD0004\ntype: uint8\ndimension: 3\nsizes: 2 2 2\nencoding: raw\n"
                                      "data file: " + dataFile + "\n");
        return dir / "sub" / name;
    }
    fs::path metaHeader(const std::string &name, const std::string &dataFile) {
        fs::create_directories(dir / "sub");
        writeFile(dir / "x.raw", std::string(8, '\1'));
        writeFile(dir / "sub" / name, "ObjectType = Image\nNDims = 3\nDimSize = 2 2 2\nElementType = MET_UCHAR\n"
                                      "ElementDataFile = " + dataFile + "\n");
        return dir / "sub" / name;
    }
    // No server path in the message: the data file as the header names it, nothing more.
    void expectNoOutsidePath(const fs::path &p) {
        try {
            loadVolume(p);
        } catch (const VolumeLoadError &e) {
            EXPECT_EQ(std::string(e.what()).find((dir / "x.raw").string()), std::string::npos) << e.what();
        }
    }
    // Loads on another thread: a loader that opened a FIFO would wait for a writer forever.
    // If it does, the test writes nothing, closes the FIFO's write end to free it, and fails.
    void expectRefusedWithoutBlocking(const fs::path &p, const fs::path &fifo,
                                      std::initializer_list<const char *> words) {
        auto result = std::async(std::launch::async, [p, words] { expectLoadError(p, words); });
        if (result.wait_for(std::chrono::seconds(10)) != std::future_status::ready) {
            ADD_FAILURE() << "loading " << p << " blocked on the FIFO " << fifo;
            const int fd = ::open(fifo.c_str(), O_WRONLY | O_NONBLOCK);
            if (fd >= 0) ::close(fd);
        }
        result.wait();
    }
};

TEST_F(VolumeIoDataFiles, ValidDetachedDataFileLoads) {  // the baseline the others break
    writeFile(dir / "sub" / "in.raw", std::string(8, '\2'));
    const fs::path p = header("ok.nhdr", "in.raw");
    EXPECT_EQ(loadVolume(p).samples().toFloats(), std::vector<float>(8, 2.0f));
}
TEST_F(VolumeIoDataFiles, NrrdDataFileWithDotDotIsRefused) {
    const fs::path p = header("dotdot.nhdr", "../x.raw");
    expectLoadError(p, {"../x.raw", "outside"});
    expectNoOutsidePath(p);
}
TEST_F(VolumeIoDataFiles, NrrdAbsoluteDataFileIsRefused) {
    expectLoadError(header("rooted.nhdr", "/etc/passwd"), {"/etc/passwd", "absolute"});
}
TEST_F(VolumeIoDataFiles, NrrdDataFileLinkLeadingOutIsRefused) {
    const fs::path p = header("link.nhdr", "link.raw");
    fs::create_symlink(dir / "x.raw", dir / "sub" / "link.raw");
    expectLoadError(p, {"link.raw", "outside"});
    expectNoOutsidePath(p);
}
TEST_F(VolumeIoDataFiles, NrrdDataFileThatIsAFolderIsRefused) {
    fs::create_directories(dir / "sub" / "inner");
    expectLoadError(header("dir.nhdr", "inner"), {"inner", "folder"});
}
TEST_F(VolumeIoDataFiles, NrrdDataFileThatIsAFifoIsRefusedBeforeOpening) {
    const fs::path p = header("fifo.nhdr", "fifo.raw");
    ASSERT_EQ(::mkfifo((dir / "sub" / "fifo.raw").c_str(), 0600), 0) << std::strerror(errno);
    expectRefusedWithoutBlocking(p, dir / "sub" / "fifo.raw", {"fifo.raw", "regular file"});
}
TEST_F(VolumeIoDataFiles, NrrdListDataFilesAreConfined) {
    writeFile(dir / "sub" / "a.raw", std::string(4, '\1'));
    const fs::path p = header("list.nhdr", "LIST\na.raw\n../x.raw");
    expectLoadError(p, {"../x.raw", "outside"});
}
TEST_F(VolumeIoDataFiles, NrrdPatternDataFilesAreConfined) {
    writeFile(dir / "s1.raw", std::string(4, '\1'));
    writeFile(dir / "s2.raw", std::string(4, '\1'));
    expectLoadError(header("pattern.nhdr", "../s%d.raw 1 2 1"), {"../s1.raw", "outside"});
}
TEST_F(VolumeIoDataFiles, NrrdListAndPatternInsideTheFolderLoad) {
    // Two files of one z slice (4 bytes) each, in both multi-file forms.
    writeFile(dir / "sub" / "s01.raw", std::string(4, '\1'));
    writeFile(dir / "sub" / "s02.raw", std::string(4, '\2'));
    const std::vector<float> expected = {1, 1, 1, 1, 2, 2, 2, 2};
    EXPECT_EQ(loadVolume(header("list_ok.nhdr", "LIST\ns01.raw\ns02.raw")).samples().toFloats(), expected);
    EXPECT_EQ(loadVolume(header("pattern_ok.nhdr", "s%02d.raw 1 2 1")).samples().toFloats(), expected);
}
TEST_F(VolumeIoDataFiles, MetaImageDataFileOutsideOrAbsoluteOrFifoIsRefused) {
    expectLoadError(metaHeader("dotdot.mhd", "../x.raw"), {"../x.raw", "outside"});
    expectLoadError(metaHeader("rooted.mhd", "/etc/passwd"), {"/etc/passwd", "absolute"});
    ASSERT_EQ(::mkfifo((dir / "sub" / "fifo.raw").c_str(), 0600), 0) << std::strerror(errno);
    expectRefusedWithoutBlocking(metaHeader("fifo.mhd", "fifo.raw"), dir / "sub" / "fifo.raw",
                                 {"fifo.raw", "regular file"});
}
// The header as its own data (its last 8 bytes read as the voxels): never meant, refused.
TEST_F(VolumeIoDataFiles, NrrdDataFileThatIsTheHeaderItselfIsRefused) {
    writeFile(dir / "sub" / "self.nhdr", "NRRD0004\ntype: uint8\ndimension: 3\nsizes: 2 2 2\nencoding: raw\n"
                                         "byte skip: -1\ndata file: self.nhdr\n\n" + std::string(8, '\1'));
    expectLoadError(dir / "sub" / "self.nhdr", {"self.nhdr", "header's own file"});
}
// A file from outside (an upload) comes alone: a header naming any data file is refused.
TEST_F(VolumeIoDataFiles, DetachedDataFileOfAFileFromOutsideIsRefused) {
    writeFile(dir / "sub" / "in.raw", std::string(8, '\2'));
    LoadOptions options;
    options.parseInChild = true;
    expectLoadError(header("ok.nhdr", "in.raw"), {"an upload must carry its data", "in.raw"}, options);
    expectLoadError(metaHeader("ok.mhd", "in.raw"), {"an upload must carry its data", "in.raw"}, options);
}
TEST_F(VolumeIoDataFiles, HeaderThatIsAFifoIsRefusedBeforeOpening) {
    ASSERT_EQ(::mkfifo((dir / "pipe.nrrd").c_str(), 0600), 0) << std::strerror(errno);
    expectRefusedWithoutBlocking(dir / "pipe.nrrd", dir / "pipe.nrrd", {"regular file"});
}
TEST_F(VolumeIoDataFiles, DicomFolderHoldingAFifoIsRefusedBeforeScanning) {
    Volume src;
    src.dims = {4, 4, 2};
    src.voxels.assign(src.voxelCount(), 5.0f);
    saveDicomSeries(src, dir / "series", VoxelType::Int16);
    ASSERT_EQ(::mkfifo((dir / "series" / "pipe.dcm").c_str(), 0600), 0) << std::strerror(errno);
    expectRefusedWithoutBlocking(dir / "series", dir / "series" / "pipe.dcm", {"pipe.dcm", "regular file"});
}

} // namespace
} // namespace volcast
