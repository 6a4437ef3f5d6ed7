// Slices in the patient frame (renderer/model/slice.hpp) against closed forms: a linear ramp is
// reproduced exactly by trilinear reconstruction, a marker at a known patient position shows
// on the side the radiological layout puts it whatever order the file stores its axes in,
// and extreme requests are clear errors or background, never NaN.

#include "renderer/model/slice.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <functional>
#include <limits>
#include <numbers>
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


// A slab of the linear ramp: trilinear reconstruction is exact inside the samples, so the
// mean over planes placed symmetrically about the slice is the slice's own value, and the
// maximum / minimum are the values on the slab's two faces (the ramp rises 0.5 per mm along
// +z, the axial normal). Only rounding remains: 1e-4 of values near 40 in float.
TEST(Slab, LinearRampMeanIsTheCentreAndTheExtremesAreTheFaces) {
    const Volume v = makeVolume({8, 6, 9}, {1, 2, 3}, {10, 20, 30}, Mat3d::identity(), ramp);
    SliceRequestGeometry g;
    g.axis = SliceAxis::Axial;
    g.point = {13.3, 25.1, 42.2};
    g.width = 20;
    g.height = 15;
    g.pixelSpacing = 0.3;
    const SlicePlane plane = slicePlane(v, g);
    const double t = 4;
    EXPECT_EQ(slabPlaneCount(v, t), 9) << "4 mm at half of the smallest spacing (1 mm): 8 gaps, 9 planes";
    const SliceImage mip = sampleSlab(v, plane, {t, SlabMode::Maximum});
    const SliceImage minip = sampleSlab(v, plane, {t, SlabMode::Minimum});
    const SliceImage mean = sampleSlab(v, plane, {t, SlabMode::Mean});
    int checked = 0;
    for (int r = 0; r < plane.height; ++r)
        for (int c = 0; c < plane.width; ++c) {
            const Vec3d w = plane.worldAt(c, r);
            // Only pixels whose column stays within the sample centres (x in [10, 17], y in [20, 30]).
            if (w.x < 10 || w.x > 17 || w.y < 20 || w.y > 30) continue;
            const size_t at = size_t(r * plane.width + c);
            ASSERT_TRUE(mip.inside[at] && minip.inside[at] && mean.inside[at]);
            EXPECT_NEAR(mean.values[at], ramp(w), 1e-4);
            EXPECT_NEAR(mip.values[at], ramp(w + Vec3d{0, 0, t / 2}), 1e-4);
            EXPECT_NEAR(minip.values[at], ramp(w - Vec3d{0, 0, t / 2}), 1e-4);
            ++checked;
        }
    EXPECT_GT(checked, 100);
    // Thickness 0 is the plane itself, bit for bit.
    const SliceImage plain = sampleSlice(v, plane);
    const SliceImage zero = sampleSlab(v, plane, {0, SlabMode::Mean});
    EXPECT_EQ(plain.values, zero.values);
    EXPECT_EQ(plain.inside, zero.inside);
}

TEST(Slab, ThicknessLimitsAreClearErrors) {
    const Volume v = makeVolume({8, 8, 8}, {1, 1, 1}, {0, 0, 0}, Mat3d::identity(), ramp);
    const double nan = std::numeric_limits<double>::quiet_NaN(), inf = std::numeric_limits<double>::infinity();
    for (double t : {-1.0, nan, inf}) EXPECT_THROW(slabPlaneCount(v, t), std::invalid_argument) << t;
    // 1023 gaps of 0.5 mm is the thickest slab: 511.5 mm.
    EXPECT_EQ(slabPlaneCount(v, 511.5), kMaxSlabPlanes);
    EXPECT_GT(slabPlaneCount(v, 512), kMaxSlabPlanes);
    EXPECT_GT(slabPlaneCount(v, 1e300), kMaxSlabPlanes) << "no integer overflow";
    SliceRequestGeometry g;
    g.point = v.center();
    g.width = 16;
    g.height = 16;
    const SlicePlane plane = slicePlane(v, g);
    try {
        sampleSlab(v, plane, {1e6, SlabMode::Maximum});
        ADD_FAILURE() << "no error for a slab of 1e6 mm";
    } catch (const std::length_error &e) {
        EXPECT_NE(std::string(e.what()).find("1024"), std::string::npos) << e.what();
    }
    g.width = g.height = 4096;   // 2^24 pixels x 17 planes: over 2^28 samples
    EXPECT_THROW(sampleSlab(v, slicePlane(v, g), {8, SlabMode::Mean}), std::length_error);
}

