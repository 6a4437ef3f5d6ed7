#pragma once
// Transfer function of docs/design.md: control points {value, r, g, b, a} in data units,
// piecewise linear between points and clamped outside. `a` is the opacity of a segment
// of length opacityUnit (world units), so the extinction is tau = -ln(1 - a) / opacityUnit.

#include "renderer/model/volume.hpp"

#include <cmath>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

namespace volcast {

struct ControlPoint {
    double value = 0;
    double r = 0, g = 0, b = 0, a = 0;
    bool operator==(const ControlPoint &) const = default;
};

struct Rgba {
    double r = 0, g = 0, b = 0, a = 0;
};

struct TransferFunction {
    std::vector<ControlPoint> points;     // strictly increasing values, components in [0, 1]
    std::optional<double> opacityUnit;    // world units; unset means the smallest voxel spacing

    // Colour (not premultiplied) and opacity per opacityUnit at data value v.
    Rgba evaluate(double v) const;
    // Index of the segment [points[i], points[i+1]] containing v, or -1 / size-1 outside.
    int segmentOf(double v) const;
    double resolvedOpacityUnit(const Volume &v) const {
        return opacityUnit ? *opacityUnit : v.smallestSpacing();
    }
    // Throws std::invalid_argument naming the problem if the points break the contract.
    void validate() const;
    bool operator==(const TransferFunction &) const = default;
};

// Extinction coefficient (per world unit) of opacity a per unit length u: -ln(1 - a) / u.
// Infinite for a = 1.
template <typename Real>
Real extinction(Real a, Real opacityUnit) {
    return -std::log1p(-a) / opacityUnit;
}

// Opacity correction (paper Eq. 3): alpha = 1 - (1 - a)^(d / u), written as
// -expm1((d/u)·log1p(-a)) so it stays exact for tiny d, for a near 0 and for a = 1.
template <typename Real>
Real correctedOpacity(Real a, Real dOverU) {
    if (dOverU <= Real(0)) return Real(0);
    if (a >= Real(1)) return Real(1);
    return -std::expm1(dOverU * std::log1p(-a));
}

// Named presets: "ct_bone", "ct_soft_tissue", "ct_angiography" (Hounsfield units),
// "mr", "micro_ct" (placed on the volume's value range, which MR and micro-CT lack units for).
std::vector<std::string> transferFunctionPresetNames();
TransferFunction presetTransferFunction(std::string_view name, const ValueRange &range);

} // namespace volcast
