/* Direct volume rendering by ray casting (paper Eq. 2), front to back.
 *
 * Feature switches, as build options (a scene's program holds only what it uses):
 *   JITTER               random start offset per ray and pass (onion rings)
 *   BOUNDARY_SEGMENT     partial last segment at the volume boundary and clip planes (jerky edges)
 *   EARLY_TERMINATION    stop once the optical depth reaches the threshold's
 *   CLIP_PLANES          honour the scene's clip planes
 *   CUBIC                prefiltered tricubic B-spline, 64 taps from a padded coefficient buffer
 *   CUBIC_IMAGE          the same spline as 8 trilinear fetches from a 3-D image (GPUs)
 *   PREINTEGRATED        segment colour and opacity from the 2-D pre-integration table
 *   EMPTY_SPACE_SKIPPING skip the segments whose sample lies in a brick the transfer function makes
 *                        transparent (pre-integrated: that lie wholly in one), found by a brick walk
 *   SHADING              gradient Phong lighting with a headlight
 *   COMPOSITING_MAX      maximum intensity projection instead of emission–absorption
 *   COMPOSITING_MIN      minimum intensity projection (the host builds neither skipping,
 *                        early termination, pre-integration nor shading with these two)
 *   VOXEL_BYTES=1 or 2   trilinear voxels held narrow, as uchar or ushort sample − narrowOffset
 *                        (narrow_samples.hpp): widened exactly, so the image is the float one's
 */
#ifndef VOLCAST_EMBEDDED
#include "../../model/phong_constants.h"
#include "raycast_shared.h"
#endif

/* KERNEL_VOLUME_ARG: the kernel's volume argument; VOLUME_ARG and VOLUME: how functions take
 * and pass it on (narrow voxels carry their offset, read from the parameters once). */
#if defined(CUBIC_IMAGE)
#define KERNEL_VOLUME_ARG __read_only image3d_t volume
#define VOLUME_ARG __read_only image3d_t volume
#define VOLUME volume
#elif defined(VOXEL_BYTES)
#if VOXEL_BYTES == 1
typedef uchar narrow_voxel;
#else
typedef ushort narrow_voxel;
#endif
#define KERNEL_VOLUME_ARG __global const narrow_voxel *volume
#define VOLUME_ARG __global const narrow_voxel *volume, float narrowOffset
#define VOLUME volume, narrowOffset
#else
#define KERNEL_VOLUME_ARG __global const float *volume
#define VOLUME_ARG __global const float *volume
#define VOLUME volume
#endif

/* Reconstruction at level index coordinate p, clamped to the outermost samples (docs/design.md). */
#if defined(CUBIC)
/* Coefficients padded by one before and two after on each axis (mirror boundary, written by
 * the host), so the 4×4×4 footprint never needs a bounds check. */
void cubicWeights(float f, float4 *w) {
    const float g = 1.0f - f;
    *w = (float4)(g * g * g, 4.0f - 6.0f * f * f + 3.0f * f * f * f, 4.0f - 6.0f * g * g + 3.0f * g * g * g,
                  f * f * f) * (1.0f / 6.0f);
}

float sampleVolume(__global const float *c, int4 n, float3 p) {
    p = clamp(p, (float3)(0.0f), convert_float3(n.xyz - 1));
    const int3 i = min(convert_int3(p), n.xyz - 1);
    const float3 f = p - convert_float3(i);
    float4 wx, wy, wz;
    cubicWeights(f.x, &wx);
    cubicWeights(f.y, &wy);
    cubicWeights(f.z, &wz);
    const int px = n.x + 3, py = n.y + 3;
    float sum = 0.0f;
    for (int z = 0; z < 4; ++z) {
        const float wzz = z == 0 ? wz.x : (z == 1 ? wz.y : (z == 2 ? wz.z : wz.w));
        float sz = 0.0f;
        for (int y = 0; y < 4; ++y) {
            const float wyy = y == 0 ? wy.x : (y == 1 ? wy.y : (y == 2 ? wy.z : wy.w));
            /* Padded index of tap (i − 1 + x, i − 1 + y, i − 1 + z) is (i + x, i + y, i + z). */
            __global const float *row = c + ((size_t)(i.z + z) * py + (size_t)(i.y + y)) * px + (size_t)i.x;
            sz += wyy * (wx.x * row[0] + wx.y * row[1] + wx.z * row[2] + wx.w * row[3]);
        }
        sum += wzz * sz;
    }
    return sum;
}
#elif defined(CUBIC_IMAGE)
/* Sigg and Hadwiger's form: per axis, two linear fetches placed so that the hardware's
 * trilinear weights reproduce the four B-spline weights. */
