/* The per-sample formulas of the ray march, written once for both back ends: compiled as
 * OpenCL C in the ray-casting kernel (renderer/opencl/kernels/raycast.cl; the build embeds
 * this file before it) and as C++ in the native SIMD march (renderer/cpu/cpu_march.cpp).
 * The reference integrator (renderer/reference/) stays apart, in double: it is the judge.
 *
 * Each formula is written against a value type VC_REAL and its mask type VC_MASK with + − * /,
 * comparisons and the few operations below (vc_*). OpenCL C gets one ray per work item, a
 * float and an int mask. C++ gets plain float and bool unless the includer names another
 * type first: cpu_march.cpp names Highway's vectors (one ray per lane) and maps the
 * operations to Highway's, so each formula is one lane-wise expression on both back ends.
 * Where the kernel writes a·b + c (vc_mad) the OpenCL compiler may fuse it, as OpenCL's
 * default FP_CONTRACT allows; the native path fuses it explicitly. Both draw the same image
 * to float rounding (CpuRenderer.DrawsTheOpenClImageToFloatRounding).
 *
 * Under Highway each instruction set includes this file again in its own namespace
 * (foreach_target.h), hence the guard that follows HWY_TARGET_TOGGLE; without Highway it is
 * an ordinary include guard. */
#if defined(VOLCAST_RAY_MATH_H) == defined(HWY_TARGET_TOGGLE)
#ifdef VOLCAST_RAY_MATH_H
#undef VOLCAST_RAY_MATH_H
#else
#define VOLCAST_RAY_MATH_H
#endif

#ifndef VOLCAST_EMBEDDED
#include "../model/phong_constants.h"
#endif

#if defined(__OPENCL_VERSION__) || defined(__OPENCL_C_VERSION__)
/* VC_FP_CONTRACT_OFF (a build option for diagnosis, tests/device/run-on-device.sh): the
 * kernel as OpenCL C would be without the contraction of a·b + c it allows by default. */
#ifdef VC_FP_CONTRACT_OFF
#pragma OPENCL FP_CONTRACT OFF
#endif
#define VC_INLINE static inline
#define VC_UINT uint
#define VC_BOOL int
#define VC_LIBM(f) f
#else
#define VC_UINT uint32_t /* a C++ includer naming VC_REAL includes <cstdint> first */
#ifndef VC_REAL
#include <cmath>
#include <cstdint>
#define VC_INLINE inline
#define VC_BOOL bool
#define VC_LIBM(f) std::f
#endif
#endif

#ifndef VC_REAL
/* One ray in plain float: OpenCL C, or scalar C++. */
#define VC_REAL float
#define VC_MASK VC_BOOL
#define VC_CONST(c) (c)
#define VC_INFINITY INFINITY
#define vc_select(m, a, b) ((m) ? (a) : (b))
#define vc_any(m) (m)
#define vc_and(a, b) ((a) && (b))
#define vc_or(a, b) ((a) || (b))
#define vc_neg(x) (-(x))
#define vc_mad(a, b, c) ((a) * (b) + (c))
#define vc_min(a, b) VC_LIBM(fmin)(a, b)
#define vc_max(a, b) VC_LIBM(fmax)(a, b)
#define vc_abs(x) VC_LIBM(fabs)(x)
#define vc_sqrt(x) VC_LIBM(sqrt)(x)
#define vc_floor(x) VC_LIBM(floor)(x)
#define vc_exp(x) VC_LIBM(exp)(x)
#define vc_log1p(x) VC_LIBM(log1p)(x)
#define vc_isinf(x) VC_LIBM(isinf)(x)
#endif

/* ---- jitter ---------------------------------------------------------------------------- */

/* PCG hash: a reproducible uniform number in [0, 1) per pixel, seed and pass. Per ray, in
 * 32-bit unsigned arithmetic on both back ends, so jittered images match. */
