/* Direct volume rendering by ray casting (paper Eq. 2), front to back.
 *
 * Feature switches, as build options (a scene's program holds only what it uses):
 *   JITTER               random start offset per ray and pass (onion rings)
 *   BOUNDARY_SEGMENT     partial last segment at the volume boundary and clip planes (jerky edges)
 *   EARLY_TERMINATION    stop once the optical depth reaches the threshold's
 *   CLIP_PLANES          honour the scene's clip planes
 *   CUBIC                prefiltered tricubic B-spline, 64 taps from a padded coefficient buffer
 *   CUBIC_IMAGE          the same spline as 8 trilinear fetches from a 3-D image (only when asked:
 *                        texture filtering rounds its weights as the device chooses, docs/gpu.md)
 *   PREINTEGRATED        segment colour and opacity from the 2-D pre-integration table
 *   EMPTY_SPACE_SKIPPING skip the segments whose sample lies in a brick the transfer function makes
 *                        transparent (pre-integrated: that lie wholly in one), found by a brick walk
 *   SHADING              gradient Phong lighting with a headlight
 *   ADAPTIVE_STEP        each segment as long as the step of the brick it starts in (adaptive_step.hpp),
 *                        found by the brick walk; with EMPTY_SPACE_SKIPPING a transparent brick
 *                        (step −1) is crossed without a sample
 *   COMPOSITING_MAX      maximum intensity projection instead of emission–absorption
 *   COMPOSITING_MIN      minimum intensity projection (the host builds neither skipping,
 *                        early termination, pre-integration nor shading with these two)
 *   VOXEL_BYTES=1 or 2   trilinear voxels held narrow, as uchar or ushort sample − narrowOffset
 *                        (narrow_samples.hpp): widened exactly, so the image is the float one's
 *
 * The per-sample formulas (ray_math.h: clipping, jitter hash, table coordinates, opacity
 * correction, Kahan sums, transmittance, Phong, brick walls) are the native path's too
 * (renderer/cpu/cpu_march.cpp); the build embeds that header before this file. The kernel is
 * cut into stages, each switch inside a short function: ray set-up and clipping, the
 * segments, reconstruction (sampleVolume), classification, shading, empty-space skipping,
 * compositing, early termination.
 */
#ifndef VOLCAST_EMBEDDED
#include "../../model/phong_constants.h"
#include "../../common/ray_math.h"
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
float3 levelFromIndex(const RayCastParams *P, float3 p) {
    return (p + 0.5f) * P->levelScale - 0.5f;
}

/* What every stage reads besides the volume (VOLUME_ARG): the parameters, tables, counters. */
typedef struct {
    const RayCastParams *P;
    __global const float4 *tfTable;
#ifdef PREINTEGRATED
    __global const float4 *preTable;
    __global const float *preNodes;
    __global const int *preLocator;
#endif
#if defined(EMPTY_SPACE_SKIPPING) && !defined(ADAPTIVE_STEP)
    __global const int *brickReach;
#endif
#ifdef ADAPTIVE_STEP
    __global const float *brickStep;
#endif
    __global volatile uint *stats;
    int4 n; /* samples per axis of the level sampled */
} Frame;

/* ---- classification ---------------------------------------------------------------------- */

/* Transfer function: colour and sigma = −ln(1 − a), the optical depth of one opacity unit,
 * linear between table entries (tf_table.hpp). */
float4 classify(__global const float4 *table, const RayCastParams *P, float v) {
    const float x = vcTableCoordinate(v, P->tfMin, P->tfScale, (float)(P->tfEntries - 1));
    const int i = min((int)x, P->tfEntries - 2);
    return mix(table[i], table[i + 1], x - (float)i);
}

#ifdef PREINTEGRATED
/* Fractional node coordinate of value v: the locator gives the node intervals a uniform
 * bucket overlaps, a binary search the one holding v (preintegration.hpp). */
float nodeCoordinate(__global const float *nodes, __global const int *locator, const RayCastParams *P,
                     float v) {
    v = clamp(v, nodes[0], nodes[P->preNodes - 1]);
    const int b = clamp((int)((v - P->preLocatorMin) * P->preLocatorScale), 0, P->preLocatorSize - 1);
    int i = locator[b], last = locator[b + 1];
    while (i < last) { /* binary search: nodes cluster around narrow spikes */
        const int m = (i + last + 1) / 2;
        if (v >= nodes[m]) i = m;
        else last = m - 1;
    }
    return (float)i + vcNodeFraction(v, nodes[i], nodes[i + 1]);
}

