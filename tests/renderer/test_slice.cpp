// Slices in the patient frame (renderer/slice.hpp) against closed forms: a linear ramp is
// reproduced exactly by trilinear reconstruction, a marker at a known patient position shows
// on the side the radiological layout puts it whatever order the file stores its axes in,
// and extreme requests are clear errors or background, never NaN.

#include "renderer/slice.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <functional>
#include <limits>
#include <stdexcept>

namespace volcast {
namespace {

Volume makeVolume(Vec3i dims, Vec3d spacing, Vec3d origin, Mat3d direction,
                  const std::function<double(const Vec3d &world)> &value) {
    Volume v;
    v.name = "test";
    v.dims = dims;
    v.spacing = spacing;
    v.origin = origin;
    v.direction = direction;
    v.voxels.resize(v.voxelCount());
    for (int64_t k = 0; k < dims.z; ++k)
        for (int64_t j = 0; j < dims.y; ++j)
            for (int64_t i = 0; i < dims.x; ++i)
                v.voxels[v.index(i, j, k)] = float(value(v.worldFromIndex(Vec3d(Vec3i{i, j, k}))));
    computeStatistics(v);
    return v;
}

double ramp(const Vec3d &w) { return 2.0 * w.x - 3.0 * w.y + 0.5 * w.z + 7.0; }

Mat3d columns(Vec3d a, Vec3d b, Vec3d c) {
    Mat3d m;
    for (int r = 0; r < 3; ++r) {
        m(r, 0) = a[r];
        m(r, 1) = b[r];
        m(r, 2) = c[r];
    }
    return m;
}

TEST(Slice, LinearRampIsExactWithinTheSamples) {
    const Volume v = makeVolume({8, 6, 5}, {1, 2, 3}, {10, 20, 30}, Mat3d::identity(), ramp);
    for (SliceAxis axis : {SliceAxis::Axial, SliceAxis::Coronal, SliceAxis::Sagittal}) {
        SliceRequestGeometry g;
        g.axis = axis;
        g.point = {13.3, 25.1, 35.2};   // between samples on every axis
        g.width = 40;
        g.height = 30;
        g.pixelSpacing = 0.37;
        const SlicePlane plane = slicePlane(v, g);
        const SliceImage img = sampleSlice(v, plane);
        int checked = 0;
        for (int r = 0; r < img.height; ++r)
            for (int c = 0; c < img.width; ++c) {
                const Vec3d w = plane.worldAt(c, r);
                // The plane passes through the point along its normal.
                ASSERT_NEAR(dot(w - g.point, plane.normal), 0, 1e-9);
                const Vec3d q = v.indexFromWorld(w);
                const bool withinSamples = q.x >= 0 && q.y >= 0 && q.z >= 0 && q.x <= 7 && q.y <= 5 && q.z <= 4;
                if (!withinSamples) continue;
                ASSERT_EQ(img.inside[size_t(r * img.width + c)], 1);
                // Voxels are float32 (values up to ~100: 1e-5 rounding) and the result is
                // stored as float: 1e-4 covers both.
                ASSERT_NEAR(img.values[size_t(r * img.width + c)], ramp(w), 1e-4)
                    << sliceAxisName(axis) << " pixel (" << c << ", " << r << ")";
                ++checked;
            }
        EXPECT_GT(checked, 100) << sliceAxisName(axis) << ": the slice should cross the samples";
    }
}

TEST(Slice, WindowLevelMapsTheRampLinearly) {
    // level - window/2 -> 0, level + window/2 -> 255, rounded to nearest.
    EXPECT_EQ(windowValue(-100, 200, 0), 0);
    EXPECT_EQ(windowValue(100, 200, 0), 255);
    EXPECT_EQ(windowValue(0, 200, 0), 128);   // 127.5 rounds up
    EXPECT_EQ(windowValue(-1e300, 1e300, 0), 0);
    EXPECT_EQ(windowValue(std::numeric_limits<double>::infinity(), 1, 0), 255);
    EXPECT_EQ(windowValue(std::numeric_limits<double>::quiet_NaN(), 1, 0), 0);
    SliceImage img;
    img.width = 3;
    img.height = 1;
    img.values = {10, 20, 30};
    img.inside = {1, 1, 0};
    const auto grey = windowToGray8(img, 20, 20);
    EXPECT_EQ(grey, (std::vector<uint8_t>{0, 128, 0})) << "the outside pixel is background 0";
    EXPECT_THROW(windowToGray8(img, 0, 0), std::invalid_argument);
    EXPECT_THROW(windowToGray8(img, -1, 0), std::invalid_argument);
    EXPECT_THROW(windowToGray8(img, 1, std::numeric_limits<double>::quiet_NaN()), std::invalid_argument);
}

// A sphere of radius 4 mm at a point on the patient's left (+x), anterior (-y) and superior
// (+z) of the centre, in a 40 mm cube centred at the origin.
const Vec3d kMarker{8, -8, 8};
double marker(const Vec3d &w) { return length(w - kMarker) < 4 ? 1000.0 : 0.0; }

struct Centroid {
    double c = 0, r = 0;
    int count = 0;
};
Centroid centroid(const SliceImage &img) {
    Centroid m;
    for (int r = 0; r < img.height; ++r)
        for (int c = 0; c < img.width; ++c)
            if (img.values[size_t(r * img.width + c)] > 500) {
                m.c += c;
                m.r += r;
                ++m.count;
            }
    if (m.count) {
        m.c /= m.count;
        m.r /= m.count;
    }
    return m;
}

// The same patient stored in three ways: identity, axes permuted, axes flipped.
std::vector<std::pair<const char *, Volume>> orientedVolumes() {
    std::vector<std::pair<const char *, Volume>> out;
    const Mat3d identity = Mat3d::identity();
    // index i -> world -y, j -> world +x, k -> world +z (a rotation; rows of the file run
    // posterior-to-anterior).
    const Mat3d permuted = columns({0, -1, 0}, {1, 0, 0}, {0, 0, 1});
    // index i -> world -x, j -> +y, k -> -z (two flips: right-to-left, superior-to-inferior).
    const Mat3d flipped = columns({-1, 0, 0}, {0, 1, 0}, {0, 0, -1});
    for (auto [name, d] : {std::pair{"identity", identity}, std::pair{"permuted", permuted},
                           std::pair{"flipped", flipped}}) {
        // The origin puts voxel (0,0,0) at the corner the direction starts from, so every
        // storage covers the same cube [-19.5, 19.5]^3 (40 samples, 1 mm).
        const Vec3d origin = d * Vec3d{-19.5, -19.5, -19.5};
        out.emplace_back(name, makeVolume({40, 40, 40}, {1, 1, 1}, origin, d, marker));
    }
    return out;
}

TEST(Slice, MarkerShowsOnTheRadiologicalSideWhateverTheStorageOrder) {
    for (const auto &[name, v] : orientedVolumes()) {
        SCOPED_TRACE(name);
        SliceRequestGeometry g;
        g.point = kMarker;
        g.width = 80;
        g.height = 80;
        g.pixelSpacing = 0.5;
        g.center = Vec3d{0, 0, 0};
        // Image centre is pixel 39.5; the marker is 8 mm = 16 px off the centre on both axes.
        g.axis = SliceAxis::Axial;   // columns +x (patient left: right of image), rows +y
        Centroid m = centroid(sampleSlice(v, slicePlane(v, g)));
        ASSERT_GT(m.count, 0);
        EXPECT_NEAR(m.c, 39.5 + 16, 1.0) << "axial: patient left shows on the image's right";
        EXPECT_NEAR(m.r, 39.5 - 16, 1.0) << "axial: anterior shows at the top";

        g.axis = SliceAxis::Coronal;   // columns +x, rows -z
        m = centroid(sampleSlice(v, slicePlane(v, g)));
        ASSERT_GT(m.count, 0);
        EXPECT_NEAR(m.c, 39.5 + 16, 1.0) << "coronal: patient left shows on the image's right";
        EXPECT_NEAR(m.r, 39.5 - 16, 1.0) << "coronal: superior shows at the top";

        g.axis = SliceAxis::Sagittal;   // columns +y, rows -z
        m = centroid(sampleSlice(v, slicePlane(v, g)));
        ASSERT_GT(m.count, 0);
        EXPECT_NEAR(m.c, 39.5 - 16, 1.0) << "sagittal: anterior shows on the left";
        EXPECT_NEAR(m.r, 39.5 - 16, 1.0) << "sagittal: superior shows at the top";
    }
}

TEST(Slice, DefaultSpacingFitsTheVolumeAndCentresIt) {
    // 20 x 10 mm in-plane (axial), into a 100 x 100 image: 0.2 mm per pixel, limited by x.
    const Volume v = makeVolume({20, 10, 4}, {1, 1, 1}, {0, 0, 0}, Mat3d::identity(), ramp);
    SliceRequestGeometry g;
    g.point = v.center();
    g.width = 100;
    g.height = 100;
    const SlicePlane p = slicePlane(v, g);
    EXPECT_DOUBLE_EQ(p.pixelSpacing, 0.2);
    const SliceImage img = sampleSlice(v, p);
    int insideRow = 0, insideColumn = 0;
    for (int c = 0; c < 100; ++c) insideRow += img.inside[size_t(50 * 100 + c)];
    for (int r = 0; r < 100; ++r) insideColumn += img.inside[size_t(r * 100 + 50)];
    EXPECT_EQ(insideRow, 100) << "x spans the whole width";
    EXPECT_EQ(insideColumn, 50) << "y (10 mm) spans half the height, centred";
}

TEST(Slice, ExtremeRequestsAreErrorsOrBackgroundNeverNaN) {
    const Volume v = makeVolume({8, 8, 8}, {1, 1, 1}, {0, 0, 0}, Mat3d::identity(), ramp);
    SliceRequestGeometry g;
    g.point = v.center();
    g.width = 16;
    g.height = 16;
    const auto throwsNaming = [&](SliceRequestGeometry bad, const std::string &field) {
        try {
            slicePlane(v, bad);
            ADD_FAILURE() << "no error for a bad " << field;
        } catch (const std::invalid_argument &e) {
            EXPECT_EQ(std::string(e.what()).rfind(field, 0), 0u) << e.what();
        }
    };
    const double nan = std::numeric_limits<double>::quiet_NaN(), inf = std::numeric_limits<double>::infinity();
    auto b = g;
    b.width = 0;
    throwsNaming(b, "width");
    b = g;
    b.height = -3;
    throwsNaming(b, "height");
    b = g;
    b.width = 1000000;
    throwsNaming(b, "width");
    b = g;
    b.width = kMaxSliceSide;
    b.height = kMaxSliceSide;
    throwsNaming(b, "width x height");
    b = g;
    b.point = {nan, 0, 0};
    throwsNaming(b, "point");
    b = g;
    b.center = Vec3d{0, inf, 0};
    throwsNaming(b, "center");
    for (double s : {0.0, -1.0, nan, inf}) {
        b = g;
        b.pixelSpacing = s;
        throwsNaming(b, "pixel_spacing");
    }
    b = g;
    b.pixelSpacing = 1e308;   // finite, but the image's far corner is not
    throwsNaming(b, "pixel_spacing");

    // Far outside: a valid, empty image (all background).
    b = g;
    b.point = {1e6, -1e6, 1e12};
    b.center = Vec3d{1e6, -1e6, 1e12};
    const SliceImage far = sampleSlice(v, slicePlane(v, b));
    for (size_t i = 0; i < far.values.size(); ++i) {
        ASSERT_EQ(far.inside[i], 0);
        ASSERT_TRUE(std::isfinite(far.values[i]));
    }
    // A huge but finite spacing: the volume falls between pixel centres or onto one; no NaN.
    b = g;
    b.pixelSpacing = 1e200;
    const SliceImage coarse = sampleSlice(v, slicePlane(v, b));
    for (float value : coarse.values) ASSERT_TRUE(std::isfinite(value));
    // A one-pixel slice through the centre samples the centre.
    b = g;
    b.width = 1;
    b.height = 1;
    const SliceImage one = sampleSlice(v, slicePlane(v, b));
    ASSERT_EQ(one.inside[0], 1);
    EXPECT_NEAR(one.values[0], ramp(v.center()), 1e-4);
}

} // namespace
} // namespace volcast
