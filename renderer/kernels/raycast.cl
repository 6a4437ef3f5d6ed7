/* Direct volume rendering by ray casting (paper Eq. 2), front to back.
 *
 * Feature switches, as build options (a scene's program holds only what it uses):
 *   JITTER            random start offset per ray and pass (onion rings)
 *   BOUNDARY_SEGMENT  partial last segment at the volume boundary and clip planes (jerky edges)
 *   EARLY_TERMINATION stop once the transmittance falls to the threshold
 *   CLIP_PLANES       honour the scene's clip planes
 */
#ifndef VOLCAST_EMBEDDED
#include "raycast_shared.h"
#endif

inline float voxel(__global const float *volume, int4 n, int i, int j, int k) {
    return volume[(k * n.y + j) * n.x + i];
}

/* Trilinear reconstruction from a buffer with clamp-to-edge (DESIGN.md): on CPUs a buffer
 * is several times faster than a 3-D image (PLATFORM.md). */
float sampleTrilinear(__global const float *volume, int4 n, float3 p) {
    const float3 hi = convert_float3(n.xyz - 1);
    p = clamp(p, (float3)(0.0f), hi);
    const int3 i0 = min(convert_int3(p), max(n.xyz - 2, (int3)(0)));
    const float3 f = p - convert_float3(i0);
    const int3 i1 = min(i0 + 1, n.xyz - 1);
    const float c000 = voxel(volume, n, i0.x, i0.y, i0.z), c100 = voxel(volume, n, i1.x, i0.y, i0.z);
    const float c010 = voxel(volume, n, i0.x, i1.y, i0.z), c110 = voxel(volume, n, i1.x, i1.y, i0.z);
    const float c001 = voxel(volume, n, i0.x, i0.y, i1.z), c101 = voxel(volume, n, i1.x, i0.y, i1.z);
    const float c011 = voxel(volume, n, i0.x, i1.y, i1.z), c111 = voxel(volume, n, i1.x, i1.y, i1.z);
    const float c00 = mix(c000, c100, f.x), c10 = mix(c010, c110, f.x);
    const float c01 = mix(c001, c101, f.x), c11 = mix(c011, c111, f.x);
    return mix(mix(c00, c10, f.y), mix(c01, c11, f.y), f.z);
}

/* Transfer function: colour and opacity per opacityUnit, linear between table entries. */
float4 classify(__global const float4 *table, __global const RayCastParams *P, float v) {
    const float x = clamp((v - P->tfMin) * P->tfScale, 0.0f, (float)(P->tfEntries - 1));
    const int i = min((int)x, P->tfEntries - 2);
    return mix(table[i], table[i + 1], x - (float)i);
}

/* PCG hash: a reproducible uniform number in [0, 1) per pixel, seed and pass. */
float random01(uint x, uint y, uint seed, uint pass) {
    uint s = x * 1973u + y * 9277u + seed * 26699u + pass * 104729u;
    s = s * 747796405u + 2891336453u;
    uint w = ((s >> ((s >> 28u) + 4u)) ^ s) * 277803737u;
    w = (w >> 22u) ^ w;
    return (float)(w >> 8) * (1.0f / 16777216.0f);
}

__kernel void raycast(__global const float *volume, __global const float4 *tfTable,
                      __global const RayCastParams *P, __global float4 *image,
                      __global volatile uint *stats) {
    const int x = get_global_id(0), y = get_global_id(1);
    if (x >= P->width || y >= P->height) return;

    /* Ray through the pixel centre (DESIGN.md's camera), world space. */
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
    const int4 n = (int4)(P->dims[0], P->dims[1], P->dims[2], 0);
    float t0 = 0.0f, t1 = INFINITY;
    for (int a = 0; a < 3; ++a) {
        const float pa = a == 0 ? p0.x : (a == 1 ? p0.y : p0.z);
        const float da = a == 0 ? dq.x : (a == 1 ? dq.y : dq.z);
        const float lo = -0.5f, hi = (float)P->dims[a] - 0.5f;
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

    /* Segment boundaries at t0 + (k + j)·step; j is the jitter offset in [0, 1). */
    const float d = P->step;
#ifdef JITTER
    const float j = random01((uint)x, (uint)y, P->seed, P->pass);
#else
    const float j = 0.0f;
#endif
    float opticalDepth = 0.0f; /* accumulated, so faint media keep their precision */
    float3 color = (float3)(0.0f);
    uint samples = 0;
    bool terminated = false;
    float segStart = t0;
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
        if (take) {
            if ((int)samples >= P->maxSamples) {
                atomic_inc(&stats[VC_STAT_TRUNCATED]);
                break;
            }
            ++samples;
            /* Sample the segment at its centre and classify. */
            const float3 p = p0 + (segStart + 0.5f * len) * dq;
            const float4 rgba = classify(tfTable, P, sampleTrilinear(volume, n, p));
            /* Correct opacity for the segment length (Eq. 3), as -expm1(-tau·len). */
            const float tau = rgba.w >= 1.0f ? INFINITY : -log1p(-rgba.w) / P->opacityUnit;
            const float segDepth = tau * len;
            const float alpha = -expm1(-segDepth);
            color += exp(-opticalDepth) * alpha * rgba.xyz;
            opticalDepth += segDepth;
#ifdef EARLY_TERMINATION
            if (exp(-opticalDepth) <= P->terminationTransmittance) {
                terminated = true;
                break;
            }
#endif
        }
        if (boundary >= t1) break;
        segStart = segEnd;
    }
    image[y * P->width + x] = (float4)(color, -expm1(-opticalDepth));
    atomic_add(&stats[VC_STAT_SAMPLES], samples);
    atomic_inc(&stats[VC_STAT_RAYS_HIT]);
    if (terminated) atomic_inc(&stats[VC_STAT_TERMINATED_EARLY]);
}
