#pragma once
// The studies of volcast-bench, one function each (see tests/bench/README.md). Each writes
// its JSON, CSV, Markdown table and SVG plot into options.out and prints the table.

#include "renderer/common/frame_renderer.hpp"
#include "renderer/opencl/opencl_context.hpp"
#include "renderer/model/scene.hpp"
#include "tests/bench/bench.hpp"

#include <filesystem>
#include <memory>
#include <string>
#include <vector>

namespace volcast::bench {

struct StudyOptions {
    std::filesystem::path out = "out/bench";
    std::filesystem::path data;        // the real scans (VOLCAST_DATA_DIR, tests/README.md)
    RepeatOptions repeat{0, 5, 20};    // warm-up is a small frame of its own, see warmUp()
    bool quick = false;                // tiny sizes: checks the command works, times nothing
    std::vector<std::string> volumes = {"small", "tooth", "large"}; // Table 1's volumes
    std::string sizes = "512x512,800x600,1024x768,1280x1024,1920x1080";
    // Table 1's ray caster: opencl (the context's device) or cpu (native); auto is resolved
    // to one of them before a study runs (resolveBackEnd).
    std::string backEnd = "auto";
    // Table 1's sample layout on the native path: slices or bricks (CpuRendererOptions::layout).
    std::string layout = "slices";
    // Figure 5's and the error study's ray casters, timed in turn cell by cell (interleaved).
    std::vector<std::string> backEnds = {"auto"};
    // The error studies' stepping, each cell drawn with each side by side: uniform (quality.step
    // everywhere) and adaptive (quality.adaptive_step, step the longest).
    std::vector<std::string> steppings = {"uniform", "adaptive"};
};

void table1(const std::shared_ptr<OpenClContext> &cl, const StudyOptions &options);
void prefilter(OpenClContext &cl, const StudyOptions &options);
void figure5(const std::shared_ptr<OpenClContext> &cl, const StudyOptions &options, int viewport);
void errorVsTime(const std::shared_ptr<OpenClContext> &cl, const StudyOptions &options, int viewport, const std::vector<std::string> &scans);
// Uniform against adaptive stepping where the answer is known in advance: synthetic volumes
// (side³) whose transfer functions are steep in few bricks, in every brick, or in none,
// configuration A against the reference of the same trilinear field, error against samples
// per ray and time.
void errorSynthetic(const std::shared_ptr<OpenClContext> &cl, const StudyOptions &options, int viewport, int side);

// run_table.py's --extra interface: one JSON line per size on stdout.
struct PeerModeOptions {
    std::filesystem::path volume;
    std::vector<std::pair<int, int>> sizes;
    int frames = 5;
    double sampleDistance = 1;
    double maxSeconds = 30;
    std::filesystem::path png; // if set: each size's last frame, as PATH_WxH.png
    std::string backEnd = "auto"; // opencl or cpu; auto resolved as StudyOptions::backEnd
    std::string layout = "slices"; // the native path's sample layout: slices or bricks
};

// "auto" as the server and volcast-render resolve it (resolveDeviceChoice: opencl where an
// OpenCL GPU exists, else cpu); "opencl" and "cpu" as they are.
std::string resolveBackEnd(const std::string &backEnd);

// The ray caster a study times: "opencl" on `cl`, or "cpu" (the native path, its narrow
// samples held in `layout`: "slices", as the server holds them, or "bricks"). Throws
// std::invalid_argument for anything else (auto is resolved before).
std::unique_ptr<FrameRenderer> makeStudyRenderer(const std::shared_ptr<OpenClContext> &cl, const std::string &backEnd,
                                                 std::shared_ptr<const Volume> volume,
                                                 const std::string &layout = "slices");
void peerMode(const std::shared_ptr<OpenClContext> &cl, const PeerModeOptions &options);

// A CT-like int16 NRRD (detached .raw beside the header) of `dims`, written slice by slice.
void writeSyntheticCt(const std::filesystem::path &header, Vec3i dims);
// Loads `file` and draws a trilinear frame at mip levels 0 and 1 on the native path; prints
// one JSON line: the samples' bytes, the renderer's, resident and peak memory after each step.
void memoryStudy(const std::filesystem::path &file, int size);

// Renders `scan` on the native path at each size (the final frame, and the interactive one at
// half scale, upsampled) and times the server's encoders on them, `rounds` interleaved rounds
// after one untimed: JPEG at qualities 50 and 80, PNG. One JSON line per size on stdout.
void encodeStudy(const std::filesystem::path &scan, const std::vector<std::pair<int, int>> &sizes, int rounds);

// "512x512,800x600" → {{512, 512}, {800, 600}}; throws std::invalid_argument naming the part.
std::vector<std::pair<int, int>> parseSizes(const std::string &text);

// The quality the Table-1 and peer studies run at: 1 sample per voxel, trilinear, with our
// interactive accelerations on (empty-space skipping, early termination at 0.99).
Quality table1Quality(double step = 1.0);

} // namespace volcast::bench