float sampleVolume(__read_only image3d_t c, int4 n, float3 p) {
    const sampler_t linear = CLK_NORMALIZED_COORDS_FALSE | CLK_ADDRESS_CLAMP_TO_EDGE | CLK_FILTER_LINEAR;
    p = clamp(p, (float3)(0.0f), convert_float3(n.xyz - 1));
    const float3 i = floor(p);
    const float3 f = p - i;
    const float3 g = 1.0f - f;
    const float3 w0 = g * g * g / 6.0f, w1 = (4.0f - 6.0f * f * f + 3.0f * f * f * f) / 6.0f;
    const float3 w2 = (4.0f - 6.0f * g * g + 3.0f * g * g * g) / 6.0f, w3 = f * f * f / 6.0f;
    const float3 g0 = w0 + w1, g1 = w2 + w3;
    /* Texel k of the padded image holds coefficient k − 1; its centre is at k + 1/2. */
    const float3 h0 = i - 1.0f + w1 / g0 + 1.5f, h1 = i + 1.0f + w3 / g1 + 1.5f;
    const float v000 = read_imagef(c, linear, (float4)(h0.x, h0.y, h0.z, 0.0f)).x;
    const float v100 = read_imagef(c, linear, (float4)(h1.x, h0.y, h0.z, 0.0f)).x;
    const float v010 = read_imagef(c, linear, (float4)(h0.x, h1.y, h0.z, 0.0f)).x;
    const float v110 = read_imagef(c, linear, (float4)(h1.x, h1.y, h0.z, 0.0f)).x;
    const float v001 = read_imagef(c, linear, (float4)(h0.x, h0.y, h1.z, 0.0f)).x;
    const float v101 = read_imagef(c, linear, (float4)(h1.x, h0.y, h1.z, 0.0f)).x;
    const float v011 = read_imagef(c, linear, (float4)(h0.x, h1.y, h1.z, 0.0f)).x;
    const float v111 = read_imagef(c, linear, (float4)(h1.x, h1.y, h1.z, 0.0f)).x;
    return g0.z * (g0.y * (g0.x * v000 + g1.x * v100) + g1.y * (g0.x * v010 + g1.x * v110)) +
           g1.z * (g0.y * (g0.x * v001 + g1.x * v101) + g1.y * (g0.x * v011 + g1.x * v111));
}
#else
inline float voxel(VOLUME_ARG, int4 n, int i, int j, int k) {
#ifdef VOXEL_BYTES
    return (float)volume[((size_t)k * n.y + j) * n.x + i] + narrowOffset;
#else
    return volume[((size_t)k * n.y + j) * n.x + i];
#endif
}

/* Trilinear from a buffer: on CPUs several times faster than a 3-D image (docs/platform.md). */
float sampleVolume(VOLUME_ARG, int4 n, float3 p) {
    p = clamp(p, (float3)(0.0f), convert_float3(n.xyz - 1));
    const int3 i0 = min(convert_int3(p), max(n.xyz - 2, (int3)(0)));
    const float3 f = p - convert_float3(i0);
    const int3 i1 = min(i0 + 1, n.xyz - 1);
    const float c000 = voxel(VOLUME, n, i0.x, i0.y, i0.z), c100 = voxel(VOLUME, n, i1.x, i0.y, i0.z);
    const float c010 = voxel(VOLUME, n, i0.x, i1.y, i0.z), c110 = voxel(VOLUME, n, i1.x, i1.y, i0.z);
    const float c001 = voxel(VOLUME, n, i0.x, i0.y, i1.z), c101 = voxel(VOLUME, n, i1.x, i0.y, i1.z);
    const float c011 = voxel(VOLUME, n, i0.x, i1.y, i1.z), c111 = voxel(VOLUME, n, i1.x, i1.y, i1.z);
    const float c00 = mix(c000, c100, f.x), c10 = mix(c010, c110, f.x);
    const float c01 = mix(c001, c101, f.x), c11 = mix(c011, c111, f.x);
    return mix(mix(c00, c10, f.y), mix(c01, c11, f.y), f.z);
}
#endif

