#include "renderer/reference/reference_renderer.hpp"

#include "renderer/common/parallel_for.hpp"
#include "renderer/model/shading.hpp"

#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <limits>
#include <optional>
#include <stdexcept>
#include <vector>

namespace volcast {

namespace {

using Clock = std::chrono::steady_clock;

constexpr int kMaxDegree = 9;
// Extinction cap: a = 1 gives τ = ∞; capping keeps 0·∞ out of the quadrature while any
// cap this large still makes the segment opaque to double precision.
constexpr double kTauMax = 1e30;
// A rule is trusted only on intervals of optical depth below ln 30: across a thicker one the
// transmittance falls in a boundary layer its five nodes can all miss, and the coarse and fine
// rules then agree on a colour near 0 (the check preintegration.cpp makes with its "steep").
constexpr double kMaxRuleDepth = 3.4011973816621555; // ln 30
// Subdivision limits: past these an interval is accepted and its estimate kept.
constexpr int kMaxDepth = 48;
constexpr int kMaxRootDepth = 52;

// 5-point Gauss–Legendre on [0, 1].
constexpr std::array<double, 5> kNodes = {0.5 - 0.5 * 0.9061798459386640, 0.5 - 0.5 * 0.5384693101056831, 0.5,
                                          0.5 + 0.5 * 0.5384693101056831, 0.5 + 0.5 * 0.9061798459386640};
constexpr std::array<double, 5> kWeights = {0.5 * 0.2369268850561891, 0.5 * 0.4786286704993665,
                                            0.5 * 0.5688888888888889, 0.5 * 0.4786286704993665,
                                            0.5 * 0.2369268850561891};

struct Tables {
    // partial[i][j]: ∫₀^{node i} of the Lagrange polynomial through the nodes that is 1 at
    // node j. It gives the optical depth up to each node from τ at the nodes.
    double partial[5][5];
    // vandermondeInverse[m]: maps values at s = i/m (i = 0..m) to monomial coefficients.
    std::array<std::vector<double>, kMaxDegree + 1> vandermondeInverse;
};

std::vector<double> invert(std::vector<double> a, int n) {
    std::vector<double> inv(size_t(n * n), 0.0);
    for (int i = 0; i < n; ++i) inv[size_t(i * n + i)] = 1;
    for (int c = 0; c < n; ++c) {
        int pivot = c;
        for (int r = c + 1; r < n; ++r)
            if (std::fabs(a[size_t(r * n + c)]) > std::fabs(a[size_t(pivot * n + c)])) pivot = r;
        for (int k = 0; k < n; ++k) {
            std::swap(a[size_t(c * n + k)], a[size_t(pivot * n + k)]);
            std::swap(inv[size_t(c * n + k)], inv[size_t(pivot * n + k)]);
        }
        const double d = a[size_t(c * n + c)];
        for (int k = 0; k < n; ++k) { a[size_t(c * n + k)] /= d; inv[size_t(c * n + k)] /= d; }
        for (int r = 0; r < n; ++r) {
            if (r == c) continue;
            const double f = a[size_t(r * n + c)];
            for (int k = 0; k < n; ++k) {
                a[size_t(r * n + k)] -= f * a[size_t(c * n + k)];
                inv[size_t(r * n + k)] -= f * inv[size_t(c * n + k)];
            }
        }
    }
    return inv;
}

const Tables &tables() {
    static const Tables t = [] {
        Tables tb{};
        for (int i = 0; i < 5; ++i)
            for (int j = 0; j < 5; ++j) {
                // The Lagrange polynomial has degree 4: 5-point Gauss is exact on [0, node i].
                double sum = 0;
                for (int q = 0; q < 5; ++q) {
                    const double u = kNodes[size_t(i)] * kNodes[size_t(q)];
                    double l = 1;
                    for (int k = 0; k < 5; ++k)
                        if (k != j) l *= (u - kNodes[size_t(k)]) / (kNodes[size_t(j)] - kNodes[size_t(k)]);
                    sum += kWeights[size_t(q)] * l;
                }
                tb.partial[i][j] = sum * kNodes[size_t(i)];
            }
        for (int m : {3, kMaxDegree}) {
            std::vector<double> v(size_t((m + 1) * (m + 1)));
            for (int i = 0; i <= m; ++i)
                for (int j = 0; j <= m; ++j) v[size_t(i * (m + 1) + j)] = std::pow(double(i) / m, j);
            tb.vandermondeInverse[size_t(m)] = invert(v, m + 1);
        }
        return tb;
    }();
    return t;
}

double binomial(int n, int k) {
    double r = 1;
    for (int i = 1; i <= k; ++i) r = r * (n - k + i) / i;
    return r;
}

// v(s) on one piece, s in [0, 1]: monomial form to evaluate, Bernstein form to bound.
struct PiecePolynomial {
    int degree = 3;
    double mono[kMaxDegree + 1];
    double bern[kMaxDegree + 1];

