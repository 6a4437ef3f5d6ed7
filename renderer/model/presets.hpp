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
// W 1500 / L −600, angiography W 600 / L 300). MR and micro-CT data have no units: their
// windows are fractions of the volume's robust range (the 0.5th to the 99.5th percentile of
// the voxels above the background), resolved on the loaded volume. CT stored as grey values
// (a scan windowed to 8 bits, a raw CT without its rescale) gets the CT presets too, placed
// as if its robust range spanned −1000 HU (air) to +1000 HU (dense bone): the windowing a
// grey-value export of a body CT typically has, so lung, soft tissue and bone fall near
// where they do in Hounsfield units.
//
// Every preset of every modality is resolved on every scan (a client lets the user pick
// another modality than the one chosen here); the chosen modality's default comes first.

#include "renderer/model/volume.hpp"

#include <array>
#include <string>
#include <string_view>
#include <vector>

namespace volcast {

// What the data is, and how that was decided: the line a client shows the user.
struct ModalityChoice {
    std::string modality;       // "CT", "MR", or "micro-CT" (grey values)
    bool hounsfield = false;    // CT whose values are Hounsfield units (else grey values)
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
    bool shading = false;                        // gradient Phong lighting (renderer/model/phong_constants.h)
};

// The modality a volume's header states (Volume::modality: a DICOM or NRRD-key code, or the
// words of an NRRD content or NIfTI description), else inferred from its voxel type, value
// range and histogram, and from words in its name ("mr", "t1", "ct", "cta", ...).
ModalityChoice chooseModality(const Volume &volume, std::string_view name);

// Every preset of every modality, resolved on this volume: the chosen default first, then
// the rest of the chosen modality's, then the other modalities' (each modality's own
// default first among its presets).
std::vector<ResolvedPreset> presetsFor(const Volume &volume, const ModalityChoice &choice);

// The modalities presets exist for, the chosen one first.
std::vector<std::string> modalitiesFor(const ModalityChoice &choice);

// The robust value range the grey-value presets are placed on (see the top of this file).
ValueRange robustRange(const Volume &volume);

} // namespace volcast