/* Segment of length step from value sf to sb: premultiplied colour and opacity. */
float4 preintegratedSegment(const Frame *f, float sf, float sb) {
    const int N = f->P->preNodes;
    const float x = nodeCoordinate(f->preNodes, f->preLocator, f->P, sf);
    const float y = nodeCoordinate(f->preNodes, f->preLocator, f->P, sb);
    const int i = min((int)x, N - 2), j = min((int)y, N - 2);
    const float fx = x - (float)i, fy = y - (float)j;
    __global const float4 *table = f->preTable;
    const float4 a = mix(table[j * N + i], table[j * N + i + 1], fx);
    const float4 b = mix(table[(j + 1) * N + i], table[(j + 1) * N + i + 1], fx);
    return mix(a, b, fy);
}
#endif

#ifdef SHADING
/* Headlight Phong (vcPhong) on the gradient by central differences (one level voxel apart),
 * taken into world space: (diffuse factor, specular term). */
float2 phong(VOLUME_ARG, const Frame *f, float3 q, float3 dir) {
    const int4 n = f->n;
    const float gx = sampleVolume(VOLUME, n, q + (float3)(1.0f, 0.0f, 0.0f)) -
                     sampleVolume(VOLUME, n, q - (float3)(1.0f, 0.0f, 0.0f));
    const float gy = sampleVolume(VOLUME, n, q + (float3)(0.0f, 1.0f, 0.0f)) -
                     sampleVolume(VOLUME, n, q - (float3)(0.0f, 1.0f, 0.0f));
    const float gz = sampleVolume(VOLUME, n, q + (float3)(0.0f, 0.0f, 1.0f)) -
                     sampleVolume(VOLUME, n, q - (float3)(0.0f, 0.0f, 1.0f));
    const float4 *m = f->P->indexFromWorld;
    float diffuse, specular;
    vcPhong(vcWorldGradient(gx, gy, gz, m[0].x, m[1].x, m[2].x), vcWorldGradient(gx, gy, gz, m[0].y, m[1].y, m[2].y),
            vcWorldGradient(gx, gy, gz, m[0].z, m[1].z, m[2].z), dir.x, dir.y, dir.z, &diffuse, &specular);
    return (float2)(diffuse, specular);
}
#endif

/* ---- ray set-up ---------------------------------------------------------------------------- */

typedef struct {
    float3 origin, dir; /* world; dir is a unit vector */
    float3 p0, dq;      /* level-0 index space: p(t) = p0 + t·dq */
    float3 q0, dqL;     /* the sampled level's coordinates: q(t) = q0 + t·dqL */
    float t0, t1;       /* the part inside the box (or crop box) and the clip planes */
} Ray;

/* Ray through the pixel centre (docs/design.md's camera), world space, and into index space,
 * where the volume is the box [-1/2, n - 1/2]. */
Ray cameraRay(const RayCastParams *P, int x, int y) {
    const float u = vcImageU((float)x, (float)P->width, P->inverseWidth);
    const float v = vcImageV((float)y, (float)P->height, P->inverseHeight);
    /* ray_math.h reads the frame's constants from private arrays (OpenCL 1.2 has no generic
     * address space). */
    const float eye[3] = {P->eye.x, P->eye.y, P->eye.z}, forward[3] = {P->forward.x, P->forward.y, P->forward.z};
    const float right[3] = {P->right.x, P->right.y, P->right.z}, up[3] = {P->up.x, P->up.y, P->up.z};
    float origin[3], dir[3], p0[3], dq[3];
    vcCameraRay(u, v, eye, forward, right, up, P->orthographic, origin, dir);
    for (int a = 0; a < 3; ++a) {
        const float4 m = P->indexFromWorld[a];
        const float row[4] = {m.x, m.y, m.z, m.w};
        p0[a] = vcAffineRow(row, origin);
        dq[a] = vcLinearRow(row, dir);
    }
    Ray r;
    r.origin = (float3)(origin[0], origin[1], origin[2]);
    r.dir = (float3)(dir[0], dir[1], dir[2]);
    r.p0 = (float3)(p0[0], p0[1], p0[2]);
    r.dq = (float3)(dq[0], dq[1], dq[2]);
    return r;
}

/* [t0, t1]: the ray inside the volume's box [-1/2, n - 1/2], or the crop box inside it. */
void clipToBox(const RayCastParams *P, Ray *r) {
    float t0 = 0.0f, t1 = INFINITY;
    vcClipToSlab(r->p0.x, r->dq.x, P->boxLo.x, P->boxHi.x, &t0, &t1);
    vcClipToSlab(r->p0.y, r->dq.y, P->boxLo.y, P->boxHi.y, &t0, &t1);
    vcClipToSlab(r->p0.z, r->dq.z, P->boxLo.z, P->boxHi.z, &t0, &t1);
    r->t0 = t0;
    r->t1 = t1;
}

