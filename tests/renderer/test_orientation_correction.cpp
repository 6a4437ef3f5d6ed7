// The user's orientation correction (quality.orientation_correction, a signed permutation of
// the world axes applied about the volume's centre): read, written and refused by the scene
// parser, and drawn by every back end and the reference integrator as the flipped or turned
// volume — a flip is the mirror image of the uncorrected frame, which no camera move gives.

#include "renderer/cpu/cpu_renderer.hpp"
#include "renderer/reference/error_metrics.hpp"
#include "renderer/opencl/opencl_renderer.hpp"
#include "renderer/model/orientation_correction.hpp"
#include "renderer/reference/reference_renderer.hpp"
#include "renderer/model/slice.hpp"
#include "renderer/model/synthetic.hpp"
#include "opencl_test_context.hpp"
#include "test_scenes.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <memory>
#include <string>

namespace volcast {
namespace {

const OrientationCorrection kFlipX{{-1, 0, 0, 0, 1, 0, 0, 0, 1}};   // flip L/R
const OrientationCorrection kFlipZ{{1, 0, 0, 0, 1, 0, 0, 0, -1}};   // flip S/I
const OrientationCorrection kTurnY{{0, 0, -1, 0, 1, 0, 1, 0, 0}};   // quarter turn about A/P: x -> z, z -> -x

// Two blobs of different sizes off the centre on different axes, in a box of unequal sides
// and spacings: no flip or quarter turn maps it onto itself, so a mirrored frame is not the
// frame itself.
const SyntheticVolume &asymmetric() {
    static const SyntheticVolume v = sampleField(
        "asymmetric", {20, 18, 22}, {1.0, 1.1, 0.9}, {3, -2, 5}, [](const Vec3d &p) {
            const Vec3d c{3 + 9.5, -2 + 8.5 * 1.1, 5 + 10.5 * 0.9};
            const Vec3d a = p - (c + Vec3d{4.5, 0, 0}), b = p - (c + Vec3d{-1, 0, 6});
            return 200 * std::exp(-dot(a, a) / (2 * 2.5 * 2.5)) + 150 * std::exp(-dot(b, b) / (2 * 1.6 * 1.6));
        });
    return v;
}

TransferFunction rampTf() {
    TransferFunction tf;
    tf.points = {{0, 0, 0, 0, 0}, {30, 0.2, 0.5, 1, 0.05}, {120, 1, 0.6, 0.2, 0.3}, {200, 1, 1, 1, 0.8}};
    tf.opacityUnit = 1.0;
    return tf;
}

// Looking from anterior (−y) along +y at the volume's centre, superior (+z) up: image x is +x.
Camera frontCamera(const Volume &v) {
    Camera c;
    c.target = v.center();
    c.eye = v.center() - Vec3d{0, 70, 0};
    c.up = {0, 0, 1};
    c.fovYDeg = 30;
    return c;
}

// The uncorrected frame as the corrected one should show it: pixel (x, y) of the corrected
// frame shows what pixel q of the uncorrected one shows, where q's offset from the image
// centre in world axes (x to the right, z up) is Cᵀ of the pixel's. C keeps the view axis y,
// and the eye lies on it, so both rays see the same values at the same depths.
Image expectedCorrected(const Image &plain, const OrientationCorrection &c) {
    Image out(plain.width, plain.height);
    for (int y = 0; y < plain.height; ++y)
        for (int x = 0; x < plain.width; ++x) {
            const double dx = x + 0.5 - plain.width / 2.0, dz = -(y + 0.5 - plain.height / 2.0);
            const double ex = c(0, 0) * dx + c(2, 0) * dz, ez = c(0, 2) * dx + c(2, 2) * dz;   // Cᵀ
            const int qx = int(std::lround(ex + plain.width / 2.0 - 0.5));
            const int qy = int(std::lround(-ez + plain.height / 2.0 - 0.5));
            for (int k = 0; k < 4; ++k) out.pixel(x, y)[k] = plain.pixel(qx, qy)[k];
        }
    return out;
}

double maxDifference(const Image &a, const Image &b) { return compareImages(a, b).maxAbs; }

enum class Backend { OpenCl, Cpu };

class OrientationCorrectionFrames : public testing::TestWithParam<Backend> {
  protected:
    std::unique_ptr<FrameRenderer> renderer(const Volume &v) const {
        if (GetParam() == Backend::Cpu) return std::make_unique<CpuRenderer>(v);
        return std::make_unique<OpenClRenderer>(test::sharedOpenClContext(), v);
    }
};

INSTANTIATE_TEST_SUITE_P(Backends, OrientationCorrectionFrames, testing::Values(Backend::OpenCl, Backend::Cpu),
                         [](const testing::TestParamInfo<Backend> &i) { return i.param == Backend::Cpu ? "Cpu" : "OpenCl"; });

// Square, so that a quarter turn maps the pixel grid onto itself.
constexpr int kSide = 40;

TEST_P(OrientationCorrectionFrames, FlipsMirrorAndTurnsRotateTheFrame) {
    const Volume &v = asymmetric().volume;
    const auto r = renderer(v);
    const Camera cam = frontCamera(v);
    const Quality q = test::plainQuality(0.4);
    const Image plain = r->render({rampTf(), cam, kSide, kSide, q, {}});
    for (const auto &[name, c] : {std::pair{"flip L/R", kFlipX}, {"flip S/I", kFlipZ}, {"turn about A/P", kTurnY}}) {
        Quality corrected = q;
        corrected.orientationCorrection = c;
        const Image img = r->render({rampTf(), cam, kSide, kSide, corrected, {}});
        const Image expected = expectedCorrected(plain, c);
        // The volume must not look like its own mirror, or the test could not fail.
        EXPECT_GT(maxDifference(plain, expected), 0.1) << name << ": the test volume is symmetric under it";
        // Same rays through the same values in float32: the samples' index coordinates differ
        // by float rounding (~1e-6 of ~20 voxels), which moves a colour by far less than 1e-4
        // (measured: at most 5.4e-7 on both back ends).
        EXPECT_LT(maxDifference(img, expected), 1e-4) << name << ": not the uncorrected frame "
                                                      << (c(0, 0) == -1 ? "mirrored left-right" : "flipped/turned");
    }
}

TEST_P(OrientationCorrectionFrames, RefusesAMatrixThatIsNotASignedPermutation) {
    const Volume &v = asymmetric().volume;
    const auto r = renderer(v);
    Quality q = test::plainQuality(0.5);
    q.orientationCorrection = OrientationCorrection{{1, 1, 0, 0, 1, 0, 0, 0, 1}};
    try {
        r->render({rampTf(), frontCamera(v), 8, 8, q, {}});
        FAIL() << "a shear was drawn";
    } catch (const std::invalid_argument &e) {
        EXPECT_NE(std::string(e.what()).find("quality.orientation_correction"), std::string::npos) << e.what();
    }
}

TEST(OrientationCorrectionReference, FlipsMirrorAndTurnsRotateTheExactFrame) {
    const Volume &v = asymmetric().volume;
    const Camera cam = frontCamera(v);
    ReferenceOptions options;
    options.tolerance = 1e-6;
    for (const bool analytic : {false, true}) {
        const auto make = [&] {
            return analytic ? ReferenceRenderer(v, rampTf(), asymmetric().field)
                            : ReferenceRenderer(v, rampTf(), Reconstruction::Linear);
        };
        const Image plain = make().render(cam, 24, 24, {}, options);
        for (const auto &[name, c] : {std::pair{"flip L/R", kFlipX}, {"flip S/I", kFlipZ}, {"turn about A/P", kTurnY}}) {
            ReferenceRenderer ref = make();
            Quality q;
            q.orientationCorrection = c;
            ref.setQuality(q);
            const Image expected = expectedCorrected(plain, c);
            EXPECT_GT(maxDifference(plain, expected), 0.1) << name;
            // Both integrals to 1e-6 per pixel: they agree to twice that (measured: exactly,
            // the mirrored rays split at the same places).
            EXPECT_LT(maxDifference(ref.render(cam, 24, 24, {}, options), expected), 2e-6)
                << name << (analytic ? " (analytic field)" : " (trilinear)");
        }
    }
}

TEST(OrientationCorrectionPlacement, TurnsTheVolumeAboutItsCentreInWorldAxes) {
    Volume v = asymmetric().volume;
    // An oblique file: index axes x, y, z along world −y, x, z.
    v.direction = Mat3d{{0, 1, 0, -1, 0, 0, 0, 0, 1}};
    const VolumePlacement p = correctedPlacement(v, kTurnY);
    const Vec3d c = v.center();
    for (const Vec3d q : {Vec3d{0, 0, 0}, Vec3d{19, 0, 3}, Vec3d{-0.5, 17.5, 21.5}}) {
        const Vec3d x = v.worldFromIndex(q) - c;
        const Vec3d expected = c + Vec3d{-x.z, x.y, x.x};   // kTurnY · x
        EXPECT_LT(length(p.worldFromIndex(q) - expected), 1e-12);
        EXPECT_LT(length(p.indexFromWorld(expected) - q), 1e-12);
    }
    const VolumePlacement same = correctedPlacement(v, {});
    EXPECT_EQ(same.origin, v.origin);
    EXPECT_EQ(same.direction, v.direction);
}

// The axial slice (columns +x, towards the patient's left) of the volume flipped left/right
// is the uncorrected one mirrored column for column: slices show the volume where frames do.
TEST(OrientationCorrectionSlices, AnAxialSliceOfTheFlippedVolumeIsTheMirroredSlice) {
    const Volume &v = asymmetric().volume;
    SliceRequestGeometry g;
    g.axis = SliceAxis::Axial;
    g.point = v.center() + Vec3d{0, 0, -1.3};   // through the larger blob, off the grid planes
    g.width = 30;
    g.height = 26;
    const SliceImage plain = sampleSlice(v, slicePlane(v, g));
    const SliceImage flipped = sampleSlice(v, slicePlane(v, g, kFlipX), kFlipX);
    double worstMirror = 0, worstSame = 0;
    for (int r = 0; r < g.height; ++r)
        for (int c = 0; c < g.width; ++c) {
            const float got = flipped.values[size_t(r * g.width + c)];
            worstMirror = std::max(worstMirror, double(std::fabs(got - plain.values[size_t(r * g.width + (g.width - 1 - c))])));
            worstSame = std::max(worstSame, double(std::fabs(got - plain.values[size_t(r * g.width + c)])));
        }
    EXPECT_GT(worstSame, 10.0) << "the slice is symmetric left-right: the test could not fail";
    // Mirrored pixel centres are the same points of the mirrored volume up to double rounding.
    EXPECT_LT(worstMirror, 1e-3) << "the slice of the flipped volume is not the mirrored slice";
}

TEST(SceneOrientationCorrection, ReadsWritesAndRefuses) {
    const std::string base = R"({"volume": "builtin:gaussian_blob", "transfer_function": {"preset": "ct_bone"},
        "camera": {"eye": [0, 0, 100], "target": [0, 0, 0], "up": [0, 1, 0]}, "image": {"width": 8, "height": 8},
        "quality": )";
    const Scene s = parseScene(base + R"({"orientation_correction": [[0, 0, -1], [0, 1, 0], [1, 0, 0]]}})");
    EXPECT_EQ(s.quality.orientationCorrection, kTurnY);
    EXPECT_EQ(parseScene(sceneToJson(s)), s);
    // Written as people write it: one row of the matrix a line.
    const std::string written = sceneToJson(s);
    const size_t at = written.find("\"orientation_correction\": [\n");
    ASSERT_NE(at, std::string::npos) << written;
    EXPECT_NE(written.find("[0, 0, -1],", at), std::string::npos) << written;
    EXPECT_NE(written.find("[1, 0, 0]\n", at), std::string::npos) << written;
    // The identity is the default and is not written: scenes without it read as before.
    EXPECT_EQ(sceneToJson(parseScene(base + "{}}")).find("orientation_correction"), std::string::npos);
    EXPECT_TRUE(parseScene(base + R"({"orientation_correction": [[1, 0, 0], [0, 1, 0], [0, 0, 1]]}})")
                    .quality.orientationCorrection.identity());

