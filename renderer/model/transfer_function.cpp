#include "renderer/model/transfer_function.hpp"

#include <algorithm>
#include <stdexcept>

namespace volcast {

int TransferFunction::segmentOf(double v) const {
    if (points.empty() || v < points.front().value) return -1;
    auto it = std::upper_bound(points.begin(), points.end(), v,
                               [](double x, const ControlPoint &p) { return x < p.value; });
    return int(it - points.begin()) - 1;
}

Rgba TransferFunction::evaluate(double v) const {
    if (points.empty()) return {};
    if (std::isnan(v)) return {}; // NaN data is transparent, never propagated
    if (v <= points.front().value) {
        const auto &p = points.front();
        return {p.r, p.g, p.b, p.a};
    }
    if (v >= points.back().value) {
        const auto &p = points.back();
        return {p.r, p.g, p.b, p.a};
    }
    const int i = segmentOf(v);
    const auto &p0 = points[size_t(i)];
    const auto &p1 = points[size_t(i) + 1];
    const double w = (v - p0.value) / (p1.value - p0.value);
    auto lerp = [w](double x0, double x1) { return x0 + w * (x1 - x0); };
    return {lerp(p0.r, p1.r), lerp(p0.g, p1.g), lerp(p0.b, p1.b), lerp(p0.a, p1.a)};
}

void TransferFunction::validate() const {
    if (points.empty()) throw std::invalid_argument("transfer_function.points: needs at least one point");
    for (size_t i = 0; i < points.size(); ++i) {
        const auto &p = points[i];
        const std::string where = "transfer_function.points[" + std::to_string(i) + "]";
        if (!std::isfinite(p.value)) throw std::invalid_argument(where + ": value must be finite");
        for (double c : {p.r, p.g, p.b, p.a})
            if (!(c >= 0 && c <= 1))
                throw std::invalid_argument(where + ": r, g, b, a must be in [0, 1]");
        if (i > 0 && !(p.value > points[i - 1].value))
            throw std::invalid_argument(where + ": values must be strictly increasing");
    }
    if (opacityUnit && !(std::isfinite(*opacityUnit) && *opacityUnit > 0))
        throw std::invalid_argument("transfer_function.opacity_unit: must be a positive number");
}

std::vector<std::string> transferFunctionPresetNames() {
    return {"ct_bone", "ct_soft_tissue", "ct_angiography", "mr", "micro_ct"};
}

TransferFunction presetTransferFunction(std::string_view name, const ValueRange &range) {
    TransferFunction tf;
    // Hounsfield-unit presets follow the usual windows of CT viewers.
    if (name == "ct_bone") {
        tf.points = {{-1000, 0, 0, 0, 0}, {150, 0.9, 0.6, 0.4, 0},  {300, 0.95, 0.85, 0.7, 0.3},
                     {1000, 1, 1, 0.95, 0.8}, {3000, 1, 1, 1, 0.9}};
    } else if (name == "ct_soft_tissue") {
        tf.points = {{-1000, 0, 0, 0, 0}, {-600, 0.6, 0.3, 0.25, 0}, {-100, 0.8, 0.45, 0.35, 0.05},
                     {60, 0.95, 0.6, 0.5, 0.15}, {300, 1, 0.9, 0.85, 0.4}, {3000, 1, 1, 1, 0.8}};
    } else if (name == "ct_angiography") {
        tf.points = {{-1000, 0, 0, 0, 0}, {120, 0.7, 0.1, 0.05, 0}, {250, 0.9, 0.3, 0.2, 0.4},
                     {500, 1, 0.9, 0.8, 0.8}, {3000, 1, 1, 1, 0.9}};
    } else if (name == "mr" || name == "micro_ct") {
        // Relative presets: MR intensities and micro-CT grey values have no fixed units.
        const double lo = range.min, span = std::max(double(range.max) - double(range.min), 1e-6);
        auto at = [&](double f) { return lo + f * span; };
        if (name == "mr")
            tf.points = {{at(0.0), 0, 0, 0, 0}, {at(0.12), 0.6, 0.4, 0.3, 0},
                         {at(0.35), 0.9, 0.7, 0.6, 0.15}, {at(0.7), 1, 0.95, 0.9, 0.4},
                         {at(1.0), 1, 1, 1, 0.6}};
        else
            tf.points = {{at(0.0), 0, 0, 0, 0}, {at(0.3), 0.8, 0.6, 0.4, 0},
                         {at(0.5), 0.9, 0.8, 0.7, 0.5}, {at(1.0), 1, 1, 1, 0.95}};
    } else {
        std::string known;
        for (const auto &n : transferFunctionPresetNames()) known += (known.empty() ? "" : ", ") + n;
        throw std::invalid_argument("unknown transfer function preset '" + std::string(name) +
                                    "' (known: " + known + ")");
    }
    return tf;
}

} // namespace volcast