VC_INLINE float vcRandom01(VC_UINT x, VC_UINT y, VC_UINT seed, VC_UINT pass) {
    VC_UINT s = x * 1973u + y * 9277u + seed * 26699u + pass * 104729u;
    s = s * 747796405u + 2891336453u;
    VC_UINT w = ((s >> ((s >> 28u) + 4u)) ^ s) * 277803737u;
    w = (w >> 22u) ^ w;
    return (float)(w >> 8) * (1.0f / 16777216.0f);
}

/* ---- ray set-up ------------------------------------------------------------------------ */

/* Image-plane coordinates of pixel centre x of n, from −1 (left, bottom) to 1 (docs/design.md's
 * camera): u = 2(x + ½)/n − 1 across, v = 1 − 2(y + ½)/n down the rows, as the exact integer
 * 2x + 1 − n times inverseN = 1/n rounded once on the host. Products are correctly rounded on
 * every OpenCL device, quotients only to 2.5 ulp: the middle pixel of an odd n is exactly 0,
 * mirrored pixels exactly opposite, and edge pixels of a power-of-two n exact, whatever the
 * device. 1 − 2(y + ½)/n put the middle row of a camera on a face, looking along it, 1 ulp off
 * the face on an NVIDIA GPU: outside the box (tests/renderer/test_device_rounding.cpp). */
VC_INLINE VC_REAL vcImageU(VC_REAL x, VC_REAL n, VC_REAL inverseN) {
    return (VC_CONST(2.0f) * x + VC_CONST(1.0f) - n) * inverseN;
}
VC_INLINE VC_REAL vcImageV(VC_REAL y, VC_REAL n, VC_REAL inverseN) {
    return (n - VC_CONST(2.0f) * y - VC_CONST(1.0f)) * inverseN;
}

/* The world ray through image-plane point (u, v) of the camera (eye, forward, right, up: the
 * frame's constants, right and up scaled by the view's half-extents): origin and direction,
 * the direction a unit vector in perspective. A zero component of forward, right and up
 * with a zero u or v stays exactly zero, whether or not a·b + c is fused. */
VC_INLINE void vcCameraRay(VC_REAL u, VC_REAL v, const float *eye, const float *forward, const float *right,
                           const float *up, int orthographic, VC_REAL *origin, VC_REAL *dir) {
    for (int a = 0; a < 3; ++a) {
        const VC_REAL offset = u * VC_CONST(right[a]) + v * VC_CONST(up[a]);
        origin[a] = orthographic ? VC_CONST(eye[a]) + offset : VC_CONST(eye[a]);
        dir[a] = orthographic ? VC_CONST(forward[a]) : VC_CONST(forward[a]) + offset;
    }
    if (!orthographic) {
        const VC_REAL len = vc_sqrt(dir[0] * dir[0] + dir[1] * dir[1] + dir[2] * dir[2]);
        for (int a = 0; a < 3; ++a) dir[a] = dir[a] / len;
    }
}

/* Row r·x + r[3] of an affine map (r: the row's linear part, then its translation), and its
 * linear part alone: a point and a direction into index space, a point's and a direction's
 * value under a plane (n, w). Summed left to right on both back ends. */
VC_INLINE VC_REAL vcAffineRow(const float *r, const VC_REAL *x) {
    return VC_CONST(r[0]) * x[0] + VC_CONST(r[1]) * x[1] + VC_CONST(r[2]) * x[2] + VC_CONST(r[3]);
}
VC_INLINE VC_REAL vcLinearRow(const float *r, const VC_REAL *x) {
    return VC_CONST(r[0]) * x[0] + VC_CONST(r[1]) * x[1] + VC_CONST(r[2]) * x[2];
}

/* Clips the ray's [t0, t1] to the slab lo ≤ p + t·d ≤ hi of one axis. A ray parallel to the
 * slab misses (t1 = −∞) when it lies outside; its divisions by 0 are discarded. */
