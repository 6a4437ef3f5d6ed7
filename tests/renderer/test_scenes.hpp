#pragma once
// Small scene pieces several test files use.

#include "renderer/model/camera.hpp"
#include "renderer/model/scene.hpp"
#include "renderer/model/synthetic.hpp"
#include "renderer/model/transfer_function.hpp"
#include "renderer/model/volume.hpp"

#include <algorithm>
#include <limits>
#include <random>

namespace volcast::test {

// Chord of a ray through the axis-aligned cell-extent box, computed independently of the
// renderer: the textbook slab test in world space.
inline double chordLength(const Volume &v, const Ray &ray) {
    double t0 = 0, t1 = std::numeric_limits<double>::infinity();
    for (int a = 0; a < 3; ++a) {
        const double lo = v.origin[a] - 0.5 * v.spacing[a];
        const double hi = v.origin[a] + (double(v.dims[a]) - 0.5) * v.spacing[a];
        if (ray.dir[a] == 0) {
            if (ray.origin[a] < lo || ray.origin[a] > hi) return 0;
            continue;
        }
        double ta = (lo - ray.origin[a]) / ray.dir[a], tb = (hi - ray.origin[a]) / ray.dir[a];
        if (ta > tb) std::swap(ta, tb);
        t0 = std::max(t0, ta);
        t1 = std::min(t1, tb);
    }
    return std::max(0.0, t1 - t0);
}

// Every quality switch off but the partial boundary segment, at `step`: a test turns on
// only what it measures.
inline Quality plainQuality(double step) {
    Quality q;
    q.step = step;
    q.earlyTermination = 1;
    q.emptySpaceSkipping = false;
    q.boundarySegment = true;
    return q;
}

// The same colour and opacity at every data value.
inline TransferFunction constantTf(double r, double g, double b, double a, double unit) {
    TransferFunction tf;
    tf.points = {{-1e6, r, g, b, a}, {1e6, r, g, b, a}};
    tf.opacityUnit = unit;
    return tf;
}

// A perspective camera looking at the volume from an oblique direction, with a tilted up.
inline Camera obliqueCamera(const Volume &v, double fovYDeg) {
    Camera c;
    c.eye = v.center() + Vec3d{41, 27, 55};
    c.target = v.center() + Vec3d{0.3, -0.2, 0.1};
    c.up = {0.1, 1, 0.2};
    c.fovYDeg = fovYDeg;
    return c;
}

// A smooth Gaussian blob (24³) and a transfer function with three visible bands: the scene
// the remedy tests of both back ends share.
inline TransferFunction blobTf() {
    TransferFunction tf;
    tf.points = {{0, 0, 0, 0, 0}, {40, 0, 0, 0, 0}, {90, 1, 0.4, 0.1, 0.15}, {150, 0.3, 0.7, 1, 0.4},
                 {220, 1, 1, 1, 0.7}};
    return tf;
}

// White noise in [−100, 100]: the worst case for bounds on a reconstruction's values and slopes.
inline Volume noiseVolume(Vec3i dims, unsigned seed) {
    Volume v;
    v.name = "noise";
    v.dims = dims;
    v.voxels.resize(v.voxelCount());
    std::mt19937 rng(seed);
    std::uniform_real_distribution<float> u(-100, 100);
    for (float &x : v.voxels) x = u(rng);
    computeStatistics(v);
    return v;
}

inline const SyntheticVolume &blob() {
    static const SyntheticVolume v = makeGaussianBlob({24, 24, 24}, {1, 1, 1}, 4, 220);
    return v;
}

} // namespace volcast::test
