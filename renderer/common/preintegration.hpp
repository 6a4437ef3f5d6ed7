#pragma once
// Pre-integration (Engel, Kraus & Ertl 2001; the `preintegrated` switch of docs/design.md).
//
// A ray segment of length `step` whose reconstructed value goes linearly from sf (front)
// to sb (back) has an emission–absorption integral that depends only on (sf, sb): the
// premultiplied colour C = ∫₀ᵈ c(v(t)) τ(v(t)) exp(−∫₀ᵗ τ) dt and the optical depth
// D = ∫₀ᵈ τ dt, alpha = 1 − exp(−D). `integrateSegment` computes it exactly (double
// precision); `PreintegrationTable` tabulates it over (sf, sb) for the kernels, on
// non-uniform nodes refined until the table's own bilinear error is below a tolerance.
//
// ---- The table, as the kernel reads it -------------------------------------------------
// nodes    N floats, strictly increasing, nodes[0] = valueMin, nodes[N−1] = valueMax (data
//          units, rounded to float). Every transfer-function control point inside the range
//          is a node, so the function's kinks lie on grid lines. Nodes are non-uniform: dense
//          only where the table needs them (around a narrow spike, near a = 1).
// rgba     N·N·4 floats; entry (front i, back j) at ((j·N) + i)·4: premultiplied r, g, b
//          and alpha = 1 − exp(−D) of a full segment of length `step` world units whose
//          value goes from nodes[i] to nodes[j]. All finite, alpha in [0, 1] (alpha, not D,
//          is stored: D is +inf behind a = 1 and a bilinear weight of 0 times inf is NaN).
// locator  locatorBuckets + 1 ints over uniform buckets of [valueMin, valueMax]: entry b is
//          the index of the node interval [nodes[i], nodes[i+1]) containing the bucket's
//          start valueMin + b / locatorScale (at most N − 2); locator[locatorBuckets] = N − 2.
//          A value in bucket b lies in an interval i with locator[b] ≤ i ≤ locator[b+1], and
//          locatorMaxScan = max_b (locator[b+1] − locator[b]) bounds that range (≤ 8 unless
//          nodes cluster, e.g. around a narrow spike, past the bucket cap of max(256, 16·N)).
//
// Lookup of one value v (what `locate` does, in float, as OpenCL C would):
//     x = clamp(v, nodes[0], nodes[N−1]);                   // outside the range: end nodes
//     b = clamp((int)((x − locatorMin) * locatorScale), 0, locatorBuckets − 1);
//     i = locator[b]; last = locator[b + 1];
//     while (i < last) {                                     // ≤ ceil(log2(locatorMaxScan + 1)) steps
//         m = (i + last + 1) / 2;                            // last node ≤ x in [i, last]
//         if (x >= nodes[m]) i = m; else last = m − 1;
//     }
//     f = clamp((x − nodes[i]) / (nodes[i + 1] − nodes[i]), 0, 1);
// (A bucket index that float rounding moves across a bucket edge is harmless: x is then
// within rounding of a node and the clamp of f puts it on that node.)
// Lookup of a segment (sf, sb): (i, f) = locate(sf), (j, g) = locate(sb), then bilinear
// interpolation of the four entries (i, j), (i+1, j), (i, j+1), (i+1, j+1) with weights f, g.
// Interpolate in the kernel with four reads (or nearest-filtered image reads): hardware
// linear filtering uses 8-bit weights on common GPUs, an error of up to 1/512 of the
// difference between neighbouring entries, which alone can exceed the tolerance.
//
// Partial segments (the last one at the volume boundary or a clip plane, length len < step,
// values sf at its front and sb at its back): look up (sf, sb) as if it were a full step,
// then correct it. The optical depth of a linear-value segment is proportional to its length
// (D = len · mean τ over [sf, sb]), so alpha' = 1 − (1 − alpha)^(len/step) exactly (Eq. 3);
// the colour is scaled by alpha'/alpha (→ len/step as alpha → 0, and 1 when alpha = 1),
// which is exact for a constant value and a close approximation otherwise. `partialSegment`
// implements this.

#include "renderer/model/transfer_function.hpp"

#include <cmath>
#include <vector>