/* CLIP_PLANES: [t0, t1] within the half spaces the scene's clip planes keep. */
void clipToPlanes(const RayCastParams *P, Ray *r) {
#ifdef CLIP_PLANES
    float t0 = r->t0, t1 = r->t1;
    for (int c = 0; c < P->clipPlaneCount; ++c) {
        const float4 n = P->clipPlanes[c];
        const float plane[4] = {n.x, n.y, n.z, n.w};
        const float origin[3] = {r->origin.x, r->origin.y, r->origin.z}, dir[3] = {r->dir.x, r->dir.y, r->dir.z};
        vcClipToPlane(vcAffineRow(plane, origin), vcLinearRow(plane, dir), &t0, &t1);
    }
    r->t0 = t0;
    r->t1 = t1;
#endif
}

/* ---- the segments -------------------------------------------------------------------------- */

/* Segment boundaries at t0 + (k + j)·step along [t0, t1], j the jitter offset in [0, 1): from
 * k = 0 under jitter (a partial first segment), else from 1. */
typedef struct {
    float t0, t1, j, d;
    int k;       /* the current segment ends at boundary k */
    float start; /* where it starts */
} Segments;

typedef struct {
    float boundary, end, len;
    bool partial; /* the first one under jitter, or the last at the exit */
} Segment;

/* JITTER: a random start offset per ray and pass (against onion rings), else 0. */
float jitterOffset(const RayCastParams *P, int x, int y) {
#ifdef JITTER
    return vcRandom01((uint)x, (uint)y, P->seed, P->pass);
#else
    return 0.0f;
#endif
}

Segments firstSegment(const Ray *r, float d, float j) {
    Segments s;
    s.t0 = r->t0;
    s.t1 = r->t1;
    s.j = j;
    s.d = d;
    s.k = j > 0.0f ? 0 : 1;
    s.start = r->t0;
    return s;
}

Segment segmentAt(const Segments *s) {
    Segment g;
    g.boundary = s->t0 + ((float)s->k + s->j) * s->d;
    g.end = fmin(g.boundary, s->t1);
    g.len = g.end - s->start;
    g.partial = g.boundary > s->t1 || (s->k == 0);
    return g;
}

/* BOUNDARY_SEGMENT: every non-empty segment is sampled, partial ones included (no jerky
 * edges); without it only full ones. */
bool segmentTaken(Segment g) {
#ifdef BOUNDARY_SEGMENT
    return g.len > 0.0f;
#else
    return g.len > 0.0f && !g.partial;
#endif
}

/* Moves on to the next segment; false past the ray's exit. */
bool nextSegment(Segments *s, Segment g) {
    if (g.boundary >= s->t1) return false;
    s->start = g.end;
    ++s->k;
    return true;
}

/* Counts a sample; false, and the ray counted as truncated, beyond the per-ray limit. */
bool countSample(const Frame *f, uint *samples) {
    if ((int)*samples >= f->P->maxSamples) {
        atomic_inc(&f->stats[VC_STAT_TRUNCATED]);
        return false;
    }
    ++*samples;
    return true;
}

/* ---- intensity projection ------------------------------------------------------------------ */

#if defined(COMPOSITING_MAX) || defined(COMPOSITING_MIN)
/* COMPOSITING_MAX: the larger value, COMPOSITING_MIN: the smaller. */
float extremeOf(float a, float b) {
#ifdef COMPOSITING_MAX
    return fmax(a, b);
#else
    return fmin(a, b);
#endif
}

/* The extreme of the values sampled at the segments' centres (the same segments, partial ones
 * included, as emission–absorption samples), mapped through the transfer function:
 * premultiplied colour and its opacity a(v). */
float4 projectIntensity(VOLUME_ARG, const Frame *f, const Ray *r, float j, uint *samples) {
    Segments s = firstSegment(r, f->P->step, j);
    bool found = false;
    float extreme = 0.0f;
    for (;;) {
        const Segment g = segmentAt(&s);
        if (segmentTaken(g)) {
            if (!countSample(f, samples)) break;
            const float v = sampleVolume(VOLUME, f->n, r->q0 + (s.start + 0.5f * g.len) * r->dqL);
            extreme = found ? extremeOf(extreme, v) : v;
            found = true;
        }
        if (!nextSegment(&s, g)) break;
    }
    if (!found) return (float4)(0.0f);
    const float4 rgbs = classify(f->tfTable, f->P, extreme);
    const float a = vcOpacityFromDepth(rgbs.w); /* the table holds sigma = −ln(1 − a) */
    return (float4)(a * rgbs.xyz, a);
}
#endif

/* ---- emission–absorption ------------------------------------------------------------------- */

