// The ray set-up under the liberties OpenCL C gives a device's float arithmetic, emulated here
// in C++ on the formulas both back ends share (renderer/common/ray_math.h), so that geometry
// which holds only under one rounding is caught without a GPU.
//
// What a device may do (OpenCL C 1.2, §7.4 and the default FP_CONTRACT): divide to 2.5 ulp and
// take square roots to 3 ulp unless built with -cl-fp32-correctly-rounded-divide-sqrt; fuse
// a·b + c within an expression into one rounding; flush denormal inputs and results to zero.
// `DeviceFloat` does each on demand: a quotient or root k ulp from the correctly rounded one
// (k fixed per run, both signs tried), expression templates that fuse a product with the sum
// or difference it appears in (as a compiler contracts within one expression, not across
// statements), and flushing of every operand and result.
//
// The judge is the reference's camera (RayGenerator, in double) and the closed box
// [−½, n − ½] in double: which rays hit, and where they enter and leave.

#include <cmath>
#include <cstdint>
#include <string>
#include <vector>

namespace device_rounding {

struct Liberties {
    int divisionUlps = 0;   // quotients this many ulp from the correctly rounded one
    int sqrtUlps = 0;       // square roots likewise
    bool contract = false;  // a·b ± c within an expression as one fused operation
    bool flushDenormals = false;

    std::string describe() const {
        return "division " + std::to_string(divisionUlps) + " ulp, sqrt " + std::to_string(sqrtUlps) + " ulp, " +
               (contract ? "contracted" : "not contracted") + (flushDenormals ? ", denormals flushed" : "");
    }
};
inline Liberties active;

inline float flush(float x) {
    return active.flushDenormals && std::fpclassify(x) == FP_SUBNORMAL ? std::copysign(0.0f, x) : x;
}
// x moved k ulp (toward +∞ for k > 0).
inline float ulpsAway(float x, int k) {
    for (; k > 0; --k) x = std::nextafter(x, INFINITY);
    for (; k < 0; ++k) x = std::nextafter(x, -INFINITY);
    return x;
}

struct DeviceFloat {
    float v = 0;
    DeviceFloat() = default;
    DeviceFloat(float x) : v(flush(x)) {}
};
// A product not yet rounded: it rounds when used alone, or fuses with the sum it is part of.
struct Product {
    float a, b;
    operator DeviceFloat() const { return DeviceFloat(flush(a) * flush(b)); }
};
using F = DeviceFloat;

inline F fused(float a, float b, float c) {
    return active.contract ? F(std::fma(flush(a), flush(b), flush(c))) : F(F(Product{a, b}).v + flush(c));
}
inline Product operator*(F a, F b) { return {a.v, b.v}; }
inline Product operator*(Product p, F b) { return {F(p).v, b.v}; }
inline Product operator*(F a, Product p) { return {a.v, F(p).v}; }
inline Product operator*(Product p, Product q) { return {F(p).v, F(q).v}; }
inline F operator+(F a, F b) { return F(a.v + b.v); }
inline F operator-(F a, F b) { return F(a.v - b.v); }
inline F operator+(Product p, F c) { return fused(p.a, p.b, c.v); }
inline F operator+(F c, Product p) { return fused(p.a, p.b, c.v); }
inline F operator+(Product p, Product q) { return fused(p.a, p.b, F(q).v); }
inline F operator-(Product p, F c) { return fused(p.a, p.b, -c.v); }
inline F operator-(F c, Product p) { return fused(-p.a, p.b, c.v); }
inline F operator-(Product p, Product q) { return fused(p.a, p.b, -F(q).v); }
inline F operator/(F a, F b) {
    const float q = a.v / b.v;
    // An exact zero, infinity or NaN stays one: the error bound is relative to the result.
    if (q == 0 || !std::isfinite(q)) return F(q);
    return F(ulpsAway(q, active.divisionUlps));
}
inline bool operator==(F a, F b) { return a.v == b.v; }
inline bool operator!=(F a, F b) { return a.v != b.v; }
inline bool operator<(F a, F b) { return a.v < b.v; }
inline bool operator>(F a, F b) { return a.v > b.v; }
inline bool operator<=(F a, F b) { return a.v <= b.v; }
inline bool operator>=(F a, F b) { return a.v >= b.v; }

inline F select(bool m, F a, F b) { return m ? a : b; }
inline F neg(F x) { return F(-x.v); }
inline F mad(F a, F b, F c) { return fused(a.v, b.v, c.v); }
inline F min(F a, F b) { return F(std::fmin(a.v, b.v)); }
inline F max(F a, F b) { return F(std::fmax(a.v, b.v)); }
inline F abs(F x) { return F(std::fabs(x.v)); }
inline F sqrt(F x) {
    const float r = std::sqrt(x.v);
    return F(r == 0 || !std::isfinite(r) ? r : ulpsAway(r, active.sqrtUlps));
}
inline F floor(F x) { return F(std::floor(x.v)); }
inline F exp(F x) { return F(std::exp(x.v)); }
inline F log1p(F x) { return F(std::log1p(x.v)); }
inline bool isinf(F x) { return std::isinf(x.v); }

} // namespace device_rounding

