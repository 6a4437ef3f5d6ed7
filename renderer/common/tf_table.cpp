#include "renderer/common/tf_table.hpp"

#include <algorithm>
#include <cmath>

namespace volcast {

namespace {

TfTable sampleTable(const TransferFunction &tf, int entries) {
    TfTable t;
    const double lo = tf.points.front().value, hi = tf.points.back().value;
    t.minValue = lo;
    t.scale = hi > lo ? double(entries - 1) / (hi - lo) : 0;
    t.rgba.resize(size_t(entries) * 4);
    for (int i = 0; i < entries; ++i) {
        const Rgba c = tf.evaluate(hi > lo ? lo + i / t.scale : lo);
        t.rgba[size_t(i) * 4 + 0] = float(c.r);
        t.rgba[size_t(i) * 4 + 1] = float(c.g);
        t.rgba[size_t(i) * 4 + 2] = float(c.b);
        t.rgba[size_t(i) * 4 + 3] = c.a >= 1 ? kOpaqueSigma : float(std::min(-std::log1p(-c.a), double(kOpaqueSigma)));
    }
    return t;
}

Rgba lookup(const TfTable &t, double v) {
    const double x = std::clamp((v - t.minValue) * t.scale, 0.0, double(t.entries() - 1));
    const int i = std::min(int(x), t.entries() - 2);
    const double f = x - i;
    const float *a = &t.rgba[size_t(i) * 4], *b = a + 4;
    const double sigma = a[3] + f * (double(b[3]) - a[3]);
    return {a[0] + f * (b[0] - a[0]), a[1] + f * (b[1] - a[1]), a[2] + f * (b[2] - a[2]), -std::expm1(-sigma)};
}

// Colour is exact at the entries and linear between, like the function away from its control
// points; sigma is exact at the entries and convex where a is linear, so both channels' worst
// errors sit at control points and between entries: check there, in opacity.
double measureError(const TransferFunction &tf, const TfTable &t) {
    double worst = 0;
    auto check = [&](double v) {
        const Rgba e = tf.evaluate(v), g = lookup(t, v);
        worst = std::max({worst, std::fabs(e.r - g.r), std::fabs(e.g - g.g), std::fabs(e.b - g.b), std::fabs(e.a - g.a)});
    };
    for (const auto &p : tf.points) check(p.value);
    if (t.scale > 0)
        for (int i = 0; i + 1 < t.entries(); ++i) check(t.minValue + (i + 0.5) / t.scale);
    return worst;
}

} // namespace

TfTable buildTfTable(const TransferFunction &tf, double bound, int maxEntries) {
    TfTable t;
    for (int entries = 256;; entries *= 2) {
        t = sampleTable(tf, entries);
        t.maxError = measureError(tf, t);
        if (t.maxError <= bound || entries >= maxEntries) return t;
    }
}

} // namespace volcast