#if defined(EMPTY_SPACE_SKIPPING) || defined(ADAPTIVE_STEP)
/* The incremental brick walk (DDA) over the brick grid: the brick holding the point the ray has
 * reached, whether the transfer function leaves it visible, and the t at which the ray crosses
 * each of its walls (vcBrickOf, vcBrickWall, vcBrickExit). Moving on costs a comparison per
 * segment and a division per wall crossed. A point within float rounding of a wall may be put
 * in either brick: harmless, as each brick's value range covers half a voxel beyond its box
 * (minmax_bricks.hpp). An empty brick at chessboard distance r from the nearest visible one
 * (brickReach, emptyReach) is the centre of a cube of empty bricks `extent` = r − 1 on each
 * side, and the walk takes the cube's walls as the brick's, so a run of empty segments ends
 * where the ray leaves the cube. Pre-integrated segments keep single bricks (two empty bricks
 * may hold values on either side of a visible range). The native path walks a packet of rays
 * with the same formulas (cpu_march.cpp's BrickWalk).
 * ADAPTIVE_STEP: the walk reads the brick's step instead, visible where it is positive, a
 * brick at a time. */
typedef struct {
    float q0[3], dq[3]; /* the ray in level coordinates */
    int b[3];
    int extent; /* bricks each side of b that are empty too */
    float wall[3];
    bool visible;
    float step; /* ADAPTIVE_STEP: the brick's segment length */
} BrickWalk;

void brickLookUp(const Frame *f, BrickWalk *w) {
    const RayCastParams *P = f->P;
    const int bx = clamp(w->b[0], 0, P->bricks[0] - 1), by = clamp(w->b[1], 0, P->bricks[1] - 1),
              bz = clamp(w->b[2], 0, P->bricks[2] - 1);
    const size_t brick = ((size_t)bz * P->bricks[1] + by) * P->bricks[0] + bx;
#ifdef ADAPTIVE_STEP
    w->step = f->brickStep[brick];
    w->visible = w->step > 0.0f;
#else
    const int reach = f->brickReach[brick];
    w->visible = reach == 0;
#ifndef PREINTEGRATED
    w->extent = max(reach - 1, 0);
#endif
#endif
}

/* The wall on axis a of the cube of bricks b ± extent that the ray leaves by. */
float brickWallAt(const Frame *f, const BrickWalk *w, int a) {
    const int ahead = w->dq[a] < 0.0f ? -w->extent : w->extent;
    return vcBrickWall((float)(w->b[a] + ahead), (float)f->P->brickSize, w->q0[a], w->dq[a]);
}

float brickWalkExit(const BrickWalk *w) { return vcBrickExit(w->wall[0], w->wall[1], w->wall[2]); }

/* The brick of q(t) for the ray entering at t. */
void brickWalkStart(const Frame *f, const Ray *r, BrickWalk *w) {
    const RayCastParams *P = f->P;
    const float inverseB = 1.0f / (float)P->brickSize;
    w->q0[0] = r->q0.x, w->q0[1] = r->q0.y, w->q0[2] = r->q0.z;
    w->dq[0] = r->dqL.x, w->dq[1] = r->dqL.y, w->dq[2] = r->dqL.z;
    for (int a = 0; a < 3; ++a) {
        const float q = fma(r->t0, w->dq[a], w->q0[a]);
        w->b[a] = clamp((int)vcBrickOf(q, inverseB), 0, P->bricks[a] - 1);
    }
    w->extent = 0;
    brickLookUp(f, w);
    for (int a = 0; a < 3; ++a) w->wall[a] = brickWallAt(f, w, a);
}

/* Moves on to the brick (or cube) holding q(t), t not before where the walk is: bricks are
 * crossed one wall at a time and looked up once at the end. Leaving a cube moves the brick on
 * the crossed axis past it and takes the bricks on the other axes from the point reached,
 * kept inside the cube's slab against rounding. */
void brickWalkTo(const Frame *f, float t, BrickWalk *w) {
    bool moved = false;
    for (;;) {
        const float first = brickWalkExit(w);
        if (!(t >= first)) break;
        moved = true;
        const int a = w->wall[0] == first ? 0 : (w->wall[1] == first ? 1 : 2);
        const int e = w->extent;
        if (e > 0) {
            const float inverseB = 1.0f / (float)f->P->brickSize;
            for (int o = 0; o < 3; ++o)
                if (o != a) w->b[o] = clamp((int)vcBrickOf(fma(first, w->dq[o], w->q0[o]), inverseB), w->b[o] - e, w->b[o] + e);
        }
        w->b[a] += w->dq[a] > 0.0f ? e + 1 : -(e + 1);
        w->extent = 0;
        if (e > 0)
            for (int o = 0; o < 3; ++o) w->wall[o] = brickWallAt(f, w, o);
        else
            w->wall[a] = brickWallAt(f, w, a);
    }
    if (!moved) return;
    brickLookUp(f, w);
    if (w->extent > 0)
        for (int o = 0; o < 3; ++o) w->wall[o] = brickWallAt(f, w, o);
}