VC_INLINE void vcClipToSlab(VC_REAL p, VC_REAL d, VC_REAL lo, VC_REAL hi, VC_REAL *t0, VC_REAL *t1) {
    const VC_MASK parallel = d == VC_CONST(0.0f);
    const VC_MASK outside = vc_and(parallel, vc_or(p < lo, p > hi));
    const VC_REAL ta = (lo - p) / d, tb = (hi - p) / d;
    *t0 = vc_select(parallel, *t0, vc_max(*t0, vc_min(ta, tb)));
    *t1 = vc_select(parallel, *t1, vc_min(*t1, vc_max(ta, tb)));
    *t1 = vc_select(outside, VC_CONST(-VC_INFINITY), *t1);
}

/* Clips [t0, t1] to the half space a clip plane keeps, g(t) = g0 + t·gd ≥ 0, where g0 and gd
 * are the plane's value at the origin and its rate along the direction. */
VC_INLINE void vcClipToPlane(VC_REAL g0, VC_REAL gd, VC_REAL *t0, VC_REAL *t1) {
    const VC_REAL at = vc_neg(g0) / gd;
    *t1 = vc_select(vc_and(gd == VC_CONST(0.0f), g0 < VC_CONST(0.0f)), VC_CONST(-VC_INFINITY), *t1);
    *t0 = vc_select(gd > VC_CONST(0.0f), vc_max(*t0, at), *t0);
    *t1 = vc_select(gd < VC_CONST(0.0f), vc_min(*t1, at), *t1);
}

/* ---- classification -------------------------------------------------------------------- */

/* Fractional table position of value v in a uniform table whose entry 0 holds value lo, with
 * `scale` entries per data unit and entries 0 … last (tf_table.hpp), clamped to the table. */
VC_INLINE VC_REAL vcTableCoordinate(VC_REAL v, VC_REAL lo, VC_REAL scale, VC_REAL last) {
    return vc_min(vc_max((v - lo) * scale, VC_CONST(0.0f)), last);
}

/* Where v lies between pre-integration nodes lo and hi, 0 … 1 (preintegration.hpp). */
VC_INLINE VC_REAL vcNodeFraction(VC_REAL v, VC_REAL lo, VC_REAL hi) {
    return vc_min(vc_max((v - lo) / (hi - lo), VC_CONST(0.0f)), VC_CONST(1.0f));
}

/* ---- opacity --------------------------------------------------------------------------- */

/* Optical depth of a segment of length len whose transfer function gives sigma = −ln(1 − a)
 * per opacity unit: the opacity correction for the segment length (Eq. 3) before 1 − exp. */
VC_INLINE VC_REAL vcSegmentDepth(VC_REAL sigma, VC_REAL len, VC_REAL opacityUnit) {
    return sigma * (len / opacityUnit);
}

/* Opacity of optical depth x, 1 − exp(−x), to ~1e-7 relative at every x ≥ 0: its Taylor
 * series below 1/2 (where 1 − exp cancels; error x⁹/9! < 6e-9), exp above. On PoCL this is
 * half the cost of expm1, the most expensive step of a sample; under SIMD the exp is taken
 * only when some lane needs it. */
VC_INLINE VC_REAL vcOpacityFromDepth(VC_REAL x) {
    const VC_REAL one = VC_CONST(1.0f);
    VC_REAL r = one - x * VC_CONST(1.0f / 8.0f);
    r = one - x * VC_CONST(1.0f / 7.0f) * r;
    r = one - x * VC_CONST(1.0f / 6.0f) * r;
    r = one - x * VC_CONST(1.0f / 5.0f) * r;
    r = one - x * VC_CONST(1.0f / 4.0f) * r;
    r = one - x * VC_CONST(1.0f / 3.0f) * r;
    r = one - x * VC_CONST(1.0f / 2.0f) * r;
    r = x * r;
    const VC_MASK large = x >= VC_CONST(0.5f);
    if (vc_any(large)) r = vc_select(large, one - vc_exp(vc_neg(x)), r);
    return r;
}

