#pragma once
// The paper's Figure-5 configurations A–F as quality switches, and the scans the studies
// render with a transfer function each.

#include "renderer/model/scene.hpp"
#include "renderer/model/volume.hpp"

#include <filesystem>
#include <string>
#include <vector>

namespace volcast::bench {

struct Configuration {
    std::string key;        // "A" ... "F"
    std::string label;      // the paper's words
    bool preintegrated = false;
    bool shading = false;
    bool cubic = false;
    bool doubledVolume = false; // D: the same scan on a 2n − 1 grid (8× the voxels)
};
const std::vector<Configuration> &paperConfigurations();

// `accelerated`: our interactive defaults (empty-space skipping, early termination at 0.99);
// otherwise as the paper measured Figure 5, with neither.
Quality configurationQuality(const Configuration &c, double step, bool accelerated);

struct Scan {
    std::string name;       // file stem in the data folder
    TransferFunction tf;
};
// bonsai, aneurism, cranium_ct, engine: a transfer function each that shows the object.
Scan scanByName(const std::string &name, const Volume &volume);

} // namespace volcast::bench