#if defined(EMPTY_SPACE_SKIPPING) && !defined(ADAPTIVE_STEP)
#ifdef PREINTEGRATED
/* A pre-integrated segment reads the values at both ends and between: it is empty when it lies
 * wholly in a brick the transfer function makes transparent. A later full segment k' is
 * decided by its end, t0 + (k' + j)·d. */
#define SKIP_DECIDING_POINT 0.0f
bool emptySegment(const Frame *f, const Segments *s, Segment g, BrickWalk *w) {
    brickWalkTo(f, s->start, w);
    return !w->visible && g.end <= brickWalkExit(w);
}
#else
/* A sampled segment is empty when its sample, at its centre, lies in such a brick (it would add
 * exactly 0); a later full segment k' is decided by its centre, t0 + (k' + j − ½)·d. */
#define SKIP_DECIDING_POINT 0.5f
bool emptySegment(const Frame *f, const Segments *s, Segment g, BrickWalk *w) {
    brickWalkTo(f, fma(0.5f, g.len, s->start), w);
    return !w->visible;
}
#endif
#endif
#endif

/* One ray's emission–absorption march: the compensated sums, the transmittance, counters. */
typedef struct {
    float opticalDepth, depthCarry; /* accumulated, so faint media keep their precision */
    float T;                        /* transmittance in front of the current segment */
    float color[3], colorCarry[3];
    uint samples, skipped;
    bool terminated;
    bool refreshOwed; /* a transmittance refresh fell on a segment that added nothing */
#ifdef PREINTEGRATED
    float sf;     /* the value at the segment's front */
    bool sfStale; /* after a skip: sf must be sampled at the segment's start first */
#endif
#if defined(EMPTY_SPACE_SKIPPING) || defined(ADAPTIVE_STEP)
    BrickWalk walk;
#endif
} March;

March startMarch(VOLUME_ARG, const Frame *f, const Ray *r) {
    March m;
    m.opticalDepth = m.depthCarry = 0.0f;
    m.T = 1.0f;
    for (int c = 0; c < 3; ++c) m.color[c] = m.colorCarry[c] = 0.0f;
    m.samples = m.skipped = 0u;
    m.terminated = false;
    m.refreshOwed = false;
#ifdef PREINTEGRATED
    m.sf = sampleVolume(VOLUME, f->n, r->q0 + r->t0 * r->dqL);
    m.sfStale = false;
#endif
#if defined(EMPTY_SPACE_SKIPPING) || defined(ADAPTIVE_STEP)
    brickWalkStart(f, r, &m.walk);
#endif
    return m;
}

/* EMPTY_SPACE_SKIPPING: whether segment g is empty by the brick walk (it is then not taken),
 * and *jumpTo, the last later full segment k' that is empty too: its deciding point before the
 * brick's exit (one fewer for rounding), ending before t1. */
bool inEmptySpace(const Frame *f, const Segments *s, Segment g, March *m, float *jumpTo) {
#if defined(EMPTY_SPACE_SKIPPING) && !defined(ADAPTIVE_STEP)
    if (!emptySegment(f, s, g, &m->walk)) return false;
    *jumpTo = fmin(floor((brickWalkExit(&m->walk) - s->t0) / s->d - s->j + SKIP_DECIDING_POINT) - 1.0f,
                   floor((s->t1 - s->t0) / s->d - s->j) - 1.0f);
#ifdef PREINTEGRATED
    m->sfStale = true;
#endif
    return true;
#else
    return false;
#endif
}

/* Skips the full segments k … jumpTo at once (segment k is the current one): moves on to
 * jumpTo + 1 and returns how many. */
uint skipSegmentsTo(Segments *s, float jumpTo) {
    if (!(jumpTo >= (float)s->k)) return 0u;
    const uint n = (uint)(jumpTo - (float)s->k) + 1u;
    s->k = (int)jumpTo + 1;
    s->start = fma(jumpTo + s->j, s->d, s->t0);
    return n;
}

/* A segment's part of the pixel: T·weight·rgb, its optical depth and opacity. weight is alpha
 * for a sampled segment's colour, 1 for a premultiplied (pre-integrated) one. */
typedef struct {
    float3 rgb;
    float weight, depth, alpha;
} SegmentColour;