    auto error = [&](const std::string &quality) {
        try {
            parseScene(base + quality + "}");
        } catch (const SceneError &e) {
            return std::string(e.what());
        }
        return std::string("no error");
    };
    const auto refuses = [&](const std::string &quality, const std::string &path, const std::string &why) {
        const std::string e = error(quality);
        EXPECT_NE(e.find(path), std::string::npos) << quality << " -> " << e;
        EXPECT_NE(e.find(why), std::string::npos) << quality << " -> " << e;
    };
    refuses(R"({"orientation_correction": [[1, 0, 0], [0, 2, 0], [0, 0, 1]]})", "quality.orientation_correction[1][1]",
            "-1, 0 or 1");
    refuses(R"({"orientation_correction": [[1, 0, 0], [0, 0.5, 0], [0, 0, 1]]})", "quality.orientation_correction[1][1]",
            "");
    refuses(R"({"orientation_correction": [[1, 1, 0], [0, 1, 0], [0, 0, 1]]})", "quality.orientation_correction",
            "row 0 has 2 non-zero entries");
    refuses(R"({"orientation_correction": [[1, 0, 0], [1, 0, 0], [0, 0, 1]]})", "quality.orientation_correction",
            "column 0 has 2");
    refuses(R"({"orientation_correction": [[0, 0, 0], [0, 1, 0], [0, 0, 1]]})", "quality.orientation_correction",
            "row 0 has 0");
    refuses(R"({"orientation_correction": [[1, 0, 0], [0, 1, 0]]})", "quality.orientation_correction", "got 2 rows");
    refuses(R"({"orientation_correction": [[1, 0, 0], [0, 1], [0, 0, 1]]})", "quality.orientation_correction[1]",
            "got 2");
    refuses(R"({"orientation_correction": "flip_x"})", "quality.orientation_correction", "signed permutation");
}

} // namespace
} // namespace volcast
