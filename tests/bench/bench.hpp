#pragma once
// What every volcast-bench study shares: timing with warm-up and repeats, the machine it
// ran on, the peers' camera and transfer function, and the files a study writes.

#include "renderer/model/camera.hpp"
#include "renderer/opencl/opencl_context.hpp"
#include "renderer/model/transfer_function.hpp"
#include "renderer/model/volume.hpp"

#include <nlohmann/json.hpp>

#include <filesystem>
#include <functional>
#include <string>
#include <vector>

namespace volcast::bench {

// Median (the mean of the middle two for an even count, as Python's statistics.median),
// min and max of timed repeats, in ms.
struct Timing {
    double median = 0, min = 0, max = 0;
    int n = 0;
    std::vector<double> samples;
};
Timing summarize(std::vector<double> ms);
nlohmann::json toJson(const Timing &t);

struct RepeatOptions {
    int warmup = 1;            // untimed runs first: program build, tables, caches
    int repeats = 5;           // timed runs at most ...
    double maxSeconds = 30;    // ... stopping early once this much time went to timed runs
};
// Runs `once(k)` warmup + repeats times (k counts from 0, warm-up included) and returns the
// timed runs' wall-clock ms. At least one timed run always happens. `prepare`, if given, runs
// untimed before each run (e.g. a fresh copy of data the run changes in place).
Timing repeat(const RepeatOptions &options, const std::function<void(int k)> &once,
              const std::function<void()> &prepare = {});

// Times several variants of one cell side by side: each round runs every variant once, in the
// given order on even rounds and reversed on odd ones (so that neither always runs right after
// the other, whose caches and clock it would inherit); options.warmup untimed rounds first.
// Stops after options.repeats timed rounds, or after the round in which the timed runs passed
// options.maxSeconds, so every variant has the same number of runs. One Timing per variant.
std::vector<Timing> repeatInterleaved(const RepeatOptions &options, const std::vector<std::function<void()>> &variants);

// The machine and OpenCL device, written into every study's JSON.
nlohmann::json machineInfo(const OpenClContext *cl);

// The peers' framing (the peers' harness, vtk_bench.py's camera_orbit): VTK's ResetCamera for a
// 30° view angle, i.e. the bounding sphere of the sample points fits the view height, at
// `elevationDeg` above the xy plane; frame k orbits the z axis by k·orbitDeg. The sample
// points' box is VTK's image bounds: [origin, origin + (n − 1)·s].
Camera peerCamera(const Volume &volume, int frame, double orbitDeg = 3, double elevationDeg = 20);

// The peers' transfer function (vtk_bench.py, transfer_function, grey colour map): opacity 0
// below lo = vmin + rampLo·span, rising linearly to maxOpacity per voxel length at
// hi = vmin + rampHi·span; grey from black at vmin through 0.25 at lo to white at vmax.
TransferFunction peerTransferFunction(ValueRange nominal, double opacityUnit, double rampLo = 0.40,
                                      double rampHi = 1.0, double maxOpacity = 0.25);
// The range the peers' ramp is placed on: 0..255 for 8-bit data, 0..4095 for 16-bit data
// within 12 bits (their phantoms), else the data's own range.
ValueRange nominalRange(const Volume &volume);

// Points no other point beats in both time and error (ties count as beaten only when the
// other is strictly better in one): the Pareto front, as flags in input order.
std::vector<bool> paretoFront(const std::vector<double> &time, const std::vector<double> &error);
// paretoFront within each group alone (e.g. uniform and adaptive stepping): a point is flagged
// when no point of its own group beats it, whatever the other groups hold.
std::vector<bool> paretoFrontWithin(const std::vector<double> &cost, const std::vector<double> &error,
                                    const std::vector<std::string> &group);
// Where a curve of (cost, error) points reaches `error`: between the two neighbouring points
// (by cost) whose errors bracket it, interpolated linearly in log cost against log error (exact
// for error ∝ cost^−p, as a step's error against samples). NaN when no pair brackets it: the
// target lies above the cheapest point's error or below every error reached.
double costAtError(std::vector<double> cost, std::vector<double> error, double target);

// A study's output folder: JSON (with the machine), CSV and SVG side by side.
class StudyOutput {
  public:
    StudyOutput(std::filesystem::path dir, std::string study);
    void writeJson(const nlohmann::json &j) const;
    // <study><suffix>.csv
    void writeCsv(const std::vector<std::string> &header, const std::vector<std::vector<std::string>> &rows,
                  const std::string &suffix = "") const;
    void writeSvg(const std::string &svg, const std::string &suffix = "") const;
    void writeMarkdown(const std::string &text) const;
    const std::filesystem::path &dir() const { return dir_; }

  private:
    std::filesystem::path dir_;
    std::string study_;
};

std::string fmt(double v, int decimals = 1);

} // namespace volcast::bench
