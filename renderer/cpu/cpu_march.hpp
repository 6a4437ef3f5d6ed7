#pragma once
// The interface between the CPU renderer's preparation (cpu_renderer.cpp, plain C++) and
// its SIMD ray march (cpu_march.cpp, compiled once per instruction set by Highway and
// dispatched at run time to the best the machine has). One frame's data, in float: the same
// numbers the OpenCL kernel reads from RayCastParams, so both back ends cast the same rays.

#include "renderer/common/frame_setup.hpp"

#include <atomic>
#include <cstdint>
#include <string>

namespace volcast::cpu {

// The switches the march branches on, as the frame's set-up decided them (cubic: from the
// padded coefficients).
using Features = FrameFeatures;

struct FrameParams {
    Features features;
    float eye[3];
    float forward[3];               // unit view direction
    float right[3], up[3];          // image axes scaled by the view's half-width and half-height
    float indexFromWorld[3][4];     // rows: linear part, translation (level-0 index space)
    float clipPlanes[6][4];         // (n, w): keeps dot(n, x) + w >= 0, world
    int clipPlaneCount = 0;
    int dims[3];                    // level-0 samples per axis
    float boxLo[3], boxHi[3];       // the box rays are clipped to, level-0 index space: the
                                    // volume's [−1/2, n − 1/2] or the crop box inside it
    int width = 0, height = 0;      // rays of the whole grid (after image_scale)
    float inverseWidth = 1, inverseHeight = 1; // 1/width, 1/height rounded once (vcImageU)
    // The window of the grid that rgba holds: rays [outX, outX + outWidth) × [outY, …); the
    // whole grid is 0, 0, width. Rays keep their grid coordinates (camera, jitter).
    int outX = 0, outY = 0, outWidth = 0;
    bool orthographic = false;
    float levelScale = 1;           // 2^-mip_level
    float step = 1;                 // world units; the longest with the adaptive step
    float opacityUnit = 1;          // world units
    float terminationDepth = 0;     // optical depth of the early-termination opacity
    uint32_t seed = 0, pass = 0;
    int maxSamples = 0;

    // The sampled level. Trilinear: its float samples where they lie (the volume's or the mip
    // pyramid's), unpadded; the sampler steps to no upper tap past the last sample. Cubic: its
    // B-spline coefficients with one mirrored before and two after on each axis (as the
    // kernel's buffer), so the 4×4×4 taps need no clamps. Index with int32.
    const float *voxels = nullptr;
    // Trilinear from an 8- or 16-bit scan's level 0: the volume's own narrow store
    // (Volume::narrowVoxels), unpadded, sample − narrowOffset in narrowBytes (1 or 2) bytes
    // each, kNarrowSlack bytes after the last. Exact: the taps widen to the same floats. One
    // 32-bit gather fetches both x taps, so a sample takes 4 gathers, not 8, from a quarter
    // (half) of the bytes. Null: `voxels` holds the level.
    const uint8_t *narrowVoxels = nullptr;
    int narrowBytes = 0;
    float narrowOffset = 0;
    // The same narrow level bricked (bricked_samples.hpp): 9³ samples a brick, bricks
    // kLayoutBrickSamples apart, x fastest. Set: read instead of narrowVoxels.
    const uint8_t *brickedVoxels = nullptr;
    int layoutBricks[2] = {0, 0};   // bricks along x and y
    int levelDims[3];               // samples per axis of the level (unpadded)
    int rowStride = 0, sliceStride = 0; // in samples, of what is sampled

    // Transfer-function table (tf_table.hpp): entries × (r, g, b, sigma).
    const float *tf = nullptr;
    float tfMin = 0, tfScale = 1;
    int tfEntries = 0;

    // Pre-integration table (preintegration.hpp): N nodes, N·N·4 rgba by (back·N + front),
    // and the uniform locator into the nodes.
    const float *preRgba = nullptr, *preNodes = nullptr;
    const int32_t *preLocator = nullptr;
    int preNodeCount = 0, preLocatorSize = 0;
    float preLocatorMin = 0, preLocatorScale = 0;

    // Empty-space skipping: per brick its chessboard distance in bricks to the nearest visible
    // brick, 0 where visible (emptyReach, minmax_bricks.hpp), as int32 so that lanes gather it.
    const int32_t *brickReach = nullptr;
    int bricks[3] = {0, 0, 0};
    int brickSize = 8;
    // The adaptive step: per brick its segment length, world units, or −1 where the brick is
    // skipped (adaptive_step.hpp). Set: the brick walk reads it instead of brickReach.
    const float *brickStep = nullptr;
};

// Sums over a frame, added to by every tile.
struct Counters {
    std::atomic<uint64_t> samples{0}, raysHit{0}, terminatedEarly{0}, truncated{0}, segmentsSkipped{0};
};

// Casts the rays of pixels [x0, x1) × [y0, y1) into rgba (the window outX, outY, outWidth wide,
// × 4, premultiplied).
void marchTile(const FrameParams &p, int x0, int y0, int x1, int y1, float *rgba, Counters &counters);

// The instruction set the march runs on here ("AVX3", "AVX2", …) and its rays per packet.
std::string marchTarget();
int raysPerPacket();

} // namespace volcast::cpu