/* Optical depth of opacity a, −ln(1 − a): +∞ for an opaque segment (transmittance 0 behind). */
VC_INLINE VC_REAL vcDepthFromOpacity(VC_REAL a) {
    const VC_MASK opaque = a >= VC_CONST(1.0f);
    return vc_select(opaque, VC_CONST(VC_INFINITY),
                     vc_neg(vc_log1p(vc_neg(vc_select(opaque, VC_CONST(0.0f), a)))));
}

/* Largest full-step alpha from which a partial pre-integrated segment takes its depth,
 * −ln(1 − alpha): 1 − 2^-12 (D ≈ 8.3), where float rounding of alpha already moves D by
 * 2^-24 · 2^12 / 8.3 ≈ 3e-5 of itself. Above it the partial segment is classified at its
 * centre instead, or a thin silhouette would turn opaque. */
#define VC_ALPHA_HOLDS_DEPTH (1.0f - 1.0f / 4096.0f)

/* A partial pre-integrated segment (fraction len/step of a full one) keeps the full step's
 * colour per unit opacity: its premultiplied colour scales by alphaPartial/alphaFull, or by
 * the fraction where the full step is transparent. */
VC_INLINE VC_REAL vcPartialColourScale(VC_REAL alphaFull, VC_REAL alphaPartial, VC_REAL fraction) {
    return vc_select(alphaFull > VC_CONST(0.0f), alphaPartial / alphaFull, fraction);
}

/* ---- compositing ----------------------------------------------------------------------- */

/* Kahan-compensated sum += x. A plain float sum of n terms can lose up to n·2^-24 of itself:
 * in faint media, 819,200 terms of 1e-9 build a sum near 8e-4 whose half ulp is 3 % of a
 * term, rounded away mostly the same way (0.6 % in all, more on longer chords). The carry
 * keeps the sum exact to a few roundings, for ~5 % more time per sample on PoCL. The result
 * is sum − carry. */
VC_INLINE void vcAddCompensated(VC_REAL *sum, VC_REAL *carry, VC_REAL x) {
    const VC_REAL y = x - *carry;
    const VC_REAL t = *sum + y;
    *carry = (t - *sum) - y;
    *sum = t;
}

/* The same for the optical depth, which becomes infinite behind opaque material: an infinite
 * sum keeps a zero carry, since inf − inf is NaN. (Colour stays below 1: never infinite.) */
VC_INLINE void vcAddCompensatedDepth(VC_REAL *sum, VC_REAL *carry, VC_REAL x) {
    vcAddCompensated(sum, carry, x);
    *carry = vc_select(vc_isinf(*sum), VC_CONST(0.0f), *carry);
}

/* The transmittance is exact again every this many samples (a power of two). */
#define VC_EXACT_TRANSMITTANCE_EVERY 16u

/* Transmittance behind a segment of opacity alpha, T = exp(−depth): kept by products (one exp
 * per sample saved) and made exact again from the compensated depth (depth − carry) where
 * `exact`, every VC_EXACT_TRANSMITTANCE_EVERY samples: a factor 1 − alpha that rounds to 1 in
 * faint media would otherwise stop T from falling while the depth grows. */
VC_INLINE VC_REAL vcNextTransmittance(VC_REAL T, VC_REAL alpha, VC_REAL depth, VC_REAL depthCarry, VC_MASK exact) {
    VC_REAL next = T * (VC_CONST(1.0f) - alpha);
    if (vc_any(exact)) next = vc_select(exact, vc_exp(vc_neg(depth - depthCarry)), next);
    return next;
}

/* ---- shading --------------------------------------------------------------------------- */

/* World-space gradient, one component: row c of the index-from-world linear part transposed
 * times the index-space gradient (gx, gy, gz); m0, m1, m2 are that matrix's column c. */