    void fit(const double *values) {
        const auto &inv = tables().vandermondeInverse[size_t(degree)];
        const int n = degree + 1;
        for (int i = 0; i < n; ++i) {
            double s = 0;
            for (int j = 0; j < n; ++j) s += inv[size_t(i * n + j)] * values[j];
            mono[i] = s;
        }
        for (int i = 0; i < n; ++i) {
            double s = 0;
            for (int j = 0; j <= i; ++j) s += binomial(i, j) / binomial(degree, j) * mono[j];
            bern[i] = s;
        }
    }
    double operator()(double s) const {
        double r = mono[degree];
        for (int i = degree - 1; i >= 0; --i) r = r * s + mono[i];
        return r;
    }
};

// Roots of p(s) = level on [lo, hi], given p's Bernstein coefficients on that interval.
// Subdivides until the coefficients show no sign change (no root: the convex hull property)
// or exactly one (Descartes' rule: bisect). A tangential touch ends as a tiny interval whose
// midpoint is returned; an extra split point never hurts the integral.
void isolateRoots(const double *b, int m, double lo, double hi, double level, const PiecePolynomial &p,
                  int depth, std::vector<double> &roots) {
    double d[kMaxDegree + 1];
    bool pos = false, neg = false;
    int changes = 0, lastSign = 0;
    for (int i = 0; i <= m; ++i) {
        d[i] = b[i] - level;
        const int sign = d[i] > 0 ? 1 : (d[i] < 0 ? -1 : 0);
        pos |= sign > 0;
        neg |= sign < 0;
        if (sign != 0) {
            if (lastSign != 0 && sign != lastSign) ++changes;
            lastSign = sign;
        }
    }
    if (!pos || !neg) return;
    if (changes == 1 && d[0] * d[m] < 0) {
        double a = lo, c = hi, fa = d[0];
        for (int it = 0; it < 80 && c - a > 1e-16; ++it) {
            const double mid = 0.5 * (a + c);
            const double fm = p(mid) - level;
            if ((fm < 0) == (fa < 0)) { a = mid; fa = fm; } else { c = mid; }
        }
        roots.push_back(0.5 * (a + c));
        return;
    }
    if (hi - lo < 1e-13 || depth >= kMaxRootDepth) {
        roots.push_back(0.5 * (lo + hi));
        return;
    }
    // de Casteljau split at the midpoint.
    double left[kMaxDegree + 1], right[kMaxDegree + 1], work[kMaxDegree + 1];
    std::copy(b, b + m + 1, work);
    for (int r = 0; r <= m; ++r) {
        left[r] = work[0];
        right[m - r] = work[m - r];
        for (int i = 0; i < m - r; ++i) work[i] = 0.5 * (work[i] + work[i + 1]);
    }
    const double mid = 0.5 * (lo + hi);
    isolateRoots(left, m, lo, mid, level, p, depth + 1, roots);
    isolateRoots(right, m, mid, hi, level, p, depth + 1, roots);
}

// A segment's own emission (premultiplied, as if unoccluded) and optical depth.
struct Segment {
    double c[3] = {0, 0, 0};
    double od = 0;
};

Segment compose(const Segment &front, const Segment &back) {
    Segment s;
    const double t = std::exp(-front.od);
    for (int k = 0; k < 3; ++k) s.c[k] = front.c[k] + t * back.c[k];
    s.od = front.od + back.od;
    return s;
}

// Integrates one ray front to back, holding its running colour and transmittance.
class RayIntegrator {
  public:
    RayIntegrator(const TransferFunction &tf, double opacityUnit, double tolerance)
        : tf_(tf), unit_(opacityUnit), tolerance_(tolerance) {}