/* SHADING: a sample's colour lit by the headlight where it is not transparent. */
float3 shadeSample(VOLUME_ARG, const Frame *f, const Ray *r, float3 q, float3 rgb, float alpha) {
#ifdef SHADING
    if (alpha > 0.0f) {
        const float2 light = phong(VOLUME, f, q, r->dir);
        rgb = (float3)(vcShade(rgb.x, light.x, light.y), vcShade(rgb.y, light.x, light.y),
                       vcShade(rgb.z, light.x, light.y));
    }
#endif
    return rgb;
}

/* SHADING: a premultiplied segment colour lit at the segment's centre q. */
float3 shadeSegment(VOLUME_ARG, const Frame *f, const Ray *r, float3 q, float3 rgb, float alpha) {
#ifdef SHADING
    const float2 light = phong(VOLUME, f, q, r->dir);
    rgb = (float3)(vcShadePremultiplied(rgb.x, alpha, light.x, light.y),
                   vcShadePremultiplied(rgb.y, alpha, light.x, light.y),
                   vcShadePremultiplied(rgb.z, alpha, light.x, light.y));
#endif
    return rgb;
}

/* The segment sampled at its centre and classified, its opacity corrected for its length. */
SegmentColour sampledColour(VOLUME_ARG, const Frame *f, const Ray *r, const Segments *s, Segment g) {
    const float3 q = r->q0 + (s->start + 0.5f * g.len) * r->dqL;
    const float4 rgba = classify(f->tfTable, f->P, sampleVolume(VOLUME, f->n, q));
    SegmentColour c;
    c.depth = vcSegmentDepth(rgba.w, g.len, f->P->opacityUnit);
    c.alpha = vcOpacityFromDepth(c.depth);
    c.rgb = shadeSample(VOLUME, f, r, q, rgba.xyz, c.alpha);
    c.weight = c.alpha;
    return c;
}

#ifdef PREINTEGRATED
/* The segment's colour and optical depth from the table for a full step; a partial one scales
 * the depth by len/step (Eq. 3) and the colour with its opacity. Partial by position, not by
 * len < d: far from the eye, float rounding of the boundaries makes full segments a little
 * shorter or longer than d, and scaling only the shorter ones would bias the sum (by 0.7 %
 * over 800,000 faint segments). Where the full step's alpha is too close to 1 to hold its
 * depth (VC_ALPHA_HOLDS_DEPTH), the partial segment is classified at its centre instead. */
SegmentColour preintegratedColour(VOLUME_ARG, const Frame *f, const Ray *r, const Segments *s, Segment g, March *m) {
    if (m->sfStale) {
        m->sf = sampleVolume(VOLUME, f->n, r->q0 + s->start * r->dqL);
        m->sfStale = false;
    }
    const float sb = sampleVolume(VOLUME, f->n, r->q0 + g.end * r->dqL);
    const float4 seg = preintegratedSegment(f, m->sf, sb);
    m->sf = sb;
    SegmentColour c;
    c.depth = vcDepthFromOpacity(seg.w); /* +inf behind opaque material: T becomes 0 */
    c.alpha = seg.w;
    c.rgb = seg.xyz;
    c.weight = 1.0f;
#ifdef ADAPTIVE_STEP
    const bool scaled = true; /* every segment is scaled from the table's (the longest) step */
#else
    const bool scaled = g.partial;
#endif
    if (scaled && seg.w <= VC_ALPHA_HOLDS_DEPTH) {
        const float fraction = g.len / s->d;
        c.depth *= fraction;
        c.alpha = vcOpacityFromDepth(c.depth);
        c.rgb *= vcPartialColourScale(seg.w, c.alpha, fraction);
    } else if (scaled) {
        const float4 rgba = classify(f->tfTable, f->P, sampleVolume(VOLUME, f->n, r->q0 + (s->start + 0.5f * g.len) * r->dqL));
        c.depth = vcSegmentDepth(rgba.w, g.len, f->P->opacityUnit);
        c.alpha = vcOpacityFromDepth(c.depth);
        c.rgb = c.alpha * rgba.xyz;
    }
    c.rgb = shadeSegment(VOLUME, f, r, r->q0 + (s->start + 0.5f * g.len) * r->dqL, c.rgb, c.alpha);
    return c;
}
#endif

/* PREINTEGRATED: the segment from the pre-integration table, else sampled at its centre. */
SegmentColour segmentColour(VOLUME_ARG, const Frame *f, const Ray *r, const Segments *s, Segment g, March *m) {
#ifdef PREINTEGRATED
    return preintegratedColour(VOLUME, f, r, s, g, m);
#else
    return sampledColour(VOLUME, f, r, s, g);
#endif
}

