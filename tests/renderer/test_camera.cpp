#include "renderer/model/camera.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <stdexcept>

namespace volcast {
namespace {

TEST(Camera, CentrePixelLooksAtTheTarget) {
    Camera c;
    c.eye = {10, 20, 30};
    c.target = {1, 2, 3};
    const RayGenerator g(c, 5, 7); // odd sizes: pixel (2, 3) is the centre
    const Ray r = g.pixelRay(2, 3);
    const Vec3d toTarget = normalize(c.target - c.eye);
    EXPECT_NEAR(dot(r.dir, toTarget), 1.0, 1e-15); // unit vectors, double rounding only
}

TEST(Camera, ImageAxesFollowTheContract) {
    Camera c; // looks down −z with y up
    c.eye = {0, 0, 10};
    c.target = {0, 0, 0};
    c.up = {0, 1, 0};
    const RayGenerator g(c, 4, 4);
    // x axis = forward × up = (−z) × y = +x; row 0 is at the top (+y).
    EXPECT_GT(g.pixelRay(3, 1).dir.x, 0);
    EXPECT_LT(g.pixelRay(0, 1).dir.x, 0);
    EXPECT_GT(g.pixelRay(1, 0).dir.y, 0);
    EXPECT_LT(g.pixelRay(1, 3).dir.y, 0);
}

TEST(Camera, PerspectiveFieldOfViewIsTheFullVerticalAngle) {
    Camera c;
    c.eye = {0, 0, 0};
    c.target = {0, 0, -1};
    c.fovYDeg = 60;
    const RayGenerator g(c, 8, 4);
    // The top edge of the image (py = 0) is at half the angle: 30 degrees above forward.
    const Ray top = g.rayThrough(4, 0);
    EXPECT_NEAR(std::atan2(top.dir.y, -top.dir.z) * 180 / M_PI, 30, 1e-12);
    // Aspect 2: the right edge is at atan(2·tan 30°).
    const Ray right = g.rayThrough(8, 2);
    EXPECT_NEAR(std::atan2(right.dir.x, -right.dir.z), std::atan(2 * std::tan(M_PI / 6)), 1e-12);
}

TEST(Camera, OrthographicRaysAreParallelAndSpanTheHeight) {
    Camera c;
    c.eye = {0, 0, 10};
    c.target = {0, 0, 0};
    c.projection = Projection::Orthographic;
    c.height = 6;
    const RayGenerator g(c, 6, 3);
    const Ray a = g.rayThrough(0, 0), b = g.rayThrough(6, 3);
    EXPECT_EQ(a.dir, b.dir);
    EXPECT_NEAR(a.origin.y - b.origin.y, 6, 1e-12);
    EXPECT_NEAR(b.origin.x - a.origin.x, 12, 1e-12); // width = height · aspect
}

TEST(Camera, DegenerateCamerasAreRefusedNamingTheKey) {
    Camera c;
    c.eye = c.target = {1, 1, 1};
    EXPECT_THROW(c.validate(), std::invalid_argument);
    c.eye = {0, 0, 5};
    c.target = {0, 0, 0};
    c.up = {0, 0, 1}; // parallel to the view
    try {
        c.validate();
        FAIL();
    } catch (const std::invalid_argument &e) {
        EXPECT_NE(std::string(e.what()).find("camera.up"), std::string::npos);
    }
}

} // namespace
} // namespace volcast