    template <typename ValueAt>
    void integrateSubPiece(const ValueAt &valueAt, double sa, double sb, double worldPerS) {
        if (done_ || !(sb > sa)) return;
        // Opaque material (a = 1 across the sub-piece): the ray ends at its entry.
        const Rgba mid = tf_.evaluate(valueAt(0.5 * (sa + sb)));
        if (mid.a >= 1) {
            Rgba entry = tf_.evaluate(valueAt(sa));
            lit(sa, entry);
            const double t = transmittance();
            color_[0] += t * entry.r;
            color_[1] += t * entry.g;
            color_[2] += t * entry.b;
            if (markDepth_ && !markT_) markT_ = pieceStart_ + sa * pieceLength_;
            od_ = std::numeric_limits<double>::infinity();
            ++intervals_;
            done_ = true;
            return;
        }
        adapt(valueAt, sa, sb, worldPerS, rule(valueAt, sa, sb, worldPerS), 0);
    }

    void setRayLength(double length) { tolDensity_ = tolerance_ / std::max(length, 1e-300); }
    // Records where the optical depth first reaches `depth` (opacity 1 − e^−depth), as a ray
    // parameter: sub-piece parameters s map to t = start + s·length of the current piece.
    void setMark(double depth) { markDepth_ = depth; }
    void setPiece(double start, double length) { pieceStart_ = start, pieceLength_ = length; }
    std::optional<double> markT() const { return markT_; }
    // Shading: (diffuse factor, specular term) at piece parameter s, or none for unlit colour.
    void setLight(const std::function<void(double s, double &diffuse, double &specular)> *light) { light_ = light; }
    bool done() const { return done_; }
    double transmittance() const { return std::exp(-od_); }
    RayIntegral result() const {
        RayIntegral r;
        r.color = {color_[0], color_[1], color_[2], -std::expm1(-od_)};
        r.errorEstimate = error_;
        return r;
    }
    uint64_t intervals() const { return intervals_; }

  private:
    template <typename ValueAt>
    Segment rule(const ValueAt &valueAt, double sa, double sb, double worldPerS) const {
        const double h = (sb - sa) * worldPerS;
        double tau[5], rgb[5][3];
        for (int i = 0; i < 5; ++i) {
            const double s = sa + kNodes[size_t(i)] * (sb - sa);
            Rgba q = tf_.evaluate(valueAt(s));
            if (q.a > 0) lit(s, q);
            tau[i] = std::min(extinction(q.a, unit_), kTauMax);
            rgb[i][0] = q.r;
            rgb[i][1] = q.g;
            rgb[i][2] = q.b;
        }
        const auto &tb = tables();
        Segment s;
        for (int i = 0; i < 5; ++i) {
            // Optical depth from the segment start to node i (interpolated τ, integrated).
            double od = 0;
            for (int j = 0; j < 5; ++j) od += tb.partial[i][j] * tau[j];
            const double w = h * kWeights[size_t(i)] * tau[i] * std::exp(-std::max(od * h, 0.0));
            for (int k = 0; k < 3; ++k) s.c[k] += w * rgb[i][k];
            s.od += h * kWeights[size_t(i)] * tau[i];
        }
        return s;
    }