/* Front to back (Eq. 2): colour += T·weight·rgb and depth += the segment's, compensated, and T
 * behind the segment (vcNextTransmittance). A sampled segment of depth 0 has opacity 0 and adds
 * nothing (T·0·rgb, depth + 0, T·1), so it is not composited; a refresh of T due on it is made
 * at the ray's next segment that adds. The native march does the same (cpu_march.cpp). */
void composite(March *m, SegmentColour c) {
    bool exact = (m->samples & (VC_EXACT_TRANSMITTANCE_EVERY - 1u)) == 0u;
#ifndef PREINTEGRATED
    if (!(c.depth > 0.0f)) {
        m->refreshOwed = m->refreshOwed || exact;
        return;
    }
    exact = exact || m->refreshOwed;
    m->refreshOwed = false;
#endif
    const float w = m->T * c.weight;
    vcAddCompensated(&m->color[0], &m->colorCarry[0], w * c.rgb.x);
    vcAddCompensated(&m->color[1], &m->colorCarry[1], w * c.rgb.y);
    vcAddCompensated(&m->color[2], &m->colorCarry[2], w * c.rgb.z);
    vcAddCompensatedDepth(&m->opticalDepth, &m->depthCarry, c.depth);
    m->T = vcNextTransmittance(m->T, c.alpha, m->opticalDepth, m->depthCarry, exact);
}

/* EARLY_TERMINATION: whether the ray stops, its optical depth at the threshold's. */
bool terminatesEarly(const Frame *f, March *m) {
#ifdef EARLY_TERMINATION
    if (m->opticalDepth >= f->P->terminationDepth) {
        m->terminated = true;
        return true;
    }
#endif
    return false;
}

#ifdef ADAPTIVE_STEP
/* The segments of the adaptive step: each starts where the last ended and is as long as the
 * step of the brick it starts in (the first, k = 0, j times that under jitter), cut at t1. A
 * transparent brick (EMPTY_SPACE_SKIPPING) adds exactly nothing: the ray starts again at its
 * exit, its first segment there jittered again so that segments do not line up on the wall. */
void marchSegments(VOLUME_ARG, const Frame *f, const Ray *r, float j, March *m) {
    Segments s = firstSegment(r, f->P->step, j);
    for (;;) {
        brickWalkTo(f, s.start, &m->walk);
        if (!m->walk.visible) {
            ++m->skipped;
            const float exit = brickWalkExit(&m->walk);
            if (exit >= s.t1) break;
            s.start = exit;
            s.k = s.j > 0.0f ? 0 : 1;
#ifdef PREINTEGRATED
            m->sfStale = true;
#endif
            continue;
        }
        Segment g;
        g.boundary = s.start + (s.k == 0 ? s.j * m->walk.step : m->walk.step);
        g.end = fmin(g.boundary, s.t1);
        g.len = g.end - s.start;
        g.partial = g.boundary > s.t1 || s.k == 0;
        if (segmentTaken(g)) {
            if (!countSample(f, &m->samples)) break;
            composite(m, segmentColour(VOLUME, f, r, &s, g, m));
            if (terminatesEarly(f, m)) break;
        }
        if (!nextSegment(&s, g)) break;
    }
}
#else
/* The segments at t0 + (k + j)·step; EMPTY_SPACE_SKIPPING jumps over the empty ones. */
void marchSegments(VOLUME_ARG, const Frame *f, const Ray *r, float j, March *m) {
    Segments s = firstSegment(r, f->P->step, j);
    for (;;) {
        const Segment g = segmentAt(&s);
        if (segmentTaken(g)) {
            float jumpTo;
            if (inEmptySpace(f, &s, g, m, &jumpTo)) {
                ++m->skipped;
                if (!nextSegment(&s, g)) break;
                m->skipped += skipSegmentsTo(&s, jumpTo);
                continue;
            }
            if (!countSample(f, &m->samples)) break;
            composite(m, segmentColour(VOLUME, f, r, &s, g, m));
            if (terminatesEarly(f, m)) break;
        }
        if (!nextSegment(&s, g)) break;
    }
}
#endif

float4 emissionAbsorption(VOLUME_ARG, const Frame *f, const Ray *r, float j, uint *samples) {
    March m = startMarch(VOLUME, f, r);
    marchSegments(VOLUME, f, r, j, &m);
    __global volatile uint *stats = f->stats;
    if (m.terminated) atomic_inc(&stats[VC_STAT_TERMINATED_EARLY]);
    if (m.skipped && atomic_add(&stats[VC_STAT_SEGMENTS_SKIPPED], m.skipped) > UINT_MAX - m.skipped)
        atomic_inc(&stats[VC_STAT_SEGMENTS_SKIPPED_HIGH]);
    *samples = m.samples;
    return (float4)(m.color[0] - m.colorCarry[0], m.color[1] - m.colorCarry[1], m.color[2] - m.colorCarry[2],
                    vcOpacityFromDepth(m.opticalDepth - m.depthCarry));
}

