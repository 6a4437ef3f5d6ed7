#include "renderer/common/preintegration.hpp"

#include "renderer/common/parallel_for.hpp"

#include <algorithm>
#include <array>
#include <atomic>
#include <chrono>
#include <limits>
#include <stdexcept>

namespace volcast {

namespace {

constexpr double kInf = std::numeric_limits<double>::infinity();
// Relative accuracy asked of each piece's colour quadrature; far below the 1e-9 the segment
// integral promises, at a cost of one or two 15-point rules per piece for smooth pieces.
constexpr double kQuadratureRelTolerance = 1e-12;
// Absolute floor for the transmittance form (its integral is in [0, 1] and enters the colour
// added to terms of order 1).
constexpr double kQuadratureAbsFloor = 1e-13;
// An interval whose error estimate is at rounding level is accepted whatever the tolerance:
// halving the tolerance at each split would otherwise push it below rounding deep in a
// refinement (near a = 1) and split forever. Costs at most ~1e-14 relative in all.
constexpr double kRoundingFloor = 64 * std::numeric_limits<double>::epsilon();
constexpr int kMaxQuadratureDepth = 40;

// ---- Closed forms -----------------------------------------------------------------------

// ∫₀¹ ln(1 + q·s) ds for q ≥ −1.
double meanLog1p(double q) {
    if (q <= -1) return -1; // ∫₀¹ ln(1 − s) ds
    if (std::fabs(q) < 0.01) {
        // Series Σ (−1)ⁿ⁺¹ qⁿ / (n(n+1)); 9 terms reach 1e-18 relative.
        double sum = 0, power = 1;
        for (int n = 1; n <= 9; ++n) {
            power *= -q;
            sum -= power / (n * (n + 1.0));
        }
        return sum;
    }
    // Closed form; its cancellation costs at most a factor 200 of rounding at |q| = 0.01.
    return ((1 + q) * std::log1p(q) - q) / q;
}

// Mean of −ln(1 − a) while a goes linearly from a0 to a1 (symmetric in a0, a1):
// −ln x_max − ∫₀¹ ln(1 + q s) ds with x = 1 − a, x_max = 1 − min(a), q = −|Δa| / x_max.
// Both terms are ≥ 0, so it stays accurate for a near 0 and near 1.
double meanExtinctionLog(double a0, double a1) {
    const double lo = std::min(a0, a1), hi = std::max(a0, a1);
    if (lo >= 1) return kInf;
    return -std::log1p(-lo) - meanLog1p(-(hi - lo) / (1 - lo));
}

// ∫₀¹ (1 − exp(−g s)) ds = 1 + expm1(−g)/g: the mean opacity over a piece of constant τ.
double meanOpacityConstant(double g) {
    if (g == kInf) return 1;
    if (g < 0.05) {
        // Series Σ (−1)ⁿ⁺¹ gⁿ / (n+1)!, 10 terms reach 1e-19 relative.
        double sum = 0, term = 1;
        for (int n = 1; n <= 10; ++n) {
            term *= -g / (n + 1.0);
            sum -= term;
        }
        return sum;
    }
    return 1 + std::expm1(-g) / g;
}

// ---- Adaptive Gauss–Kronrod (7/15 points, QUADPACK qk15) -------------------------------

constexpr std::array<double, 8> kXgk = {0.991455371120812639206854697526329, 0.949107912342758524526189684047851,
                                        0.864864423359769072789712788640926, 0.741531185599394439863864773280788,
                                        0.586087235467691130294144845693013, 0.405845151377397166906606412076961,
                                        0.207784955007898467600689403773245, 0.0};
constexpr std::array<double, 8> kWgk = {0.022935322010529224963732008058970, 0.063092092629978553290700663189204,
                                        0.104790010322250183839876322541518, 0.140653259715525918745189590510238,
                                        0.169004726639267902826583426598550, 0.190350578064785409913256402421014,
                                        0.204432940075298892414161999234649, 0.209482141084727828012999174891714};
constexpr std::array<double, 4> kWg = {0.129484966168869693270611432679082, 0.279705391489276667901467771423780,
                                       0.381830050505118944950369775488975, 0.417959183673469387755102040816327};

struct RuleResult {
    double value, error;
};

// One 15-point rule with QUADPACK's error estimate: |K15 − G7| measures the 7-point rule's
// error, far above the 15-point one's; QUADPACK scales it as resasc·min(1, (200·|K−G|/resasc)^1.5).
template <typename F>
RuleResult kronrod15(const F &f, double a, double b) {
    const double centre = 0.5 * (a + b), half = 0.5 * (b - a);
    double fm[7], fp[7];
    const double fc = f(centre);
    double kronrod = kWgk[7] * fc, gauss = kWg[3] * fc;
    for (int k = 0; k < 7; ++k) {
        const double x = half * kXgk[size_t(k)];
        fm[k] = f(centre - x);
        fp[k] = f(centre + x);
        kronrod += kWgk[size_t(k)] * (fm[k] + fp[k]);
        if (k % 2 == 1) gauss += kWg[size_t(k / 2)] * (fm[k] + fp[k]); // odd Kronrod nodes are Gauss nodes
    }
    const double mean = 0.5 * kronrod;
    double asc = kWgk[7] * std::fabs(fc - mean);
    for (int k = 0; k < 7; ++k) asc += kWgk[size_t(k)] * (std::fabs(fm[k] - mean) + std::fabs(fp[k] - mean));
    asc *= half;
    double error = std::fabs((kronrod - gauss) * half);
    if (asc > 0 && error > 0) error = asc * std::min(1.0, std::pow(200 * error / asc, 1.5));
    return {kronrod * half, error};
}

// Where a piece reaches a = 1 (or nearly) at one end, −ln(1 − a) makes the integrand behave
// like x·ln x there; the half of [0, 1] next to that end is mapped by s = s₀ ± w·σ⁴, which
// turns it into σ⁷·ln σ, smooth enough for a 15-point rule after a few splits.
enum class Cluster { none, front, back };

struct UnitMap {
    double s0 = 0, width = 1; // s = s0 + width·m(σ), σ ∈ [0, 1]
    Cluster cluster = Cluster::none;
    double s(double sigma) const {
        if (cluster == Cluster::front) return s0 + width * (sigma * sigma) * (sigma * sigma);
        if (cluster == Cluster::back) {
            const double r = 1 - sigma;
            return s0 + width * (1 - (r * r) * (r * r));
        }
        return s0 + width * sigma;
    }
    double ds(double sigma) const {
        if (cluster == Cluster::front) return width * 4 * sigma * sigma * sigma;
        if (cluster == Cluster::back) return width * 4 * (1 - sigma) * (1 - sigma) * (1 - sigma);
        return width;
    }
};

// Adaptive quadrature of an integrand f, monotone in s, over σ ∈ [a, b] of a map, with
// fa, fb = f at the mapped ends. A monotone integrand lies between its end values, so an
// interval whose bracket |fb − fa|·(s(b) − s(a)) is within tolerance is done without a rule.
// `steep(fa, fb)` forces a split before any rule is trusted: a rule whose nodes all miss a
// thin boundary layer agrees with itself and would be accepted.
template <typename F, typename Steep>
double adaptMonotone(const F &f, const Steep &steep, const UnitMap &map, double a, double b, double fa, double fb,
                     double tol, int depth, const RuleResult *rule = nullptr) {
    const double length = map.s(b) - map.s(a);
    const double bracket = 0.5 * (fa + fb) * length;
    if (std::fabs(fb - fa) * length <= std::max(2 * tol, kRoundingFloor * std::fabs(bracket))) return bracket;
    auto mapped = [&](double sigma) { return f(map.s(sigma)) * map.ds(sigma); };
    if (depth >= kMaxQuadratureDepth) return rule ? rule->value : kronrod15(mapped, a, b).value;
    if (!steep(fa, fb)) {
        const RuleResult r = rule ? *rule : kronrod15(mapped, a, b);
        if (r.error <= std::max(tol, kRoundingFloor * std::fabs(r.value))) return r.value;
    }
    const double mid = 0.5 * (a + b), fmid = f(map.s(mid));
    return adaptMonotone(f, steep, map, a, mid, fa, fmid, 0.5 * tol, depth + 1) +
           adaptMonotone(f, steep, map, mid, b, fmid, fb, 0.5 * tol, depth + 1);
}

// ∫₀¹ f ds for an f monotone in s, to kQuadratureRelTolerance relative or absFloor absolute.
template <typename F, typename Steep>
double integrateUnit(const F &f, const Steep &steep, double absFloor, Cluster cluster) {
    // Split in halves when one end is singular, the map clustering σ-points at that end.
    UnitMap maps[2];
    int count = 1;
    if (cluster == Cluster::front) {
        maps[0] = {0, 0.5, Cluster::front};
        maps[1] = {0.5, 0.5, Cluster::none};
        count = 2;
    } else if (cluster == Cluster::back) {
        maps[0] = {0, 0.5, Cluster::none};
        maps[1] = {0.5, 0.5, Cluster::back};
        count = 2;
    }
    double f0[2], f1[2], scale = 0;
    RuleResult rules[2];
    bool ruled[2] = {false, false};
    for (int m = 0; m < count; ++m) {
        f0[m] = f(maps[m].s(0));
        f1[m] = f(maps[m].s(1));
        // The whole-interval rule sets the scale of the relative tolerance and is reused.
        if (!steep(f0[m], f1[m])) {
            rules[m] = kronrod15([&](double sigma) { return f(maps[m].s(sigma)) * maps[m].ds(sigma); }, 0, 1);
            ruled[m] = true;
            scale += std::fabs(rules[m].value);
        }
    }
    const double tol = std::max({kQuadratureRelTolerance * scale, absFloor, 1e-300}) / count;
    double sum = 0;
    for (int m = 0; m < count; ++m)
        sum += adaptMonotone(f, steep, maps[m], 0.0, 1.0, f0[m], f1[m], tol, 0, ruled[m] ? &rules[m] : nullptr);
    return sum;
}

// ---- One piece (transfer function linear along it) -------------------------------------

// A piece's own emission (premultiplied, not occluded from in front) and optical depth.
struct PieceIntegral {
    double c[3] = {0, 0, 0};
    double od = 0;
};

// The piece runs from p0 to p1 over `lengthInUnits` = h/u. With s ∈ [0, 1] along it, the
// optical depth from its start is G(s) = (h/u)·s·mean(−ln(1 − a)) over [a0, a(s)], A = 1 − e^−G.
PieceIntegral integratePiece(const Rgba &p0, const Rgba &p1, double lengthInUnits) {
    PieceIntegral out;
    // Transparent piece: nothing emitted, nothing absorbed.
    if (p0.a <= 0 && p1.a <= 0) return out;
    const double c0[3] = {p0.r, p0.g, p0.b}, c1[3] = {p1.r, p1.g, p1.b};
    // Opaque plateau: the ray ends at its entry with the entry colour.
    if (std::min(p0.a, p1.a) >= 1) {
        for (int k = 0; k < 3; ++k) out.c[k] = c0[k];
        out.od = kInf;
        return out;
    }
    // Optical depth of the piece from the closed form of ∫ −ln(1 − a(t)) dt.
    const double g = lengthInUnits * meanExtinctionLog(p0.a, p1.a);
    out.od = g;
    const double alphaEnd = -std::expm1(-g), transEnd = std::exp(-g);
    // Colour by parts: ∫ c τ e^−G dt = c₁A₁ − (c₁ − c₀)·∫₀¹ A ds = c₀ − c₁T₁ + (c₁ − c₀)·∫₀¹ T ds.
    // The A form keeps relative accuracy for thin pieces, the T form for thick ones.
    double meanA = 0, meanT = 0;
    const bool thin = alphaEnd < 0.5;
    if (p0.a == p1.a) {
        // Constant τ: ∫₀¹ A ds in closed form.
        meanA = meanOpacityConstant(g);
        meanT = g == kInf ? 0.0 : (g < 0.05 ? 1 - meanA : -std::expm1(-g) / g);
    } else {
        const double a0 = p0.a, da = p1.a - p0.a;
        // G(s) = (h/u)·s·(−ln x₀ − ∫₀¹ ln(1 + q u) du), x = 1 − a, q = (x(s) − x₀)/x₀: one
        // logarithm per point with −ln x₀ hoisted. Both terms have the same sign unless a
        // falls from near 1, where the subtraction loses at most a digit. An opaque front
        // (x₀ = 0) has G(s) = (h/u)·s·(1 − ln x(s)) with x(s) = s·x₁, taken from x₁ directly:
        // 1 − a(s) would cancel to noise that no quadrature converges on.
        const double base = a0 < 1 ? -std::log1p(-a0) : 0.0, x0 = 1 - a0, x1 = 1 - p1.a;
        auto depthAt = [&](double s) {
            if (s <= 0) return 0.0;
            if (a0 >= 1) return lengthInUnits * s * (1 - std::log(s * x1));
            return lengthInUnits * s * (base - meanLog1p(-s * da / x0));
        };
        // An end where 1 − a is below 1% of the other end's is (nearly) singular.
        const Cluster cluster = x0 < 0.01 * x1 ? Cluster::front : (x1 < 0.01 * x0 ? Cluster::back : Cluster::none);
        if (thin) {
            // A < 1/2 on the whole piece: no boundary layer, relative accuracy.
            meanA = integrateUnit([&](double s) { return -std::expm1(-depthAt(s)); },
                                  [](double, double) { return false; }, 0.0, cluster);
        } else {
            // T falls by e^−G: split until each interval's optical depth is below ln 30, so
            // a layer of thickness 1/G at the front is resolved before a rule is trusted.
            meanT = integrateUnit([&](double s) { return std::exp(-depthAt(s)); },
                                  [](double fa, double fb) { return fa > 30 * fb; }, kQuadratureAbsFloor, cluster);
        }
    }
    for (int k = 0; k < 3; ++k) {
        const double dc = c1[k] - c0[k];
        out.c[k] = thin ? c1[k] * alphaEnd - dc * meanA : c0[k] - c1[k] * transEnd + dc * meanT;
        out.c[k] = std::max(out.c[k], 0.0); // rounding must not make emission negative
    }
    return out;
}

} // namespace

SegmentIntegral integrateSegment(const TransferFunction &tf, double sf, double sb, double length,
                                 double opacityUnit) {
    SegmentIntegral seg;
    if (!(length > 0) || !(opacityUnit > 0) || tf.points.empty() || !std::isfinite(sf) || !std::isfinite(sb))
        return seg;
    const double lengthInUnits = length / opacityUnit;
    // Constant value: opacity correction of a single value (Eq. 3), C = c·alpha.
    if (sf == sb) {
        const Rgba q = tf.evaluate(sf);
        seg.opticalDepth = q.a >= 1 ? kInf : lengthInUnits * -std::log1p(-q.a);
        const double alpha = correctedOpacity(q.a, lengthInUnits);
        seg.r = q.r * alpha;
        seg.g = q.g * alpha;
        seg.b = q.b * alpha;
        return seg;
    }
    // Split at every control point strictly between sf and sb (indices first … last), front
    // to back; on each piece the transfer function is linear in t.
    const auto &points = tf.points;
    const double lo = std::min(sf, sb), hi = std::max(sf, sb), span = hi - lo;
    const int first = int(std::upper_bound(points.begin(), points.end(), lo,
                                           [](double v, const ControlPoint &p) { return v < p.value; }) -
                          points.begin());
    const int last = int(std::lower_bound(points.begin(), points.end(), hi,
                                          [](const ControlPoint &p, double v) { return p.value < v; }) -
                         points.begin()) - 1;
    const int cuts = std::max(last - first + 1, 0);
    double v0 = sf;
    Rgba p0 = tf.evaluate(v0);
    double trans = 1;
    for (int k = 0; k <= cuts; ++k) {
        const double v1 = k == cuts ? sb : points[size_t(sb > sf ? first + k : last - k)].value;
        const Rgba p1 = tf.evaluate(v1);
        const PieceIntegral piece = integratePiece(p0, p1, lengthInUnits * (std::fabs(v1 - v0) / span));
        // Composite front to back: this piece is seen through the optical depth in front.
        seg.r += trans * piece.c[0];
        seg.g += trans * piece.c[1];
        seg.b += trans * piece.c[2];
        seg.opticalDepth += piece.od;
        if (seg.opticalDepth == kInf) break;
        trans = std::exp(-seg.opticalDepth);
        v0 = v1;
        p0 = p1;
    }
    return seg;
}

// ---- The table ---------------------------------------------------------------------------

namespace {

using Clock = std::chrono::steady_clock;

struct Sample {
    float v[4]; // r, g, b (premultiplied), alpha
};

Sample sampleSegment(const TransferFunction &tf, double sf, double sb, double step, double unit) {
    const SegmentIntegral s = integrateSegment(tf, sf, sb, step, unit);
    return {{float(s.r), float(s.g), float(s.b), float(s.alpha())}};
}

double snapToFloat(double v) { return double(float(v)); }

// An interval can be split while a float lies strictly inside it. Splitting down to adjacent
// floats is what resolves the log singularity where a reaches 1 at a single value: float
// data cannot fall between two adjacent float nodes, so such a cell has no error to show.
bool splittable(double a, double b) {
    const double mid = snapToFloat(0.5 * (a + b));
    return mid > a && mid < b;
}

// Builds the uniform bucket locator over the final nodes: buckets are doubled until a bucket
// holds at most 8 node intervals, up to max(256, 16·N) buckets (64 bytes per node, small
// beside the N²·16-byte table); past that the kernel's binary search takes a few more steps.
void buildLocator(PreintegrationTable &t) {
    const int n = t.nodeCount();
    const double lo = t.nodes.front(), hi = t.nodes.back();
    const int cap = std::max(256, 16 * n);
    for (int buckets = 64;; buckets *= 2) {
        std::vector<int> loc(size_t(buckets) + 1);
        const double width = (hi - lo) / buckets;
        int i = 0, maxScan = 0;
        for (int b = 0; b < buckets; ++b) {
            const double start = lo + b * width;
            while (i < n - 2 && double(t.nodes[size_t(i) + 1]) <= start) ++i;
            loc[size_t(b)] = i;
        }
        loc[size_t(buckets)] = n - 2;
        for (int b = 0; b < buckets; ++b) maxScan = std::max(maxScan, loc[size_t(b) + 1] - loc[size_t(b)]);
        if (maxScan <= 8 || buckets >= cap) {
            t.locator = std::move(loc);
            t.locatorMin = t.nodes.front();
            t.locatorScale = float(buckets / (hi - lo));
            t.locatorBuckets = buckets;
            t.locatorMaxScan = maxScan;
            return;
        }
    }
}

} // namespace

PreintegrationTable buildPreintegrationTable(const TransferFunction &tf, double step, double opacityUnit,
                                             double valueMin, double valueMax, double tolerance, int maxNodes,
                                             int threads) {
    if (tf.points.empty()) throw std::invalid_argument("pre-integration: the transfer function has no points");
    if (!(step > 0) || !(opacityUnit > 0))
        throw std::invalid_argument("pre-integration: step and opacity unit must be positive");
    if (!(float(valueMax) > float(valueMin)) || !std::isfinite(float(valueMin)) || !std::isfinite(float(valueMax)))
        throw std::invalid_argument("pre-integration: needs a finite value range with max > min (as floats)");
    if (!(tolerance > 0)) throw std::invalid_argument("pre-integration: tolerance must be positive");
    maxNodes = std::max(maxNodes, 2);
    const auto started = Clock::now();

    PreintegrationTable t;
    t.step = step;
    t.opacityUnit = opacityUnit;
    t.valueMin = valueMin;
    t.valueMax = valueMax;
    t.tolerance = tolerance;
    // Check points see the error only where they are; half the tolerance leaves room for the
    // error between them.
    const double target = 0.5 * tolerance;

    // Initial nodes: both ends, the control points inside, a coarse uniform grid; in float.
    std::vector<double> nodes = {snapToFloat(valueMin), snapToFloat(valueMax)};
    for (const auto &p : tf.points)
        if (p.value > valueMin && p.value < valueMax) nodes.push_back(snapToFloat(p.value));
    for (int k = 1; k < 8; ++k) nodes.push_back(snapToFloat(valueMin + (valueMax - valueMin) * k / 8));
    // Where an a = 1 plateau begins or ends, a segment reaching one float into it is opaque
    // while one ending at its edge is not (−ln(1 − a) is integrable up to a single a = 1
    // value): a jump no bilinear cell can follow. A node one float beyond the edge, on the
    // plateau side, puts the jump between two adjacent floats, where no data value can fall.
    // The pair is the last float outside the plateau and the first inside, both as nodes.
    constexpr float kUp = std::numeric_limits<float>::infinity();
    const auto &cp = tf.points;
    for (size_t k = 0; k < cp.size(); ++k) {
        const bool opaqueLeft = cp[k].a >= 1 && (k == 0 || cp[k - 1].a >= 1);
        const bool opaqueRight = cp[k].a >= 1 && (k + 1 == cp.size() || cp[k + 1].a >= 1);
        if (opaqueLeft == opaqueRight) continue;
        float below = float(cp[k].value), above = below;
        if (opaqueRight) {
            // Opaque above the edge: last float ≤ edge, first float > edge.
            if (double(below) > cp[k].value) below = std::nextafter(below, -kUp);
            above = std::nextafter(below, kUp);
        } else {
            // Opaque below the edge: last float < edge, first float ≥ edge.
            if (double(above) < cp[k].value) above = std::nextafter(above, kUp);
            below = std::nextafter(above, -kUp);
        }
        for (const double v : {double(below), double(above)})
            if (v > valueMin && v < valueMax) nodes.push_back(v);
    }
    std::sort(nodes.begin(), nodes.end());
    nodes.erase(std::unique(nodes.begin(), nodes.end()), nodes.end());

    // Samples on the points P = nodes and interval midpoints (P[2i] = node i), P×P, kept
    // across passes: a split interval's midpoint becomes a node, so its samples are reused.
    std::vector<double> points;
    std::vector<Sample> samples;
    std::vector<float> errFront, errBack, errCentre;
    for (;;) {
        const int n = int(nodes.size());
        std::vector<double> newPoints(size_t(2 * n - 1));
        for (int i = 0; i < n; ++i) newPoints[size_t(2 * i)] = nodes[size_t(i)];
        for (int i = 0; i + 1 < n; ++i)
            newPoints[size_t(2 * i + 1)] = snapToFloat(0.5 * (nodes[size_t(i)] + nodes[size_t(i) + 1]));
        // Where each new point was among the old ones (-1: new).
        const int p = int(newPoints.size()), oldP = int(points.size());
        std::vector<int> oldIndex(size_t(p), -1);
        for (int a = 0, b = 0; a < p && b < oldP;) {
            if (newPoints[size_t(a)] == points[size_t(b)]) oldIndex[size_t(a++)] = b++;
            else if (newPoints[size_t(a)] < points[size_t(b)]) ++a;
            else ++b;
        }
        std::vector<Sample> newSamples(size_t(p) * size_t(p));
        std::atomic<long long> integrated{0};
        parallelFor(p, threads, [&](int row) {
            long long count = 0;
            const int oldRow = oldIndex[size_t(row)];
            for (int col = 0; col < p; ++col) {
                const int oldCol = oldIndex[size_t(col)];
                Sample &s = newSamples[size_t(row) * size_t(p) + size_t(col)];
                if (oldRow >= 0 && oldCol >= 0) {
                    s = samples[size_t(oldRow) * size_t(oldP) + size_t(oldCol)];
                } else {
                    // Row = back value, column = front value.
                    s = sampleSegment(tf, newPoints[size_t(col)], newPoints[size_t(row)], step, opacityUnit);
                    ++count;
                }
            }
            integrated += count;
        });
        t.segmentsIntegrated += integrated;
        points = std::move(newPoints);
        samples = std::move(newSamples);

        // Bilinear error of each cell at its edge midpoints (along the front direction on
        // the bottom and top edges, along the back direction on the left and right ones) and
        // at its centre.
        auto at = [&](int front, int back) -> const Sample & {
            return samples[size_t(back) * size_t(p) + size_t(front)];
        };
        std::vector<double> frac(size_t(n - 1));
        for (int i = 0; i + 1 < n; ++i)
            frac[size_t(i)] = (points[size_t(2 * i + 1)] - points[size_t(2 * i)]) /
                              (points[size_t(2 * i + 2)] - points[size_t(2 * i)]);
        const size_t cells = size_t(n - 1) * size_t(n - 1);
        errFront.assign(cells, 0.0f);
        errBack.assign(cells, 0.0f);
        errCentre.assign(cells, 0.0f);
        parallelFor(n - 1, threads, [&](int j) {
            const double g = frac[size_t(j)];
            for (int i = 0; i + 1 < n; ++i) {
                const double f = frac[size_t(i)];
                const Sample &s00 = at(2 * i, 2 * j), &s10 = at(2 * i + 2, 2 * j);
                const Sample &s01 = at(2 * i, 2 * j + 2), &s11 = at(2 * i + 2, 2 * j + 2);
                double eF = 0, eB = 0, eC = 0;
                for (int k = 0; k < 4; ++k) {
                    const double v00 = s00.v[k], v10 = s10.v[k], v01 = s01.v[k], v11 = s11.v[k];
                    const double bottom = v00 + f * (v10 - v00), top = v01 + f * (v11 - v01);
                    const double left = v00 + g * (v01 - v00), right = v10 + g * (v11 - v10);
                    eF = std::max({eF, std::fabs(at(2 * i + 1, 2 * j).v[k] - bottom),
                                   std::fabs(at(2 * i + 1, 2 * j + 2).v[k] - top)});
                    eB = std::max({eB, std::fabs(at(2 * i, 2 * j + 1).v[k] - left),
                                   std::fabs(at(2 * i + 2, 2 * j + 1).v[k] - right)});
                    eC = std::max(eC, std::fabs(at(2 * i + 1, 2 * j + 1).v[k] - (bottom + g * (top - bottom))));
                }
                const size_t c = size_t(j) * size_t(n - 1) + size_t(i);
                errFront[c] = float(eF);
                errBack[c] = float(eB);
                errCentre[c] = float(eC);
            }
        });
        // What each interval needs: a cell's error along the front direction asks for its
        // front interval to be split, along the back direction for its back interval; a centre
        // error well above both edge errors (a mixed term) asks for both. Splitting only the
        // direction at fault matters: a long interval beside a sharp feature would otherwise
        // split every short interval across from it, again and again.
        std::vector<double> intervalError(size_t(n - 1), 0.0);
        t.maxError = 0;
        for (int j = 0; j + 1 < n; ++j)
            for (int i = 0; i + 1 < n; ++i) {
                const size_t c = size_t(j) * size_t(n - 1) + size_t(i);
                const double eF = errFront[c], eB = errBack[c], eC = errCentre[c];
                // The centre goes to the worse direction, or to both when it is clearly worse
                // than either edge.
                const bool both = eC > 1.5 * std::max(eF, eB);
                const double toFront = both || eF >= eB ? std::max(eF, eC) : eF;
                const double toBack = both || eB > eF ? std::max(eB, eC) : eB;
                intervalError[size_t(i)] = std::max(intervalError[size_t(i)], toFront);
                intervalError[size_t(j)] = std::max(intervalError[size_t(j)], toBack);
                t.maxError = std::max({t.maxError, eF, eB, eC});
            }
        if (t.maxError <= target) break;
        // Split the intervals above target, worst first while the node budget lasts.
        std::vector<int> split;
        for (int i = 0; i + 1 < n; ++i)
            if (intervalError[size_t(i)] > target && splittable(nodes[size_t(i)], nodes[size_t(i) + 1]))
                split.push_back(i);
        if (split.empty()) break;
        const int budget = maxNodes - n;
        if (budget <= 0) {
            t.hitNodeLimit = true;
            break;
        }
        if (int(split.size()) > budget) {
            std::partial_sort(split.begin(), split.begin() + budget, split.end(),
                              [&](int a, int b) { return intervalError[size_t(a)] > intervalError[size_t(b)]; });
            split.resize(size_t(budget));
        }
        for (int i : split) nodes.push_back(points[size_t(2 * i + 1)]);
        std::sort(nodes.begin(), nodes.end());
    }

    // Copy the node samples out in the device layout.
    const int n = int(nodes.size()), p = int(points.size());
    t.nodes.resize(size_t(n));
    for (int i = 0; i < n; ++i) t.nodes[size_t(i)] = float(nodes[size_t(i)]);
    t.rgba.resize(size_t(n) * size_t(n) * 4);
    for (int j = 0; j < n; ++j)
        for (int i = 0; i < n; ++i)
            for (int k = 0; k < 4; ++k)
                t.rgba[(size_t(j) * size_t(n) + size_t(i)) * 4 + size_t(k)] =
                    samples[size_t(2 * j) * size_t(p) + size_t(2 * i)].v[k];
    buildLocator(t);
    t.converged = t.maxError <= tolerance;
    t.buildSeconds = std::chrono::duration<double>(Clock::now() - started).count();
    return t;
}

PreintegrationTable::NodeCoordinate PreintegrationTable::locate(float v) const {
    const float x = std::clamp(v, nodes.front(), nodes.back());
    const int b = std::clamp(int((x - locatorMin) * locatorScale), 0, locatorBuckets - 1);
    // Binary search for the last node ≤ x among locator[b] … locator[b + 1].
    int i = locator[size_t(b)], last = locator[size_t(b) + 1];
    while (i < last) {
        const int mid = (i + last + 1) / 2;
        if (x >= nodes[size_t(mid)]) i = mid;
        else last = mid - 1;
    }
    const float f = std::clamp((x - nodes[size_t(i)]) / (nodes[size_t(i) + 1] - nodes[size_t(i)]), 0.0f, 1.0f);
    return {i, f};
}

Rgba PreintegrationTable::lookup(float sf, float sb) const {
    const NodeCoordinate front = locate(sf), back = locate(sb);
    const size_t n = nodes.size();
    const float *e00 = &rgba[(size_t(back.i) * n + size_t(front.i)) * 4];
    const float *e10 = e00 + 4;
    const float *e01 = e00 + n * 4;
    const float *e11 = e01 + 4;
    float out[4];
    for (int k = 0; k < 4; ++k) {
        const float bottom = e00[k] + front.f * (e10[k] - e00[k]);
        const float top = e01[k] + front.f * (e11[k] - e01[k]);
        out[k] = bottom + back.f * (top - bottom);
    }
    return {out[0], out[1], out[2], out[3]};
}

Rgba PreintegrationTable::partialSegment(float sf, float sb, float length) const {
    if (!(length > 0)) return {};
    const float s = std::min(length / float(step), 1.0f);
    const Rgba full = lookup(sf, sb);
    const float alpha = float(full.a);
    // Optical depth scales with length (Eq. 3): alpha' = 1 − (1 − alpha)^s.
    const float alphaPart = alpha >= 1 ? 1.0f : -std::expm1(s * std::log1p(-alpha));
    // Colour scales with the opacity; its limit for alpha → 0 is s.
    const float ratio = alpha > 0 ? alphaPart / alpha : s;
    return {full.r * ratio, full.g * ratio, full.b * ratio, alphaPart};
}

} // namespace volcast