    template <typename ValueAt>
    void adapt(const ValueAt &valueAt, double sa, double sb, double worldPerS, const Segment &coarse, int depth) {
        const double mid = 0.5 * (sa + sb);
        const Segment left = rule(valueAt, sa, mid, worldPerS);
        const Segment right = rule(valueAt, mid, sb, worldPerS);
        const Segment fine = compose(left, right);
        double err = std::fabs(std::exp(-fine.od) - std::exp(-coarse.od));
        for (int k = 0; k < 3; ++k) err = std::max(err, std::fabs(fine.c[k] - coarse.c[k]));
        const double t = transmittance();
        const double h = (sb - sa) * worldPerS;
        if ((t * err <= tolDensity_ * h && coarse.od <= kMaxRuleDepth) || depth >= kMaxDepth) {
            apply(fine, t * err, sa, sb);
            return;
        }
        adapt(valueAt, sa, mid, worldPerS, left, depth + 1);
        if (!done_) adapt(valueAt, mid, sb, worldPerS, right, depth + 1);
    }

    void apply(const Segment &s, double err, double sa, double sb) {
        // The interval is accepted, so τ is resolved on it to the tolerance: the crossing is
        // placed by the optical depth growing linearly across it (exact for constant τ, and
        // off by at most the interval's length otherwise).
        if (markDepth_ && !markT_ && od_ + s.od >= *markDepth_) {
            const double f = s.od > 0 ? std::clamp((*markDepth_ - od_) / s.od, 0.0, 1.0) : 0.0;
            markT_ = pieceStart_ + (sa + f * (sb - sa)) * pieceLength_;
        }
        const double t = transmittance();
        for (int k = 0; k < 3; ++k) color_[k] += t * s.c[k];
        od_ += s.od;
        error_ += err;
        ++intervals_;
        // What is left behind a nearly opaque front adds at most the transmittance.
        if (transmittance() < tolerance_ * 1e-3) {
            error_ += transmittance();
            done_ = true;
        }
    }

    void lit(double s, Rgba &c) const {
        if (!light_) return;
        double diffuse, specular;
        (*light_)(s, diffuse, specular);
        c.r = phongShade(c.r, diffuse, specular);
        c.g = phongShade(c.g, diffuse, specular);
        c.b = phongShade(c.b, diffuse, specular);
    }

