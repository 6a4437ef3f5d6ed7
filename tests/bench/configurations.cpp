#include "tests/bench/configurations.hpp"

#include <stdexcept>

namespace volcast::bench {

const std::vector<Configuration> &paperConfigurations() {
    static const std::vector<Configuration> configs = {
        {"A", "simple", false, false, false, false},
        {"B", "pre-integrated", true, false, false, false},
        {"C", "pre-integrated, Phong", true, true, false, false},
        {"D", "simple, 8× voxels", false, false, false, true},
        {"E", "tricubic", false, false, true, false},
        {"F", "pre-integrated tricubic", true, false, true, false},
    };
    return configs;
}

Quality configurationQuality(const Configuration &c, double step, bool accelerated) {
    Quality q;
    q.step = step;
    q.preintegrated = c.preintegrated;
    q.shading = c.shading;
    q.interpolation = c.cubic ? Interpolation::Cubic : Interpolation::Linear;
    q.jitter = false;
    q.boundarySegment = true;
    q.emptySpaceSkipping = accelerated;
    q.earlyTermination = accelerated ? 0.99 : 1.0;
    return q;
}

Scan scanByName(const std::string &name, const Volume &volume) {
    Scan s{name, {}};
    if (name == "bonsai") // leaves translucent green, trunk and pot opaque (as tests/bench/remedies.py)
        s.tf.points = {{0, 0, 0, 0, 0}, {40, 0.3, 0.6, 0.2, 0}, {60, 0.4, 0.8, 0.3, 0.1}, {120, 0.8, 0.6, 0.3, 0.6},
                       {255, 1, 1, 1, 0.9}};
    else if (name == "aneurism") // vessels, from faint to opaque
        s.tf.points = {{0, 0, 0, 0, 0}, {60, 0.9, 0.3, 0.2, 0}, {120, 1, 0.85, 0.7, 0.5}, {255, 1, 1, 1, 0.8}};
    else if (name == "cranium_ct") // the CT bone preset: skull
        s.tf = presetTransferFunction("ct_bone", volume.range);
    else if (name == "engine") // translucent block, denser metal
        s.tf.points = {{0, 0, 0, 0, 0}, {50, 0.8, 0.7, 0.5, 0}, {140, 0.95, 0.85, 0.65, 0.12}, {255, 1, 1, 1, 0.2}};
    else
        throw std::invalid_argument("no transfer function for scan '" + name +
                                    "' (known: bonsai, aneurism, cranium_ct, engine)");
    return s;
}

} // namespace volcast::bench