/* Level-0 index coordinates to the sampled level's (mip_level; identity at level 0). */
float3 levelFromIndex(__global const RayCastParams *P, float3 p) {
    return (p + 0.5f) * P->levelScale - 0.5f;
}

#ifdef PREINTEGRATED
/* Largest full-step alpha from which a partial segment takes its depth, −ln(1 − alpha): 1 − 2^-12
 * (D ≈ 8.3), where float rounding of alpha already moves D by 2^-24 · 2^12 / 8.3 ≈ 3e-5 of itself. */
#define VC_ALPHA_HOLDS_DEPTH (1.0f - 1.0f / 4096.0f)

/* Fractional node coordinate of value v: the locator gives the node intervals a uniform
 * bucket overlaps, a binary search the one holding v (preintegration.hpp). */
float nodeCoordinate(__global const float *nodes, __global const int *locator, __global const RayCastParams *P,
                     float v) {
    v = clamp(v, nodes[0], nodes[P->preNodes - 1]);
    const int b = clamp((int)((v - P->preLocatorMin) * P->preLocatorScale), 0, P->preLocatorSize - 1);
    int i = locator[b], last = locator[b + 1];
    while (i < last) { /* binary search: nodes cluster around narrow spikes */
        const int m = (i + last + 1) / 2;
        if (v >= nodes[m]) i = m;
        else last = m - 1;
    }
    return (float)i + clamp((v - nodes[i]) / (nodes[i + 1] - nodes[i]), 0.0f, 1.0f);
}

/* Segment of length step from value sf to sb: premultiplied colour and opacity. */
float4 preintegratedSegment(__global const float4 *table, __global const float *nodes,
                            __global const int *locator, __global const RayCastParams *P, float sf, float sb) {
    const int N = P->preNodes;
    const float x = nodeCoordinate(nodes, locator, P, sf), y = nodeCoordinate(nodes, locator, P, sb);
    const int i = min((int)x, N - 2), j = min((int)y, N - 2);
    const float fx = x - (float)i, fy = y - (float)j;
    const float4 a = mix(table[j * N + i], table[j * N + i + 1], fx);
    const float4 b = mix(table[(j + 1) * N + i], table[(j + 1) * N + i + 1], fx);
    return mix(a, b, fy);
}
#endif

/* Transfer function: colour and sigma = −ln(1 − a), the optical depth of one opacity unit,
 * linear between table entries (tf_table.hpp). */
float4 classify(__global const float4 *table, __global const RayCastParams *P, float v) {
    const float x = clamp((v - P->tfMin) * P->tfScale, 0.0f, (float)(P->tfEntries - 1));
    const int i = min((int)x, P->tfEntries - 2);
    return mix(table[i], table[i + 1], x - (float)i);
}

#ifdef SHADING
/* Headlight Phong on the gradient by central differences (one level voxel apart), taken
 * into world space: (diffuse factor, specular term). A zero gradient leaves the colour
 * unlit, (1, 0). The same model as shading.hpp. */
