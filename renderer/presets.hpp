#pragma once
// The display presets a volume opens with, and the modality they are chosen by.
//
// One table (presets.cpp) defines every preset; the server resolves the ones that suit a
// volume into data units and sends them with the volume's information, so the web and the
// scripted clients show the same presets and need no copy of the table.
//
// A preset is a window/level and a curve across that window: the curve's points are at
// `level − window/2 + t·window` for t in [0, 1], so the window/level a client reads off the
// points (first to last point) is the preset's own. CT presets are in Hounsfield units with
// the usual radiology windows (bone W 2000 / L 400, soft tissue W 400 / L 40, lung
// W 1500 / L −600). MR and grey-value (micro-CT, non-HU CT) data have no units: their
// windows are fractions of the volume's robust range (the 0.5th to the 99.5th percentile of
// the voxels above the background), resolved on the loaded volume.

#include "renderer/volume.hpp"

#include <array>
#include <string>
#include <string_view>
#include <vector>

namespace volcast {

// What the data is, and how that was decided: the line a client shows the user.
struct ModalityChoice {
    std::string modality;       // "CT" (Hounsfield units), "MR", or "micro-CT" (grey values)
    std::string source;         // "file" (the header states it) or "inferred"
    std::string reason;         // one sentence: why this modality and this preset
    std::string defaultPreset;  // name of the preset the volume opens with
};

struct ResolvedPreset {
    std::string name;    // "ct.bone", "mr.t1_brain", ...
    std::string label;   // "CT bone", for menus
    std::string modality;
    double window = 1, level = 0;                // data units
    std::vector<std::array<double, 5>> points;   // [value, r, g, b, a], data units
    bool shading = false;                        // gradient Phong lighting (renderer/phong_constants.h)
};

// The modality a volume's header states (Volume::modality), else inferred from its voxel
// type, value range and histogram, and from words in its name ("mr", "t1", "cta", ...).
ModalityChoice chooseModality(const Volume &volume, std::string_view name);

// The presets of the chosen modality, resolved on this volume, the default first.
std::vector<ResolvedPreset> presetsFor(const Volume &volume, const ModalityChoice &choice);

// The robust value range the grey-value presets are placed on (see the top of this file).
ValueRange robustRange(const Volume &volume);

} // namespace volcast
