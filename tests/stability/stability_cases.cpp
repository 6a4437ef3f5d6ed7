#include "tests/stability/stability_cases.hpp"

#include "renderer/model/camera.hpp"
#include "renderer/cpu/cpu_renderer.hpp"
#include "renderer/opencl/opencl_renderer.hpp"
#include "renderer/common/preintegration.hpp"
#include "renderer/reference/reference_renderer.hpp"
#include "renderer/model/scene.hpp"
#include "renderer/model/synthetic.hpp"
#include "renderer/io/volume_io.hpp"
#include "tests/renderer/test_scenes.hpp"

#include <algorithm>
#include <chrono>
#include <climits>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <limits>
#include <random>
#include <span>
#include <sstream>

#include <unistd.h>

namespace volcast::stability {

namespace {

namespace fs = std::filesystem;
using Clock = std::chrono::steady_clock;

constexpr double kInf = std::numeric_limits<double>::infinity();
constexpr double kFloatEps = 0x1p-24; // float's unit roundoff

// ---- Rows ----------------------------------------------------------------------------------

// Collects one row: its errors, the outputs it saw, and any check that is not a number.
class Check {
  public:
    Check(std::string caseName, std::string path, std::string comparedWith, double bound) {
        row_.caseName = std::move(caseName);
        row_.path = std::move(path);
        row_.comparedWith = std::move(comparedWith);
        row_.bound = bound;
    }
    // A NaN error is an infinite one.
    void error(double e) {
        if (std::isnan(e)) e = kInf;
        // VOLCAST_STABILITY_VERBOSE=1: every new worst error, with the variant it came from.
        static const bool verbose = std::getenv("VOLCAST_STABILITY_VERBOSE") != nullptr;
        if (verbose && e > row_.worst)
            std::fprintf(stderr, "  %s [%s] %s: %.3g\n", row_.caseName.c_str(), row_.path.c_str(), context_.c_str(), e);
        if (e > row_.worst || (row_.worstAt.empty() && e == row_.worst)) {
            row_.worst = e;
            row_.worstAt = context_;
        }
    }
    void value(double v) {
        ++row_.values;
        row_.nonFinite += !std::isfinite(v);
    }
    // Every value finite, every pixel premultiplied RGBA in [0, 1] (colour ≤ alpha up to the
    // rounding of their float sums).
    void image(const Image &img) {
        size_t invalid = 0;
        for (size_t i = 0; i < img.rgba.size(); i += 4) {
            const float a = img.rgba[i + 3];
            bool ok = a >= 0 && a <= 1;
            for (size_t k = 0; k < 4; ++k) value(img.rgba[i + k]);
            for (size_t k = 0; k < 3; ++k) ok = ok && img.rgba[i + k] >= 0 && img.rgba[i + k] <= a + 1e-5f;
            invalid += !ok;
        }
        require(invalid == 0, std::to_string(invalid) + " pixels are not premultiplied RGBA in [0, 1]");
    }
    void require(bool ok, const std::string &what) {
        if (!ok) row_.failures.push_back(what);
    }
    // A note for the table; repeated notes are kept once.
    void outcome(const std::string &text) {
        if (row_.outcome.find(text) != std::string::npos) return;
        row_.outcome = row_.outcome.empty() ? text : row_.outcome + "; " + text;
    }
    void expectsClearError() { row_.clearError = true; }
    // Runs one variant; an exception fails the row, not the whole table.
    template <typename F>
    void attempt(const std::string &what, F &&f) {
        context_ = what;
        try {
            f();
        } catch (const std::exception &e) {
            require(false, what + " threw: " + e.what());
        }
        context_.clear();
    }
    Row row() const { return row_; }

  private:
    Row row_;
    std::string context_;
};

// Where a case cannot be right, the answer is a clear error: f must throw std::invalid_argument
// whose message contains `needle`, quickly (before any allocation or rendering).
template <typename F>
void expectClearError(Check &check, const std::string &what, const std::string &needle, F &&f) {
    check.expectsClearError();
    const auto start = Clock::now();
    try {
        f();
        check.require(false, what + ": no error");
    } catch (const std::invalid_argument &e) {
        const double seconds = std::chrono::duration<double>(Clock::now() - start).count();
        check.require(std::string(e.what()).find(needle) != std::string::npos,
                      what + ": the message \"" + e.what() + "\" does not name " + needle);
        // Refused before any work: well under the cost of one allocation of an image this big.
        check.require(seconds < 0.05, what + ": took " + std::to_string(seconds) + " s to refuse");
        check.outcome(std::string("“") + e.what() + "”");
    } catch (const std::exception &e) {
        check.require(false, what + ": threw something other than a clear error: " + e.what());
    }
}

// ---- Scenes --------------------------------------------------------------------------------

// A constant medium: colour (not premultiplied; exact in float, so the table holds it
// exactly), opacity a per opacity unit (world units).
struct Medium {
    double r = 0.75, g = 0.5, b = 0.25;
    double a = 0.1;
    double unit = 1;