float2 phong(VOLUME_ARG, int4 n, __global const RayCastParams *P, float3 q, float3 dir) {
    const float gx = sampleVolume(VOLUME, n, q + (float3)(1.0f, 0.0f, 0.0f)) -
                     sampleVolume(VOLUME, n, q - (float3)(1.0f, 0.0f, 0.0f));
    const float gy = sampleVolume(VOLUME, n, q + (float3)(0.0f, 1.0f, 0.0f)) -
                     sampleVolume(VOLUME, n, q - (float3)(0.0f, 1.0f, 0.0f));
    const float gz = sampleVolume(VOLUME, n, q + (float3)(0.0f, 0.0f, 1.0f)) -
                     sampleVolume(VOLUME, n, q - (float3)(0.0f, 0.0f, 1.0f));
    /* World gradient = (index-from-world linear part)ᵀ · index gradient. */
    const float3 g = gx * P->indexFromWorld[0].xyz + gy * P->indexFromWorld[1].xyz + gz * P->indexFromWorld[2].xyz;
    const float len = length(g);
    if (!(len > 0.0f)) return (float2)(1.0f, 0.0f);
    const float ndl = fmin(fabs(dot(g, dir)) / len, 1.0f);
    return (float2)(VC_PHONG_AMBIENT + VC_PHONG_DIFFUSE * ndl, VC_PHONG_SPECULAR * pow(ndl, VC_PHONG_SHININESS));
}
#endif

/* Opacity of optical depth x, 1 − exp(−x), to ~1e-7 relative at every x ≥ 0: its Taylor
 * series below 1/2 (where 1 − exp cancels; error x⁹/9! < 6e-9), exp above. On PoCL this is
 * half the cost of expm1, the most expensive step of a sample. */
float opacityFromDepth(float x) {
    if (x >= 0.5f) return 1.0f - exp(-x);
    return x * (1.0f - x * (1.0f / 2.0f) * (1.0f - x * (1.0f / 3.0f) * (1.0f - x * (1.0f / 4.0f) *
           (1.0f - x * (1.0f / 5.0f) * (1.0f - x * (1.0f / 6.0f) * (1.0f - x * (1.0f / 7.0f) *
           (1.0f - x * (1.0f / 8.0f))))))));
}

/* Kahan-compensated sum += x. A plain float sum of n terms can lose up to n·2^-24 of itself:
 * in faint media, 819,200 terms of 1e-9 build a sum near 8e-4 whose half ulp is 3 % of a
 * term, rounded away mostly the same way (0.6 % in all, more on longer chords). The carry
 * keeps the sum exact to a few roundings, for ~5 % more time per sample on PoCL. An infinite
 * sum keeps a zero carry, since inf − inf is NaN. */
void addCompensated(float *sum, float *carry, float x) {
    const float y = x - *carry;
    const float t = *sum + y;
    *carry = isinf(t) ? 0.0f : (t - *sum) - y;
    *sum = t;
}

void addCompensated3(float3 *sum, float3 *carry, float3 x) {
    const float3 y = x - *carry;
    const float3 t = *sum + y;
    *carry = (t - *sum) - y; /* colour stays below 1: never infinite */
    *sum = t;
}

/* PCG hash: a reproducible uniform number in [0, 1) per pixel, seed and pass. */
float random01(uint x, uint y, uint seed, uint pass) {
    uint s = x * 1973u + y * 9277u + seed * 26699u + pass * 104729u;
    s = s * 747796405u + 2891336453u;
    uint w = ((s >> ((s >> 28u) + 4u)) ^ s) * 277803737u;
    w = (w >> 22u) ^ w;
    return (float)(w >> 8) * (1.0f / 16777216.0f);
}

#ifdef EMPTY_SPACE_SKIPPING
/* The incremental brick walk (DDA) over the brick grid: the brick holding the point the ray has
 * reached, whether the transfer function leaves it visible, and the t at which the ray crosses
 * each of its walls. Moving on costs a comparison per segment and a division per wall crossed.
 * A point within float rounding of a wall may be put in either brick: harmless, as each
 * brick's value range covers half a voxel beyond its box (minmax_bricks.hpp). The CPU path's
 * BrickWalk (renderer/cpu/cpu_march.cpp) does the same arithmetic. */
typedef struct {
    int b[3];
    float wall[3];
    bool visible;
} BrickWalk;

