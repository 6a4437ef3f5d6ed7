/* Parameters shared by the host (C++) and the ray-casting kernel (OpenCL C): one layout,
 * explicit padding, its size checked on the host. */
#ifndef VOLCAST_RAYCAST_SHARED_H
#define VOLCAST_RAYCAST_SHARED_H

#ifdef __OPENCL_VERSION__
typedef float4 vc_float4;
typedef float vc_float;
typedef int vc_int;
typedef uint vc_uint;
#else
#ifndef CL_TARGET_OPENCL_VERSION
#define CL_TARGET_OPENCL_VERSION 120
#endif
#include <CL/cl_platform.h>
typedef cl_float4 vc_float4;
typedef cl_float vc_float;
typedef cl_int vc_int;
typedef cl_uint vc_uint;
#endif

#define VC_MAX_CLIP_PLANES 6

typedef struct {
    vc_float4 eye;                  /* world; orthographic: the centre of the image plane */
    vc_float4 forward;              /* unit view direction */
    vc_float4 right;                /* image x axis scaled by the half-width of the view */
    vc_float4 up;                   /* image y axis scaled by the half-height of the view */
    vc_float4 indexFromWorld[3];    /* rows of the affine map world -> level-0 index space */
    vc_float4 clipPlanes[VC_MAX_CLIP_PLANES]; /* (n, w): keeps dot(n, x) + w >= 0, world */
    vc_int dims[4];                 /* level-0 samples per axis: the box rays are clipped to */
    vc_int levelDims[4];            /* samples per axis of the data sampled (mip level) */
    vc_int bricks[4];               /* min-max bricks per axis (empty-space skipping) */
    vc_float levelScale;            /* 2^-mip_level: level index = (index + 1/2)·scale − 1/2 */
    vc_int brickSize;               /* level voxels per brick edge */
    vc_float tfMin;                 /* transfer-function table: value of entry 0 */
    vc_float tfScale;               /* entries per data unit */
    vc_int tfEntries;
    vc_int clipPlaneCount;
    vc_int width, height;           /* rays cast (after image_scale) */
    vc_int orthographic;
    vc_int maxSamples;              /* per ray; beyond it the ray stops and is counted */
    vc_float step;                  /* segment length, world units */
    vc_float opacityUnit;           /* world units */
    vc_float terminationDepth;      /* early termination once the optical depth reaches it */
    vc_float narrowOffset;          /* VOXEL_BYTES 1 or 2: sample = stored value + narrowOffset */
    vc_uint seed;
    vc_uint pass;
    /* Pre-integration table: nodes over the value range, a uniform locator into them. */
    vc_int preNodes;
    vc_int preLocatorSize;
    vc_float preLocatorMin;
    vc_float preLocatorScale;       /* locator buckets per data unit */
    vc_float inverseWidth, inverseHeight; /* 1/width, 1/height rounded once on the host (vcImageU) */
    vc_int pad3, pad4;
    /* The box rays are clipped to, level-0 index space: [-1/2, n - 1/2] per axis, or the crop box. */
    vc_float4 boxLo, boxHi;
} RayCastParams;

/* stats[]: counters the kernel accumulates, read back by the host. */
#define VC_STAT_SAMPLES 0
#define VC_STAT_TERMINATED_EARLY 1
#define VC_STAT_TRUNCATED 2
#define VC_STAT_RAYS_HIT 3
#define VC_STAT_SEGMENTS_SKIPPED 4
/* Carries of the two 32-bit sums that outgrow 2^32 on big frames (1000² rays × 8 samples per
 * voxel × 880 voxels is 7e9): 64-bit atomics are optional in OpenCL 1.2. */
#define VC_STAT_SAMPLES_HIGH 5
#define VC_STAT_SEGMENTS_SKIPPED_HIGH 6
#define VC_STAT_COUNT 7

#endif
