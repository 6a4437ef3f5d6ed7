#include "renderer/model/presets.hpp"

#include <algorithm>
#include <cctype>
#include <cmath>
#include <cstdio>
#include <initializer_list>
#include <set>

namespace volcast {

namespace {

// One point of a preset's curve: t across the window (0 at level − window/2, 1 at
// level + window/2), colour and opacity as docs/design.md's transfer-function points.
struct CurvePoint {
    double t, r, g, b, a;
};

struct PresetDef {
    const char *name;
    const char *label;
    const char *modality;
    bool hounsfield;        // window/level in HU; otherwise fractions of the robust range
    double window, level;
    bool shading;
    std::initializer_list<CurvePoint> curve;
};

// The table. Every curve starts at t = 0 and ends at t = 1, values outside clamp to the
// ends (as every transfer function does), so above the window the last opacity holds.
const PresetDef kPresets[] = {
    {"ct.bone", "CT bone", "CT", true, 2000, 400, true,
     {{0, 0, 0, 0, 0}, {0.375, 0.9, 0.6, 0.4, 0}, {0.45, 0.95, 0.85, 0.7, 0.3}, {0.7, 1, 1, 0.95, 0.75},
      {1, 1, 1, 1, 0.9}}},
    {"ct.soft_tissue", "CT soft tissue", "CT", true, 400, 40, true,
     {{0, 0, 0, 0, 0}, {0.15, 0.85, 0.65, 0.45, 0.02}, {0.45, 0.8, 0.35, 0.3, 0.12}, {0.65, 0.9, 0.45, 0.4, 0.3},
      {1, 1, 0.9, 0.85, 0.6}}},
    {"ct.lung", "CT lung", "CT", true, 1500, -600, true,
     {{0, 0, 0, 0, 0}, {0.25, 0.8, 0.5, 0.45, 0}, {0.35, 0.85, 0.55, 0.5, 0.04}, {0.5, 0.9, 0.6, 0.55, 0.08},
      {0.7, 0.9, 0.6, 0.55, 0}, {1, 0.9, 0.6, 0.55, 0}}},
    {"ct.angiography", "CT angiography", "CT", true, 600, 300, true,
     {{0, 0, 0, 0, 0}, {0.25, 0.8, 0.1, 0.05, 0}, {0.42, 0.9, 0.25, 0.15, 0.35}, {0.7, 1, 0.8, 0.7, 0.7},
      {1, 1, 1, 1, 0.85}}},
    {"mr.t1_brain", "MR T1 brain", "MR", false, 1.0, 0.55, true,
     {{0, 0, 0, 0, 0}, {0.2, 0.55, 0.4, 0.35, 0}, {0.45, 0.85, 0.7, 0.6, 0.05}, {0.7, 0.95, 0.85, 0.8, 0.15},
      {1, 1, 1, 1, 0.35}}},
    // T2: fluid (CSF) is the brightest tissue; the curve lifts it over grey and white matter.
    {"mr.t2_brain", "MR T2 brain", "MR", false, 1.0, 0.5, true,
     {{0, 0, 0, 0, 0}, {0.3, 0.5, 0.45, 0.5, 0}, {0.55, 0.75, 0.7, 0.8, 0.04}, {0.8, 0.85, 0.9, 1, 0.2},
      {1, 0.95, 0.97, 1, 0.4}}},
    {"mr.angiography", "MR angiography", "MR", false, 0.5, 0.75, true,
     {{0, 0, 0, 0, 0}, {0.4, 0.8, 0.2, 0.1, 0}, {0.7, 1, 0.5, 0.4, 0.4}, {1, 1, 0.9, 0.8, 0.8}}},
    {"micro_ct.default", "Micro-CT", "micro-CT", false, 0.8, 0.6, true,
     {{0, 0, 0, 0, 0}, {0.25, 0.8, 0.6, 0.4, 0}, {0.5, 0.9, 0.8, 0.7, 0.25}, {1, 1, 1, 1, 0.8}}},
    {"micro_ct.vessels", "Micro-CT vessels", "micro-CT", false, 0.5, 0.75, true,
     {{0, 0, 0, 0, 0}, {0.4, 0.8, 0.2, 0.1, 0}, {0.7, 1, 0.5, 0.4, 0.4}, {1, 1, 0.9, 0.8, 0.8}}},
};

// The modalities presets exist for, in the table's order.
const char *const kModalities[] = {"CT", "MR", "micro-CT"};

// Grey-value CT: the robust range is taken to span these Hounsfield units (presets.hpp).
constexpr double kGreyCtLowHu = -1000, kGreyCtHighHu = 1000;

// Words that name a modality, in a file's description or its name.
const std::initializer_list<const char *> kCtWords = {"ct", "cta", "cbct", "cect", "hrct", "mdct"};
const std::initializer_list<const char *> kMrWords = {"mr",   "mri", "t1",  "t2",  "flair", "mra",
                                                      "dwi",  "pd",  "tof", "mprage", "spgr", "bold"};
const std::initializer_list<const char *> kMicroCtWords = {"microct", "uct", "micro"};
const std::initializer_list<const char *> kAngioWords = {"cta",      "mra",    "angio", "angiography", "aneurism",
                                                         "aneurysm", "avm",    "carotid", "vessels",   "tof"};

// The value below which `fraction` of the counted voxels lie, interpolated in the bin.
double percentile(const Histogram &h, double fraction, size_t firstBin) {
    uint64_t total = 0;
    for (size_t i = firstBin; i < h.counts.size(); ++i) total += h.counts[i];
    const double binWidth = (double(h.range.max) - double(h.range.min)) / double(Histogram::kBins);
    if (total == 0 || !(binWidth > 0)) return h.range.min;
    const double want = fraction * double(total);
    double below = 0;
    for (size_t i = firstBin; i < h.counts.size(); ++i) {
        const double c = double(h.counts[i]);
        if (below + c >= want && c > 0)
            return h.range.min + binWidth * (double(i) + (want - below) / c);
        below += c;
    }
    return h.range.max;
}

double fractionBetween(const Histogram &h, double lo, double hi) {
    uint64_t total = 0, inside = 0;
    const double binWidth = (double(h.range.max) - double(h.range.min)) / double(Histogram::kBins);
    for (size_t i = 0; i < h.counts.size(); ++i) {
        total += h.counts[i];
        const double centre = h.range.min + binWidth * (double(i) + 0.5);
        if (centre >= lo && centre <= hi) inside += h.counts[i];
    }
    return total ? double(inside) / double(total) : 0;
}

std::set<std::string> wordsOf(std::string_view name) {
    std::set<std::string> words;
    std::string word;
    for (char c : name) {
        if (std::isalnum(static_cast<unsigned char>(c))) {
            word += char(std::tolower(static_cast<unsigned char>(c)));
        } else if (!word.empty()) {
            words.insert(word);
            word.clear();
        }
    }
    if (!word.empty()) words.insert(word);
    return words;
}

// The word of the name that says something, or empty.
std::string nameSays(const std::set<std::string> &words, std::initializer_list<const char *> candidates,
                     bool prefix = false) {
    for (const std::string &w : words)
        for (const char *c : candidates)
            if (prefix ? w.rfind(c, 0) == 0 : w == c) return w;
    return {};
}

bool isSigned(VoxelType t) {
    return t == VoxelType::Int8 || t == VoxelType::Int16 || t == VoxelType::Int32 || t == VoxelType::Float32 ||
           t == VoxelType::Float64;
}

// A number for a sentence: up to `digits` significant digits.
std::string number(double x, int digits = 4) {
    char buffer[48];
    std::snprintf(buffer, sizeof buffer, "%.*g", digits, x);
    return buffer;
}

} // namespace

ValueRange robustRange(const Volume &volume) {
    const Histogram &h = volume.histogram;
    if (h.counts.size() != size_t(Histogram::kBins)) return volume.range;
    uint64_t total = 0;
    for (uint64_t c : h.counts) total += c;
    // A background (air around a scan, zeros outside a micro-CT's field) fills the lowest
    // bin; it would pull the percentiles down onto itself.
    const size_t firstBin = total && double(h.counts[0]) > 0.1 * double(total) ? 1 : 0;
    ValueRange r{float(percentile(h, 0.005, firstBin)), float(percentile(h, 0.995, firstBin))};
    if (!(r.max > r.min)) return volume.range;
    return r;
}

namespace {

bool looksHounsfield(const Volume &volume, double *airFraction = nullptr) {
    const double air = fractionBetween(volume.histogram, -1100, -900);
    if (airFraction) *airFraction = air;
    return isSigned(volume.sourceType) && volume.range.min <= -900 && volume.range.max >= 200 && air >= 0.005;
}

std::string defaultPresetOf(const std::string &modality, bool angio) {
    if (modality == "CT") return angio ? "ct.angiography" : "ct.bone";
    if (modality == "MR") return angio ? "mr.angiography" : "mr.t1_brain";
    return angio ? "micro_ct.vessels" : "micro_ct.default";
}

// A modality named by a word of `words`: the micro-CT words before the CT ones ("microct").
std::string modalityOfWords(const std::set<std::string> &words, std::string *word) {
    for (const auto &[modality, list] : {std::pair{"micro-CT", kMicroCtWords}, std::pair{"CT", kCtWords},
                                         std::pair{"MR", kMrWords}}) {
        const std::string w = nameSays(words, list);
        if (!w.empty()) {
            *word = w;
            return modality;
        }
    }
    return {};
}

} // namespace

ModalityChoice chooseModality(const Volume &volume, std::string_view name) {
    const std::set<std::string> nameWords = wordsOf(name);
    const bool description = volume.modalityField == "NRRD content" || volume.modalityField == "NIfTI descrip";
    const std::set<std::string> describedWords = description ? wordsOf(volume.modality) : std::set<std::string>{};
    std::string angioWord = nameSays(describedWords, kAngioWords);
    std::string angioWhere = "the file's description";
    if (angioWord.empty()) {
        angioWord = nameSays(nameWords, kAngioWords);
        angioWhere = "the name";
    }
    double air = 0;
    const bool hounsfield = looksHounsfield(volume, &air);
    const std::string typeName(voxelTypeName(volume.sourceType));
    const auto pick = [&](std::string modality, std::string source, std::string reason) {
        ModalityChoice c{std::move(modality), false, std::move(source), std::move(reason), {}};
        c.defaultPreset = defaultPresetOf(c.modality, !angioWord.empty());
        if (!angioWord.empty()) c.reason += "; " + angioWhere + " says '" + angioWord + "': angiography preset";
        return c;
    };
    // CT: in Hounsfield units when the values look so (air near -1000), else grey values.
    const auto ct = [&](std::string source, std::string reason) {
        ModalityChoice c = pick("CT", std::move(source), std::move(reason));
        c.hounsfield = hounsfield;
        c.reason += hounsfield ? "; values in Hounsfield units"
                               : "; the " + typeName + " values are not Hounsfield units (no air near -1000): " +
                                     "CT presets placed on the robust range " + number(double(robustRange(volume).min)) +
                                     " .. " + number(double(robustRange(volume).max));
        return c;
    };

    if (!volume.modality.empty() && !description) {
        const std::string m = volume.modality;
        const std::string where =
            volume.modalityField == "NRRD key" ? "the NRRD header's key 'modality'" : "the DICOM header";
        if (m == "CT") {
            // A DICOM CT's pixel data is rescaled to Hounsfield units by the loader.
            if (volume.modalityField.empty() || volume.modalityField == "DICOM") {
                ModalityChoice c = pick("CT", "file", where + " says modality CT (Hounsfield units)");
                c.hounsfield = true;
                return c;
            }
            return ct("file", where + " says modality CT");
        }
        if (m == "MR") return pick("MR", "file", where + " says modality MR");
        return pick("micro-CT", "file",
                    where + " says modality " + m + ", which has no presets of its own: grey-value presets");
    }
    if (description) {
        std::string word;
        const std::string m = modalityOfWords(describedWords, &word);
        const std::string said = "the " + volume.modalityField + " '" + volume.modality + "' says '" + word + "'";
        if (m == "CT") return ct("file", said + ": CT");
        if (m == "MR") return pick("MR", "file", said + ": MR");
        if (m == "micro-CT") return pick("micro-CT", "file", said + ": micro-CT (grey values)");
    }

    if (hounsfield) {
        ModalityChoice c = pick("CT", "inferred",
                                "no modality in the file; " + typeName + " values from " +
                                    number(double(volume.range.min)) + " with " + number(100 * air, 2) +
                                    "% of voxels near -1000 (air): CT in Hounsfield units");
        c.hounsfield = true;
        return c;
    }
    std::string word;
    const std::string byName = modalityOfWords(nameWords, &word);
    if (byName == "MR")
        return pick("MR", "inferred",
                    std::string("no modality in the file and no Hounsfield air in the ") + typeName +
                        " values; the name says '" + word + "': MR");
    if (byName == "CT") return ct("inferred", "no modality in the file; the name says '" + word + "': CT");
    if (byName == "micro-CT")
        return pick("micro-CT", "inferred",
                    "no modality in the file; the name says '" + word + "': micro-CT (grey values)");
    if (volume.sourceType == VoxelType::Float32 || volume.sourceType == VoxelType::Float64)
        return pick("MR", "inferred",
                    std::string("no modality in the file; ") + typeName +
                        " values with no Hounsfield air, as MR maps and reconstructions are stored: MR presets");
    return pick("micro-CT", "inferred",
                std::string("no modality in the file; ") + typeName +
                    " values with no Hounsfield air: grey-value (micro-CT) presets on the robust range " +
                    number(double(robustRange(volume).min)) + " .. " + number(double(robustRange(volume).max)));
}

std::vector<ResolvedPreset> presetsFor(const Volume &volume, const ModalityChoice &choice) {
    const ValueRange robust = robustRange(volume);
    const double lo = robust.min, span = std::max(double(robust.max) - double(robust.min), 1e-6);
    const bool greyCt = !(choice.modality == "CT" && choice.hounsfield);
    const bool angio = choice.defaultPreset == defaultPresetOf(choice.modality, true);
    std::vector<ResolvedPreset> out;
    for (const PresetDef &d : kPresets) {
        ResolvedPreset p;
        p.name = d.name;
        p.label = d.label;
        p.modality = d.modality;
        if (!d.hounsfield) {
            p.window = d.window * span;
            p.level = lo + d.level * span;
        } else if (!greyCt) {
            p.window = d.window;
            p.level = d.level;
        } else {
            // Hounsfield units onto the grey values (presets.hpp): a linear map keeps the curve's shape.
            const double perHu = span / (kGreyCtHighHu - kGreyCtLowHu);
            p.window = d.window * perHu;
            p.level = lo + (d.level - kGreyCtLowHu) * perHu;
            p.label += " (grey values)";
        }
        p.shading = d.shading;
        const double start = p.level - 0.5 * p.window;
        for (const CurvePoint &c : d.curve) p.points.push_back({start + c.t * p.window, c.r, c.g, c.b, c.a});
        out.push_back(std::move(p));
    }
    // The chosen modality first, each modality's default first among its own (angiography
    // defaults follow the choice's), the chosen default first of all.
    const std::vector<std::string> order = modalitiesFor(choice);
    const auto rank = [&](const ResolvedPreset &p) {
        const size_t m = size_t(std::find(order.begin(), order.end(), p.modality) - order.begin());
        const bool isDefault = p.name == defaultPresetOf(p.modality, angio);
        return 2 * m + (isDefault ? 0 : 1);
    };
    std::stable_sort(out.begin(), out.end(),
                     [&](const ResolvedPreset &a, const ResolvedPreset &b) { return rank(a) < rank(b); });
    std::stable_partition(out.begin(), out.end(),
                          [&](const ResolvedPreset &p) { return p.name == choice.defaultPreset; });
    return out;
}

std::vector<std::string> modalitiesFor(const ModalityChoice &choice) {
    std::vector<std::string> out;
    for (const char *m : kModalities)
        if (choice.modality == m) out.insert(out.begin(), m);
        else out.push_back(m);
    return out;
}

} // namespace volcast