    TransferFunction tf() const {
        TransferFunction t;
        t.points = {{-1e6, r, g, b, a}, {1e6, r, g, b, a}};
        t.opacityUnit = unit;
        return t;
    }
    // Over a chord of length L: A = 1 − (1 − a)^(L/u) (Eq. 3 over the whole chord), colour c·A.
    Rgba over(double L) const {
        const double A = !(L > 0) ? 0.0 : a >= 1 ? 1.0 : -std::expm1(L / unit * std::log1p(-a));
        return {r * A, g * A, b * A, A};
    }
};

Quality plain(double step) { return test::plainQuality(step); }
Quality with(Quality q, bool jitter, bool preintegrated, bool defaults = false) {
    if (defaults) {
        // The defaults of the scene contract: early termination at 0.99, empty-space skipping.
        q.earlyTermination = 0.99;
        q.emptySpaceSkipping = true;
    }
    q.jitter = jitter;
    q.preintegrated = preintegrated;
    return q;
}
// plain, jittered, pre-integrated, with empty-space skipping and early termination (at
// 1 − 1e-7, so that what it leaves out, at most the transmittance left, is below the bounds),
// and the adaptive step (step the longest) with those and jitter: every segment length
// between step / 8 and step, restarts after skips.
std::vector<std::pair<std::string, Quality>> variants(double step) {
    Quality skipping = with(plain(step), false, false, true);
    skipping.earlyTermination = 1 - 1e-7;
    Quality adaptive = with(skipping, true, false);
    adaptive.adaptiveStep = true;
    return {{"plain", plain(step)},
            {"jitter", with(plain(step), true, false)},
            {"pre-integrated", with(plain(step), false, true)},
            {"skipping + early termination", skipping},
            {"adaptive step + jitter + skipping + early termination", adaptive}};
}

} // namespace

Camera orthographic(Vec3d eye, Vec3d forward, Vec3d up, double height) {
    Camera c;
    c.eye = eye;
    c.target = eye + forward; // forward is a unit axis: the view direction is exact
    c.up = up;
    c.projection = Projection::Orthographic;
    c.height = height;
    return c;
}
Camera perspective(Vec3d eye, Vec3d target, Vec3d up, double fovYDeg) {
    Camera c;
    c.eye = eye;
    c.target = target;
    c.up = up;
    c.fovYDeg = fovYDeg;
    return c;
}

namespace {

Camera oblique(const Volume &v, Vec3d offset, double fovYDeg) {
    return perspective(v.center() + offset, v.center() + Vec3d{0.3, -0.2, 0.1}, {0.1, 1, 0.2}, fovYDeg);
}

Volume constantBox(Vec3i dims, Vec3d spacing = {1, 1, 1}) { return makeConstantBox(dims, spacing, 1).volume; }

// The ray's interval inside an axis-aligned volume's cell-extent box (closed, docs/design.md) and
// the clip half-spaces, in double: the closed forms' chord. Empty: t1 ≤ t0.
struct Interval {
    double t0 = 0, t1 = 0;
    double planeSlack = 0; // how far float rounding of the clip planes can move t0 or t1
    double length() const { return std::max(t1 - t0, 0.0); }
};
double maxAbs(const Vec3d &v) { return std::max({std::fabs(v.x), std::fabs(v.y), std::fabs(v.z)}); }

// A plane's offset from the ray origin, g0 = (origin − point)·n, carries float rounding of
// the coordinates (8 ulp of their size, as for chordSlack), so the ray parameter where it
// crosses, −g0/(dir·n), moves by that over |dir·n|: without bound for a ray (nearly) in the
// plane, which float may keep or clip. A plane through the camera makes such rays.
double planeSlack(const Ray &ray, const ClipPlane &c) {
    const double rounding = 8 * kFloatEps * (maxAbs(ray.origin) + maxAbs(c.point) + 1);
    const double gd = std::fabs(dot(ray.dir, c.normal));
    return gd > 0 ? rounding / gd : kInf;
}

Interval insideOf(const Volume &v, const Ray &ray, std::span<const ClipPlane> planes = {}) {
    double t0 = 0, t1 = kInf;
    for (int a = 0; a < 3; ++a) {
        const double lo = v.origin[a] - 0.5 * v.spacing[a], hi = v.origin[a] + (double(v.dims[a]) - 0.5) * v.spacing[a];
        if (ray.dir[a] == 0) {
            if (ray.origin[a] < lo || ray.origin[a] > hi) return {};
            continue;
        }
        const double ta = (lo - ray.origin[a]) / ray.dir[a], tb = (hi - ray.origin[a]) / ray.dir[a];
        t0 = std::max(t0, std::min(ta, tb));
        t1 = std::min(t1, std::max(ta, tb));
    }
    double slack = 0;
    for (const ClipPlane &c : planes) {
        const double g0 = dot(ray.origin - c.point, c.normal), gd = dot(ray.dir, c.normal);
        slack += planeSlack(ray, c);
        if (gd == 0) {
            if (g0 < 0) return {0, 0, slack};
        } else if (gd > 0) {
            t0 = std::max(t0, -g0 / gd);
        } else {
            t1 = std::min(t1, -g0 / gd);
        }
    }
    return t1 > t0 ? Interval{t0, t1, slack} : Interval{0, 0, slack};
}

// How far float32 ray geometry can move a chord's ends: the kernel's t0 and t1 each come from
// a few roundings (the direction's normalisation, the index-space dot products, one division)
// of quantities up to the ray's exit distance and the coordinates involved: 8 ulp of their sum.
double chordSlack(const Volume &v, const Camera &cam, double tExit) {
    const double coordinates = std::max({maxAbs(cam.eye), maxAbs(v.worldBoundsMin()),
                                         maxAbs(v.worldFromIndex(Vec3d(v.dims) - Vec3d{0.5, 0.5, 0.5}))});
    return 8 * kFloatEps * (tExit + coordinates);
}

enum class Measure { Absolute, Relative };

// Every pixel against a constant medium's closed form over its chord. The error is the
// distance from the pixel to the closed form's values for chords L ± slack (A and c·A grow
// with L), so float ray geometry is not counted against the opacity arithmetic; with
// `exactGeometry` (axis-aligned orthographic rays at exact coordinates) the slack is 0.
// Relative: |Δ| / max(|want|, floor).
void compareWithMedium(Check &check, const Image &img, const Volume &v, const Camera &cam,
                       std::span<const ClipPlane> planes, const Medium &m, Measure measure = Measure::Absolute,
                       double floor = 0, bool exactGeometry = false) {
    check.image(img);
    const RayGenerator rays(cam, img.width, img.height);
    for (int y = 0; y < img.height; ++y)
        for (int x = 0; x < img.width; ++x) {
            const Ray ray = rays.pixelRay(x, y);
            const Interval in = insideOf(v, ray, planes);
            const double slack = exactGeometry ? 0.0 : chordSlack(v, cam, in.t1) + in.planeSlack;
            const Rgba lo = m.over(in.length() - slack), hi = m.over(in.length() + slack), at = m.over(in.length());
            const double wantLo[4] = {lo.r, lo.g, lo.b, lo.a}, wantHi[4] = {hi.r, hi.g, hi.b, hi.a};
            const double want[4] = {at.r, at.g, at.b, at.a};
            const float *p = img.pixel(x, y);
            for (int k = 0; k < 4; ++k) {
                const double outside = std::isfinite(p[k]) ? std::max({0.0, p[k] - wantHi[k], wantLo[k] - p[k]}) : kInf;
                check.error(measure == Measure::Relative ? outside / std::max(std::fabs(want[k]), floor) : outside);
            }
        }
}

// Largest per-channel |a − b| of two images of one size.
double maxDifference(const Image &a, const Image &b) {
    if (a.width != b.width || a.height != b.height) return kInf;
    double worst = 0;
    for (size_t i = 0; i < a.rgba.size(); ++i) {
        const double d = std::fabs(double(a.rgba[i]) - double(b.rgba[i]));
        worst = std::isnan(d) ? kInf : std::max(worst, d);
        if (worst == kInf) break;
    }
    return worst;
}

Image referenceImage(const Volume &v, const TransferFunction &tf, const Camera &cam, int w, int h,
                     std::span<const ClipPlane> planes = {}, Reconstruction rec = Reconstruction::Linear,
                     double tolerance = 1e-7) {
    ReferenceOptions o;
    o.tolerance = tolerance;
    return ReferenceRenderer(v, tf, rec).render(cam, w, h, planes, o);
}

// A scratch folder for volumes the loader cases write, removed with the object.
struct ScratchDir {
    fs::path path = fs::temp_directory_path() / ("volcast_stability_" + std::to_string(getpid()));
    ScratchDir() { fs::create_directories(path); }
    ~ScratchDir() {
        std::error_code ec;
        fs::remove_all(path, ec);
    }
};

std::string format(double x) {
    char buffer[32];
    std::snprintf(buffer, sizeof buffer, "%.2g", x);
    return buffer;
}
// An opacity, with values just below 1 as 1 − x.
std::string formatOpacity(double a) { return a > 0.99 && a < 1 ? "1 − " + format(1 - a) : format(a); }

// ---- Opacity correction ------------------------------------------------------------------

std::vector<Row> opacityCorrection(const Backend &be) {
    // A 2×2×8 box seen along z by a 2×2 orthographic camera: every ray runs from z = −1/2 to
    // 15/2 at x, y ∈ {0, 1}, with every coordinate exact in float, so what is left is the
    // opacity correction's own error. The opacity unit sets d/u.
    const Volume box = constantBox({2, 2, 8});
    const Camera cam = orthographic({0.5, 0.5, -10}, {0, 0, 1}, {0, 1, 0}, 2);
    const auto rendererPtr = be.make(box);
    FrameRenderer &renderer = *rendererPtr;
    // The required bound: 1e-6 relative to the double value, 1e-12 absolute near 0, i.e.
    // |Δ| / max(|want|, 1e-6) ≤ 1e-6.
    const std::string name = "opacity correction (Eq. 3), d/u 1e-6…1e4, a ∈ {0, 1e-9, 1e-7, 0.5, 1 − 1e-7, 1}";
    const std::string against = "closed form 1 − (1 − a)^(d/u), relative (absolute 1e-12 near 0)";
    Check ocl(name, be.name, against, 1e-6), ref(name, "reference", against, 1e-6);
    for (double a : {0.0, 1e-9, 1e-7, 0.5, 1 - 1e-7, 1.0}) {
        std::vector<double> ratios;
        for (int e = -24; e <= 16; ++e) ratios.push_back(std::pow(10.0, e / 4.0)); // 4 per decade
        // Either side of optical depth 1/2, where the kernel's opacity switches from its
        // series to 1 − exp.
        if (a > 0 && a < 1)
            for (double s : {1 - 1e-6, 1.0, 1 + 1e-6}) ratios.push_back(0.5 / -std::log1p(-a) * s);
        for (double r : ratios) {
            Medium m;
            m.a = a;
            m.unit = 8 / r;
            ocl.attempt("a = " + formatOpacity(a) + ", d/u = " + format(r), [&] {
                // One segment of d/u = r (the step is longer than the box), then eight of r/8.
                for (double step : {100.0, 1.0})
                    compareWithMedium(ocl, renderer.render({m.tf(), cam, 2, 2, plain(step), {}}), box, cam, {}, m,
                                      Measure::Relative, 1e-6, true);
            });
            ref.attempt("a = " + formatOpacity(a) + ", d/u = " + format(r), [&] {
                compareWithMedium(ref, referenceImage(box, m.tf(), cam, 2, 2), box, cam, {}, m, Measure::Relative,
                                  1e-6, true);
            });
        }
    }
    return {ocl.row(), ref.row()};
}

// ---- Faint media -------------------------------------------------------------------------

std::vector<Row> faintMedia(const Backend &be) {
    // a = 1e-7 per voxel along 8192 voxels at step 0.01: 819,200 segments (under the 2^20
    // bound) of optical depth 1e-9 each, A = 1 − (1 − 1e-7)^8192 ≈ 8.2e-4. Seen along the
    // long axis (one ray, exact chord), and by a narrow perspective camera of 3×1 pixels whose
    // outer rays leave through the sides after ~3400 voxels.
    const Volume box = constantBox({2, 2, 8192});
    Medium m;
    m.a = 1e-7;
    const Camera along = orthographic({0.5, 0.5, -10}, {0, 0, 1}, {0, 1, 0}, 2);
    const Camera narrow = perspective({0.5, 0.5, -20}, {0.5, 0.5, 8000}, {0, 1, 0}, 0.05);
    const auto rendererPtr = be.make(box);
    FrameRenderer &renderer = *rendererPtr;
    // The required bound: 1 % relative. A plain float sum of 819,200 depths of 1e-9 rounds each
    // addition by up to half an ulp of a sum near 8e-4, 2.9e-11 = 3 % of the term, mostly the
    // same way: 0.63 % in all was measured before the kernel compensated its sums.
    const std::string name = "faint media: a = 1e-7, step 0.01, chord 8192 voxels";
    const std::string against = "closed form 1 − (1 − a)^(L/u), relative";
    Check ocl(name, be.name, against, 0.01), pre(name, be.name + " pre-integrated", against, 0.01),
        ref(name, "reference", against, 0.01);
    for (const Camera *cam : {&along, &narrow}) {
        const int w = cam == &along ? 1 : 3, h = 1;
        const bool exact = cam == &along;
        const std::string view = cam == &along ? "along z" : "narrow perspective";
        ocl.attempt(view, [&] {
            compareWithMedium(ocl, renderer.render({m.tf(), *cam, w, h, plain(0.01), {}}), box, *cam, {}, m,
                              Measure::Relative, 1e-9, exact);
        });
        pre.attempt(view, [&] {
            compareWithMedium(pre, renderer.render({m.tf(), *cam, w, h, with(plain(0.01), false, true), {}}), box,
                              *cam, {}, m, Measure::Relative, 1e-9, exact);
        });
        ref.attempt(view, [&] {
            compareWithMedium(ref, referenceImage(box, m.tf(), *cam, w, h), box, *cam, {}, m, Measure::Relative,
                              1e-9, exact);
        });
    }
    // A medium so faint that 1 − a rounds to 1 in float (a = 2e-8 per voxel), so that T falls
    // only through its exact refreshes, with a clear voxel (value 0) in every 16 placed where
    // each refresh falls: samples at voxel centres, the 16th, 32nd … on the clear ones. Those
    // add nothing and are not composited; the refresh due on each is made at the next sample.
    // Dropped instead, T would stay 1 and the colour be 0.9 % high. The bound: T between
    // refreshes 16 roundings (1e-6 relative), each alpha ~2e-7 relative, the sums compensated:
    // 1e-4 relative, with room.
    {
        constexpr int kPeriod = 16, kChord = kPeriod * 60000;
        const SyntheticVolume gaps = sampleField("faint_with_gaps", {2, 2, kChord}, {1, 1, 1}, {}, [](const Vec3d &p) {
            return std::lround(p.z) % kPeriod == kPeriod - 1 ? 0.0 : 1.0;
        });
        Medium faint;
        faint.a = 2e-8;
        TransferFunction tf = faint.tf();
        tf.points = {{0, faint.r, faint.g, faint.b, 0}, {1, faint.r, faint.g, faint.b, faint.a}};
        const Rgba want = faint.over(double(kChord) / kPeriod * (kPeriod - 1));
        const Camera alongGaps = orthographic({0.5, 0.5, -10}, {0, 0, 1}, {0, 1, 0}, 2);
        Check gapRow("faint media with a clear voxel in every 16: a = 2e-8 (1 − a rounds to 1), step 1, " +
                         std::to_string(kChord) + " voxels",
                     be.name, "closed form 1 − (1 − a)^n over the n faint voxels, rgb = c·A, relative", 1e-4);
        gapRow.attempt("along z", [&] {
            const auto gapRenderer = be.make(gaps.volume);
            const Image img = gapRenderer->render({tf, alongGaps, 1, 1, plain(1), {}});
            gapRow.image(img);
            const float *px = img.pixel(0, 0);
            const double wanted[4] = {want.r, want.g, want.b, want.a};
            for (int k = 0; k < 4; ++k) gapRow.error(std::fabs(double(px[k]) - wanted[k]) / wanted[k]);
        });
        return {ocl.row(), pre.row(), ref.row(), gapRow.row()};
    }
}

// ---- Opaque media ------------------------------------------------------------------------

std::vector<Row> opaqueMedia(const Backend &be) {
    // A 16³ box from an oblique perspective camera, and along z by an orthographic one.
    const Volume box = constantBox({16, 16, 16});
    const Camera obliqueView = oblique(box, {20, 13, 27}, 40);
    const Camera along = orthographic({7.5, 7.5, -10}, {0, 0, 1}, {0, 1, 0}, 16);
    const auto rendererPtr = be.make(box);
    FrameRenderer &renderer = *rendererPtr;
    std::vector<Row> rows;
    for (double a : {1.0, 1 - 1e-6}) {
        Medium m;
        m.a = a;
        const std::string name = a == 1 ? "opaque media: a = 1, steps 0.01…10 voxels"
                                        : "opaque media: a = 1 − 1e-6, steps 0.01…10 voxels";
        // a = 1: A = 1 and colour = the transfer function's, exactly (bound 0), on every ray
        // longer than float rounding. a = 1 − 1e-6: 2e-6 for the compositing (segment alphas
        // to ~2e-7 relative, T to 16 roundings between its exact refreshes).
        const double bound = a == 1 ? 0 : 2e-6;
        const std::string against = "closed form, |ΔA|, |Δrgb| (rgb = c·A)";
        Check ocl(name, be.name + " (plain, jitter, pre-integrated, skipping + early termination, adaptive step)", against, bound),
            ref(name, "reference", against, bound);
        for (double step : {0.01, 0.1, 1.0, 10.0})
            for (const auto &[label, q] : variants(step))
                for (const Camera *cam : {&obliqueView, &along})
                    ocl.attempt(label + " at step " + format(step) + (cam == &along ? ", along z" : ", oblique"), [&] {
                        RenderStats st;
                        compareWithMedium(ocl, renderer.render({m.tf(), *cam, 12, 12, q, {}}, &st), box, *cam, {}, m,
                                          Measure::Absolute, 0, cam == &along);
                        // Opaque beyond the first segment: early termination stops every ray
                        // after one sample when that sample is already opaque.
                        if (a == 1 && q.earlyTermination < 1)
                            ocl.require(st.meanSamplesPerRay == 1, label + " at step " + format(step) + ": " +
                                                                       std::to_string(st.meanSamplesPerRay) +
                                                                       " samples per ray behind an opaque first one");
                    });
        for (const Camera *cam : {&obliqueView, &along})
            ref.attempt(cam == &along ? "along z" : "oblique", [&] {
                compareWithMedium(ref, referenceImage(box, m.tf(), *cam, 12, 12), box, *cam, {}, m, Measure::Absolute,
                                  0, cam == &along);
            });
        rows.push_back(ocl.row());
        rows.push_back(ref.row());
    }
    return rows;
}

// ---- Pre-integration ---------------------------------------------------------------------

// Colours either side of the step, exact in float.
constexpr double kFront[3] = {0.25, 0.5, 1.0}, kBack[3] = {1.0, 0.5, 0.25};
constexpr double kStepValue = 100;

// (kFront, a0) up to value 100, (kBack, a1) from 100 + 1e-12 on: a step, as steep as a
// transfer function's strictly increasing values allow (the ramp between shifts any segment's
// optical depth by at most τ·d·1e-12/|sb − sf| ≤ 1e-9 below).
TransferFunction stepTf(double a0, double a1, double unit) {
    TransferFunction tf;
    tf.points = {{0, kFront[0], kFront[1], kFront[2], a0},
                 {kStepValue, kFront[0], kFront[1], kFront[2], a0},
                 {kStepValue + 1e-12, kBack[0], kBack[1], kBack[2], a1},
                 {200, kBack[0], kBack[1], kBack[2], a1}};
    tf.opacityUnit = unit;
    return tf;
}

// Closed form of a segment made of constant pieces (length, colour, a), front to back:
// D = Σ τᵢLᵢ, C = Σ Tᵢ·cᵢ·(1 − exp(−τᵢLᵢ)) with Tᵢ the transmittance in front of piece i.
struct Piece {
    double length;
    const double *c;
    double a;
};
Rgba piecewise(std::initializer_list<Piece> pieces, double unit) {
    double depth = 0, rgb[3] = {0, 0, 0};
    for (const Piece &p : pieces) {
        if (!(p.length > 0)) continue;
        const double d = p.a >= 1 ? kInf : p.length / unit * -std::log1p(-p.a);
        const double alpha = -std::expm1(-d), t = std::exp(-depth);
        for (int k = 0; k < 3; ++k) rgb[k] += t * p.c[k] * alpha;
        depth += d;
    }
    return {rgb[0], rgb[1], rgb[2], -std::expm1(-depth)};
}

// A segment of length d from value sf to sb across stepTf: the part on each side of 100.
Rgba stepSegment(double sf, double sb, double d, double a0, double a1, double unit) {
    auto side = [&](double v) { return v <= kStepValue ? std::make_pair(kFront, a0) : std::make_pair(kBack, a1); };
    const auto [cf, af] = side(sf);
    const auto [cb, ab] = side(sb);
    if (cf == cb) return piecewise({{d, cf, af}}, unit);
    const double front = d * (kStepValue - sf) / (sb - sf);
    return piecewise({{front, cf, af}, {d - front, cb, ab}}, unit);
}

double rgbaDifference(const Rgba &got, const Rgba &want) {
    return std::max({std::fabs(got.r - want.r), std::fabs(got.g - want.g), std::fabs(got.b - want.b),
                     std::fabs(got.a - want.a)});
}

std::vector<Row> preintegration(const Backend &be) {
    std::vector<Row> rows;
    const double ln2 = std::log(2.0);

    // (1) The exact segment integral (double). integrateSegment promises ~1e-11 relative; the
    // step's 1e-12-wide ramp moves D by ≤ 1e-9 (see stepTf): bound 1e-8.
    Check exact("pre-integration: front = back, front and back either side of a step, τ·d 1e-3…1e4",
                "integrateSegment (double)", "closed form, |ΔA|, |Δrgb|", 1e-8);
    for (double a : {1e-7, 0.5, 1 - 1e-7, 1.0})
        for (int e = -6; e <= 4; ++e) {
            Medium m;
            m.a = a;
            const double d = std::pow(10.0, e);
            const SegmentIntegral s = integrateSegment(m.tf(), 50, 50, d, 1);
            exact.value(s.r + s.g + s.b + s.alpha());
            exact.error(rgbaDifference({s.r, s.g, s.b, s.alpha()}, m.over(d)));
        }
    for (double tauD : {1e-3, 1.0, 1e2, 1e4}) {
        const double a0 = 0.05, a1 = 0.6, d = 1;
        const double unit = d * -std::log1p(-a1) / tauD; // τ₁·d = tauD
        const TransferFunction tf = stepTf(a0, a1, unit);
        for (double sf : {60.0, 99.9, 99.999, 100.001, 100.1, 140.0})
            for (double sb : {60.0, 99.9, 99.999, kStepValue, 100.001, 100.1, 140.0}) {
                const SegmentIntegral s = integrateSegment(tf, sf, sb, d, unit);
                exact.value(s.r + s.g + s.b + s.alpha());
                exact.error(rgbaDifference({s.r, s.g, s.b, s.alpha()}, stepSegment(sf, sb, d, a0, a1, unit)));
            }
        // Constant τ, colour linear in the value (0 at 0, 1 at 200): with x = τd,
        // C = c_f·A + (c_b − c_f)·(A − x·e^−x)/x, A = 1 − e^−x.
        TransferFunction ramp;
        ramp.points = {{0, 0, 0, 0, 0.5}, {200, 1, 1, 1, 0.5}};
        ramp.opacityUnit = d * ln2 / tauD;
        for (double sf : {10.0, 150.0})
            for (double sb : {30.0, 190.0}) {
                const SegmentIntegral s = integrateSegment(ramp, sf, sb, d, *ramp.opacityUnit);
                const double x = tauD, A = -std::expm1(-x), cf = sf / 200, cb = sb / 200;
                const double c = cf * A + (cb - cf) * (A - x * std::exp(-x)) / x;
                exact.value(s.r + s.alpha());
                exact.error(rgbaDifference({s.r, s.g, s.b, s.alpha()}, {c, c, c, A}));
            }
    }
    rows.push_back(exact.row());

    // (2) The table the kernel reads, at random (front, back) pairs against the closed form.
    // Bound: the table's tolerance (1e-3, the default), which its build measures at every
    // cell's centre and edge midpoints with a margin of 2 for the error between them. Pairs
    // within 1e-3 of the step are left out: there the table holds the step between two nodes
    // 32 float ulps apart (its finest split), and interpolates across it.
    Check table("pre-integration: front = back, front and back either side of a step, τ·d 1 and 1e4",
                "pre-integration table (float)", "closed form, |ΔA|, |Δrgb|", 1e-3);
    std::mt19937 random(4);
    std::uniform_real_distribution<float> value(0, 200);
    for (double tauD : {1.0, 1e4}) {
        const double a0 = 0.05, a1 = 0.6, d = 1, unit = d * -std::log1p(-a1) / tauD;
        table.attempt("τ·d = " + format(tauD), [&] {
            const PreintegrationTable t = buildPreintegrationTable(stepTf(a0, a1, unit), d, unit, 0, 200);
            for (int i = 0; i < 4000; ++i) {
                const float sf = value(random), sb = i % 4 == 0 ? sf : value(random); // a quarter on the diagonal
                if (std::fabs(sf - kStepValue) < 1e-3 || std::fabs(sb - kStepValue) < 1e-3) continue;
                const Rgba got = t.lookup(sf, sb);
                for (double v : {got.r, got.g, got.b, got.a}) table.value(v);
                table.error(rgbaDifference(got, stepSegment(sf, sb, d, a0, a1, unit)));
            }
        });
    }
    rows.push_back(table.row());

    // (3) The kernel. A 2×2×8 box along z: front = back, opacity corrected to τ·d up to 1e4;
    // a ramp along x (values 40…165 over 32 voxels, the step at x ≈ 14.9) seen along x from
    // either end, so segments straddle the step at every step length.
    const std::string kernelCase = "pre-integration: front = back, front and back either side of a step, τ·d 0.26…1e4";
    // The table's tolerance (1e-3) for each of the two segments that hold interpolation error:
    // the one across the step and the partial one at the exit. Everywhere else the table
    // interpolates a constant.
    Check ocl(kernelCase, be.name, "closed form, |ΔA|, |Δrgb|", 2e-3);
    Check ref(kernelCase, "reference", "closed form, |ΔA|, |Δrgb|", 1e-6);
    {
        const Volume box = constantBox({2, 2, 8});
        const Camera cam = orthographic({0.5, 0.5, -10}, {0, 0, 1}, {0, 1, 0}, 2);
        const auto rendererPtr = be.make(box);
        FrameRenderer &renderer = *rendererPtr;
        for (double a : {0.5, 1 - 1e-7, 1.0})
            for (double tauD : {1.0, 1e2, 1e4}) {
                Medium m;
                m.a = a;
                m.unit = a < 1 ? -std::log1p(-a) / tauD : 1.0; // step 1 voxel: τ·d = tauD
                ocl.attempt("box, a = " + formatOpacity(a) + ", τ·d = " + format(tauD), [&] {
                    compareWithMedium(ocl, renderer.render({m.tf(), cam, 2, 2, with(plain(1), false, true), {}}), box,
                                      cam, {}, m, Measure::Absolute, 0, true);
                });
            }
    }
    const SyntheticVolume ramp = makeLinearRamp({32, 2, 2}, {1, 1, 1}, 40, 165);
    // Where the trilinear ray crosses 100 between the float samples.
    double xStep = 0;
    for (int i = 0; i + 1 < 32; ++i) {
        const double v0 = ramp.volume.at(i, 0, 0), v1 = ramp.volume.at(i + 1, 0, 0);
        if (v0 <= kStepValue && v1 > kStepValue) xStep = i + (kStepValue - v0) / (v1 - v0);
    }
    const auto rampRendererPtr = be.make(ramp.volume);
    FrameRenderer &rampRenderer = *rampRendererPtr;
    const double a0 = 1e-3, a1 = 0.5;
    // Step 0.37 at τ₁·d = 0.26 (u = 1), step 3.3 at τ₁·d = 1e4; each table serves both directions.
    for (const auto &[step, unit] : {std::pair{0.37, 1.0}, std::pair{3.3, 3.3 * ln2 / 1e4}}) {
        const TransferFunction tf = stepTf(a0, a1, unit);
        for (int direction : {+1, -1}) {
            // Orthographic along ±x: rays at y, z ∈ {0, 1} from x = −1/2 to 31.5 (or back).
            const Camera cam = orthographic({direction > 0 ? -10.0 : 42.0, 0.5, 0.5}, {double(direction), 0, 0},
                                            {0, 1, 0}, 2);
            const double lowSide = xStep + 0.5, highSide = 31.5 - xStep;
            const Rgba want = direction > 0 ? piecewise({{lowSide, kFront, a0}, {highSide, kBack, a1}}, unit)
                                            : piecewise({{highSide, kBack, a1}, {lowSide, kFront, a0}}, unit);
            auto compare = [&](Check &check, const Image &img) {
                check.image(img);
                for (int y = 0; y < 2; ++y)
                    for (int x = 0; x < 2; ++x) {
                        const float *p = img.pixel(x, y);
                        check.error(rgbaDifference({p[0], p[1], p[2], p[3]}, want));
                    }
            };
            const std::string label =
                std::string(direction > 0 ? "+x" : "−x") + ", step " + format(step) + ", u " + format(unit);
            ocl.attempt(label, [&] {
                compare(ocl, rampRenderer.render({tf, cam, 2, 2, with(plain(step), false, true), {}}));
            });
            ref.attempt(label, [&] { compare(ref, referenceImage(ramp.volume, tf, cam, 2, 2)); });
        }
    }
    rows.push_back(ocl.row());
    rows.push_back(ref.row());
    return rows;
}

// ---- Degenerate volumes ------------------------------------------------------------------

// Colour and opacity changing across [lo, hi].
TransferFunction spreadTf(double lo, double hi, double unit) {
    const double w = hi - lo;
    TransferFunction tf;
    tf.points = {{lo, 0.25, 0.5, 1, 0.02},
                 {lo + 0.3 * w, 1, 0.5, 0.25, 0.1},
                 {lo + 0.7 * w, 0.5, 1, 0.25, 0.3},
                 {hi, 1, 1, 1, 0.5}};
    tf.opacityUnit = unit;
    return tf;
}

// A back end against the reference on a non-constant volume, where no closed form exists. The
// bound covers what the fast path approximates: the midpoint rule at step 0.05 (second order,
// d²/24 · |∂²(c·τ·T)/∂t²| per unit length: ~1e-4 on these fields) and the 1-D table (≤ 1e-4
// in colour and in opacity per opacity unit, tf_table.hpp), with room for 3×.
constexpr double kAgainstReferenceStep = 0.05;
constexpr double kAgainstReferenceBound = 1e-3;
// Pre-integration at the default step, 0.5: it takes the value as linear along each segment,
// but trilinear reconstruction is cubic along a ray, so on small, steep fields its error is
// second order in the step (~5e-3 on the blobs here, test_opencl_remedies measures 3.5e-3 at
// step 2 on its own), plus the table's own ≤ 1e-3 per segment.
constexpr double kPreintegratedAgainstReferenceStep = 0.5;
constexpr double kPreintegratedAgainstReferenceBound = 1e-2;

// Renders `v` trilinear and cubic at kAgainstReferenceStep (into `plainCheck`) and
// pre-integrated at kPreintegratedAgainstReferenceStep (into `preCheck`), each against the
// reference of the same reconstruction (whose outputs go to `refCheck`).
void compareWithReference(Check &plainCheck, Check &preCheck, Check &refCheck, FrameRenderer &renderer,
                          const Volume &v, const TransferFunction &tf, const Camera &cam, const std::string &name,
                          bool preintegrated = true) {
    constexpr int kSize = 8;
    for (Reconstruction rec : {Reconstruction::Linear, Reconstruction::Cubic}) {
        // Tolerance 1e-5: far below the bounds, at a fraction of 1e-7's cost.
        const Image exact = referenceImage(v, tf, cam, kSize, kSize, {}, rec, 1e-5);
        refCheck.image(exact);
        Quality q = plain(kAgainstReferenceStep);
        q.interpolation = rec == Reconstruction::Cubic ? Interpolation::Cubic : Interpolation::Linear;
        plainCheck.attempt(name + (rec == Reconstruction::Cubic ? ", cubic" : ", trilinear"), [&] {
            const Image img = renderer.render({tf, cam, kSize, kSize, q, {}});
            plainCheck.image(img);
            plainCheck.error(maxDifference(img, exact));
        });
        if (rec == Reconstruction::Linear && preintegrated)
            preCheck.attempt(name, [&] {
                const Image img =
                    renderer.render({tf, cam, kSize, kSize, with(plain(kPreintegratedAgainstReferenceStep), false, true), {}});
                preCheck.image(img);
                preCheck.error(maxDifference(img, exact));
            });
    }
}

struct DegenerateVolume {
    std::string name;
    Volume volume;
    TransferFunction tf;
    Camera camera;
    // Whether pre-integration at step 0.5 is measured against the reference: not on a 2×2×2
    // of arbitrary values or a checkerboard, which change over the whole range within a voxel
    // (the ±1e30 one is checked by scaling instead), nor on the 1:1000 volume, whose rays
    // cross 6000 segments of alpha ~3e-3 each, where the table's absolute 1e-3 per entry adds
    // up to 0.016 (an accuracy limit of the table's tolerance, not a stability defect).
    bool preintegrated = true;
};

// The volumes, each with a transfer function over its range and a camera that sees all of it.
std::vector<DegenerateVolume> makeDegenerateVolumes(const fs::path &scratch) {
    std::vector<DegenerateVolume> out;
    auto add = [&](std::string name, Volume v, double unit, Vec3d offset) {
        DegenerateVolume d;
        d.name = std::move(name);
        d.tf = spreadTf(v.range.min, v.range.max, unit);
        d.camera = oblique(v, offset, 40);
        d.volume = std::move(v);
        out.push_back(std::move(d));
    };
    const auto blobYZ = [](const Vec3d &p) { return 200 * std::exp(-((p.y - 5.5) * (p.y - 5.5) + (p.z - 5.5) * (p.z - 5.5)) / 18); };
    add("1×12×12", sampleField("slab", {1, 12, 12}, {1, 1, 1}, {}, blobYZ).volume, 1, {15, 10, 20});
    add("24×1×1", sampleField("rod", {24, 1, 1}, {1, 1, 1}, {}, [](const Vec3d &p) { return 100 + 90 * std::sin(p.x / 3); }).volume,
        1, {15, 10, 20});
    {
        // Cubic prefilter on axes shorter than its 4-tap support.
        const float values[8] = {10, 200, 60, 120, 180, 30, 90, 250};
        Volume v = makeConstantBox({2, 2, 2}, {1, 1, 1}, 0).volume;
        v.voxels.assign(values, values + 8);
        computeStatistics(v);
        add("2×2×2", std::move(v), 1, {3, 2, 4});
        out.back().preintegrated = false;
    }
    // Spacing 1:1000: 8×8 voxels of 1 across, 3 slices 1000 apart, seen along the long axis
    // by a narrow camera (opacity unit 100: a few units across the 3000 deep box).
    {
        Volume v = sampleField("anisotropic", {8, 8, 3}, {1, 1, 1000}, {}, [](const Vec3d &p) {
                       return 100 + 60 * std::sin(p.x / 2) * std::cos(p.y / 3) + 30 * p.z / 1000;
                   }).volume;
        DegenerateVolume d;
        d.name = "spacing 1:1000";
        d.tf = spreadTf(v.range.min, v.range.max, 100);
        d.camera = perspective(v.center() + Vec3d{0.7, -0.4, -3000}, v.center(), {0, 1, 0}, 0.2);
        d.volume = std::move(v);
        d.preintegrated = false;
        out.push_back(std::move(d));
    }
    {
        // A 16-bit volume using its full range 0…65535, through the loader.
        Volume ramp = sampleField("uint16", {16, 6, 6}, {1, 1, 1}, {}, [](const Vec3d &p) {
                          return std::clamp(65535 * (p.x / 15) + 3000 * std::sin(p.y + p.z), 0.0, 65535.0);
                      }).volume;
        const fs::path file = scratch / "full_range_uint16.nrrd";
        SaveOptions o;
        o.type = VoxelType::UInt16;
        saveVolume(ramp, file, o);
        Volume v = loadVolume(file);
        if (v.sourceType != VoxelType::UInt16 || v.range.min != 0 || v.range.max != 65535)
            throw std::runtime_error("the 16-bit volume did not load as uint16 over 0…65535");
        add("16-bit, values 0…65535", std::move(v), 1, {20, 12, 18});
    }
    {
        // Values ±1e30 in a checkerboard, the transfer function over [−1e30, 1e30].
        Volume v = sampleField("huge", {5, 5, 5}, {1, 1, 1}, {}, [](const Vec3d &p) {
                       return (int(p.x + p.y + p.z) % 2 == 0) ? 1e30 : -1e30;
                   }).volume;
        add("float ±1e30", std::move(v), 1, {6, 4, 7});
        out.back().preintegrated = false;
    }
    return out;
}

std::vector<Row> degenerateVolumes(const Backend &be) {
    std::vector<Row> rows;
    // 1×1×1: one value everywhere in the cell-extent box [−1/2, 1/2]³: a closed form.
    {
        const Volume one = makeConstantBox({1, 1, 1}, {1, 1, 1}, 50).volume;
        const TransferFunction tf = spreadTf(0, 100, 1);
        const Rgba at50 = tf.evaluate(50);
        Medium m;
        m.r = at50.r;
        m.g = at50.g;
        m.b = at50.b;
        m.a = at50.a;
        m.unit = 1;
        const Camera cam = oblique(one, {2.1, 1.3, 2.7}, 40);
        const std::string name = "1×1×1 volume (linear, cubic, pre-integrated, skipping)";
        // As for the opaque media: 2e-6 for the compositing (the colour here is 0.75,
        // 0.75, 0.25 evaluated in double and held in float: 3e-8 more).
        Check ocl(name, be.name, "closed form, |ΔA|, |Δrgb|", 2e-6), ref(name, "reference", "closed form, |ΔA|, |Δrgb|", 2e-6);
        const auto rendererPtr = be.make(one);
        FrameRenderer &renderer = *rendererPtr;
        std::vector<std::pair<std::string, Quality>> qualities = variants(0.1);
        Quality cubic = plain(0.1);
        cubic.interpolation = Interpolation::Cubic;
        qualities.emplace_back("cubic", cubic);
        for (const auto &[label, q] : qualities)
            ocl.attempt(label, [&] { compareWithMedium(ocl, renderer.render({tf, cam, 12, 12, q, {}}), one, cam, {}, m); });
        for (Reconstruction rec : {Reconstruction::Linear, Reconstruction::Cubic})
            ref.attempt(rec == Reconstruction::Linear ? "linear" : "cubic", [&] {
                compareWithMedium(ref, referenceImage(one, tf, cam, 12, 12, {}, rec), one, cam, {}, m);
            });
        rows.push_back(ocl.row());
        rows.push_back(ref.row());
    }
    // The others against the reference with the same reconstruction: trilinear and cubic at
    // step 0.05, pre-integrated (trilinear) at step 0.5.
    const ScratchDir scratch;
    std::vector<DegenerateVolume> volumes;
    Check setup("degenerate volumes", "setup", "", 0);
    setup.attempt("making the volumes", [&] { volumes = makeDegenerateVolumes(scratch.path); });
    if (!setup.row().failures.empty()) rows.push_back(setup.row());
    const std::string name = "volumes 1×12×12, 24×1×1, 2×2×2, spacing 1:1000, 16-bit 0…65535, float ±1e30";
    const std::string against = "reference, same reconstruction, max |Δ| over RGBA";
    Check ocl(name, be.name + " trilinear and cubic, step 0.05", against, kAgainstReferenceBound),
        pre(name, be.name + " pre-integrated, step 0.5 (1×12×12, 24×1×1, 16-bit)", against, kPreintegratedAgainstReferenceBound),
        ref(name, "reference", "outputs only", 0);
    for (const DegenerateVolume &d : volumes)
        ocl.attempt(d.name, [&] {
            const auto rendererPtr = be.make(d.volume);
            FrameRenderer &renderer = *rendererPtr;
            compareWithReference(ocl, pre, ref, renderer, d.volume, d.tf, d.camera, d.name, d.preintegrated);
        });
    rows.push_back(ocl.row());
    rows.push_back(pre.row());
    rows.push_back(ref.row());

    // ±1e30 against the same volume and transfer function scaled by 2^-100 (values ±0.79):
    // every difference and ratio the renderers form scales exactly, so the images must agree
    // to rounding, whatever the approximations. Bound: a few float roundings, 1e-6.
    Check scaled("float ±1e30 volume (trilinear, cubic, pre-integrated)", be.name + " and reference",
                 "the same volume scaled by 2^-100, max |Δ| over RGBA", 1e-6);
    for (const DegenerateVolume &d : volumes) {
        if (d.name != "float ±1e30") continue;
        scaled.attempt(d.name, [&] {
            Volume small = d.volume;
            for (float &x : small.voxels) x = std::ldexp(x, -100);
            computeStatistics(small);
            TransferFunction tf = d.tf;
            for (ControlPoint &p : tf.points) p.value = std::ldexp(p.value, -100);
            const auto bigPtr = be.make(d.volume), littlePtr = be.make(small);
            FrameRenderer &big = *bigPtr, &little = *littlePtr;
            Quality cubic = plain(0.5);
            cubic.interpolation = Interpolation::Cubic;
            for (const Quality &q : {plain(0.5), cubic, with(plain(0.5), false, true)}) {
                const Image a = big.render({d.tf, d.camera, 8, 8, q, {}}), b = little.render({tf, d.camera, 8, 8, q, {}});
                scaled.image(a);
                scaled.image(b);
                scaled.error(maxDifference(a, b));
            }
            for (Reconstruction rec : {Reconstruction::Linear, Reconstruction::Cubic}) {
                const Image a = referenceImage(d.volume, d.tf, d.camera, 8, 8, {}, rec, 1e-5);
                const Image b = referenceImage(small, tf, d.camera, 8, 8, {}, rec, 1e-5);
                scaled.image(a);
                scaled.image(b);
                scaled.error(maxDifference(a, b));
            }
        });
    }
    rows.push_back(scaled.row());
    return rows;
}

// ---- Cameras and rays --------------------------------------------------------------------

std::vector<Row> camerasAndRays(const Backend &be) {
    // An 8³ box [−1/2, 15/2]³ of a = 0.2 per voxel; 9×9 images, so the middle row and column
    // have image-plane coordinate exactly 0 (rays in the planes through the view direction).
    const Volume box = constantBox({8, 8, 8});
    Medium m;
    m.a = 0.2;
    const auto rendererPtr = be.make(box);
    FrameRenderer &renderer = *rendererPtr;
    const std::string against = "closed form, |ΔA|, |Δrgb|";
    // The compositing's 2e-6, as for the opaque media; chords are taken ± their float slack.
    const double bound = 2e-6;
    std::vector<std::pair<std::string, Quality>> qualities = variants(0.5);
    qualities.erase(qualities.begin() + 1); // jitter adds nothing to the geometry

    struct View {
        std::string name;
        Camera camera;
        std::vector<ClipPlane> planes;
        const Volume *volume;
        int size = 9;
        bool exact = false;
    };
    const Vec3d inside{3.3, 3.6, 3.1};
    const Volume box7 = constantBox({7, 7, 8}); // for the orthographic grid below
    const auto renderer7Ptr = be.make(box7);
    FrameRenderer &renderer7 = *renderer7Ptr;
    const std::vector<View> placements = {
        {"camera inside", perspective(inside, inside + Vec3d{1, 0.4, 0.2}, {0, 1, 0}, 100), {}, &box},
        {"camera on a face, looking in", perspective({3.3, 3.6, -0.5}, {3.3, 3.6, 7}, {0, 1, 0}, 120), {}, &box},
        // The middle row runs in the face plane z = −1/2: inside the closed box.
        {"camera on a face, looking along it", perspective({3.3, 3.6, -0.5}, {7, 3.6, -0.5}, {0, 0, 1}, 90), {}, &box},
        {"camera on an edge, looking at the centre", perspective({-0.5, -0.5, 3.3}, {3.5, 3.5, 3.5}, {0, 1, 0}, 90), {}, &box},
        // The middle ray runs along the edge x = y = −1/2.
        {"camera on an edge, looking along it", perspective({-0.5, -0.5, 3.3}, {-0.5, -0.5, 10}, {0, 1, 0}, 90), {}, &box},
    };
    const std::vector<View> rays = {
        // 8×8 orthographic rays along z at x, y ∈ {−1/2, 1/2, …, 13/2}: zero direction
        // components, the outer rays in the faces x, y = −1/2 and 13/2 of a 7×7×8 box, the
        // corner rays along its edges; every coordinate exact in float.
        {"orthographic along z: rays in faces and along edges", orthographic({3, 3, -20}, {0, 0, 1}, {0, 1, 0}, 8), {}, &box7, 8, true},
        // The middle ray of 9×9 enters at corner (−1/2, −1/2, −1/2) and leaves at (15/2, 15/2, 15/2).
        {"ray through two corners", perspective({-10.5, -10.5, -10.5}, {7.5, 7.5, 7.5}, {0, 1, 0}, 60), {}, &box},
    };
    const std::vector<View> clipped = {
        // The view direction lies in the plane: the middle ray runs inside it, kept or clipped
        // within rounding (planeSlack), the rays either side kept from the eye or not at all.
        {"clip plane through the camera (inside)", perspective(inside, inside + Vec3d{1, 0.4, 0.2}, {0, 1, 0}, 100),
         {{inside, normalize(Vec3d{0.3, -1, 0.5})}}, &box},
        {"clip plane through the camera (outside)", oblique(box, {12, 8, 15}, 40),
         {{box.center() + Vec3d{12, 8, 15}, normalize(Vec3d{-1, -0.2, 0.1})}}, &box},
        {"clip plane that removes everything", oblique(box, {12, 8, 15}, 40),
         {{{100, 100, 100}, normalize(Vec3d{1, 1, 1})}}, &box},
    };
    std::vector<Row> rows;
    for (const auto &[name, views] :
         {std::pair{std::string("camera inside the volume, on a face, on an edge"), &placements},
          std::pair{std::string("rays parallel to faces, along edges, through corners; orthographic along an axis"), &rays},
          std::pair{std::string("clip plane through the camera; clip plane that removes everything"), &clipped}}) {
        Check ocl(name, be.name + " (plain, pre-integrated, skipping + early termination, adaptive step)", against, bound),
            ref(name, "reference", against, bound);
        for (const View &v : *views) {
            FrameRenderer &r = v.volume == &box ? renderer : renderer7;
            for (const auto &[label, q] : qualities)
                ocl.attempt(v.name + ", " + label, [&] {
                    compareWithMedium(ocl, r.render({m.tf(), v.camera, v.size, v.size, q, v.planes}), *v.volume, v.camera,
                                      v.planes, m, Measure::Absolute, 0, v.exact);
                });
            ref.attempt(v.name, [&] {
                compareWithMedium(ref, referenceImage(*v.volume, m.tf(), v.camera, v.size, v.size, v.planes), *v.volume,
                                  v.camera, v.planes, m, Measure::Absolute, 0, v.exact);
            });
        }
        rows.push_back(ocl.row());
        rows.push_back(ref.row());
    }

    // Cases that cannot be right: a clear error from every entry point.
    Camera parallel = perspective({0, 0, 20}, {0, 0, 0}, {0, 0, 1}, 30);
    Camera nowhere = perspective({1, 2, 3}, {1, 2, 3}, {0, 1, 0}, 30);
    Check errors("up parallel to the view direction; eye = target", be.name + ", reference, scene file",
                 "a clear error naming the key", 0);
    expectClearError(errors, be.name + ", up ∥ view", "camera.up", [&] { renderer.render({m.tf(), parallel, 4, 4, plain(1), {}}); });
    expectClearError(errors, "reference, up ∥ view", "camera.up", [&] { referenceImage(box, m.tf(), parallel, 4, 4); });
    expectClearError(errors, "scene file, up ∥ view", "camera.up", [&] {
        parseScene(R"({"volume": "builtin:demo", "transfer_function": {"points": [[0, 0, 0, 0, 0], [255, 1, 1, 1, 1]]},
                      "camera": {"eye": [0, 0, 20], "target": [0, 0, 0], "up": [0, 0, 3], "projection": "perspective",
                                 "fov_y_deg": 30}, "image": {"width": 8, "height": 8}})");
    });
    expectClearError(errors, be.name + ", eye = target", "camera.target", [&] { renderer.render({m.tf(), nowhere, 4, 4, plain(1), {}}); });
    expectClearError(errors, "reference, eye = target", "camera.target", [&] { referenceImage(box, m.tf(), nowhere, 4, 4); });
    rows.push_back(errors.row());
    return rows;
}

// ---- Steps -------------------------------------------------------------------------------

std::vector<Row> steps(const Backend &be) {
    std::vector<Row> rows;
    {
        // Steps of 50 to 1e30 voxels through a 12×9×15 box of spacing (1, 1.5, 0.8): one
        // segment per ray, partial at the exit (and at the entry under jitter).
        const Volume box = constantBox({12, 9, 15}, {1, 1.5, 0.8});
        Medium m;
        m.a = 0.07;
        const Camera cam = oblique(box, {20, 13, 27}, 30);
        const auto rendererPtr = be.make(box);
        FrameRenderer &renderer = *rendererPtr;
        Check ocl("step larger than the whole volume: 50, 1e3, 1e6, 1e30 voxels",
                  be.name + " (plain, jitter, pre-integrated, skipping + early termination, adaptive step)", "closed form, |ΔA|, |Δrgb|",
                  2e-6); // the compositing's, as for the opaque media
        for (double step : {50.0, 1e3, 1e6, 1e30})
            for (const auto &[label, q] : variants(step))
                ocl.attempt(label + " at step " + format(step), [&] {
                    compareWithMedium(ocl, renderer.render({m.tf(), cam, 12, 12, q, {}}), box, cam, {}, m);
                });
        rows.push_back(ocl.row());
    }
    {
        // A 1e-4 voxel step along 120 voxels would take 1.2 million segments per ray, more than
        // the kernel's bound of 2^20: the renderer raises the step to the shortest that keeps
        // every ray within the bound (diagonal / (2^20 − 16) ≈ 1.15e-4 voxels), says so in its
        // stats and log, and no ray is cut off. 2×1 orthographic rays along x, chord exactly 120.
        const Volume box = constantBox({120, 4, 4});
        Medium m;
        m.a = 0.01;
        const Camera cam = orthographic({-10, 1.5, 1.5}, {1, 0, 0}, {0, 1, 0}, 2);
        const auto rendererPtr = be.make(box);
        FrameRenderer &renderer = *rendererPtr;
        // Over a million compensated additions the sums stay exact to a few roundings; what
        // is left is each segment's alpha (~2e-7 relative) and T between its refreshes: 2e-6.
        Check ocl("step of 1e-4 voxels, 120-voxel chords (bounded at 2^20 samples per ray)",
                  be.name + " (plain, jitter, pre-integrated)", "closed form, |ΔA|, |Δrgb|", 2e-6);
        // The frame's budget: 2 rays × 2^20 samples. One PoCL thread takes the rays of a work
        // group in turn at ~1e7 samples per second here, so 0.2 s alone; beside three builds on
        // the 2 cores it took 2.3 s. What this guards against is a frame without the bound,
        // which would not end at all: 10 s tells the two apart on any machine that runs CI.
        Check time("step of 1e-4 voxels: render time of a 2×1 frame", be.name, "seconds against the frame's budget", 10);
        std::vector<std::pair<std::string, Quality>> qualities = variants(1e-4);
        // Early termination would stop these rays early.
        std::erase_if(qualities, [](const auto &v) { return v.first.find("early termination") != std::string::npos; });
        for (const auto &[label, q] : qualities)
            ocl.attempt(label, [&] {
                RenderStats st;
                const auto start = Clock::now();
                const Image img = renderer.render({m.tf(), cam, 2, 1, q, {}}, &st);
                time.error(std::chrono::duration<double>(Clock::now() - start).count());
                time.value(st.renderSeconds);
                compareWithMedium(ocl, img, box, cam, {}, m, Measure::Absolute, 0, true);
                ocl.require(st.stepRaised, label + ": the step was not raised");
                ocl.require(st.raysTruncated == 0, label + ": " + std::to_string(st.raysTruncated) + " rays truncated");
                ocl.require(st.meanSamplesPerRay <= FrameRenderer::kMaxSamplesPerRay,
                            label + ": " + std::to_string(st.meanSamplesPerRay) + " samples per ray");
                if (label == "plain")
                    ocl.outcome("step raised to " + format(st.stepUsed) + " voxels, " +
                                std::to_string(std::lround(st.meanSamplesPerRay)) + " samples per ray, 0 rays truncated");
            });
        rows.push_back(ocl.row());
        rows.push_back(time.row());
    }
    return rows;
}

// ---- Images ------------------------------------------------------------------------------

std::vector<Row> images(const Backend &be) {
    const Volume box = constantBox({8, 8, 8});
    Medium m;
    m.a = 0.2;
    const Camera cam = oblique(box, {12, 8, 15}, 40);
    const auto rendererPtr = be.make(box);
    FrameRenderer &renderer = *rendererPtr;
    std::vector<Row> rows;
    const std::string against = "closed form, |ΔA|, |Δrgb|";
    Check ocl("images of 1×1, 1×64 and 64×1 pixels", be.name + " (plain, jitter, pre-integrated, skipping + early termination, adaptive step)",
              against, 2e-6),
        ref("images of 1×1, 1×64 and 64×1 pixels", "reference", against, 2e-6);
    for (const auto &[w, h] : {std::pair{1, 1}, std::pair{1, 64}, std::pair{64, 1}}) {
        const std::string size = std::to_string(w) + "×" + std::to_string(h);
        for (const auto &[label, q] : variants(0.5))
            ocl.attempt(size + ", " + label, [&] { compareWithMedium(ocl, renderer.render({m.tf(), cam, w, h, q, {}}), box, cam, {}, m); });
        ref.attempt(size, [&] { compareWithMedium(ref, referenceImage(box, m.tf(), cam, w, h), box, cam, {}, m); });
    }
    rows.push_back(ocl.row());
    rows.push_back(ref.row());

    // Past the memory budget (kMaxImageSide per side, kMaxImagePixels in all, scene.hpp): a
    // clear error before anything is allocated, from every entry point.
    Check big("images past the budget: 16385×1, 1×16385, 16384×16384, 0×1, −1×5, INT_MAX²",
              be.name + ", reference, scene file", "a clear error naming the image", 0);
    for (const auto &[w, h] : {std::pair{16385, 1}, std::pair{1, 16385}, std::pair{16384, 16384}, std::pair{0, 1},
                               std::pair{-1, 5}, std::pair{INT_MAX, INT_MAX}}) {
        const std::string size = std::to_string(w) + "×" + std::to_string(h);
        expectClearError(big, be.name + " " + size, "image", [&] { renderer.render({m.tf(), cam, w, h, plain(1), {}}); });
        expectClearError(big, "reference " + size, "image", [&] { referenceImage(box, m.tf(), cam, w, h); });
    }
    expectClearError(big, "scene file 16384×16384", "image", [&] {
        parseScene(R"({"volume": "builtin:demo", "transfer_function": {"points": [[0, 0, 0, 0, 0], [255, 1, 1, 1, 1]]},
                      "camera": {"eye": [0, 0, 20], "target": [0, 0, 0], "up": [0, 1, 0], "projection": "perspective",
                                 "fov_y_deg": 30}, "image": {"width": 16384, "height": 16384}})");
    });
    // The table shows the two kinds of message; every one was checked.
    Row r = big.row();
    std::string perSide, total;
    std::istringstream notes(r.outcome);
    for (std::string note; std::getline(notes, note, ';');) {
        if (perSide.empty() && note.find("per side") != std::string::npos) perSide = note;
        if (total.empty() && note.find("more than the limit") != std::string::npos) total = note;
    }
    r.outcome = perSide + ";" + total;
    rows.push_back(r);
    return rows;
}