    const TransferFunction &tf_;
    const std::function<void(double, double &, double &)> *light_ = nullptr;
    double unit_;
    double tolerance_;
    double tolDensity_ = 0;
    double color_[3] = {0, 0, 0};
    double od_ = 0;
    double error_ = 0;
    uint64_t intervals_ = 0;
    bool done_ = false;
    std::optional<double> markDepth_;
    std::optional<double> markT_;
    double pieceStart_ = 0, pieceLength_ = 0;
};

// Largest opacity the transfer function takes on [lo, hi] (it is piecewise linear).
double maxAlphaOver(const TransferFunction &tf, double lo, double hi) {
    double a = std::max(tf.evaluate(lo).a, tf.evaluate(hi).a);
    for (const auto &p : tf.points)
        if (p.value > lo && p.value < hi) a = std::max(a, p.a);
    return a;
}

} // namespace

ReferenceRenderer::ReferenceRenderer(const Volume &volume, TransferFunction tf, Reconstruction reconstruction)
    : volume_(volume), tf_(std::move(tf)), reconstruction_(reconstruction) {
    if (reconstruction == Reconstruction::Analytic)
        throw std::invalid_argument("reference renderer: analytic reconstruction needs a field");
    tf_.validate();
    opacityUnit_ = tf_.resolvedOpacityUnit(volume);
    const auto start = Clock::now();
    if (reconstruction == Reconstruction::Cubic) cubic_ = std::make_unique<CubicBSplineField>(volume);
    preprocessSeconds_ = std::chrono::duration<double>(Clock::now() - start).count();
}

ReferenceRenderer::ReferenceRenderer(const Volume &volume, TransferFunction tf,
                                     std::function<double(const Vec3d &)> analyticField)
    : volume_(volume), tf_(std::move(tf)), reconstruction_(Reconstruction::Analytic),
      analytic_(std::move(analyticField)) {
    tf_.validate();
    opacityUnit_ = tf_.resolvedOpacityUnit(volume);
}

void ReferenceRenderer::setOrientationCorrection(const OrientationCorrection &correction) {
    if (const std::string problem = signedPermutationProblem(correction); !problem.empty())
        throw std::invalid_argument("quality.orientation_correction: is not a signed permutation: " + problem);
    placement_ = correctedPlacement(volume_, correction);
}

double ReferenceRenderer::valueAtIndex(const Vec3d &q) const {
    switch (reconstruction_) {
    case Reconstruction::Linear: return TrilinearField(volume_)(q);
    case Reconstruction::Cubic: return (*cubic_)(q);
    case Reconstruction::Analytic: return analytic_(volume_.worldFromIndex(q));
    }
    return 0;
}

bool ReferenceRenderer::clipRay(const Ray &ray, std::span<const ClipPlane> clipPlanes, double &t0,
                                double &t1) const {
    t0 = 0;
    t1 = std::numeric_limits<double>::infinity();
    const Vec3d p0 = placement_.indexFromWorld(ray.origin);
    const Vec3d dq = placement_.indexFromWorldDir(ray.dir);
    // Slabs of the cell-extent box [-1/2, n - 1/2] in index space (closed), or of the crop
    // box [-1/2 + min·n, -1/2 + max·n] inside it.
    for (int a = 0; a < 3; ++a) {
        const double n = double(volume_.dims[a]);
        const double lo = -0.5 + crop_.min[a] * n, hi = -0.5 + crop_.max[a] * n;
        if (dq[a] == 0) {
            if (p0[a] < lo || p0[a] > hi) return false;
            continue;
        }
        double ta = (lo - p0[a]) / dq[a], tb = (hi - p0[a]) / dq[a];
        if (ta > tb) std::swap(ta, tb);
        t0 = std::max(t0, ta);
        t1 = std::min(t1, tb);
    }
    // Clip half-spaces dot(x − point, normal) ≥ 0.
    for (const ClipPlane &c : clipPlanes) {
        if (!(length(c.normal) > 0)) throw std::invalid_argument("clip plane normal has zero length");
        const double g0 = dot(ray.origin - c.point, c.normal);
        const double gd = dot(ray.dir, c.normal);
        if (gd == 0) {
            if (g0 < 0) return false;
            continue;
        }
        const double t = -g0 / gd;
        if (gd > 0) t0 = std::max(t0, t);
        else t1 = std::min(t1, t);
    }
    return t1 > t0;
}

RayIntegral ReferenceRenderer::integrate(const Ray &ray, std::span<const ClipPlane> clipPlanes, double tolerance,
                                         ReferenceStats *stats) const {
    double t0, t1;
    if (!clipRay(ray, clipPlanes, t0, t1)) return {};
    if (compositing_ != Compositing::EmissionAbsorption) return project(ray, t0, t1, tolerance, stats);
    return emission(ray, t0, t1, tolerance, stats, std::nullopt, nullptr);
}

RayPick ReferenceRenderer::pick(const Ray &ray, std::span<const ClipPlane> clipPlanes, double threshold,
                                double tolerance) const {
    if (!(threshold > 0 && threshold < 1)) throw std::invalid_argument("pick: the opacity threshold must be in (0, 1)");
    RayPick out;
    double t0, t1;
    if (!clipRay(ray, clipPlanes, t0, t1)) return out;
    std::optional<double> t;
    if (compositing_ != Compositing::EmissionAbsorption) {
        double at = 0;
        out.opacity = project(ray, t0, t1, tolerance, nullptr, &at).color.a;
        if (out.opacity >= threshold) t = at;
    } else {
        out.opacity = emission(ray, t0, t1, tolerance, nullptr, -std::log1p(-threshold), &t).color.a;
    }
    if (t) {
        out.hit = true;
        out.t = *t;
        out.point = ray.origin + ray.dir * *t;
    }
    return out;
}

// Where a ray from index-space point p0 along dq is cut between t0 and t1, sorted: the knot
// planes of the grid (integer index coordinates), or for an analytic field pieces of a
// quarter voxel, short enough for a degree-9 fit. Between two cuts the reconstruction is one
// polynomial.
std::vector<double> ReferenceRenderer::splitPoints(const Vec3d &p0, const Vec3d &dq, double t0, double t1) const {
    std::vector<double> splits{t0, t1};
    if (reconstruction_ == Reconstruction::Analytic) {
        const double maxRate = std::max({std::fabs(dq.x), std::fabs(dq.y), std::fabs(dq.z)});
        const double dt = 0.25 / maxRate;
        for (double t = t0 + dt; t < t1; t += dt) splits.push_back(t);
    } else {
        for (int a = 0; a < 3; ++a) {
            if (dq[a] == 0) continue;
            const double pa = p0[a] + t0 * dq[a], pb = p0[a] + t1 * dq[a];
            for (double k = std::ceil(std::min(pa, pb)); k <= std::floor(std::max(pa, pb)); k += 1) {
                const double t = (k - p0[a]) / dq[a];
                if (t > t0 && t < t1) splits.push_back(t);
            }
        }
    }
    std::sort(splits.begin(), splits.end());
    return splits;
}

RayIntegral ReferenceRenderer::emission(const Ray &ray, double t0, double t1, double tolerance, ReferenceStats *stats,
                                        std::optional<double> markDepth, std::optional<double> *markT) const {
    const Vec3d p0 = placement_.indexFromWorld(ray.origin);
    const Vec3d dq = placement_.indexFromWorldDir(ray.dir);

    const std::vector<double> splits = splitPoints(p0, dq, t0, t1);

    RayIntegrator integrator(tf_, opacityUnit_, tolerance);
    integrator.setRayLength(t1 - t0);
    if (markDepth) integrator.setMark(*markDepth);
    PiecePolynomial poly;
    poly.degree = reconstruction_ == Reconstruction::Linear ? 3 : kMaxDegree;
    std::vector<double> roots;
    double fitError = 0;

    for (size_t piece = 0; piece + 1 < splits.size() && !integrator.done(); ++piece) {
        const double ta = splits[piece], tb = splits[piece + 1];
        if (!(tb > ta)) continue;
        const double len = tb - ta;
        integrator.setPiece(ta, len);
        auto indexAt = [&](double s) { return p0 + dq * (ta + s * len); };

        // Fit v on the piece: exact for trilinear (degree 3) and cubic B-spline (degree 9).
        double values[kMaxDegree + 1];
        for (int i = 0; i <= poly.degree; ++i) values[i] = valueAtIndex(indexAt(double(i) / poly.degree));
        poly.fit(values);
        if (reconstruction_ == Reconstruction::Analytic) {
            const double sCheck = 0.5 / poly.degree;
            fitError = std::max(fitError, std::fabs(poly(sCheck) - valueAtIndex(indexAt(sCheck))));
        }

        // Skip pieces the transfer function makes transparent over the whole value bound.
        const double lo = *std::min_element(poly.bern, poly.bern + poly.degree + 1);
        const double hi = *std::max_element(poly.bern, poly.bern + poly.degree + 1);
        if (maxAlphaOver(tf_, lo, hi) <= 0) continue;

        // Split further where v crosses a control point: the transfer function is linear between.
        roots.clear();
        for (const auto &cp : tf_.points)
            if (cp.value > lo && cp.value < hi)
                isolateRoots(poly.bern, poly.degree, 0, 1, cp.value, poly, 0, roots);
        roots.push_back(0);
        roots.push_back(1);
        std::sort(roots.begin(), roots.end());

        // Headlight Phong on the central-difference gradient (shading.hpp), world space.
        const std::function<void(double, double &, double &)> light = [&](double s, double &diffuse,
                                                                          double &specular) {
            const Vec3d q = indexAt(s);
            Vec3d g;
            for (int a = 0; a < 3; ++a) {
                Vec3d e{0, 0, 0};
                e[a] = 1;
                g[a] = (valueAtIndex(q + e) - valueAtIndex(q - e)) / volume_.spacing[a];
            }
            const Vec3d gWorld = placement_.direction * g;
            const double gLength = length(gWorld);
            if (!(gLength > 0)) {
                diffuse = 1;
                specular = 0;
                return;
            }
            phongLight(std::min(std::fabs(dot(gWorld, ray.dir)) / gLength, 1.0), diffuse, specular);
        };
        integrator.setLight(shading_ ? &light : nullptr);

        if (reconstruction_ == Reconstruction::Analytic) {
            // The field at the sample's index position: its world point as the file places it.
            auto valueAt = [&](double s) { return valueAtIndex(indexAt(s)); };
            for (size_t r = 0; r + 1 < roots.size(); ++r)
                integrator.integrateSubPiece(valueAt, roots[r], roots[r + 1], len);
        } else {
            for (size_t r = 0; r + 1 < roots.size(); ++r)
                integrator.integrateSubPiece(poly, roots[r], roots[r + 1], len);
        }
    }

    if (stats) {
        stats->intervals += integrator.intervals();
        stats->analyticFitError = std::max(stats->analyticFitError, fitError);
    }
    if (markT) *markT = integrator.markT();
    return integrator.result();
}

// The intensity projection: the largest (MIP) or smallest (MinIP) value of the continuous
// field on [t0, t1]. Between knot planes v(t) is a polynomial (degree 3 trilinear, 9 cubic);
// its extreme on a piece lies between the extreme of its values at the ends and the extreme
// of its Bernstein coefficients (the convex hull property), so pieces are subdivided (de
// Casteljau) until the two agree to a tolerance far below the colour tolerance, and pieces
// whose coefficients cannot beat the best value found are dropped. The value is exact to
// that tolerance, not sampled: a thin peak between samples is found wherever it is.
RayIntegral ReferenceRenderer::project(const Ray &ray, double t0, double t1, double tolerance,
                                       ReferenceStats *stats, double *where) const {
    const Vec3d p0 = placement_.indexFromWorld(ray.origin);
    const Vec3d dq = placement_.indexFromWorldDir(ray.dir);
    const std::vector<double> splits = splitPoints(p0, dq, t0, t1);

    // Work on s·v so that the minimum is the maximum of −v.
    const double sign = compositing_ == Compositing::Maximum ? 1.0 : -1.0;
    PiecePolynomial poly;
    poly.degree = reconstruction_ == Reconstruction::Linear ? 3 : kMaxDegree;
    const int m = poly.degree;
    double best = -std::numeric_limits<double>::infinity();
    double bestT = t0;   // where along the ray the best value lies
    const auto offer = [&](double value, double t) {
        if (value > best) best = value, bestT = t;
    };
    double worstGap = 0; // largest upper bound − best over accepted pieces
    uint64_t pieces = 0;
    double fitError = 0;
    struct Pending {
        double b[kMaxDegree + 1];
        int depth;
        double lo, hi;   // the sub-piece, in the piece's parameter s
    };
    std::vector<Pending> stack;
    for (size_t piece = 0; piece + 1 < splits.size(); ++piece) {
        const double ta = splits[piece], tb = splits[piece + 1];
        if (!(tb > ta)) continue;
        const double len = tb - ta;
        double values[kMaxDegree + 1];
        for (int i = 0; i <= m; ++i) values[i] = sign * valueAtIndex(p0 + dq * (ta + len * double(i) / m));
        poly.fit(values);
        if (reconstruction_ == Reconstruction::Analytic) {
            const double sCheck = 0.5 / m;
            fitError = std::max(fitError, std::fabs(poly(sCheck) - sign * valueAtIndex(p0 + dq * (ta + sCheck * len))));
        }
        // The ends are values of the field: candidates at once.
        offer(values[0], ta);
        offer(values[m], tb);
        const double scale = std::max({1.0, std::fabs(values[0]), std::fabs(values[m])});
        const double valueTolerance = 1e-12 * scale;
        stack.clear();
        Pending first{};
        first.hi = 1;
        std::copy(poly.bern, poly.bern + m + 1, first.b);
        stack.push_back(first);
        while (!stack.empty()) {
            const Pending p = stack.back();
            stack.pop_back();
            ++pieces;
            const double upper = *std::max_element(p.b, p.b + m + 1);
            offer(p.b[0], ta + p.lo * len); // the end coefficients are values
            offer(p.b[m], ta + p.hi * len);
            if (upper <= best + valueTolerance || p.depth >= kMaxRootDepth) {
                worstGap = std::max(worstGap, upper - best);
                continue;
            }
            Pending left{}, right{};
            left.depth = right.depth = p.depth + 1;
            left.lo = p.lo;
            left.hi = right.lo = 0.5 * (p.lo + p.hi);
            right.hi = p.hi;
            double work[kMaxDegree + 1];
            std::copy(p.b, p.b + m + 1, work);
            for (int r = 0; r <= m; ++r) {
                left.b[r] = work[0];
                right.b[m - r] = work[m - r];
                for (int i = 0; i < m - r; ++i) work[i] = 0.5 * (work[i] + work[i + 1]);
            }
            stack.push_back(right);
            stack.push_back(left);
        }
    }
    const double value = sign * best;
    if (where) *where = bestT;
    const Rgba c = tf_.evaluate(value);
    RayIntegral r;
    r.color = {c.r * c.a, c.g * c.a, c.b * c.a, c.a};
    // The colour's error from the value's: the transfer function's steepest slope times the gap.
    double slope = 0;
    for (size_t i = 0; i + 1 < tf_.points.size(); ++i) {
        const auto &a = tf_.points[i], &b = tf_.points[i + 1];
        const double dv = b.value - a.value;
        if (dv > 0)
            slope = std::max({slope, std::fabs(b.a - a.a) / dv, std::fabs(b.r * b.a - a.r * a.a) / dv,
                              std::fabs(b.g * b.a - a.g * a.a) / dv, std::fabs(b.b * b.a - a.b * a.a) / dv});
    }
    r.errorEstimate = slope * worstGap;
    (void)tolerance; // the value is found to ~1e-12 of itself, far below any colour tolerance asked
    if (stats) {
        stats->intervals += pieces;
        stats->analyticFitError = std::max(stats->analyticFitError, fitError);
    }
    return r;
}

Image ReferenceRenderer::render(const Camera &camera, int width, int height, std::span<const ClipPlane> clipPlanes,
                                const ReferenceOptions &options, ReferenceStats *stats) const {
    const auto start = Clock::now();
    const RayGenerator rays(camera, width, height);
    Image image(width, height);
    // Rows handed out one at a time (their cost varies with what the rays cross); each row
    // keeps its own statistics, merged after in row order.
    std::vector<ReferenceStats> perRow(size_t(std::max(height, 0)));
    std::vector<double> worstError(perRow.size(), 0.0);
    parallelFor(height, options.threads, [&](int y) {
        ReferenceStats &st = perRow[size_t(y)];
        for (int x = 0; x < width; ++x) {
            const RayIntegral r = integrate(rays.pixelRay(x, y), clipPlanes, options.tolerance, &st);
            float *px = image.pixel(x, y);
            px[0] = float(r.color.r);
            px[1] = float(r.color.g);
            px[2] = float(r.color.b);
            px[3] = float(r.color.a);
            worstError[size_t(y)] = std::max(worstError[size_t(y)], r.errorEstimate);
        }
    });

    if (stats) {
        *stats = {};
        stats->toleranceRequested = options.tolerance;
        for (size_t y = 0; y < perRow.size(); ++y) {
            stats->intervals += perRow[y].intervals;
            stats->analyticFitError = std::max(stats->analyticFitError, perRow[y].analyticFitError);
            stats->toleranceReached = std::max(stats->toleranceReached, worstError[y]);
        }
        stats->renderSeconds = std::chrono::duration<double>(Clock::now() - start).count();
    }
    return image;
}

} // namespace volcast