/* Brick b covers level coordinates [b·B − 1/2, (b + 1)·B − 1/2] on each axis. */
float brickWall(__global const RayCastParams *P, int b, float q0, float dq) {
    if (dq == 0.0f) return INFINITY;
    const float B = (float)P->brickSize;
    const float lo = (float)b * B - 0.5f;
    return ((dq > 0.0f ? lo + B : lo) - q0) / dq;
}

void brickLookUp(__global const uchar *visible, __global const RayCastParams *P, BrickWalk *w) {
    const int bx = clamp(w->b[0], 0, P->bricks[0] - 1), by = clamp(w->b[1], 0, P->bricks[1] - 1),
              bz = clamp(w->b[2], 0, P->bricks[2] - 1);
    w->visible = visible[((size_t)bz * P->bricks[1] + by) * P->bricks[0] + bx] != 0;
}

void brickWalkStart(__global const uchar *visible, __global const RayCastParams *P, const float *q0, const float *dq,
                    float t, BrickWalk *w) {
    const float inverseB = 1.0f / (float)P->brickSize;
    for (int a = 0; a < 3; ++a) {
        const float q = fma(t, dq[a], q0[a]);
        w->b[a] = clamp((int)floor((q + 0.5f) * inverseB), 0, P->bricks[a] - 1);
        w->wall[a] = brickWall(P, w->b[a], q0[a], dq[a]);
    }
    brickLookUp(visible, P, w);
}

float brickWalkExit(const BrickWalk *w) { return fmin(w->wall[0], fmin(w->wall[1], w->wall[2])); }

/* Moves on to the brick holding q(t), t not before where the walk is. */
void brickWalkTo(__global const uchar *visible, __global const RayCastParams *P, const float *q0, const float *dq,
                 float t, BrickWalk *w) {
    bool moved = false;
    for (;;) {
        const float first = brickWalkExit(w);
        if (!(t >= first)) break;
        moved = true;
        const int a = w->wall[0] == first ? 0 : (w->wall[1] == first ? 1 : 2);
        w->b[a] += dq[a] > 0.0f ? 1 : -1;
        w->wall[a] = brickWall(P, w->b[a], q0[a], dq[a]);
    }
    if (moved) brickLookUp(visible, P, w);
}
#endif