// ---- Data --------------------------------------------------------------------------------

std::vector<Row> nonFiniteData(const Backend &be) {
    // A 6³ blob written as float32 NRRD with a NaN, a +Inf and a −Inf voxel, loaded back: the
    // loader's policy (volume_io.hpp) puts NaN and −Inf at the smallest finite value, +Inf at
    // the largest, and counts them.
    const ScratchDir scratch;
    std::vector<Row> rows;
    Check policy("NaN and Inf voxels: the loader's policy", "loader", "voxels not as the policy says", 0);
    const std::string name = "NaN and Inf voxels: rendering the loaded volume";
    const std::string against = "reference, same reconstruction, max |Δ| over RGBA";
    Check ocl(name, be.name + " trilinear and cubic, step 0.05 (and skipping at mip level 1: outputs only)", against,
              kAgainstReferenceBound),
        pre(name, be.name + " pre-integrated, step 0.5", against, kPreintegratedAgainstReferenceBound),
        ref(name, "reference", "outputs only", 0);
    policy.attempt("save and load", [&] {
        Volume v = makeGaussianBlob({6, 6, 6}, {1, 1, 1}, 2, 200).volume;
        const float nan = std::numeric_limits<float>::quiet_NaN(), inf = std::numeric_limits<float>::infinity();
        v.voxels[v.index(1, 2, 3)] = nan;
        v.voxels[v.index(4, 4, 4)] = inf;
        v.voxels[v.index(0, 0, 5)] = -inf;
        const fs::path file = scratch.path / "non_finite.nrrd";
        saveVolume(v, file);
        const Volume loaded = loadVolume(file);
        policy.value(double(loaded.nonFiniteReplaced));
        policy.error(std::fabs(double(loaded.nonFiniteReplaced) - 3));
        policy.error(loaded.at(1, 2, 3) != loaded.range.min);
        policy.error(loaded.at(4, 4, 4) != loaded.range.max);
        policy.error(loaded.at(0, 0, 5) != loaded.range.min);
        size_t bad = 0;
        for (const float x : loaded.samples().toFloats()) bad += !std::isfinite(x);
        policy.error(double(bad));
        policy.outcome(std::to_string(loaded.nonFiniteReplaced) + " voxels replaced, range " + format(loaded.range.min) +
                       "…" + format(loaded.range.max));

        const TransferFunction tf = spreadTf(loaded.range.min, loaded.range.max, 1);
        const Camera cam = oblique(loaded, {9, 6, 11}, 40);
        const auto rendererPtr = be.make(loaded);
        FrameRenderer &renderer = *rendererPtr;
        compareWithReference(ocl, pre, ref, renderer, loaded, tf, cam, "blob");
        // Skipping, early termination and a coarser level: outputs only (no reference for these).
        Quality fast = with(plain(0.5), false, false, true);
        fast.mipLevel = 1;
        ocl.image(renderer.render({tf, cam, 12, 12, fast, {}}));
    });
    rows.push_back(policy.row());
    rows.push_back(ocl.row());
    rows.push_back(pre.row());
    rows.push_back(ref.row());
    return rows;
}

} // namespace

