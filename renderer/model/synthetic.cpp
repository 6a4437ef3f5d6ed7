#include "renderer/model/synthetic.hpp"

#include <algorithm>
#include <cmath>
#include <stdexcept>

namespace volcast {

SyntheticVolume sampleField(std::string name, Vec3i dims, Vec3d spacing, Vec3d origin,
                            std::function<double(const Vec3d &)> field) {
    SyntheticVolume s;
    Volume &v = s.volume;
    v.name = std::move(name);
    v.dims = dims;
    v.spacing = spacing;
    v.origin = origin;
    v.sourceType = VoxelType::Float32;
    v.voxels.resize(v.voxelCount());
    for (int64_t k = 0; k < dims.z; ++k)
        for (int64_t j = 0; j < dims.y; ++j)
            for (int64_t i = 0; i < dims.x; ++i)
                v.voxels[v.index(i, j, k)] = float(field(v.worldFromIndex(Vec3d(Vec3i{i, j, k}))));
    computeStatistics(v);
    s.field = std::move(field);
    return s;
}

namespace {
Vec3d centreOf(Vec3i dims, Vec3d spacing) { return mul(Vec3d(dims - Vec3i{1, 1, 1}), spacing) * 0.5; }
} // namespace

SyntheticVolume makeConstantBox(Vec3i dims, Vec3d spacing, double value) {
    return sampleField("constant_box", dims, spacing, {}, [value](const Vec3d &) { return value; });
}

SyntheticVolume makeLinearRamp(Vec3i dims, Vec3d spacing, double v0, double v1) {
    const double lengthX = double(dims.x - 1) * spacing.x;
    const double slope = lengthX > 0 ? (v1 - v0) / lengthX : 0;
    return sampleField("linear_ramp", dims, spacing, {},
                       [v0, slope](const Vec3d &p) { return v0 + slope * p.x; });
}

SyntheticVolume makeSphere(Vec3i dims, Vec3d spacing, double radius, double edge, double value) {
    const Vec3d c = centreOf(dims, spacing);
    return sampleField("sphere", dims, spacing, {}, [=](const Vec3d &p) {
        // Smooth step across the surface so the field is band-limited enough to sample.
        return value * 0.5 * (1 - std::tanh((length(p - c) - radius) / edge));
    });
}

SyntheticVolume makeGaussianBlob(Vec3i dims, Vec3d spacing, double sigma, double peak) {
    const Vec3d c = centreOf(dims, spacing);
    return sampleField("gaussian_blob", dims, spacing, {}, [=](const Vec3d &p) {
        const Vec3d d = p - c;
        return peak * std::exp(-dot(d, d) / (2 * sigma * sigma));
    });
}

SyntheticVolume makeThinTube(Vec3i dims, Vec3d spacing, Vec3d axis, double sigma, double peak) {
    const Vec3d c = centreOf(dims, spacing);
    const Vec3d a = normalize(axis);
    return sampleField("thin_tube", dims, spacing, {}, [=](const Vec3d &p) {
        const Vec3d d = p - c;
        const Vec3d radial = d - a * dot(d, a);
        return peak * std::exp(-dot(radial, radial) / (2 * sigma * sigma));
    });
}

SyntheticVolume makeDemoPhantom(int64_t n) {
    const double s = 1.0;
    const double h = double(n - 1) * 0.5;
    const Vec3d c{h, h, h};
    auto tube = [](const Vec3d &p, const Vec3d &from, const Vec3d &to, double sigma) {
        // Distance to a segment, Gaussian profile: a vessel.
        const Vec3d ab = to - from;
        const double t = std::clamp(dot(p - from, ab) / dot(ab, ab), 0.0, 1.0);
        const Vec3d d = p - (from + ab * t);
        return std::exp(-dot(d, d) / (2 * sigma * sigma));
    };
    auto smoothStep = [](double x, double w) { return 0.5 * (1 - std::tanh(x / w)); };
    return sampleField("demo", {n, n, n}, {s, s, s}, {}, [=](const Vec3d &p) {
        const double u = double(n) / 128; // features scale with the grid
        const Vec3d d = p - c;
        // Ellipsoidal head: radius in a normalized metric.
        const double r = length(Vec3d{d.x / 1.0, d.y / 1.15, d.z / 0.9});
        const double skin = smoothStep(r - 56 * u, 1.5 * u);
        const double brain = smoothStep(r - 44 * u, 1.5 * u);
        const double skull = skin * (1 - smoothStep(r - 49 * u, 1.2 * u));
        double value = 40 * skin + 30 * brain + 150 * skull;
        // Ventricles: two dark blobs.
        for (double sx : {-1.0, 1.0}) {
            const Vec3d v = d - Vec3d{sx * 9 * u, 4 * u, 0};
            value -= 25 * std::exp(-dot(v, v) / (2 * 25 * u * u));
        }
        // Vessels: a small tree of thin tubes, bright like contrast-enhanced arteries.
        const Vec3d root = c + Vec3d{0, -30 * u, -20 * u};
        const Vec3d fork = c + Vec3d{0, -5 * u, 0};
        double vessels = tube(p, root, fork, 1.6 * u);
        vessels = std::max(vessels, tube(p, fork, c + Vec3d{-25 * u, 20 * u, 15 * u}, 1.2 * u));
        vessels = std::max(vessels, tube(p, fork, c + Vec3d{25 * u, 22 * u, 10 * u}, 1.2 * u));
        vessels = std::max(vessels, tube(p, fork, c + Vec3d{3 * u, 30 * u, -22 * u}, 1.0 * u));
        // An aneurysm on the left branch.
        const Vec3d a = p - (c + Vec3d{-14 * u, 9 * u, 8 * u});
        vessels = std::max(vessels, smoothStep(length(a) - 4 * u, 0.8 * u));
        value = std::max(value, 0.0) + 200 * vessels * brain;
        return std::min(value, 255.0);
    });
}

std::vector<std::string> builtinVolumeNames() {
    return {"demo", "constant_box", "linear_ramp", "sphere", "gaussian_blob", "thin_tube"};
}

SyntheticVolume makeBuiltinVolume(std::string_view name) {
    const Vec3i d{64, 64, 64};
    const Vec3d s{1, 1, 1};
    if (name == "demo") return makeDemoPhantom(128);
    if (name == "constant_box") return makeConstantBox(d, s, 100);
    if (name == "linear_ramp") return makeLinearRamp(d, s, 0, 255);
    if (name == "sphere") return makeSphere(d, s, 24, 1.5, 200);
    if (name == "gaussian_blob") return makeGaussianBlob(d, s, 10, 255);
    if (name == "thin_tube") return makeThinTube(d, s, {1, 0.7, 0.3}, 1.0, 255);
    std::string known;
    for (const auto &n : builtinVolumeNames()) known += (known.empty() ? "" : ", ") + n;
    throw std::invalid_argument("unknown built-in volume 'builtin:" + std::string(name) +
                                "' (known: " + known + ")");
}

} // namespace volcast