#define VC_REAL device_rounding::DeviceFloat
#define VC_MASK bool
#define VC_INLINE inline
#define VC_CONST(c) device_rounding::DeviceFloat(c)
#define VC_INFINITY INFINITY
#define vc_select(m, a, b) device_rounding::select(m, a, b)
#define vc_any(m) (m)
#define vc_and(a, b) ((a) && (b))
#define vc_or(a, b) ((a) || (b))
#define vc_neg(x) device_rounding::neg(x)
#define vc_mad(a, b, c) device_rounding::mad(a, b, c)
#define vc_min(a, b) device_rounding::min(a, b)
#define vc_max(a, b) device_rounding::max(a, b)
#define vc_abs(x) device_rounding::abs(x)
#define vc_sqrt(x) device_rounding::sqrt(x)
#define vc_floor(x) device_rounding::floor(x)
#define vc_exp(x) device_rounding::exp(x)
#define vc_log1p(x) device_rounding::log1p(x)
#define vc_isinf(x) device_rounding::isinf(x)
#include "renderer/common/ray_math.h"

#include "renderer/common/frame_setup.hpp"
#include "renderer/cpu/cpu_march.hpp"
#include "renderer/model/camera.hpp"
#include "renderer/model/synthetic.hpp"
#include "tests/stability/stability_cases.hpp"

#include <gtest/gtest.h>

#include <algorithm>