namespace volcast {

// One segment's exact integral. Colour is premultiplied and not occluded by anything in
// front of the segment.
struct SegmentIntegral {
    double r = 0, g = 0, b = 0;
    double opticalDepth = 0; // D = ∫ τ dt; +inf when a = 1 over a positive length of the segment
    double alpha() const { return -std::expm1(-opticalDepth); }
};

// Exact (to ~1e-11 relative) integral of a segment of `length` world units along which the
// value goes linearly from sf to sb. The segment is split at every control point it crosses
// (the transfer function is then linear in t on each piece); each piece uses the closed
// form of ∫ −ln(1 − a(t)) dt and, for the colour, C = c₁·A₁ − (c₁ − c₀)·∫₀¹ A(s) ds (parts
// integration; A is the piece's opacity from its start) with ∫ A by adaptive Gauss–Kronrod.
// sf == sb gives the opacity-corrected single value, alpha = 1 − (1 − a)^(length/u), C = c·alpha.
// A linear approach to a = 1 at a single value has finite optical depth (−ln is
// integrable); only an a = 1 plateau, or sf == sb at a = 1, is opaque (D = +inf, alpha = 1,
// colour from the part in front). Non-finite values, length ≤ 0 or opacityUnit ≤ 0 give an
// empty (transparent) segment. Thread-safe; ~1–5 µs for a segment crossing a few control points.
SegmentIntegral integrateSegment(const TransferFunction &tf, double sf, double sb, double length,
                                 double opacityUnit);

struct PreintegrationTable {
    // What it was built for: a segment length and an opacity unit, both world units.
    double step = 0, opacityUnit = 0;
    double valueMin = 0, valueMax = 0; // data units; values outside clamp to the end nodes
    double tolerance = 0;              // requested bound on the bilinear error, per channel

    std::vector<float> nodes; // N, see the layout above
    std::vector<float> rgba;  // N·N·4, index ((back·N) + front)·4 + channel
    std::vector<int> locator; // locatorBuckets + 1
    float locatorMin = 0;     // = nodes[0]
    float locatorScale = 0;   // buckets per data unit
    int locatorBuckets = 0;
    int locatorMaxScan = 0;

    // Build record.
    double maxError = 0;       // largest |table − exact| found at the check points (every cell's
                               // centre and edge midpoints), over r, g, b and alpha
    bool converged = false;    // maxError ≤ tolerance
    bool hitNodeLimit = false; // refinement stopped at maxNodes with cells above tolerance/2
    double buildSeconds = 0;
    long long segmentsIntegrated = 0; // exact segment integrals the build computed

    int nodeCount() const { return int(nodes.size()); }

    struct NodeCoordinate {
        int i = 0;    // node interval [nodes[i], nodes[i+1]]
        float f = 0;  // position in it, [0, 1]
    };
    // The lookup algorithm above, in float.
    NodeCoordinate locate(float v) const;
    // Bilinearly interpolated premultiplied r, g, b and alpha of a full step.
    Rgba lookup(float sf, float sb) const;
    // A partial segment of `length` world units (0 < length ≤ step; longer is taken as step,
    // ≤ 0 gives zeros) with values sf, sb at its ends: alpha' = 1 − (1 − alpha)^(length/step),
    // colour · alpha'/alpha, in float as a kernel would.
    Rgba partialSegment(float sf, float sb, float length) const;
};

// Builds the table for segments of `step` world units.
// Nodes: both ends, every control point inside [valueMin, valueMax], a uniform 8-interval
// grid, and, where an a = 1 plateau begins or ends, the last float outside and the first
// float inside the plateau (a segment reaching into the plateau is opaque, one ending at its
// edge is not: that jump then lies between two adjacent floats). Then, in passes, every cell's
// bilinear error is measured against integrateSegment at its edge midpoints and centre
// (the samples live on the grid of nodes and interval midpoints, so a split reuses them),
// and each node interval at fault is split at its midpoint: the front interval for an error
// along the front direction, the back one for the back direction, both for a centre error
// well above the edges'. The target is tolerance/2, leaving room for the error between check
// points. It stops when no cell is above target, when the intervals at fault hold no float
// strictly inside (float data cannot fall between adjacent float nodes; refining down to them
// is what resolves the log singularity where a reaches 1 at a single value), or at maxNodes
// (then the worst intervals are split first and hitNodeLimit is set); the initial nodes are
// always kept. Rows of samples are integrated on `threads` threads (0: the hardware
// concurrency). Throws std::invalid_argument on an empty transfer function, a non-positive
// step, opacity unit or tolerance, or a range without float(valueMax) > float(valueMin).
PreintegrationTable buildPreintegrationTable(const TransferFunction &tf, double step, double opacityUnit,
                                             double valueMin, double valueMax, double tolerance = 1e-3,
                                             int maxNodes = 1024, int threads = 0);

} // namespace volcast