__kernel void raycast(KERNEL_VOLUME_ARG, __global const float4 *tfTable,
#ifdef PREINTEGRATED
                      __global const float4 *preTable, __global const float *preNodes, __global const int *preLocator,
#endif
#ifdef EMPTY_SPACE_SKIPPING
                      __global const uchar *brickVisible,
#endif
                      __global const RayCastParams *P, __global float4 *image, __global volatile uint *stats) {
    const int x = get_global_id(0), y = get_global_id(1);
    if (x >= P->width || y >= P->height) return;
#ifdef VOXEL_BYTES
    const float narrowOffset = P->narrowOffset;
#endif

    /* Ray through the pixel centre (docs/design.md's camera), world space. */
    const float u = 2.0f * ((float)x + 0.5f) / (float)P->width - 1.0f;
    const float v = 1.0f - 2.0f * ((float)y + 0.5f) / (float)P->height;
    const float3 offset = u * P->right.xyz + v * P->up.xyz;
    float3 origin = P->eye.xyz, dir;
    if (P->orthographic) {
        origin += offset;
        dir = P->forward.xyz;
    } else {
        dir = normalize(P->forward.xyz + offset);
    }

    /* Into index space, where the volume is the box [-1/2, n - 1/2]. */
    const float3 p0 = (float3)(dot(P->indexFromWorld[0].xyz, origin) + P->indexFromWorld[0].w,
                               dot(P->indexFromWorld[1].xyz, origin) + P->indexFromWorld[1].w,
                               dot(P->indexFromWorld[2].xyz, origin) + P->indexFromWorld[2].w);
    const float3 dq = (float3)(dot(P->indexFromWorld[0].xyz, dir), dot(P->indexFromWorld[1].xyz, dir),
                               dot(P->indexFromWorld[2].xyz, dir));
    float t0 = 0.0f, t1 = INFINITY;
    for (int a = 0; a < 3; ++a) {
        const float pa = a == 0 ? p0.x : (a == 1 ? p0.y : p0.z);
        const float da = a == 0 ? dq.x : (a == 1 ? dq.y : dq.z);
        /* The volume's box [-1/2, n - 1/2], or the crop box inside it. */
        const float lo = a == 0 ? P->boxLo.x : (a == 1 ? P->boxLo.y : P->boxLo.z);
        const float hi = a == 0 ? P->boxHi.x : (a == 1 ? P->boxHi.y : P->boxHi.z);
        if (da == 0.0f) {
            if (pa < lo || pa > hi) t1 = -INFINITY;
            continue;
        }
        const float ta = (lo - pa) / da, tb = (hi - pa) / da;
        t0 = fmax(t0, fmin(ta, tb));
        t1 = fmin(t1, fmax(ta, tb));
    }
#ifdef CLIP_PLANES
    for (int c = 0; c < P->clipPlaneCount; ++c) {
        const float4 plane = P->clipPlanes[c];
        const float g0 = dot(plane.xyz, origin) + plane.w, gd = dot(plane.xyz, dir);
        if (gd == 0.0f) {
            if (g0 < 0.0f) t1 = -INFINITY;
        } else if (gd > 0.0f) {
            t0 = fmax(t0, -g0 / gd);
        } else {
            t1 = fmin(t1, -g0 / gd);
        }
    }
#endif
    if (!(t1 > t0)) {
        image[y * P->width + x] = (float4)(0.0f);
        return;
    }

    /* The sampled level's coordinates along the ray: q(t) = q0 + t·dqL. */
    const int4 n = (int4)(P->levelDims[0], P->levelDims[1], P->levelDims[2], 0);
    const float3 q0 = levelFromIndex(P, p0), dqL = dq * P->levelScale;

    /* Segment boundaries at t0 + (k + j)·step; j is the jitter offset in [0, 1). */
    const float d = P->step;
#ifdef JITTER
    const float j = random01((uint)x, (uint)y, P->seed, P->pass);
#else
    const float j = 0.0f;
#endif
#if defined(COMPOSITING_MAX) || defined(COMPOSITING_MIN)
    {
        /* Intensity projection: the extreme of the values sampled at the segments' centres
         * (the same segments, partial ones included, as emission–absorption samples), mapped
         * through the transfer function: premultiplied colour and its opacity a(v). */
        uint samples = 0;
        bool found = false;
        float extreme = 0.0f;
        float segStart = t0;
        for (int k = (j > 0.0f ? 0 : 1);; ++k) {
            const float boundary = t0 + ((float)k + j) * d;
            const float segEnd = fmin(boundary, t1);
            const float len = segEnd - segStart;
#ifdef BOUNDARY_SEGMENT
            const bool take = len > 0.0f;
#else
            const bool take = len > 0.0f && !(boundary > t1 || k == 0);
#endif
            if (take) {
                if ((int)samples >= P->maxSamples) {
                    atomic_inc(&stats[VC_STAT_TRUNCATED]);
                    break;
                }
                ++samples;
                const float v = sampleVolume(VOLUME, n, q0 + (segStart + 0.5f * len) * dqL);
#ifdef COMPOSITING_MAX
                extreme = found ? fmax(extreme, v) : v;
#else
                extreme = found ? fmin(extreme, v) : v;
#endif
                found = true;
            }
            if (boundary >= t1) break;
            segStart = segEnd;
        }
        float4 pixel = (float4)(0.0f);
        if (found) {
            const float4 rgbs = classify(tfTable, P, extreme);
            const float a = opacityFromDepth(rgbs.w); /* the table holds sigma = −ln(1 − a) */
            pixel = (float4)(a * rgbs.xyz, a);
        }
        image[y * P->width + x] = pixel;
        if (atomic_add(&stats[VC_STAT_SAMPLES], samples) > UINT_MAX - samples) atomic_inc(&stats[VC_STAT_SAMPLES_HIGH]);
        atomic_inc(&stats[VC_STAT_RAYS_HIT]);
        return;
    }
#endif
    float opticalDepth = 0.0f, depthCarry = 0.0f; /* accumulated, so faint media keep their precision */
    float T = 1.0f;            /* transmittance in front of the current segment */
    float3 color = (float3)(0.0f), colorCarry = (float3)(0.0f);
    uint samples = 0, skipped = 0;
    bool terminated = false;
    float segStart = t0;
#ifdef PREINTEGRATED
    float sf = sampleVolume(VOLUME, n, q0 + t0 * dqL); /* value at the segment's front */
#endif
#ifdef EMPTY_SPACE_SKIPPING
    const float q0a[3] = {q0.x, q0.y, q0.z}, dqa[3] = {dqL.x, dqL.y, dqL.z};
    BrickWalk walk;
    brickWalkStart(brickVisible, P, q0a, dqa, t0, &walk);
#endif
#if defined(EMPTY_SPACE_SKIPPING) && defined(PREINTEGRATED)
    bool sfStale = false; /* sf must be sampled at segStart first */
#endif
    for (int k = (j > 0.0f ? 0 : 1);; ++k) {
        const float boundary = t0 + ((float)k + j) * d;
        const float segEnd = fmin(boundary, t1);
        const float len = segEnd - segStart;
        /* A partial segment: the first one under jitter, or the last at the exit. */
        const bool partial = boundary > t1 || (k == 0);
#ifdef BOUNDARY_SEGMENT
        const bool take = len > 0.0f;
#else
        const bool take = len > 0.0f && !partial;
#endif
#ifdef EMPTY_SPACE_SKIPPING
        /* Skipping by sample position: a sampled segment is not taken when its centre lies in
         * a brick the transfer function makes empty (it would add exactly 0); a pre-integrated
         * one, which reads the values at both ends and between, when it lies wholly in one. */
        if (take) {
#ifdef PREINTEGRATED
            brickWalkTo(brickVisible, P, q0a, dqa, segStart, &walk);
            const bool skip = !walk.visible && segEnd <= brickWalkExit(&walk);
            const float decidingPoint = 0.0f; /* the segment's end: t0 + (k' + j)·d */
#else
            brickWalkTo(brickVisible, P, q0a, dqa, fma(0.5f, len, segStart), &walk);
            const bool skip = !walk.visible;
            const float decidingPoint = 0.5f; /* its centre: t0 + (k' + j − ½)·d */
#endif
            if (skip) {
                ++skipped;
#ifdef PREINTEGRATED
                sfStale = true;
#endif
                if (boundary >= t1) break;
                /* Later full segments k' whose deciding point is before the brick's exit (one
                 * fewer for rounding) and that end before t1: skipped at once. */
                const float jumpTo = fmin(floor((brickWalkExit(&walk) - t0) / d - j + decidingPoint) - 1.0f,
                                          floor((t1 - t0) / d - j) - 1.0f);
                if (jumpTo >= (float)(k + 1)) {
                    skipped += (uint)(jumpTo - (float)k);
                    k = (int)jumpTo; /* the loop moves on to jumpTo + 1 */
                    segStart = fma(jumpTo + j, d, t0);
                } else {
                    segStart = segEnd;
                }
                continue;
            }
        }
#endif
        if (take) {
            if ((int)samples >= P->maxSamples) {
                atomic_inc(&stats[VC_STAT_TRUNCATED]);
                break;
            }
            ++samples;
#ifdef PREINTEGRATED
            /* The segment's colour and optical depth from the table for a full step; a
             * partial one scales the depth by len/step (Eq. 3) and the colour with its opacity.
             * Partial by position, not by len < d: far from the eye, float rounding of the
             * boundaries makes full segments a little shorter or longer than d, and scaling
             * only the shorter ones would bias the sum (by 0.7 % over 800,000 faint segments). */
#ifdef EMPTY_SPACE_SKIPPING
            if (sfStale) {
                sf = sampleVolume(VOLUME, n, q0 + segStart * dqL);
                sfStale = false;
            }
#endif
            const float sb = sampleVolume(VOLUME, n, q0 + segEnd * dqL);
            const float4 seg = preintegratedSegment(preTable, preNodes, preLocator, P, sf, sb);
            sf = sb;
            float segDepth = -log1p(-seg.w); /* +inf behind opaque material: T becomes 0 */
            float alpha = seg.w;
            float3 segColor = seg.xyz;
            if (partial && seg.w <= VC_ALPHA_HOLDS_DEPTH) {
                segDepth *= len / d;
                alpha = opacityFromDepth(segDepth);
                segColor *= seg.w > 0.0f ? alpha / seg.w : len / d;
            } else if (partial) {
                /* The full step's alpha is too close to 1 to hold its depth (1 − exp(−D) is 1 in
                 * float beyond D ≈ 16): classify the partial segment at its centre instead, as
                 * without pre-integration, or a thin silhouette would turn opaque. */
                const float4 rgba = classify(tfTable, P, sampleVolume(VOLUME, n, q0 + (segStart + 0.5f * len) * dqL));
                segDepth = rgba.w * (len / P->opacityUnit);
                alpha = opacityFromDepth(segDepth);
                segColor = alpha * rgba.xyz;
            }
#ifdef SHADING
            /* Light the premultiplied colour; the highlight is weighted by the opacity. */
            const float2 light = phong(VOLUME, n, P, q0 + (segStart + 0.5f * len) * dqL, dir);
            segColor = fmin(segColor * light.x + light.y * alpha, alpha);
#endif
            addCompensated3(&color, &colorCarry, T * segColor);
#else
            /* Sample the segment at its centre and classify. */
            const float3 q = q0 + (segStart + 0.5f * len) * dqL;
            const float4 rgba = classify(tfTable, P, sampleVolume(VOLUME, n, q));
            /* Correct opacity for the segment length (Eq. 3): 1 − exp(−sigma·len/u). */
            const float segDepth = rgba.w * (len / P->opacityUnit);
            const float alpha = opacityFromDepth(segDepth);
            float3 rgb = rgba.xyz;
#ifdef SHADING
            if (alpha > 0.0f) {
                const float2 light = phong(VOLUME, n, P, q, dir);
                rgb = fmin(rgb * light.x + light.y, 1.0f);
            }
#endif
            addCompensated3(&color, &colorCarry, T * alpha * rgb);
#endif
            addCompensated(&opticalDepth, &depthCarry, segDepth);
            /* T = exp(−opticalDepth), kept by products (one exp per sample saved) and made
             * exact again every 16 samples: a factor 1 − alpha that rounds to 1 in faint media
             * would otherwise stop T from falling while the depth grows. */
            T = (samples & 15u) == 0u ? exp(-(opticalDepth - depthCarry)) : T * (1.0f - alpha);
#ifdef EARLY_TERMINATION
            if (opticalDepth >= P->terminationDepth) {
                terminated = true;
                break;
            }
#endif
        }
        if (boundary >= t1) break;
        segStart = segEnd;
    }
    image[y * P->width + x] = (float4)(color - colorCarry, opacityFromDepth(opticalDepth - depthCarry));
    if (atomic_add(&stats[VC_STAT_SAMPLES], samples) > UINT_MAX - samples) atomic_inc(&stats[VC_STAT_SAMPLES_HIGH]);
    atomic_inc(&stats[VC_STAT_RAYS_HIT]);
    if (terminated) atomic_inc(&stats[VC_STAT_TERMINATED_EARLY]);
#ifdef EMPTY_SPACE_SKIPPING
    if (skipped && atomic_add(&stats[VC_STAT_SEGMENTS_SKIPPED], skipped) > UINT_MAX - skipped)
        atomic_inc(&stats[VC_STAT_SEGMENTS_SKIPPED_HIGH]);
#endif
}