// The probe is the slices' reconstruction at one point: exact on the ramp inside the samples,
// nothing outside the cell box, an error for a point that is not finite.
TEST(Probe, ValueIsTheRampInsideAndNothingOutside) {
    const Volume v = makeVolume({8, 6, 5}, {1, 2, 3}, {10, 20, 30}, Mat3d::identity(), ramp);
    for (const Vec3d &p : {Vec3d{13.3, 25.1, 35.2}, Vec3d{10, 20, 30}, Vec3d{17, 30, 42}}) {
        const auto value = probeValue(v, p);
        ASSERT_TRUE(value.has_value());
        EXPECT_NEAR(*value, ramp(p), 1e-4) << "float voxels of values near 40";
    }
    // The cell box ends half a voxel past the outermost samples: x = 17.5 is inside, 17.6 not.
    EXPECT_TRUE(probeValue(v, {17.5, 25, 35}).has_value());
    EXPECT_FALSE(probeValue(v, {17.6, 25, 35}).has_value());
    EXPECT_FALSE(probeValue(v, {1e300, -1e300, 0}).has_value());
    EXPECT_THROW(probeValue(v, {std::numeric_limits<double>::quiet_NaN(), 0, 0}), std::invalid_argument);
    // A flip of the first axis (orientation correction) moves the volume: the probe follows it
    // as the slices do. The flipped volume's x runs the other way about the box's centre.
    OrientationCorrection flip;
    flip.m = {-1, 0, 0, 0, 1, 0, 0, 0, 1};
    const auto flipped = probeValue(v, {13.3, 25.1, 35.2}, flip);
    const auto mirrored = probeValue(v, {2 * v.center().x - 13.3, 25.1, 35.2});
    ASSERT_TRUE(flipped && mirrored);
    EXPECT_NEAR(*flipped, *mirrored, 1e-4);
}

// ROI statistics on the ramp, against closed forms. A rectangle of half sides a, b made of
// whole grid cells (h = min(1/2, min(a, b)/8) = 0.25 mm here) has area 4ab exactly; the values
// at its cell centres are c + gu·u + gv·v with u, v on symmetric grids of 2N points spaced h,
// so the mean is the centre's value, the population variance (gu²(4Nu² − 1) + gv²(4Nv² − 1))·h²/12,
// and the extremes c ± (|gu|(Nu − ½) + |gv|(Nv − ½))·h. Float voxels: 1e-4.
TEST(RoiStats, RectangleOnARampMatchesClosedForms) {
    const Volume v = makeVolume({8, 6, 5}, {1, 2, 3}, {10, 20, 30}, Mat3d::identity(), ramp);
    RoiGeometry roi;
    roi.axis = SliceAxis::Axial;   // column +x (gu = 2), row +y (gv = −3)
    roi.center = {13.3, 25.1, 35.2};
    roi.a = 2;
    roi.b = 3;
    roi.shape = RoiShape::Rectangle;
    const RoiStats s = roiStats(v, roi);
    const double h = 0.25, nu = 8, nv = 12, gu = 2, gv = -3;
    EXPECT_DOUBLE_EQ(s.spacing, h);
    EXPECT_EQ(s.samples, int64_t(2 * nu * 2 * nv));
    EXPECT_NEAR(s.area, 4 * roi.a * roi.b, 1e-12);
    const double c = ramp(roi.center);
    EXPECT_NEAR(s.mean, c, 1e-4);
    EXPECT_NEAR(s.std, std::sqrt((gu * gu * (4 * nu * nu - 1) + gv * gv * (4 * nv * nv - 1)) * h * h / 12), 1e-4);
    const double spread = (std::abs(gu) * (nu - 0.5) + std::abs(gv) * (nv - 0.5)) * h;
    EXPECT_NEAR(s.min, c - spread, 1e-4);
    EXPECT_NEAR(s.max, c + spread, 1e-4);
}

