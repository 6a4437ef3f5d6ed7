// The CPU ray march: packets of rays from a small screen block, one ray per SIMD lane, each
// lane with its own segment state and a mask of lanes still marching. The per-sample formulas
// (ray set-up and clipping, jitter hash, table coordinates, opacity correction and polynomial,
// Kahan sums, transmittance refresh, Phong, brick walls) are renderer/common/ray_math.h's,
// which the OpenCL kernel compiles too, here on Highway vectors; the march around them walks
// the same segments as kernels/raycast.cl, so the two back ends draw the same image up to
// float rounding.
//
// Highway compiles this file once per instruction set (foreach_target.h re-includes it) and
// marchTile() calls the best one the machine supports.

#undef HWY_TARGET_INCLUDE
#define HWY_TARGET_INCLUDE "renderer/cpu/cpu_march.cpp"
#include <hwy/foreach_target.h> // IWYU pragma: keep

#include <hwy/contrib/math/math-inl.h>
#include <hwy/highway.h>

#include "renderer/cpu/bricked_samples.hpp"
#include "renderer/cpu/cpu_march.hpp"

#include <algorithm>
#include <cmath>
#include <limits>

HWY_BEFORE_NAMESPACE();
namespace volcast::cpu::HWY_NAMESPACE {
namespace hn = hwy::HWY_NAMESPACE;

using DF = hn::ScalableTag<float>;
using DI = hn::RebindToSigned<DF>;
using VF = hn::Vec<DF>;
using VI = hn::Vec<DI>;
using MF = hn::Mask<DF>;

constexpr size_t kMaxLanes = HWY_MAX_BYTES / sizeof(float);
constexpr float kInf = std::numeric_limits<float>::infinity();

// ray_math.h's formulas on this target's vectors, one ray per lane: its value type, mask and
// operations as Highway's (+ − * / and comparisons are Highway's operators).
#define VC_INLINE HWY_INLINE
#define VC_REAL VF
#define VC_MASK MF
#define VC_CONST(c) hn::Set(DF(), c)
#define VC_INFINITY kInf
#define vc_select(m, a, b) hn::IfThenElse(m, a, b)
#define vc_any(m) (!hn::AllFalse(DF(), m))
#define vc_and(a, b) hn::And(a, b)
#define vc_or(a, b) hn::Or(a, b)
#define vc_neg(x) hn::Neg(x)
#define vc_mad(a, b, c) hn::MulAdd(a, b, c)
#define vc_min(a, b) hn::Min(a, b)
#define vc_max(a, b) hn::Max(a, b)
#define vc_abs(x) hn::Abs(x)
#define vc_sqrt(x) hn::Sqrt(x)
#define vc_floor(x) hn::Floor(x)
#define vc_exp(x) hn::Exp(DF(), x)
#define vc_log1p(x) hn::Log1p(DF(), x)
#define vc_isinf(x) hn::IsInf(x)
#include "renderer/common/ray_math.h"

// The rays of a packet, lane-wise in the kernel's float arithmetic (raycast.cl's ray set-up):
// entry and exit t at the box (the volume's or the crop box) and the clip planes, the level
// coordinates q(t) = q0 + t·dq, the world direction; `hit` for the lanes in `inside` whose
// ray crosses the box. Lanes that miss hold zeros (finite values in lanes that do not
// march). One ray at a time, this set-up was a tenth of a frame (perf, 4 MiB 512²).
struct PacketRays {
    VF t0, t1, q0[3], dq[3], dir[3];
    MF hit;
};

PacketRays setUpPacket(const FrameParams &P, VF x, VF y, MF inside) {
    const DF df;
    const VF zero = hn::Zero(df), half = hn::Set(df, 0.5f), inf = hn::Set(df, kInf);
    const VF u = vcImageU(x, hn::Set(df, float(P.width)), hn::Set(df, P.inverseWidth));
    const VF v = vcImageV(y, hn::Set(df, float(P.height)), hn::Set(df, P.inverseHeight));
    VF origin[3], dir[3];
    vcCameraRay(u, v, P.eye, P.forward, P.right, P.up, P.orthographic, origin, dir);
    VF p0[3], dq[3];
    for (int a = 0; a < 3; ++a) {
        p0[a] = vcAffineRow(P.indexFromWorld[a], origin);
        dq[a] = vcLinearRow(P.indexFromWorld[a], dir);
    }
    VF t0 = zero, t1 = inf;
    for (int a = 0; a < 3; ++a) vcClipToSlab(p0[a], dq[a], hn::Set(df, P.boxLo[a]), hn::Set(df, P.boxHi[a]), &t0, &t1);
    if (P.features.clipPlanes)
        for (int c = 0; c < P.clipPlaneCount; ++c) {
            const float *plane = P.clipPlanes[c];
            vcClipToPlane(vcAffineRow(plane, origin), vcLinearRow(plane, dir), &t0, &t1);
        }
    PacketRays r;
    r.hit = hn::And(inside, hn::Gt(t1, t0));
    r.t0 = hn::IfThenElseZero(r.hit, t0);
    r.t1 = hn::IfThenElseZero(r.hit, t1);
    const VF scale = hn::Set(df, P.levelScale);
    for (int a = 0; a < 3; ++a) {
        r.q0[a] = hn::IfThenElseZero(r.hit, hn::Sub(hn::Mul(hn::Add(p0[a], half), scale), half));
        r.dq[a] = hn::IfThenElseZero(r.hit, hn::Mul(dq[a], scale));
        r.dir[a] = hn::IfThenElseZero(r.hit, dir[a]);
    }
    return r;
}

inline VF lerp(VF a, VF b, VF t) { return hn::MulAdd(hn::Sub(b, a), t, a); }

// The cell a trilinear sample at level coordinates (x, y, z) reads, clamped to the outermost
// samples: its lowest corner's index, the fractions along each axis, and its integer
// position. The level is sampled where it lies, without edge copies: on the last sample of
// an axis (where the fraction is exactly 0) the upper tap along it is the sample itself, as
// an edge copy would have been (upperStep).
struct TrilinearCell {
    VI corner;
    VF fx, fy, fz;
    VI ix, iy, iz;
};
HWY_INLINE TrilinearCell trilinearCell(const FrameParams &P, VF x, VF y, VF z) {
    const DF df;
    const DI di;
    const VF zero = hn::Zero(df);
    x = hn::Min(hn::Max(x, zero), hn::Set(df, float(P.levelDims[0] - 1)));
    y = hn::Min(hn::Max(y, zero), hn::Set(df, float(P.levelDims[1] - 1)));
    z = hn::Min(hn::Max(z, zero), hn::Set(df, float(P.levelDims[2] - 1)));
    const VI ix = hn::ConvertTo(di, x), iy = hn::ConvertTo(di, y), iz = hn::ConvertTo(di, z);
    return {hn::Add(hn::Add(ix, hn::Mul(iy, hn::Set(di, P.rowStride))), hn::Mul(iz, hn::Set(di, P.sliceStride))),
            hn::Sub(x, hn::ConvertTo(df, ix)), hn::Sub(y, hn::ConvertTo(df, iy)), hn::Sub(z, hn::ConvertTo(df, iz)),
            ix, iy, iz};
}

// The cell's 8 taps, named c<x><y><z>, blended along x, then y, then z.
HWY_INLINE VF blendTrilinear(const TrilinearCell &c, VF c000, VF c100, VF c010, VF c110, VF c001, VF c101, VF c011,
                             VF c111) {
    const VF c00 = lerp(c000, c100, c.fx), c10 = lerp(c010, c110, c.fx);
    const VF c01 = lerp(c001, c101, c.fx), c11 = lerp(c011, c111, c.fx);
    return lerp(lerp(c00, c10, c.fy), lerp(c01, c11, c.fy), c.fz);
}

// The step to the upper tap along an axis of n samples: `stride`, or 0 on the last sample.
HWY_INLINE VI upperStep(VI i, int n, int stride) {
    const DI di;
    return hn::IfThenElseZero(hn::Lt(i, hn::Set(di, n - 1)), hn::Set(di, stride));
}

// Trilinear from a float level: 8 gathers.
HWY_INLINE VF sampleTrilinear(const FrameParams &P, VF x, VF y, VF z) {
    const DF df;
    const TrilinearCell c = trilinearCell(P, x, y, z);
    const VI one = upperStep(c.ix, P.levelDims[0], 1), sy = upperStep(c.iy, P.levelDims[1], P.rowStride);
    const VI sz = upperStep(c.iz, P.levelDims[2], P.sliceStride);
    const VI i000 = c.corner, i010 = hn::Add(i000, sy), i001 = hn::Add(i000, sz), i011 = hn::Add(i001, sy);
    const float *v = P.voxels;
    return blendTrilinear(c, hn::GatherIndex(df, v, i000), hn::GatherIndex(df, v, hn::Add(i000, one)),
                          hn::GatherIndex(df, v, i010), hn::GatherIndex(df, v, hn::Add(i010, one)),
                          hn::GatherIndex(df, v, i001), hn::GatherIndex(df, v, hn::Add(i001, one)),
                          hn::GatherIndex(df, v, i011), hn::GatherIndex(df, v, hn::Add(i011, one)));
}

// Trilinear from four 32-bit gathers of narrow samples, each a tap (low Bytes) and its +x
// neighbour (the next Bytes): widened to float and blended as a float level's 8 taps.
template <int Bytes>
HWY_INLINE VF blendNarrowPairs(const FrameParams &P, const TrilinearCell &c, VI g00, VI g10, VI g01, VI g11) {
    const DF df;
    const DI di;
    const VI mask = hn::Set(di, Bytes == 1 ? 0xFF : 0xFFFF);
    const VF offset = hn::Set(df, P.narrowOffset);
    const auto lo = [&](VI g) { return hn::Add(hn::ConvertTo(df, hn::And(g, mask)), offset); };
    const auto hi = [&](VI g) { return hn::Add(hn::ConvertTo(df, hn::And(hn::ShiftRight<8 * Bytes>(g), mask)), offset); };
    return blendTrilinear(c, lo(g00), hi(g00), lo(g10), hi(g10), lo(g01), hi(g01), lo(g11), hi(g11));
}

// The same trilinear sample from the volume's narrow store (FrameParams::narrowVoxels): each
// 32-bit gather at a sample's byte offset holds it and its +x neighbour in its low 2·Bytes
// bytes. On the last column that +x tap is the next row's first sample (or the store's
// slack), with weight fx = 0: (b − a)·0 + a is a for any b below 2^24, as narrow samples are
// (a float level keeps upperStep there, since b − a may overflow). Widened to the same floats
// as a float level holds and blended in the same order, so the value is bit for bit the one
// sampleTrilinear returns for the same samples held as float.
template <int Bytes>
HWY_INLINE VF sampleTrilinearNarrow(const FrameParams &P, VF x, VF y, VF z) {
    const DI di;
    const TrilinearCell c = trilinearCell(P, x, y, z);
    const VI sy = upperStep(c.iy, P.levelDims[1], P.rowStride * Bytes);
    const VI sz = upperStep(c.iz, P.levelDims[2], P.sliceStride * Bytes);
    VI o000 = c.corner;
    if constexpr (Bytes == 2) o000 = hn::ShiftLeft<1>(o000);
    const int32_t *v = reinterpret_cast<const int32_t *>(P.narrowVoxels);
    const VI g00 = hn::GatherOffset(di, v, o000), g10 = hn::GatherOffset(di, v, hn::Add(o000, sy));
    const VI g01 = hn::GatherOffset(di, v, hn::Add(o000, sz)), g11 = hn::GatherOffset(di, v, hn::Add(hn::Add(o000, sy), sz));
    return blendNarrowPairs<Bytes>(P, c, g00, g10, g01, g11);
}

// The same trilinear sample from the bricked copy (FrameParams::brickedVoxels): the cell's
// brick and its corner inside it, whose 8 taps all lie in that brick (its ninth sample on
// each axis repeats the last sample past the volume's edge). Each 32-bit gather holds a tap
// and its +x neighbour, as sampleTrilinearNarrow's; the samples, widening and blend are the
// same, so the value is bit for bit the one the slice layout gives.
template <int Bytes>
HWY_INLINE VF sampleTrilinearBricked(const FrameParams &P, VF x, VF y, VF z) {
    const DI di;
    static_assert(kLayoutEdge == 8, "the brick of a cell is its corner shifted right by 3");
    const TrilinearCell c = trilinearCell(P, x, y, z);
    const VI low = hn::Set(di, kLayoutEdge - 1);
    const VI brick = hn::Add(hn::Mul(hn::Add(hn::Mul(hn::ShiftRight<3>(c.iz), hn::Set(di, P.layoutBricks[1])),
                                             hn::ShiftRight<3>(c.iy)),
                                     hn::Set(di, P.layoutBricks[0])),
                             hn::ShiftRight<3>(c.ix));
    const VI inside = hn::Add(hn::Mul(hn::Add(hn::Mul(hn::And(c.iz, low), hn::Set(di, kLayoutSide)), hn::And(c.iy, low)),
                                      hn::Set(di, kLayoutSide)),
                              hn::And(c.ix, low));
    const VI o000 = hn::Mul(hn::Add(hn::Mul(brick, hn::Set(di, kLayoutBrickSamples)), inside), hn::Set(di, Bytes));
    const VI sy = hn::Set(di, kLayoutSide * Bytes), sz = hn::Set(di, kLayoutSide * kLayoutSide * Bytes);
    const int32_t *v = reinterpret_cast<const int32_t *>(P.brickedVoxels);
    const VI g00 = hn::GatherOffset(di, v, o000), g10 = hn::GatherOffset(di, v, hn::Add(o000, sy));
    const VI g01 = hn::GatherOffset(di, v, hn::Add(o000, sz)), g11 = hn::GatherOffset(di, v, hn::Add(hn::Add(o000, sy), sz));
    return blendNarrowPairs<Bytes>(P, c, g00, g10, g01, g11);
}

// Cubic B-spline weights of the four taps around fractional position f.
inline void cubicWeights(VF f, VF w[4]) {
    const DF df;
    const VF g = hn::Sub(hn::Set(df, 1.0f), f), sixth = hn::Set(df, 1.0f / 6.0f), four = hn::Set(df, 4.0f);
    const VF f2 = hn::Mul(f, f), g2 = hn::Mul(g, g);
    w[0] = hn::Mul(hn::Mul(g2, g), sixth);
    w[1] = hn::Mul(hn::MulAdd(hn::Mul(f2, f), hn::Set(df, 3.0f), hn::NegMulAdd(f2, hn::Set(df, 6.0f), four)), sixth);
    w[2] = hn::Mul(hn::MulAdd(hn::Mul(g2, g), hn::Set(df, 3.0f), hn::NegMulAdd(g2, hn::Set(df, 6.0f), four)), sixth);
    w[3] = hn::Mul(hn::Mul(f2, f), sixth);
}

// Tricubic B-spline at level coordinates q, clamped to the outermost samples: 64 gathered
// coefficients. Padded index of tap (i − 1 + x, …) is (i + x, …), as in raycast.cl.
VF sampleCubic(const FrameParams &P, VF x, VF y, VF z) {
    const DF df;
    const DI di;
    const VF zero = hn::Zero(df);
    VF p[3] = {x, y, z};
    VI i[3];
    VF w[3][4];
    for (int a = 0; a < 3; ++a) {
        p[a] = hn::Min(hn::Max(p[a], zero), hn::Set(df, float(P.levelDims[a] - 1)));
        i[a] = hn::Min(hn::ConvertTo(di, p[a]), hn::Set(di, P.levelDims[a] - 1));
        cubicWeights(hn::Sub(p[a], hn::ConvertTo(df, i[a])), w[a]);
    }
    const VI base = hn::Add(hn::Add(i[0], hn::Mul(i[1], hn::Set(di, P.rowStride))), hn::Mul(i[2], hn::Set(di, P.sliceStride)));
    VF sum = zero;
    for (int tz = 0; tz < 4; ++tz) {
        VF sz = zero;
        for (int ty = 0; ty < 4; ++ty) {
            const VI row = hn::Add(base, hn::Set(di, tz * P.sliceStride + ty * P.rowStride));
            VF r = hn::Mul(w[0][0], hn::GatherIndex(df, P.voxels, row));
            for (int tx = 1; tx < 4; ++tx)
                r = hn::MulAdd(w[0][tx], hn::GatherIndex(df, P.voxels, hn::Add(row, hn::Set(di, tx))), r);
            sz = hn::MulAdd(w[1][ty], r, sz);
        }
        sum = hn::MulAdd(w[2][tz], sz, sum);
    }
    return sum;
}

HWY_INLINE VF sampleVolume(const FrameParams &P, VF x, VF y, VF z) {
    if (P.features.cubic) return sampleCubic(P, x, y, z);
    if (P.brickedVoxels) return P.narrowBytes == 1 ? sampleTrilinearBricked<1>(P, x, y, z) : sampleTrilinearBricked<2>(P, x, y, z);
    if (P.narrowBytes == 1) return sampleTrilinearNarrow<1>(P, x, y, z);
    if (P.narrowBytes == 2) return sampleTrilinearNarrow<2>(P, x, y, z);
    return sampleTrilinear(P, x, y, z);
}

// Where a value falls in the transfer-function table: the entry below (×4, its first float)
// and the fraction towards the next.
struct TableSpot {
    VI i4;
    VF f;
};
inline TableSpot tableSpot(const FrameParams &P, VF value) {
    const DF df;
    const DI di;
    const VF x = vcTableCoordinate(value, hn::Set(df, P.tfMin), hn::Set(df, P.tfScale), hn::Set(df, float(P.tfEntries - 1)));
    const VI i = hn::Min(hn::ConvertTo(di, x), hn::Set(di, P.tfEntries - 2));
    return {hn::ShiftLeft<2>(i), hn::Sub(x, hn::ConvertTo(df, i))};
}
// Channel c (r, g, b, sigma) at the spot, linear between table entries.
inline VF tableChannel(const FrameParams &P, const TableSpot &s, int c) {
    const DF df;
    return lerp(hn::GatherIndex(df, P.tf + c, s.i4), hn::GatherIndex(df, P.tf + 4 + c, s.i4), s.f);
}
// Colour and sigma, linear between table entries.
void classify(const FrameParams &P, VF value, VF rgbs[4]) {
    const TableSpot s = tableSpot(P, value);
    for (int c = 0; c < 4; ++c) rgbs[c] = tableChannel(P, s, c);
}

// Fractional node coordinate of value v: the locator gives the node intervals a uniform
// bucket overlaps, a binary search per lane the one holding v (raycast.cl's nodeCoordinate).
VF nodeCoordinate(const FrameParams &P, VF v) {
    const DF df;
    const DI di;
    v = hn::Min(hn::Max(v, hn::Set(df, P.preNodes[0])), hn::Set(df, P.preNodes[P.preNodeCount - 1]));
    VI b = hn::ConvertTo(di, hn::Mul(hn::Sub(v, hn::Set(df, P.preLocatorMin)), hn::Set(df, P.preLocatorScale)));
    b = hn::Min(hn::Max(b, hn::Zero(di)), hn::Set(di, P.preLocatorSize - 1));
    VI i = hn::GatherIndex(di, P.preLocator, b), last = hn::GatherIndex(di, P.preLocator, hn::Add(b, hn::Set(di, 1)));
    for (auto open = hn::Lt(i, last); !hn::AllFalse(di, open); open = hn::Lt(i, last)) {
        const VI m = hn::ShiftRight<1>(hn::Add(hn::Add(i, last), hn::Set(di, 1)));
        const auto above = hn::RebindMask(di, hn::Ge(v, hn::GatherIndex(df, P.preNodes, m)));
        i = hn::IfThenElse(hn::And(open, above), m, i);
        last = hn::IfThenElse(hn::AndNot(above, open), hn::Sub(m, hn::Set(di, 1)), last);
    }
    const VF lo = hn::GatherIndex(df, P.preNodes, i), hi = hn::GatherIndex(df, P.preNodes, hn::Add(i, hn::Set(di, 1)));
    return hn::Add(hn::ConvertTo(df, i), vcNodeFraction(v, lo, hi));
}

// Segment from value sf to sb of a full step: premultiplied colour and opacity, bilinear in
// the table (raycast.cl's preintegratedSegment).
void preintegratedSegment(const FrameParams &P, VF sf, VF sb, VF out[4]) {
    const DF df;
    const DI di;
    const int n = P.preNodeCount;
    const VF x = nodeCoordinate(P, sf), y = nodeCoordinate(P, sb);
    const VI i = hn::Min(hn::ConvertTo(di, x), hn::Set(di, n - 2)), j = hn::Min(hn::ConvertTo(di, y), hn::Set(di, n - 2));
    const VF fx = hn::Sub(x, hn::ConvertTo(df, i)), fy = hn::Sub(y, hn::ConvertTo(df, j));
    const VI c00 = hn::ShiftLeft<2>(hn::Add(hn::Mul(j, hn::Set(di, n)), i)), c01 = hn::Add(c00, hn::Set(di, 4 * n));
    for (int c = 0; c < 4; ++c) {
        const float *t = P.preRgba + c;
        const VF a = lerp(hn::GatherIndex(df, t, c00), hn::GatherIndex(df, t + 4, c00), fx);
        const VF b = lerp(hn::GatherIndex(df, t, c01), hn::GatherIndex(df, t + 4, c01), fx);
        out[c] = lerp(a, b, fy);
    }
}

// The incremental brick walk (DDA) over the 8³ brick grid, per lane: the brick holding the
// point the ray has reached, whether the transfer function leaves it visible, and the t at
// which the ray leaves it across each axis's wall (ray_math.h's vcBrickOf, vcBrickWall,
// vcBrickExit). Moving on costs a comparison per segment and a division per wall crossed,
// instead of recomputing the brick and its exit per segment. A point reached within float
// rounding of a wall may be put in either brick: harmless, as each brick's value range covers
// half a voxel beyond its box (minmax_bricks.hpp, border). The kernel walks one ray with the
// same formulas (raycast.cl's brickWalkTo), cubes included.
//
// Empty regions. An empty brick at chessboard distance r from the nearest visible one
// (FrameParams::brickReach) lies at the centre of a cube of empty bricks `extent` = r − 1 on
// each side, and the walk takes that cube as the brick: its walls are the cube's, so the
// march skips to where the ray leaves it in one step rather than one per brick. Crossing a
// cube's wall moves the brick on that axis past the cube; on the other axes the brick is the
// one holding the point reached, kept inside the cube's slab against rounding. A
// pre-integrated segment is skipped only inside one brick (its ends may read values on either
// side of a visible range in two empty bricks), and the adaptive step's bricks each have
// their own step: for those the extent stays 0, the walk a brick at a time.
//
// With the adaptive step the walk reads the brick's step (FrameParams::brickStep) instead: its
// segment length in `step`, visible where it is positive.
struct BrickWalk {
    VI b[3];
    VI extent;  // bricks each side of b[] that are empty too: the cube the walk crosses at once
    VF wall[3]; // t where the ray leaves the cube across its wall on each axis (inf if parallel)
    MF visible;
    VF step;    // the adaptive step: the brick's segment length

