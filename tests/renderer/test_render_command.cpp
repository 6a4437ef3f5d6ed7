// volcast-render as a user runs it, checked against a closed form. Apart from the model's
// tests because it reads the command's EXR: only this executable loads OpenImageIO.

#include "renderer/model/image.hpp"
#include "renderer/model/synthetic.hpp"
#include "test_scenes.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <fstream>

namespace volcast {
namespace {
using test::chordLength;
}

TEST(ReferenceRenderer, CommandLineReproducesTheClosedFormConstantBoxTo1e6) {
    // The builtin constant box (64³, value 100) through volcast-render --reference, as a user would.
    const auto dir = std::filesystem::temp_directory_path() / "volcast_ref_cli";
    std::filesystem::create_directories(dir);
    const double a = 0.05;
    std::ofstream(dir / "box.json") << R"({
      "volume": "builtin:constant_box",
      "transfer_function": {"points": [[0, 0.8, 0.6, 0.4, 0.05], [255, 0.8, 0.6, 0.4, 0.05]], "opacity_unit": 1},
      "camera": {"eye": [140, 110, 160], "target": [31.5, 31.5, 31.5], "up": [0, 1, 0],
                 "projection": "perspective", "fov_y_deg": 35},
      "image": {"width": 24, "height": 24}
    })";
    const std::string cmd = std::string(VOLCAST_RENDER_EXE) + " " + (dir / "box.json").string() + " -o " +
                            (dir / "box.exr").string() + " --reference > " + (dir / "out.txt").string();
    ASSERT_EQ(std::system(cmd.c_str()), 0);
    const Image img = readImage(dir / "box.exr");
    const SyntheticVolume box = makeConstantBox({64, 64, 64}, {1, 1, 1}, 100);
    Camera cam;
    cam.eye = {140, 110, 160};
    cam.target = {31.5, 31.5, 31.5};
    cam.fovYDeg = 35;
    const RayGenerator rays(cam, 24, 24);
    for (int y = 0; y < 24; ++y)
        for (int x = 0; x < 24; ++x) {
            const double A = -std::expm1(chordLength(box.volume, rays.pixelRay(x, y)) * std::log1p(-a));
            // The required bound: 1e-6 (float32 EXR storage adds only ~6e-8).
            EXPECT_NEAR(img.pixel(x, y)[3], A, 1e-6);
            EXPECT_NEAR(img.pixel(x, y)[0], 0.8 * A, 1e-6);
        }
}

} // namespace volcast