// An ellipse on a constant volume: every sample is the constant, the standard deviation 0;
// the area is πab to within the cells the boundary cuts (at most 2 · perimeter · h).
// Where the ellipse passes the volume's edge only the part inside counts, and an ellipse
// beside the volume has no samples.
TEST(RoiStats, EllipseAreaAndTheVolumesEdge) {
    const Volume v = makeVolume({40, 40, 4}, {0.5, 0.5, 2}, {0, 0, 0}, Mat3d::identity(),
                                [](const Vec3d &) { return 42.0; });
    RoiGeometry roi;
    roi.axis = SliceAxis::Axial;
    roi.center = {10, 10, 3};
    roi.a = 5;
    roi.b = 3;
    const RoiStats s = roiStats(v, roi);
    const double h = s.spacing;
    EXPECT_DOUBLE_EQ(h, 0.25);
    const double perimeter = std::numbers::pi * (3 * (roi.a + roi.b) - std::sqrt((3 * roi.a + roi.b) * (roi.a + 3 * roi.b)));
    EXPECT_NEAR(s.area, std::numbers::pi * roi.a * roi.b, 2 * perimeter * h);
    EXPECT_NEAR(s.mean, 42, 1e-9);
    EXPECT_NEAR(s.std, 0, 1e-9);
    EXPECT_EQ(s.min, 42);
    EXPECT_EQ(s.max, 42);
    // Centred on the volume's edge x = −0.25 (cell box): half the ellipse is inside.
    roi.center = {-0.25, 10, 3};
    const RoiStats half = roiStats(v, roi);
    EXPECT_NEAR(half.area, s.area / 2, perimeter * h);
    roi.center = {100, 10, 3};
    const RoiStats none = roiStats(v, roi);
    EXPECT_EQ(none.samples, 0);
    EXPECT_EQ(none.area, 0);
}

TEST(RoiStats, AbsurdRegionsAreClearErrors) {
    const Volume v = makeVolume({8, 8, 8}, {1, 1, 1}, {0, 0, 0}, Mat3d::identity(), ramp);
    const double nan = std::numeric_limits<double>::quiet_NaN(), inf = std::numeric_limits<double>::infinity();
    RoiGeometry roi;
    roi.center = v.center();
    roi.a = roi.b = 2;
    for (double r : {0.0, -1.0, nan, inf}) {
        RoiGeometry bad = roi;
        bad.b = r;
        EXPECT_THROW(roiStats(v, bad), std::invalid_argument) << r;
    }
    RoiGeometry bad = roi;
    bad.center = {0, inf, 0};
    EXPECT_THROW(roiStats(v, bad), std::invalid_argument);
    // Huge radii are cut to the volume: the whole 8 x 8 mm section, 64 mm².
    bad = roi;
    bad.a = bad.b = 1e12;
    bad.shape = RoiShape::Rectangle;
    const RoiStats all = roiStats(v, bad);
    EXPECT_NEAR(all.area, 64, 1e-9);
    // A sliver far thinner than a voxel takes a grid so fine it would pass the sample bound.
    bad = roi;
    bad.a = 1e3;
    bad.b = 1e-6;
    EXPECT_THROW(roiStats(v, bad), std::length_error);
}

} // namespace
} // namespace volcast