Backend openClBackend(std::shared_ptr<OpenClContext> cl) {
    return {"OpenCL", [cl](const Volume &v) -> std::unique_ptr<FrameRenderer> { return std::make_unique<OpenClRenderer>(cl, v); }};
}
Backend cpuBackend() {
    return {"CPU", [](const Volume &v) -> std::unique_ptr<FrameRenderer> { return std::make_unique<CpuRenderer>(v); }};
}

const std::vector<Case> &cases() {
    static const std::vector<Case> all = {
        {"OpacityCorrection", opacityCorrection}, {"FaintMedia", faintMedia},
        {"OpaqueMedia", opaqueMedia},             {"PreIntegration", preintegration},
        {"DegenerateVolumes", degenerateVolumes}, {"CamerasAndRays", camerasAndRays},
        {"Steps", steps},                         {"Images", images},
        {"NonFiniteData", nonFiniteData},
    };
    return all;
}

// A table cell: '|' escaped, so that |ΔA| stays in its column.
std::string cell(const std::string &text) {
    std::string out;
    for (char c : text) {
        if (c == '|') out += '\\';
        out += c;
    }
    return out;
}

std::string markdownTable(const std::vector<Row> &rows) {
    std::ostringstream out;
    out << "| case | path | compared with | worst error seen | bound | NaN/Inf in outputs |\n";
    out << "|---|---|---|---|---|---|\n";
    for (const Row &r : rows) {
        out << "| " << cell(r.caseName) << " | " << cell(r.path) << " | " << cell(r.comparedWith);
        if (r.clearError) {
            out << " | " << cell(r.outcome) << " | clear error";
        } else {
            if (!r.outcome.empty()) out << " (" << cell(r.outcome) << ")";
            out << " | " << format(r.worst) << " | " << format(r.bound);
        }
        out << " | " << (r.values ? std::to_string(r.nonFinite) + " of " + std::to_string(r.values) : "—");
        if (!r.passed()) out << " **FAILED**";
        out << " |\n";
    }
    return out.str();
}

} // namespace volcast::stability