    BrickWalk() : extent(hn::Zero(DI())), visible(hn::FirstN(DF(), 0)), step(hn::Zero(DF())) {
        for (int a = 0; a < 3; ++a) {
            b[a] = hn::Zero(DI());
            wall[a] = hn::Set(DF(), kInf);
        }
    }

    // The wall on axis a of the cube of bricks b ± extent that the ray leaves by: the outer
    // wall of brick b + extent ahead, or b − extent behind.
    VF wallAt(const FrameParams &P, const VF q0[3], const VF dq[3], int a) const {
        const DF df;
        const DI di;
        const VI ahead = hn::IfThenElse(hn::RebindMask(di, hn::Lt(dq[a], hn::Zero(df))), hn::Neg(extent), extent);
        return vcBrickWall(hn::ConvertTo(df, hn::Add(b[a], ahead)), hn::Set(df, float(P.brickSize)), q0[a], dq[a]);
    }
    // Visibility and extent of the lanes' bricks (clamped to the grid: a brick past its edge,
    // reached by rounding or beyond the box, takes the edge brick's; its cube, shifted outward
    // with it, stays inside the edge brick's within the grid).
    void lookUp(const FrameParams &P, MF lanes) {
        const DI di;
        VI c[3];
        for (int a = 0; a < 3; ++a) c[a] = hn::Min(hn::Max(b[a], hn::Zero(di)), hn::Set(di, P.bricks[a] - 1));
        const VI brick =
            hn::Add(hn::Mul(hn::Add(hn::Mul(c[2], hn::Set(di, P.bricks[1])), c[1]), hn::Set(di, P.bricks[0])), c[0]);
        MF now;
        if (P.brickStep) {
            const VF here = hn::GatherIndex(DF(), P.brickStep, brick); // clamped: valid in every lane
            step = hn::IfThenElse(lanes, here, step);
            now = hn::Gt(here, hn::Zero(DF()));
        } else {
            const VI reach = hn::GatherIndex(di, P.brickReach, brick);
            now = hn::RebindMask(DF(), hn::Eq(reach, hn::Zero(di)));
            if (!P.features.preintegrated) {
                const VI e = hn::Max(hn::Sub(reach, hn::Set(di, 1)), hn::Zero(di));
                extent = hn::IfThenElse(hn::RebindMask(di, lanes), e, extent);
            }
        }
        visible = hn::Or(hn::And(lanes, now), hn::AndNot(lanes, visible));
    }
    // The brick of q(t) for the ray entering at t.
    void start(const FrameParams &P, const VF q0[3], const VF dq[3], VF t, MF lanes) {
        const DF df;
        const DI di;
        const VF inverseB = hn::Set(df, 1.0f / float(P.brickSize));
        for (int a = 0; a < 3; ++a) {
            const VF q = hn::MulAdd(t, dq[a], q0[a]);
            b[a] = hn::ConvertTo(di, vcBrickOf(q, inverseB));
            b[a] = hn::Min(hn::Max(b[a], hn::Zero(di)), hn::Set(di, P.bricks[a] - 1));
        }
        visible = hn::FirstN(df, 0);
        extent = hn::Zero(di);
        lookUp(P, lanes);
        for (int a = 0; a < 3; ++a) wall[a] = wallAt(P, q0, dq, a);
    }
    VF exit() const { return vcBrickExit(wall[0], wall[1], wall[2]); }
    // Moves the lanes of `lanes` on to the brick (or cube) holding q(t), t not before where
    // they are. Bricks are crossed one wall at a time with their own walls, and looked up once
    // at the end: where the brick reached is the centre of an empty cube, its walls become
    // the cube's, which lie beyond the brick's, so the ray is still inside.
    void advance(const FrameParams &P, const VF q0[3], const VF dq[3], VF t, MF lanes) {
        const DF df;
        const DI di;
        const VI one = hn::Set(di, 1), zero = hn::Zero(di);
        MF moved = hn::FirstN(df, 0);
        for (;;) {
            const VF first = exit();
            const MF move = hn::And(lanes, hn::Ge(t, first));
            if (hn::AllFalse(df, move)) break;
            moved = hn::Or(moved, move);
            const auto moveI = hn::RebindMask(di, move);
            // Leaving a cube: the bricks on the other axes are those of the point reached.
            const bool leavesCube = !hn::AllFalse(di, hn::And(moveI, hn::Gt(extent, zero)));
            VI along[3];
            if (leavesCube) {
                const VF inverseB = hn::Set(df, 1.0f / float(P.brickSize));
                for (int a = 0; a < 3; ++a) {
                    const VI there = hn::ConvertTo(di, vcBrickOf(hn::MulAdd(first, dq[a], q0[a]), inverseB));
                    along[a] = hn::Min(hn::Max(there, hn::Sub(b[a], extent)), hn::Add(b[a], extent));
                }
            }
            MF done = hn::FirstN(df, 0);
            for (int a = 0; a < 3; ++a) {
                const MF here = hn::AndNot(done, hn::And(move, hn::Eq(wall[a], first)));
                done = hn::Or(done, here);
                const auto hereI = hn::RebindMask(di, here);
                const VI past = hn::Add(extent, one);
                const VI stepA = hn::IfThenElse(hn::RebindMask(di, hn::Gt(dq[a], hn::Zero(df))), past, hn::Neg(past));
                b[a] = hn::IfThenElse(hereI, hn::Add(b[a], stepA), b[a]);
                if (leavesCube) b[a] = hn::IfThenElse(hn::AndNot(hereI, moveI), along[a], b[a]);
                if (!leavesCube) wall[a] = hn::IfThenElse(here, wallAt(P, q0, dq, a), wall[a]);
            }
            if (leavesCube) {
                // The new bricks alone until they are looked up: all three walls move.
                extent = hn::IfThenElse(moveI, zero, extent);
                for (int a = 0; a < 3; ++a) wall[a] = hn::IfThenElse(move, wallAt(P, q0, dq, a), wall[a]);
            }
        }
        if (hn::AllFalse(df, moved)) return;
        lookUp(P, moved);
        const MF cube = hn::And(moved, hn::RebindMask(df, hn::Gt(extent, zero)));
        if (!hn::AllFalse(df, cube))
            for (int a = 0; a < 3; ++a) wall[a] = hn::IfThenElse(cube, wallAt(P, q0, dq, a), wall[a]);
    }
};

// Kahan sum += x in the lanes of `m` (ray_math.h); the optical depth's (`depth`) keeps a zero
// carry once infinite.
inline void addCompensated(MF m, VF &sum, VF &carry, VF x, bool depth) {
    VF t = sum, c = carry;
    if (depth) vcAddCompensatedDepth(&t, &c, x);
    else vcAddCompensated(&t, &c, x);
    carry = hn::IfThenElse(m, c, carry);
    sum = hn::IfThenElse(m, t, sum);
}

// Headlight Phong (ray_math.h's vcPhong) on the gradient by central differences, one level
// voxel apart, taken into world space: diffuse factor, specular term.
void phong(const FrameParams &P, const VF q[3], const VF dir[3], VF &diffuse, VF &specular) {
    const DF df;
    const VF one = hn::Set(df, 1.0f);
    VF g[3];
    for (int a = 0; a < 3; ++a) {
        VF plus[3] = {q[0], q[1], q[2]}, minus[3] = {q[0], q[1], q[2]};
        plus[a] = hn::Add(q[a], one);
        minus[a] = hn::Sub(q[a], one);
        g[a] = hn::Sub(sampleVolume(P, plus[0], plus[1], plus[2]), sampleVolume(P, minus[0], minus[1], minus[2]));
    }
    VF w[3];
    for (int c = 0; c < 3; ++c)
        w[c] = vcWorldGradient(g[0], g[1], g[2], hn::Set(df, P.indexFromWorld[0][c]), hn::Set(df, P.indexFromWorld[1][c]),
                               hn::Set(df, P.indexFromWorld[2][c]));
    vcPhong(w[0], w[1], w[2], dir[0], dir[1], dir[2], &diffuse, &specular);
}

// Intensity projection of one packet (raycast.cl's COMPOSITING_MAX / _MIN): the extreme of the
// values at the segments' centres, the same segments emission–absorption samples, mapped
// through the transfer function as premultiplied colour and its opacity a(v). No skipping
// or early termination: compositedQuality turns them off.
void projectPacket(const FrameParams &P, VF t0, VF t1, VF j, const VF q0[3], const VF dq[3], MF alive,
                   float out[4][kMaxLanes], int32_t samplesOut[kMaxLanes], uint64_t &truncatedTotal) {
    const DF df;
    const DI di;
    const VF zero = hn::Zero(df), one = hn::Set(df, 1.0f), d = hn::Set(df, P.step);
    const bool maximum = P.features.intensityProjection > 0;
    VF k = hn::IfThenElse(hn::Gt(j, zero), zero, one);
    VF segStart = t0;
    VF extreme = zero;
    MF found = hn::FirstN(df, 0);
    VI samples = hn::Zero(di);
    while (!hn::AllFalse(df, alive)) {
        const VF boundary = hn::MulAdd(hn::Add(k, j), d, t0);
        const VF segEnd = hn::Min(boundary, t1);
        const VF len = hn::Sub(segEnd, segStart);
        MF take = hn::And(alive, hn::Gt(len, zero));
        if (!P.features.boundarySegment) take = hn::AndNot(hn::Or(hn::Gt(boundary, t1), hn::Eq(k, zero)), take);
        if (!hn::AllFalse(df, take)) {
            const MF truncated = hn::AndNot(hn::RebindMask(df, hn::Lt(samples, hn::Set(di, P.maxSamples))), take);
            if (!hn::AllFalse(df, truncated)) {
                truncatedTotal += hn::CountTrue(df, truncated);
                alive = hn::AndNot(truncated, alive);
                take = hn::AndNot(truncated, take);
            }
            samples = hn::Add(samples, hn::IfThenElseZero(hn::RebindMask(di, take), hn::Set(di, 1)));
            const VF tMid = hn::MulAdd(hn::Set(df, 0.5f), len, segStart);
            const VF v = sampleVolume(P, hn::MulAdd(tMid, dq[0], q0[0]), hn::MulAdd(tMid, dq[1], q0[1]),
                                      hn::MulAdd(tMid, dq[2], q0[2]));
            const VF better = maximum ? hn::Max(extreme, v) : hn::Min(extreme, v);
            extreme = hn::IfThenElse(take, hn::IfThenElse(found, better, v), extreme);
            found = hn::Or(found, take);
        }
        alive = hn::AndNot(hn::Ge(boundary, t1), alive);
        segStart = hn::IfThenElse(alive, segEnd, segStart);
        k = hn::IfThenElse(alive, hn::Add(k, one), k);
    }
    VF c[4];
    classify(P, extreme, c);
    const VF a = hn::IfThenElseZero(found, vcOpacityFromDepth(c[3])); // the table holds sigma = −ln(1 − a)
    for (int ch = 0; ch < 3; ++ch) hn::Store(hn::Mul(a, c[ch]), df, out[ch]);
    hn::Store(a, df, out[3]);
    hn::Store(samples, di, samplesOut);
}

// One packet's march: its rays and where each lane has got to.
struct PacketMarch {
    VF t0, t1, j, q0[3], dq[3], dir[3];
    VF k, segStart;
    VF lastFull; // the last full segment k that ends before t1, one fewer for rounding
    BrickWalk walk;
    MF alive, sfStale;
    MF refreshOwed; // a transmittance refresh fell on a segment that added nothing
    VF depth, depthCarry, T, color[3], colorCarry[3], sf;
    VI samples;
    HWY_ALIGN int32_t hita[kMaxLanes];
    int px[kMaxLanes], py[kMaxLanes];
    int hits = 0;
};

struct MarchTotals {
    uint64_t samples = 0, hit = 0, terminated = 0, truncated = 0, skipped = 0;
};

// What one packet's current step has found so far, phase by phase (marchStep).
struct StepState {
    VF boundary, segEnd, len, tMid, jumpTo, value, segDepth, alpha, segColor[3], weight, q[3];
    MF take, partial, skipped;
    MF adds; // taken segments that add to the pixel (all of them, but sampled ones of depth 0)
    TableSpot spot;
    bool any = false, anySkipped = false, anyAdds = false;
};

// What both marches (marchStep, marchSampled) do to a step's lanes the same way.

// Takes a sample in the lanes of `take` that have samples left; the others stop, truncated.
HWY_INLINE void countSample(const FrameParams &P, MF &take, MF &alive, VI &samples, MarchTotals &totals) {
    const DF df;
    const DI di;
    const MF truncated = hn::AndNot(hn::RebindMask(df, hn::Lt(samples, hn::Set(di, P.maxSamples))), take);
    if (!hn::AllFalse(df, truncated)) {
        totals.truncated += hn::CountTrue(df, truncated);
        alive = hn::AndNot(truncated, alive);
        take = hn::AndNot(truncated, take);
    }
    samples = hn::Add(samples, hn::IfThenElseZero(hn::RebindMask(di, take), hn::Set(di, 1)));
}

// Where the transmittance is made exact this step: every VC_EXACT_TRANSMITTANCE_EVERY samples
// (counted with this one), and a refresh due on a segment that adds nothing is made at the
// lane's next segment that adds (refreshOwed).
HWY_INLINE MF exactTransmittance(MF take, MF adds, VI samples, MF &refreshOwed) {
    const DF df;
    const DI di;
    const VI refresh = hn::And(samples, hn::Set(di, int32_t(VC_EXACT_TRANSMITTANCE_EVERY - 1)));
    const MF due = hn::Or(refreshOwed, hn::And(take, hn::RebindMask(df, hn::Eq(refresh, hn::Zero(di)))));
    refreshOwed = hn::AndNot(adds, due);
    return hn::And(adds, due);
}

// Front to back (Eq. 2) in the lanes of `adds`: colour += T·weight·segColor and depth +=
// segDepth, compensated, and T behind the segment (vcNextTransmittance).
HWY_INLINE void composite(MF adds, MF exact, VF weight, const VF segColor[3], VF alpha, VF segDepth, VF &T,
                          VF color[3], VF colorCarry[3], VF &depth, VF &depthCarry) {
    const VF tw = hn::Mul(T, weight);
    for (int a = 0; a < 3; ++a) addCompensated(adds, color[a], colorCarry[a], hn::Mul(tw, segColor[a]), false);
    addCompensated(adds, depth, depthCarry, segDepth, true);
    T = hn::IfThenElse(adds, vcNextTransmittance(T, alpha, depth, depthCarry, exact), T);
}

// The last segment a skipped lane passes at once: the last full segment k' whose deciding
// point (t0 + (k' + j − decide)·d: ½ for a sampled segment's centre, 0 for a pre-integrated
// one's end) is before the empty region's exit, one fewer for rounding, and ending before t1.
HWY_INLINE VF lastSkipped(const PacketMarch &m, VF exit, VF d, float decide, MF skipped) {
    const DF df;
    const VF byExit = hn::Sub(
        hn::Floor(hn::Add(hn::Sub(hn::Div(hn::Sub(exit, m.t0), d), m.j), hn::Set(df, decide))), hn::Set(df, 1.0f));
    return hn::IfThenElse(skipped, hn::Min(byExit, m.lastFull), hn::Zero(df));
}

// Segments k … jumpTo of the skipped lanes still alive are passed (k already moved on by one);
// the next to look at is jumpTo + 1. Counts every skipped segment.
HWY_INLINE void passSkipped(const PacketMarch &m, VF d, VF jumpTo, MF skipped, MF alive, VF &k, VF &segStart,
                            MarchTotals &totals) {
    const DF df;
    const DI di;
    const VF one = hn::Set(df, 1.0f);
    const MF jump = hn::And(alive, hn::Ge(jumpTo, k));
    // Whole numbers below 2^24 (a ray's segments are bounded by maxSamples): exact in float
    // and in their int32 sum.
    const VF count = hn::IfThenElse(jump, hn::Add(hn::Sub(jumpTo, k), hn::Set(df, 2.0f)), hn::IfThenElseZero(skipped, one));
    totals.skipped += uint64_t(hn::GetLane(hn::SumOfLanes(di, hn::ConvertTo(di, count))));
    segStart = hn::IfThenElse(jump, hn::MulAdd(hn::Add(jumpTo, m.j), d, m.t0), segStart);
    k = hn::IfThenElse(jump, hn::Add(jumpTo, one), k);
}

// A pre-integrated segment's contribution: the segment from the table for a full step; a
// partial one scales the depth by len/step (Eq. 3) and the colour with its opacity, unless
// the full step's alpha is too close to 1 to hold its depth: then it is classified at its
// centre (ray_math.h's VC_ALPHA_HOLDS_DEPTH). The front value is sampled afresh after skips.
HWY_INLINE void preintegratedContribution(const FrameParams &P, PacketMarch &m, StepState &s) {
    const DF df;
    const VF d = hn::Set(df, P.step);
    const MF fresh = hn::And(s.take, m.sfStale);
    if (!hn::AllFalse(df, fresh)) {
        m.sf = hn::IfThenElse(fresh, sampleVolume(P, hn::MulAdd(m.segStart, m.dq[0], m.q0[0]),
                                                  hn::MulAdd(m.segStart, m.dq[1], m.q0[1]),
                                                  hn::MulAdd(m.segStart, m.dq[2], m.q0[2])),
                              m.sf);
        m.sfStale = hn::AndNot(fresh, m.sfStale);
    }
    const VF sb = sampleVolume(P, hn::MulAdd(s.segEnd, m.dq[0], m.q0[0]), hn::MulAdd(s.segEnd, m.dq[1], m.q0[1]),
                               hn::MulAdd(s.segEnd, m.dq[2], m.q0[2]));
    VF seg[4];
    preintegratedSegment(P, m.sf, sb, seg);
    m.sf = hn::IfThenElse(s.take, sb, m.sf);
    s.segDepth = vcDepthFromOpacity(seg[3]); // +inf behind opaque material: T becomes 0
    s.alpha = seg[3];
    for (int a = 0; a < 3; ++a) s.segColor[a] = seg[a];
    // With the adaptive step every segment is scaled from the table's (the longest) step.
    const MF partialHere = P.features.adaptiveStep ? s.take : hn::And(s.take, s.partial);
    if (!hn::AllFalse(df, partialHere)) {
        const VF fraction = hn::Div(s.len, d);
        const MF holds = hn::And(partialHere, hn::Le(seg[3], hn::Set(df, VC_ALPHA_HOLDS_DEPTH)));
        const VF scaledDepth = hn::Mul(s.segDepth, fraction);
        const VF scaledAlpha = vcOpacityFromDepth(hn::IfThenZeroElse(hn::Not(holds), scaledDepth));
        const VF colourScale = vcPartialColourScale(seg[3], scaledAlpha, fraction);
        VF c[4];
        classify(P, sampleVolume(P, s.q[0], s.q[1], s.q[2]), c);
        const VF centreDepth = vcSegmentDepth(c[3], s.len, hn::Set(df, P.opacityUnit));
        const MF centre = hn::AndNot(holds, partialHere);
        const VF centreAlpha = vcOpacityFromDepth(hn::IfThenZeroElse(hn::Not(centre), centreDepth));
        s.segDepth = hn::IfThenElse(holds, scaledDepth, hn::IfThenElse(centre, centreDepth, s.segDepth));
        s.alpha = hn::IfThenElse(holds, scaledAlpha, hn::IfThenElse(centre, centreAlpha, s.alpha));
        for (int a = 0; a < 3; ++a)
            s.segColor[a] = hn::IfThenElse(holds, hn::Mul(s.segColor[a], colourScale),
                                           hn::IfThenElse(centre, hn::Mul(centreAlpha, c[a]), s.segColor[a]));
    }
    if (P.features.shading) {
        // Light the premultiplied colour; the highlight is weighted by the opacity.
        VF diffuse, specular;
        phong(P, s.q, m.dir, diffuse, specular);
        for (int a = 0; a < 3; ++a) s.segColor[a] = vcShadePremultiplied(s.segColor[a], s.alpha, diffuse, specular);
    }
}

// The adaptive step's segment bounds (adaptive_step.hpp), in place of the uniform lattice
// t0 + (k + j)·d: a segment starts where the last ended and is as long as the step of the
// brick it starts in (the first, k = 0, j times that under jitter), cut at t1. A lane whose
// brick is skipped takes nothing and starts again at the brick's exit (marchStep's last
// phase): the part of the ray inside a transparent brick adds exactly nothing.
template <int N>
HWY_INLINE void adaptiveSegments(const FrameParams &P, PacketMarch *ms, StepState *st) {
    const DF df;
    const VF zero = hn::Zero(df), half = hn::Set(df, 0.5f);
    for (int p = 0; p < N; ++p) ms[p].walk.advance(P, ms[p].q0, ms[p].dq, ms[p].segStart, ms[p].alive);
    for (int p = 0; p < N; ++p) {
        PacketMarch &m = ms[p];
        StepState &s = st[p];
        const MF first = hn::Eq(m.k, zero);
        const VF nominal = hn::IfThenElse(first, hn::Mul(m.j, m.walk.step), m.walk.step);
        s.skipped = hn::AndNot(m.walk.visible, m.alive);
        s.anySkipped = !hn::AllFalse(df, s.skipped);
        s.boundary = hn::IfThenElse(s.skipped, m.segStart, hn::Add(m.segStart, nominal));
        s.segEnd = hn::Min(s.boundary, m.t1);
        s.len = hn::Sub(s.segEnd, m.segStart);
        s.tMid = hn::MulAdd(half, s.len, m.segStart);
        s.take = hn::AndNot(s.skipped, hn::And(m.alive, hn::Gt(s.len, zero)));
        s.partial = hn::Or(hn::Gt(s.boundary, m.t1), first);
        if (!P.features.boundarySegment) s.take = hn::AndNot(s.partial, s.take);
        s.jumpTo = zero;
    }
}

// One segment further in every lane still marching, for N packets side by side. Each phase
// (the segment's bounds and skipping, the sample, its classification, the opacity, the sums)
// is done for every packet before the next phase starts: the packets' chains are
// independent, so the core works on one while the other waits on its gathers. One packet's
// step is a chain of dependent gathers and arithmetic a few hundred instructions long; two
// packets stepped one after the other did not overlap (docs/cpu_renderer.md).
template <int N>
HWY_INLINE void marchStep(const FrameParams &P, PacketMarch *ms, MarchTotals &totals) {
    const DF df;
    const Features &F = P.features;
    const VF zero = hn::Zero(df), one = hn::Set(df, 1.0f), d = hn::Set(df, P.step), half = hn::Set(df, 0.5f);
    StepState st[N];

    if (F.adaptiveStep) {
        adaptiveSegments<N>(P, ms, st);
    } else
    for (int p = 0; p < N; ++p) {
        PacketMarch &m = ms[p];
        StepState &s = st[p];
        s.boundary = hn::MulAdd(hn::Add(m.k, m.j), d, m.t0);
        s.segEnd = hn::Min(s.boundary, m.t1);
        s.len = hn::Sub(s.segEnd, m.segStart);
        s.tMid = hn::MulAdd(half, s.len, m.segStart);
        s.take = hn::And(m.alive, hn::Gt(s.len, zero));
        // A partial segment: the first one under jitter, or the last at the exit.
        s.partial = hn::Or(hn::Gt(s.boundary, m.t1), hn::Eq(m.k, zero));
        if (!F.boundarySegment) s.take = hn::AndNot(s.partial, s.take);
        s.skipped = hn::FirstN(df, 0);
        s.jumpTo = zero; // last segment, from k, that lies in the empty brick too
        s.anySkipped = false;
    }
    // Empty-space skipping by sample position: a segment is not taken when the point that
    // decides it lies in a brick the transfer function makes empty. A sampled segment is
    // decided by its sample (its centre): there it would classify to opacity 0 and add
    // nothing. A pre-integrated one reads the values at both ends and everything between, so
    // it is skipped only when the whole segment lies in the empty brick (both ends before the
    // brick's exit).
    if (F.emptySpaceSkipping && !F.adaptiveStep) {
        for (int p = 0; p < N; ++p)
            ms[p].walk.advance(P, ms[p].q0, ms[p].dq, F.preintegrated ? ms[p].segStart : st[p].tMid, st[p].take);
        for (int p = 0; p < N; ++p) {
            PacketMarch &m = ms[p];
            StepState &s = st[p];
            const VF exit = m.walk.exit();
            s.skipped = hn::AndNot(m.walk.visible, s.take);
            if (F.preintegrated) s.skipped = hn::And(s.skipped, hn::Le(s.segEnd, exit));
            s.anySkipped = !hn::AllFalse(df, s.skipped);
            if (!s.anySkipped) continue;
            s.take = hn::AndNot(s.skipped, s.take);
            m.sfStale = hn::Or(m.sfStale, s.skipped);
            // Later segments in the empty region: skipped at once instead of one per iteration.
            s.jumpTo = lastSkipped(m, exit, d, F.preintegrated ? 0.0f : 0.5f, s.skipped);
        }
    }
    for (int p = 0; p < N; ++p) {
        PacketMarch &m = ms[p];
        StepState &s = st[p];
        s.any = !hn::AllFalse(df, s.take);
        if (!s.any) continue;
        countSample(P, s.take, m.alive, m.samples, totals);
        for (int a = 0; a < 3; ++a) s.q[a] = hn::MulAdd(s.tMid, m.dq[a], m.q0[a]);
        s.weight = one;
    }
    // Contribution T·weight·segColor: weight is alpha for a sampled segment (the kernel's
    // T·alpha·rgb, in its order), 1 for a premultiplied one.
    if (F.preintegrated) {
        for (int p = 0; p < N; ++p)
            if (st[p].any) {
                preintegratedContribution(P, ms[p], st[p]);
                st[p].adds = st[p].take;
                st[p].anyAdds = true;
            }
    } else {
        // Sample the segment at its centre and classify: sigma first, corrected for the
        // segment's length (Eq. 3: depth sigma·len/u, opacity 1 − exp(−depth)). A segment of
        // depth 0 has opacity 0 and adds nothing (T·0·colour = +0, depth + 0, T·1): it is not
        // composited, so the colour, the opacity and the sums are made only where some lane's
        // depth is positive.
        for (int p = 0; p < N; ++p)
            if (st[p].any) st[p].value = sampleVolume(P, st[p].q[0], st[p].q[1], st[p].q[2]);
        for (int p = 0; p < N; ++p)
            if (st[p].any) {
                st[p].spot = tableSpot(P, st[p].value);
                st[p].segDepth = tableChannel(P, st[p].spot, 3); // sigma, for now
            }
        for (int p = 0; p < N; ++p) {
            StepState &s = st[p];
            if (!s.any) continue;
            s.segDepth = vcSegmentDepth(s.segDepth, s.len, hn::Set(df, P.opacityUnit));
            s.adds = hn::And(s.take, hn::Gt(s.segDepth, zero));
            s.anyAdds = !hn::AllFalse(df, s.adds);
            if (s.anyAdds)
                for (int a = 0; a < 3; ++a) s.segColor[a] = tableChannel(P, s.spot, a);
        }
        for (int p = 0; p < N; ++p)
            if (st[p].anyAdds) st[p].alpha = vcOpacityFromDepth(st[p].segDepth);
        for (int p = 0; p < N; ++p) {
            StepState &s = st[p];
            if (!s.anyAdds) continue;
            if (F.shading) {
                const MF lit = hn::And(s.take, hn::Gt(s.alpha, zero));
                if (!hn::AllFalse(df, lit)) {
                    VF diffuse, specular;
                    phong(P, s.q, ms[p].dir, diffuse, specular);
                    for (int a = 0; a < 3; ++a)
                        s.segColor[a] = hn::IfThenElse(lit, vcShade(s.segColor[a], diffuse, specular), s.segColor[a]);
                }
            }
            s.weight = s.alpha;
        }
    }
    for (int p = 0; p < N; ++p) {
        PacketMarch &m = ms[p];
        StepState &s = st[p];
        if (!s.any) continue;
        const MF exact = exactTransmittance(s.take, s.adds, m.samples, m.refreshOwed);
        if (s.anyAdds)
            composite(s.adds, exact, s.weight, s.segColor, s.alpha, s.segDepth, m.T, m.color, m.colorCarry, m.depth,
                      m.depthCarry);
        if (F.earlyTermination) {
            const MF stop = hn::And(s.take, hn::Ge(m.depth, hn::Set(df, P.terminationDepth)));
            if (!hn::AllFalse(df, stop)) {
                totals.terminated += hn::CountTrue(df, stop);
                m.alive = hn::AndNot(stop, m.alive);
            }
        }
    }
    for (int p = 0; p < N; ++p) {
        PacketMarch &m = ms[p];
        StepState &s = st[p];
        m.alive = hn::AndNot(hn::Ge(s.boundary, m.t1), m.alive);
        m.segStart = hn::IfThenElse(m.alive, s.segEnd, m.segStart);
        m.k = hn::IfThenElse(m.alive, hn::Add(m.k, one), m.k);
        if (F.adaptiveStep) {
            if (s.anySkipped) {
                // A skipped lane starts again at its brick's exit, its first segment there
                // jittered again (k = 0) so that segments do not line up on the brick's wall.
                const VF exit = m.walk.exit();
                totals.skipped += hn::CountTrue(df, s.skipped);
                m.alive = hn::AndNot(hn::And(s.skipped, hn::Ge(exit, m.t1)), m.alive);
                const MF restart = hn::And(s.skipped, m.alive);
                m.segStart = hn::IfThenElse(restart, exit, m.segStart);
                m.k = hn::IfThenElse(restart, hn::IfThenElse(hn::Gt(m.j, zero), zero, one), m.k);
                if (F.preintegrated) m.sfStale = hn::Or(m.sfStale, restart);
            }
            continue;
        }
        if (F.emptySpaceSkipping && s.anySkipped) passSkipped(m, d, s.jumpTo, s.skipped, m.alive, m.k, m.segStart, totals);
    }
}

// The empty cube around the brick holding level point q, for the lanes' points (clamped to
// the grid as BrickWalk::lookUp clamps): its brick, and its reach (FrameParams::brickReach),
// 0 where the brick is visible.
struct CubeAt {
    VI b[3];
    VI reach;
};
HWY_INLINE CubeAt cubeAt(const FrameParams &P, const VF q[3]) {
    const DF df;
    const DI di;
    const VF inverseB = hn::Set(df, 1.0f / float(P.brickSize));
    CubeAt c;
    for (int a = 0; a < 3; ++a) {
        c.b[a] = hn::ConvertTo(di, vcBrickOf(q[a], inverseB));
        c.b[a] = hn::Min(hn::Max(c.b[a], hn::Zero(di)), hn::Set(di, P.bricks[a] - 1));
    }
    const VI brick = hn::Add(
        hn::Mul(hn::Add(hn::Mul(c.b[2], hn::Set(di, P.bricks[1])), c.b[1]), hn::Set(di, P.bricks[0])), c.b[0]);
    c.reach = hn::GatherIndex(di, P.brickReach, brick);
    return c;
}
// t where the ray leaves the cube of empty bricks b ± (reach − 1): BrickWalk's walls of it.
HWY_INLINE VF cubeExit(const FrameParams &P, const CubeAt &c, const VF q0[3], const VF dq[3]) {
    const DF df;
    const DI di;
    const VI extent = hn::Max(hn::Sub(c.reach, hn::Set(di, 1)), hn::Zero(di));
    VF wall[3];
    for (int a = 0; a < 3; ++a) {
        const VI ahead = hn::IfThenElse(hn::RebindMask(di, hn::Lt(dq[a], hn::Zero(df))), hn::Neg(extent), extent);
        wall[a] = vcBrickWall(hn::ConvertTo(df, hn::Add(c.b[a], ahead)), hn::Set(df, float(P.brickSize)), q0[a], dq[a]);
    }
    return vcBrickExit(wall[0], wall[1], wall[2]);
}

// What a packet carries from one sampled segment to the next: the march's running values,
// held in registers for the whole march rather than in PacketMarch.
struct SampledLanes {
    VF k, segStart, T, depth, depthCarry, color[3], colorCarry[3];
    VI samples;
    MF alive, refreshOwed;
};

// The march of N packets side by side to their end, for frames whose segments are all sampled
// at their centres (no pre-integration, no adaptive step): marchStep's segments, skips, sums
// and refreshes in the same order, compiled for the frame's switches only.
// Two things differ from marchStep, measured on Table 1's cells (docs/cpu_renderer.md, "The
// sampled march"): the running values stay in registers, and empty space is found by looking
// up the brick of each segment's centre, then, where it is empty, its cube's exit (cubeAt,
// cubeExit), rather than by carrying a brick walk from segment to segment. The brick found is
// the walk's but for a centre within rounding of a wall, where either brick is right
// (BrickWalk): the image is marchStep's up to float rounding.
template <int N, bool Skipping, bool Shading>
HWY_NOINLINE void marchSampled(const FrameParams &P, PacketMarch *ms, MarchTotals &totals) {
    const DF df;
    const DI di;
    const VF zero = hn::Zero(df), one = hn::Set(df, 1.0f), d = hn::Set(df, P.step), half = hn::Set(df, 0.5f);
    const VF unit = hn::Set(df, P.opacityUnit), stopDepth = hn::Set(df, P.terminationDepth);
    const bool boundarySegment = P.features.boundarySegment, earlyTermination = P.features.earlyTermination;
    SampledLanes L[N];
    for (int p = 0; p < N; ++p) {
        const PacketMarch &m = ms[p];
        SampledLanes &l = L[p];
        l.k = m.k;
        l.segStart = m.segStart;
        l.T = m.T;
        l.depth = m.depth;
        l.depthCarry = m.depthCarry;
        for (int a = 0; a < 3; ++a) {
            l.color[a] = m.color[a];
            l.colorCarry[a] = m.colorCarry[a];
        }
        l.samples = m.samples;
        l.alive = m.alive;
        l.refreshOwed = m.refreshOwed;
    }
    for (;;) {
        bool anyAlive = false;
        for (int p = 0; p < N; ++p) anyAlive = anyAlive || !hn::AllFalse(df, L[p].alive);
        if (!anyAlive) break;
        // The segment's bounds and centre.
        VF boundary[N], segEnd[N], len[N], q[N][3], jumpTo[N];
        MF take[N], skipped[N];
        bool any[N], anySkipped[N];
        for (int p = 0; p < N; ++p) {
            const PacketMarch &m = ms[p];
            const SampledLanes &l = L[p];
            boundary[p] = hn::MulAdd(hn::Add(l.k, m.j), d, m.t0);
            segEnd[p] = hn::Min(boundary[p], m.t1);
            len[p] = hn::Sub(segEnd[p], l.segStart);
            const VF tMid = hn::MulAdd(half, len[p], l.segStart);
            take[p] = hn::And(l.alive, hn::Gt(len[p], zero));
            if (!boundarySegment) take[p] = hn::AndNot(hn::Or(hn::Gt(boundary[p], m.t1), hn::Eq(l.k, zero)), take[p]);
            for (int a = 0; a < 3; ++a) q[p][a] = hn::MulAdd(tMid, m.dq[a], m.q0[a]);
            skipped[p] = hn::FirstN(df, 0);
            jumpTo[p] = zero;
            anySkipped[p] = false;
        }
        // Skipping by the centre's brick, and the later segments whose centre is in its cube.
        if constexpr (Skipping) {
            CubeAt cube[N];
            for (int p = 0; p < N; ++p) cube[p] = cubeAt(P, q[p]);
            for (int p = 0; p < N; ++p) {
                const PacketMarch &m = ms[p];
                skipped[p] = hn::AndNot(hn::RebindMask(df, hn::Eq(cube[p].reach, hn::Zero(di))), take[p]);
                anySkipped[p] = !hn::AllFalse(df, skipped[p]);
                if (!anySkipped[p]) continue;
                take[p] = hn::AndNot(skipped[p], take[p]);
                jumpTo[p] = lastSkipped(m, cubeExit(P, cube[p], m.q0, m.dq), d, 0.5f, skipped[p]);
            }
        }
        // The sample.
        VF value[N];
        for (int p = 0; p < N; ++p) {
            SampledLanes &l = L[p];
            any[p] = !hn::AllFalse(df, take[p]);
            if (!any[p]) continue;
            countSample(P, take[p], l.alive, l.samples, totals);
            value[p] = sampleVolume(P, q[p][0], q[p][1], q[p][2]);
        }
        // Its depth, and which lanes it adds to (marchStep's rule).
        TableSpot spot[N];
        VF segDepth[N];
        MF adds[N], exact[N];
        bool anyAdds[N];
        for (int p = 0; p < N; ++p) {
            anyAdds[p] = false;
            if (!any[p]) continue;
            SampledLanes &l = L[p];
            spot[p] = tableSpot(P, value[p]);
            segDepth[p] = vcSegmentDepth(tableChannel(P, spot[p], 3), len[p], unit);
            adds[p] = hn::And(take[p], hn::Gt(segDepth[p], zero));
            anyAdds[p] = !hn::AllFalse(df, adds[p]);
            exact[p] = exactTransmittance(take[p], adds[p], l.samples, l.refreshOwed);
        }
        // Colour, opacity and the sums where it adds.
        for (int p = 0; p < N; ++p) {
            if (!anyAdds[p]) continue;
            SampledLanes &l = L[p];
            VF segColor[3];
            for (int a = 0; a < 3; ++a) segColor[a] = tableChannel(P, spot[p], a);
            const VF alpha = vcOpacityFromDepth(segDepth[p]);
            if constexpr (Shading) {
                const MF lit = hn::And(take[p], hn::Gt(alpha, zero));
                if (!hn::AllFalse(df, lit)) {
                    VF diffuse, specular;
                    phong(P, q[p], ms[p].dir, diffuse, specular);
                    for (int a = 0; a < 3; ++a)
                        segColor[a] = hn::IfThenElse(lit, vcShade(segColor[a], diffuse, specular), segColor[a]);
                }
            }
            // weight = alpha: the kernel's T·alpha·rgb, in its order.
            composite(adds[p], exact[p], alpha, segColor, alpha, segDepth[p], l.T, l.color, l.colorCarry, l.depth,
                      l.depthCarry);
        }
        // Early termination, and on to the next segment (past the skipped ones).
        for (int p = 0; p < N; ++p) {
            const PacketMarch &m = ms[p];
            SampledLanes &l = L[p];
            if (any[p] && earlyTermination) {
                const MF stop = hn::And(take[p], hn::Ge(l.depth, stopDepth));
                if (!hn::AllFalse(df, stop)) {
                    totals.terminated += hn::CountTrue(df, stop);
                    l.alive = hn::AndNot(stop, l.alive);
                }
            }
            l.alive = hn::AndNot(hn::Ge(boundary[p], m.t1), l.alive);
            l.segStart = hn::IfThenElse(l.alive, segEnd[p], l.segStart);
            l.k = hn::IfThenElse(l.alive, hn::Add(l.k, one), l.k);
            if (anySkipped[p]) passSkipped(m, d, jumpTo[p], skipped[p], l.alive, l.k, l.segStart, totals);
        }
    }
    // What MarchTile writes to the pixels: the sums and the samples (every lane has stopped).
    for (int p = 0; p < N; ++p) {
        PacketMarch &m = ms[p];
        m.alive = L[p].alive;
        m.depth = hn::Sub(L[p].depth, L[p].depthCarry);
        m.depthCarry = hn::Zero(df);
        for (int a = 0; a < 3; ++a) {
            m.color[a] = hn::Sub(L[p].color[a], L[p].colorCarry[a]);
            m.colorCarry[a] = hn::Zero(df);
        }
        m.samples = L[p].samples;
    }
}

// Sets up the packet of the lanes' block at (bx, by): rays, cleared pixels for the lanes
// that miss, and the march's start; false when no lane hits (nothing to march).
HWY_INLINE bool startPacket(const FrameParams &P, int bx, int by, int x1, int y1, const int32_t *laneX,
                            const int32_t *laneY, float *rgba, PacketMarch &m) {
    const DF df;
    const DI di;
    const int lanes = int(hn::Lanes(df));
    const Features &F = P.features;
    const VF zero = hn::Zero(df), one = hn::Set(df, 1.0f);
    const VI xi = hn::Add(hn::Load(di, laneX), hn::Set(di, bx)), yi = hn::Add(hn::Load(di, laneY), hn::Set(di, by));
    const MF inside = hn::RebindMask(df, hn::And(hn::Lt(xi, hn::Set(di, x1)), hn::Lt(yi, hn::Set(di, y1))));
    const PacketRays rays = setUpPacket(P, hn::ConvertTo(df, xi), hn::ConvertTo(df, yi), inside);
    hn::Store(hn::IfThenElseZero(hn::RebindMask(di, rays.hit), hn::Set(di, 1)), di, m.hita);
    HWY_ALIGN float ja[kMaxLanes];
    m.hits = 0;
    for (int l = 0; l < lanes; ++l) {
        const int x = bx + laneX[l], y = by + laneY[l];
        m.px[l] = x;
        m.py[l] = y;
        if (x < x1 && y < y1 && !m.hita[l])
            std::fill_n(rgba + (size_t(y - P.outY) * size_t(P.outWidth) + size_t(x - P.outX)) * 4, 4, 0.0f);
        m.hits += m.hita[l];
        ja[l] = m.hita[l] && F.jitter ? vcRandom01(uint32_t(x), uint32_t(y), P.seed, P.pass) : 0.0f;
    }
    if (m.hits == 0) return false;
    m.t0 = rays.t0;
    m.t1 = rays.t1;
    m.j = hn::Load(df, ja);
    for (int a = 0; a < 3; ++a) {
        m.q0[a] = rays.q0[a];
        m.dq[a] = rays.dq[a];
        m.dir[a] = F.shading ? rays.dir[a] : zero;
    }
    m.alive = rays.hit;
    m.k = hn::IfThenElse(hn::Gt(m.j, zero), zero, one); // the first boundary past t0
    // The last full segment before t1, one fewer for rounding: where a jump over empty space
    // stops at the latest.
    m.lastFull = hn::Sub(hn::Floor(hn::Sub(hn::Div(hn::Sub(m.t1, m.t0), hn::Set(df, P.step)), m.j)), one);
    m.segStart = m.t0;
    // The brick walk of marchStep's segments (marchSampled looks bricks up where it samples).
    if (F.intensityProjection == 0 && (F.adaptiveStep || (F.emptySpaceSkipping && F.preintegrated)))
        m.walk.start(P, m.q0, m.dq, m.t0, m.alive);
    m.sfStale = hn::Not(m.alive); // pre-integration: sf must be sampled at segStart first
    m.refreshOwed = hn::FirstN(df, 0);
    m.depth = m.depthCarry = zero;
    m.T = one;
    for (int a = 0; a < 3; ++a) m.color[a] = m.colorCarry[a] = zero;
    m.samples = hn::Zero(di);
    m.sf = zero; // pre-integration: the value at the segment's front
    if (F.preintegrated && F.intensityProjection == 0)
        m.sf = sampleVolume(P, hn::MulAdd(m.t0, m.dq[0], m.q0[0]), hn::MulAdd(m.t0, m.dq[1], m.q0[1]),
                            hn::MulAdd(m.t0, m.dq[2], m.q0[2]));
    return true;
}

// Writes the lanes that hit: colour and opacity (out, lane-wise) and their samples.
void writePacket(const FrameParams &P, const PacketMarch &m, const float out[4][kMaxLanes], const int32_t *samples,
                 float *rgba, MarchTotals &totals) {
    const int lanes = int(hn::Lanes(DF()));
    for (int l = 0; l < lanes; ++l) {
        if (!m.hita[l]) continue;
        totals.samples += uint64_t(samples[l]);
        float *pixel = rgba + (size_t(m.py[l] - P.outY) * size_t(P.outWidth) + size_t(m.px[l] - P.outX)) * 4;
        for (int c = 0; c < 4; ++c) pixel[c] = out[c][l];
    }
}

void MarchTile(const FrameParams &P, int x0, int y0, int x1, int y1, float *rgba, Counters &counters) {
    const DF df;
    const DI di;
    const int lanes = int(hn::Lanes(df));
    const int packetWide = std::min(lanes, 4), packetHigh = lanes / packetWide;
    const Features &F = P.features;
    MarchTotals totals;
    // Every segment sampled at its centre: marchSampled, compiled for skipping and shading.
    const bool sampled = !F.preintegrated && !F.adaptiveStep && F.intensityProjection == 0;

    HWY_ALIGN float outa[4][kMaxLanes];
    HWY_ALIGN int32_t samplesa[kMaxLanes], laneX[kMaxLanes], laneY[kMaxLanes];
    for (int l = 0; l < lanes; ++l) {
        laneX[l] = l % packetWide;
        laneY[l] = l / packetWide;
    }
    // Two packets (8×4 rays on AVX-512) march side by side: marchStep interleaves their steps.
    constexpr int kPackets = 2;
    PacketMarch m[kPackets];
    for (int by = y0; by < y1; by += packetHigh)
        for (int bx = x0; bx < x1; bx += kPackets * packetWide) {
            bool marching[kPackets];
            for (int p = 0; p < kPackets; ++p) {
                const int px0 = bx + p * packetWide;
                marching[p] = px0 < x1 && startPacket(P, px0, by, x1, y1, laneX, laneY, rgba, m[p]);
                if (!marching[p]) {
                    m[p] = PacketMarch(); // no lane alive: the other packet marches alone
                    continue;
                }
                totals.hit += uint64_t(m[p].hits);
                if (F.intensityProjection != 0) {
                    projectPacket(P, m[p].t0, m[p].t1, m[p].j, m[p].q0, m[p].dq, m[p].alive, outa, samplesa,
                                  totals.truncated);
                    writePacket(P, m[p], outa, samplesa, rgba, totals);
                    marching[p] = false;
                    m[p].alive = hn::FirstN(df, 0);
                }
            }
            if (sampled) {
                if (F.emptySpaceSkipping) {
                    if (F.shading) marchSampled<kPackets, true, true>(P, m, totals);
                    else marchSampled<kPackets, true, false>(P, m, totals);
                } else {
                    if (F.shading) marchSampled<kPackets, false, true>(P, m, totals);
                    else marchSampled<kPackets, false, false>(P, m, totals);
                }
            } else
                for (;;) {
                    bool alive = false;
                    for (int p = 0; p < kPackets; ++p) alive = alive || !hn::AllFalse(df, m[p].alive);
                    if (!alive) break;
                    marchStep<kPackets>(P, m, totals);
                }
            for (int p = 0; p < kPackets; ++p) {
                if (!marching[p]) continue;
                for (int a = 0; a < 3; ++a) hn::Store(hn::Sub(m[p].color[a], m[p].colorCarry[a]), df, outa[a]);
                hn::Store(vcOpacityFromDepth(hn::Sub(m[p].depth, m[p].depthCarry)), df, outa[3]);
                hn::Store(m[p].samples, di, samplesa);
                writePacket(P, m[p], outa, samplesa, rgba, totals);
            }
        }
    counters.samples += totals.samples;
    counters.raysHit += totals.hit;
    counters.terminatedEarly += totals.terminated;
    counters.truncated += totals.truncated;
    counters.segmentsSkipped += totals.skipped;
}

int LanesHere() { return int(hn::Lanes(DF())); }
const char *TargetHere() { return hwy::TargetName(HWY_TARGET); }

} // namespace volcast::cpu::HWY_NAMESPACE
HWY_AFTER_NAMESPACE();

#if HWY_ONCE
namespace volcast::cpu {

HWY_EXPORT(MarchTile);
HWY_EXPORT(LanesHere);
HWY_EXPORT(TargetHere);

void marchTile(const FrameParams &p, int x0, int y0, int x1, int y1, float *rgba, Counters &counters) {
    HWY_DYNAMIC_DISPATCH(MarchTile)(p, x0, y0, x1, y1, rgba, counters);
}
std::string marchTarget() { return HWY_DYNAMIC_DISPATCH(TargetHere)(); }
int raysPerPacket() { return HWY_DYNAMIC_DISPATCH(LanesHere)(); }

} // namespace volcast::cpu
#endif
