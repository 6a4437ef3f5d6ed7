#pragma once
// The numerical-stability cases: stiff scenes (optical depth per step far above 1)
// and extreme ones (the other ends of every range). Each case renders through a back end (the
// OpenCL ray caster or the native CPU one) and the double-precision reference where both apply, compares with a closed form
// where one exists and with the reference otherwise, and counts NaN and Inf in every output.
//
// The renderer tests (tests/renderer/test_numerical_stability.cpp) and volcast-stability, the
// command that prints docs/accuracy.md's "Numerical stability" table, run this same code, so
// the table shows what the tests check.

#include "renderer/common/frame_renderer.hpp"
#include "renderer/model/camera.hpp"
#include "renderer/opencl/opencl_context.hpp"

#include <cstddef>
#include <functional>
#include <memory>
#include <string>
#include <vector>

namespace volcast::stability {

// One row of the table: one case on one path.
struct Row {
    std::string caseName;     // what was rendered, e.g. "opaque media, a = 1, steps 0.01–10"
    std::string path;         // "OpenCL", "reference", "pre-integration table", …
    std::string comparedWith; // the truth and the error measure, e.g. "closed form, |ΔA|, |Δrgb|"
    double worst = 0;         // the worst error seen
    std::string worstAt;      // the variant it was seen in
    double bound = 0;         // the case's bound on it (each derived where the case is defined)
    size_t values = 0;        // output values checked for NaN and Inf
    size_t nonFinite = 0;     // NaN or Inf among them
    bool clearError = false;  // the right answer is a clear error (worst, bound unused)
    std::string outcome;      // the error messages seen, or a note on what the row measured
    std::vector<std::string> failures; // checks that are not a number against a bound

    bool passed() const { return nonFinite == 0 && worst <= bound && failures.empty(); }
};

// The cameras the cases place: an orthographic one looking along the unit axis `forward` from
// `eye` (its view `height` world units), the image's y axis along `up`; a perspective one.
Camera orthographic(Vec3d eye, Vec3d forward, Vec3d up, double height);
Camera perspective(Vec3d eye, Vec3d target, Vec3d up, double fovYDeg);

// The back end a case renders with: its name starts every row's path ("OpenCL", "CPU").
struct Backend {
    std::string name;
    std::function<std::unique_ptr<FrameRenderer>(const Volume &)> make;
};
Backend openClBackend(std::shared_ptr<OpenClContext> cl); // the renderers made share it
Backend cpuBackend();                     // the native SIMD ray caster (renderer/cpu/)

// One stability case: its rows, run on the given back end.
struct Case {
    std::string id; // a test name: OpacityCorrection, FaintMedia, …
    std::function<std::vector<Row>(const Backend &)> run;
};

// Every case, in the order the table prints them.
const std::vector<Case> &cases();

// The README table: case, path, compared with, worst error seen, bound, NaN/Inf count.
std::string markdownTable(const std::vector<Row> &rows);

} // namespace volcast::stability