/* ---- the pixel ----------------------------------------------------------------------------- */

/* COMPOSITING_MAX or _MIN: an intensity projection, else emission–absorption. */
float4 compositeRay(VOLUME_ARG, const Frame *f, const Ray *r, float j, uint *samples) {
#if defined(COMPOSITING_MAX) || defined(COMPOSITING_MIN)
    return projectIntensity(VOLUME, f, r, j, samples);
#else
    return emissionAbsorption(VOLUME, f, r, j, samples);
#endif
}

float4 castRay(VOLUME_ARG, const Frame *f, int x, int y) {
    const RayCastParams *P = f->P;
    Ray r = cameraRay(P, x, y);
    clipToBox(P, &r);
    clipToPlanes(P, &r);
    if (!(r.t1 > r.t0)) return (float4)(0.0f);
    r.q0 = levelFromIndex(P, r.p0);
    r.dqL = r.dq * P->levelScale;
    uint samples = 0u;
    const float4 pixel = compositeRay(VOLUME, f, &r, jitterOffset(P, x, y), &samples);
    if (atomic_add(&f->stats[VC_STAT_SAMPLES], samples) > UINT_MAX - samples)
        atomic_inc(&f->stats[VC_STAT_SAMPLES_HIGH]);
    atomic_inc(&f->stats[VC_STAT_RAYS_HIT]);
    return pixel;
}

/* ---- the frame as it is encoded --------------------------------------------------------------- */

/* 8-bit premultiplied RGBA, channel by channel round(clamp(v, 0, 1) · 255) with halves away
 * from zero: renderer/common/frame_renderer.hpp's clampUnit and byteFromUnit bit for bit. The
 * product is one correctly rounded multiply (nothing to contract it with), and round() is exact,
 * so neither contraction nor a device's division or denormal liberties can change a byte. */
uchar byteFromUnit(float v) {
    const float c = v > 0.0f ? v : 0.0f; /* NaN to 0 */
    return (uchar)round((c < 1.0f ? c : 1.0f) * 255.0f);
}

uchar4 rgba8FromUnit(float4 v) {
    return (uchar4)(byteFromUnit(v.x), byteFromUnit(v.y), byteFromUnit(v.z), byteFromUnit(v.w));
}

/* ---- the kernel -------------------------------------------------------------------------------- */

__kernel void raycast(KERNEL_VOLUME_ARG, __global const float4 *tfTable,
#ifdef PREINTEGRATED
                      __global const float4 *preTable, __global const float *preNodes, __global const int *preLocator,
#endif
#if defined(EMPTY_SPACE_SKIPPING) && !defined(ADAPTIVE_STEP)
                      __global const int *brickReach,
#endif
#ifdef ADAPTIVE_STEP
                      __global const float *brickStep,
#endif
                      const RayCastParams params, const int4 window, __global float4 *image,
                      const int rgba8, __global volatile uint *stats) {
    /* window: (x, y, width, height) of the ray grid this launch casts, its origin the launch's
     * offset; the launch is rounded up to whole work-groups, and the rays past the window are
     * not cast (nor counted). image holds the window alone, row by row: float RGBA, or with
     * rgba8 the 8-bit RGBA a frame is encoded from (a quarter of the bytes to read back, and
     * no second kernel to convert them). stats are running totals: a frame reads what it
     * added (opencl_renderer.cpp), so no command zeroes them. params come by value, with the
     * launch: no command writes them either. */
    const RayCastParams *P = &params;
    const int x = get_global_id(0), y = get_global_id(1);
    if (x >= window.x + window.z || y >= window.y + window.w || x >= P->width || y >= P->height) return;
#ifdef VOXEL_BYTES
    const float narrowOffset = P->narrowOffset;
#endif
    Frame f;
    f.P = P;
    f.tfTable = tfTable;
#ifdef PREINTEGRATED
    f.preTable = preTable;
    f.preNodes = preNodes;
    f.preLocator = preLocator;
#endif
#if defined(EMPTY_SPACE_SKIPPING) && !defined(ADAPTIVE_STEP)
    f.brickReach = brickReach;
#endif
#ifdef ADAPTIVE_STEP
    f.brickStep = brickStep;
#endif
    f.stats = stats;
    f.n = (int4)(P->levelDims[0], P->levelDims[1], P->levelDims[2], 0);
    const float4 pixel = castRay(VOLUME, &f, x, y);
    const int i = (y - window.y) * window.z + (x - window.x);
    if (rgba8)
        ((__global uchar4 *)image)[i] = rgba8FromUnit(pixel);
    else
        image[i] = pixel;
}
