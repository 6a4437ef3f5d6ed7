#pragma once
// Continuous reconstruction of a volume in double precision, in index space, with the
// clamp-to-edge rule of docs/design.md: coordinates are clamped to [0, n − 1] per axis before
// interpolating, so the outer half-cells repeat the edge value.

#include "renderer/model/volume.hpp"

#include <vector>

namespace volcast {

// Cubic B-spline basis weights at fraction f in [0, 1) for samples i−1, i, i+1, i+2.
template <typename Real>
inline void cubicBSplineWeights(Real f, Real w[4]) {
    const Real g = Real(1) - f;
    w[0] = g * g * g / Real(6);
    w[1] = (Real(4) - Real(6) * f * f + Real(3) * f * f * f) / Real(6);
    w[2] = (Real(4) - Real(6) * g * g + Real(3) * g * g * g) / Real(6);
    w[3] = f * f * f / Real(6);
}

class TrilinearField {
  public:
    explicit TrilinearField(const Volume &v) : v_(v) {}
    double operator()(const Vec3d &indexPos) const;

  private:
    const Volume &v_;
};

// Prefiltered cubic B-spline: coefficients computed in double on construction.
class CubicBSplineField {
  public:
    explicit CubicBSplineField(const Volume &v);
    double operator()(const Vec3d &indexPos) const;
    const std::vector<double> &coefficients() const { return coeffs_; }

  private:
    Vec3i dims_;
    std::vector<double> coeffs_;
};

} // namespace volcast