namespace volcast {
namespace {

using device_rounding::active;
using device_rounding::Liberties;
using F = device_rounding::DeviceFloat;

// Every combination of what a device may do: division and square root off by up to their
// allowed error in whole ulps (2 of 2.5, 3 of 3), each sign, fused or not, flushed or not.
std::vector<Liberties> everyDevice() {
    std::vector<Liberties> all;
    for (int division = -2; division <= 2; ++division)
        for (int root : {-3, 0, 3})
            for (bool contract : {false, true})
                for (bool flushDenormals : {false, true}) all.push_back({division, root, contract, flushDenormals});
    return all;
}

struct ActiveLiberties {
    explicit ActiveLiberties(const Liberties &l) { active = l; }
    ~ActiveLiberties() { active = {}; }
};

// Former formulations, kept here to show the emulation has the teeth to catch them:
// 1 − 2(y + ½)/n, and the same integer numerator as now but divided on the device.
F formerImageV(F y, F n) { return F(1.0f) - F(2.0f) * (y + F(0.5f)) / n; }
F dividedImageU(F x, F n) { return (F(2.0f) * x + F(1.0f) - n) / n; }

TEST(DeviceRounding, EmulatedDivisionErrorBreaksTheFormerImagePlaneFormulas) {
    // 1 − 9/9 with 9/9 one ulp high is −2^-23, not 0: the row a camera on a face looks along
    // left the face on an H100. −7/8 two ulp off puts the edge ray of an orthographic 8-ray
    // view, which runs in a face, outside it. If the emulation did nothing, both would hold.
    ActiveLiberties device({1, 0, false, false});
    EXPECT_NE(formerImageV(F(4.0f), F(9.0f)).v, 0.0f);
    EXPECT_EQ(vcImageV(F(4.0f), F(9.0f), F(float(1.0 / 9))).v, 0.0f);
    active.divisionUlps = -2;
    EXPECT_NE(dividedImageU(F(0.0f), F(8.0f)).v, -0.875f);
    EXPECT_EQ(vcImageU(F(0.0f), F(8.0f), F(0.125f)).v, -0.875f);
}

TEST(DeviceRounding, EmulatedContractionFusesWithinAnExpressionOnly) {
    // x·x − x·x is 0 when each product rounds, and the rounding error of x·x when the first
    // fuses with the difference; across statements nothing fuses.
    const F x(1.0f + 1.0f / 4096);
    ActiveLiberties device({0, 0, true, false});
    EXPECT_NE((x * x - x * x).v, 0.0f);
    const F square = x * x;
    EXPECT_EQ((square - square).v, 0.0f);
    active.contract = false;
    EXPECT_EQ((x * x - x * x).v, 0.0f);
}

TEST(DeviceRounding, ImagePlaneMiddleIsZeroAndMirroredPixelsOppositeUnderEveryDevice) {
    for (const Liberties &l : everyDevice()) {
        ActiveLiberties device(l);
        // Every size to 257, and the sizes of common views around powers of two.
        std::vector<int> sizes;
        for (int n = 1; n <= 257; ++n) sizes.push_back(n);
        for (int n : {511, 512, 513, 600, 768, 1023, 1024, 1025, 1080, 1920, 2047, 2048, 2049}) sizes.push_back(n);
        for (int n : sizes) {
            for (int x = 0; x < n; ++x) {
                const F inverse(float(1.0 / n)); // as the host rounds it
                const F u = vcImageU(F(float(x)), F(float(n)), inverse);
                const F v = vcImageV(F(float(x)), F(float(n)), inverse);
                const F uMirror = vcImageU(F(float(n - 1 - x)), F(float(n)), inverse);
                // (2x + 1 − n)·(1/n): rounding 1/n (2^-24 relative) moves the product by at most
                // 2^-24·|u| ≤ 1 ulp of u, and the product rounds by ½ ulp: 1.5 ulp on any device.
                const double exact = double(2 * x + 1 - n) / n;
                const float nearest = float(exact);
                const double ulp = std::nextafter(std::fabs(nearest), INFINITY) - std::fabs(nearest);
                ASSERT_LE(std::fabs(u.v - exact), 1.5 * ulp)
                    << "u of pixel " << x << " of " << n << " under " << l.describe();
                ASSERT_EQ(u.v, -v.v) << "u and v of pixel " << x << " of " << n << " under " << l.describe();
                ASSERT_EQ(u.v, -uMirror.v) << "pixels " << x << " and " << n - 1 - x << " of " << n << " under "
                                           << l.describe();
                if (2 * x + 1 == n) {
                    ASSERT_EQ(u.v, 0.0f) << "middle pixel of " << n << " under " << l.describe();
                }
            }
        }
    }
}

// A view of a closed box whose rays run in its faces or along its edges.
struct View {
    std::string name;
    Camera camera;
    Vec3i dims;
    int size;
};

using stability::orthographic;
using stability::perspective;

// The stability suite's placements (tests/stability/stability_cases.cpp) whose rays lie in a
// face or along an edge of the box, where a hit depends on the ray being exactly there.
std::vector<View> viewsAlongFacesAndEdges() {
    return {
        {"camera on a face, looking along it", perspective({3.3, 3.6, -0.5}, {7, 3.6, -0.5}, {0, 0, 1}, 90), {8, 8, 8}, 9},
        {"camera on an edge, looking along it", perspective({-0.5, -0.5, 3.3}, {-0.5, -0.5, 10}, {0, 1, 0}, 90), {8, 8, 8}, 9},
        {"camera on a face, looking in", perspective({3.3, 3.6, -0.5}, {3.3, 3.6, 7}, {0, 1, 0}, 120), {8, 8, 8}, 9},
        {"orthographic along z: rays in faces and along edges", orthographic({3, 3, -20}, {0, 0, 1}, {0, 1, 0}, 8), {7, 7, 8}, 8},
        {"ray through two corners", perspective({-10.5, -10.5, -10.5}, {7.5, 7.5, 7.5}, {0, 1, 0}, 60), {8, 8, 8}, 9},
    };
}

struct Chord {
    bool hit = false;
    double t0 = 0, t1 = 0;
};

// The judge: the reference's ray through the pixel centre in double, clipped to the closed box.
Chord exactChord(const FrameSetup &s, const RayGenerator &rays, int x, int y) {
    const Ray ray = rays.pixelRay(x, y);
    double t0 = 0, t1 = INFINITY;
    for (int a = 0; a < 3; ++a) {
        const double *m = s.indexFromWorld[a];
        const double p = m[0] * ray.origin.x + m[1] * ray.origin.y + m[2] * ray.origin.z + m[3];
        const double d = m[0] * ray.dir.x + m[1] * ray.dir.y + m[2] * ray.dir.z;
        const double lo = a == 0 ? s.boxLo.x : a == 1 ? s.boxLo.y : s.boxLo.z;
        const double hi = a == 0 ? s.boxHi.x : a == 1 ? s.boxHi.y : s.boxHi.z;
        if (d == 0) {
            if (p < lo || p > hi) return {};
            continue;
        }
        t0 = std::max(t0, std::min((lo - p) / d, (hi - p) / d));
        t1 = std::min(t1, std::max((lo - p) / d, (hi - p) / d));
    }
    return {t1 > t0, t0, t1};
}

// The back ends' set-up (raycast.cl's cameraRay and clipToBox, cpu_march.cpp's setUpPacket)
// in the emulated arithmetic.
Chord deviceChord(const cpu::FrameParams &P, int x, int y) {
    const F u = vcImageU(F(float(x)), F(float(P.width)), F(P.inverseWidth));
    const F v = vcImageV(F(float(y)), F(float(P.height)), F(P.inverseHeight));
    F origin[3], dir[3];
    vcCameraRay(u, v, P.eye, P.forward, P.right, P.up, P.orthographic, origin, dir);
    F t0(0.0f), t1(INFINITY);
    for (int a = 0; a < 3; ++a)
        vcClipToSlab(vcAffineRow(P.indexFromWorld[a], origin), vcLinearRow(P.indexFromWorld[a], dir), F(P.boxLo[a]),
                     F(P.boxHi[a]), &t0, &t1);
    return {t1 > t0, t0.v, t1.v};
}

TEST(DeviceRounding, RaysInFacesAndAlongEdgesHitAsInTheReferenceUnderEveryDevice) {
    for (const View &view : viewsAlongFacesAndEdges()) {
        const Volume box = makeConstantBox(view.dims, {1, 1, 1}, 1).volume;
        TransferFunction tf;
        tf.points = {{0, 1, 1, 1, 0.5}, {2, 1, 1, 1, 0.5}};
        const FrameSetup s = setUpFrame(box, {tf, view.camera, view.size, view.size, Quality{}, {}}, 0, 8);
        cpu::FrameParams P{};
        fillCommonParams(s, P);
        const RayGenerator rays(view.camera, view.size, view.size);
        int hits = 0;
        for (const Liberties &l : everyDevice()) {
            ActiveLiberties device(l);
            for (int y = 0; y < view.size; ++y)
                for (int x = 0; x < view.size; ++x) {
                    const Chord exact = exactChord(s, rays, x, y), got = deviceChord(P, x, y);
                    ASSERT_EQ(got.hit, exact.hit) << view.name << ": ray (" << x << ", " << y << ") under " << l.describe()
                                                  << ", reference chord [" << exact.t0 << ", " << exact.t1 << "]";
                    if (!exact.hit) continue;
                    ++hits;
                    // A dozen roundings of coordinates up to ~20 and the allowed division and
                    // root errors move t by ~1e-6 relative; 1e-5·(|t| + 20) leaves 10×.
                    EXPECT_NEAR(got.t0, exact.t0, 1e-5 * (std::fabs(exact.t0) + 20)) << view.name << " (" << x << ", " << y << ") " << l.describe();
                    EXPECT_NEAR(got.t1, exact.t1, 1e-5 * (std::fabs(exact.t1) + 20)) << view.name << " (" << x << ", " << y << ") " << l.describe();
                }
        }
        EXPECT_GT(hits, 0) << view.name << ": no ray hit the box, so nothing was checked";
    }
}

} // namespace
} // namespace volcast