VC_INLINE VC_REAL vcWorldGradient(VC_REAL gx, VC_REAL gy, VC_REAL gz, VC_REAL m0, VC_REAL m1, VC_REAL m2) {
    return vc_mad(gz, m2, vc_mad(gy, m1, gx * m0));
}

/* Headlight Phong (the reference's shading.hpp, constants in phong_constants.h) on the world
 * gradient w for a ray along unit direction d: the diffuse factor and the specular term. A
 * zero gradient leaves the colour unlit: (1, 0). n·l to the 20th power (the shininess) as
 * products. */
#ifdef __cplusplus
static_assert(VC_PHONG_SHININESS == 20.0f, "vcPhong raises n·l to the shininess by products");
#endif
VC_INLINE void vcPhong(VC_REAL wx, VC_REAL wy, VC_REAL wz, VC_REAL dx, VC_REAL dy, VC_REAL dz, VC_REAL *diffuse,
                       VC_REAL *specular) {
    const VC_REAL len = vc_sqrt(vc_mad(wz, wz, vc_mad(wy, wy, wx * wx)));
    const VC_REAL gd = vc_mad(wz, dz, vc_mad(wy, dy, wx * dx));
    const VC_REAL ndl = vc_min(vc_abs(gd) / len, VC_CONST(1.0f));
    const VC_REAL n2 = ndl * ndl, n4 = n2 * n2, n16 = (n4 * n4) * (n4 * n4);
    const VC_MASK lit = len > VC_CONST(0.0f);
    *diffuse = vc_select(lit, vc_mad(ndl, VC_CONST(VC_PHONG_DIFFUSE), VC_CONST(VC_PHONG_AMBIENT)), VC_CONST(1.0f));
    *specular = vc_select(lit, VC_CONST(VC_PHONG_SPECULAR) * (n16 * n4), VC_CONST(0.0f));
}

/* A lit colour channel c of a sample (not premultiplied): c·diffuse + specular, at most 1. */
VC_INLINE VC_REAL vcShade(VC_REAL c, VC_REAL diffuse, VC_REAL specular) {
    return vc_min(vc_mad(c, diffuse, specular), VC_CONST(1.0f));
}

/* A lit premultiplied channel c of a segment of opacity alpha: the highlight is weighted by
 * the opacity, and the channel stays at most alpha. */
VC_INLINE VC_REAL vcShadePremultiplied(VC_REAL c, VC_REAL alpha, VC_REAL diffuse, VC_REAL specular) {
    return vc_min(vc_mad(c, diffuse, specular * alpha), alpha);
}

/* ---- empty-space skipping: the brick walk ---------------------------------------------- */

/* Brick (as a float, before clamping to the grid) holding level coordinate q on one axis,
 * bricks of B voxels (inverseB = 1/B): brick b covers [b·B − ½, (b + 1)·B − ½]. */
VC_INLINE VC_REAL vcBrickOf(VC_REAL q, VC_REAL inverseB) {
    return vc_floor((q + VC_CONST(0.5f)) * inverseB);
}

/* t at which the ray q(t) = q0 + t·dq leaves brick b (a float) across its wall on one axis;
 * +∞ for a ray parallel to the walls. */
VC_INLINE VC_REAL vcBrickWall(VC_REAL b, VC_REAL B, VC_REAL q0, VC_REAL dq) {
    const VC_REAL lo = b * B - VC_CONST(0.5f);
    const VC_REAL wall = vc_select(dq > VC_CONST(0.0f), lo + B, lo);
    return vc_select(dq != VC_CONST(0.0f), (wall - q0) / dq, VC_CONST(VC_INFINITY));
}

/* t at which the ray leaves the brick: the first of its three walls. */
VC_INLINE VC_REAL vcBrickExit(VC_REAL wallX, VC_REAL wallY, VC_REAL wallZ) {
    return vc_min(wallX, vc_min(wallY, wallZ));
}

#endif
