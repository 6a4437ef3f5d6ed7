// volcast-render: render one scene file offline and print one JSON line about it.
//
//   volcast-render scene.json -o out.exr [--reference] [--compare other.exr] [--data FOLDER]...

#include "renderer/reference/error_metrics.hpp"
#include "renderer/model/image.hpp"
#include "renderer/make_frame_renderer.hpp"
#include "renderer/reference/reference_renderer.hpp"
#include "renderer/model/scene.hpp"
#include "renderer/io/volume_source.hpp"
#include "protocol/volume_name.hpp"

#include <CLI/CLI.hpp>
#include <spdlog/sinks/stdout_color_sinks.h>
#include <spdlog/spdlog.h>
#include <nlohmann/json.hpp>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <memory>

namespace {

using Clock = std::chrono::steady_clock;
double msSince(Clock::time_point t) { return std::chrono::duration<double, std::milli>(Clock::now() - t).count(); }

// JSON has no infinity: identical images report PSNR as null.
nlohmann::json finiteOrNull(double x) { return std::isfinite(x) ? nlohmann::json(x) : nlohmann::json(nullptr); }

namespace fs = std::filesystem;

// The scene file's own "volume" string, before the scene parser makes a relative name
// relative to the scene file's folder.
std::string sceneVolumeName(const std::string &scenePath) {
    std::ifstream in(scenePath, std::ios::binary);
    const nlohmann::json j = nlohmann::json::parse(in, nullptr, /*allow_exceptions=*/false);
    const auto it = j.is_object() ? j.find("volume") : j.end();
    return it != j.end() && it->is_string() ? it->get<std::string>() : std::string();
}

bool isInside(const fs::path &p, const fs::path &folder) {
    const auto rel = p.lexically_relative(folder);
    return !rel.empty() && *rel.begin() != "..";
}

// A server-relative volume name (what a scene saved from volcast-server holds) found in
// the --data folders, confined as the server confines it: the same name rules
// (protocol/volume_name.hpp: no absolute path, no "..", no "~"), and a name whose real path
// (symbolic links followed) leaves its folder is refused. The first folder that has it wins.
fs::path resolveInDataFolders(const std::string &name, const std::vector<std::string> &folders) {
    if (const auto problem = volcast::protocol::validateVolumeName(name))
        throw std::invalid_argument("scene volume \"" + name + "\" " + *problem +
                                    " (with --data the scene must name a volume relative to the data folders)");
    std::string searched;
    for (const std::string &folder : folders) {
        std::error_code ec;
        const fs::path root = fs::canonical(folder, ec);
        if (ec) throw std::invalid_argument("--data " + folder + ": " + ec.message());
        const fs::path p = fs::weakly_canonical(root / fs::path(name), ec);
        searched += (searched.empty() ? "" : ", ") + root.string();
        if (ec || !fs::exists(p, ec)) continue;
        if (!isInside(p, root))
            throw std::invalid_argument("scene volume \"" + name + "\" resolves outside the data folder " +
                                        root.string() + " (a symbolic link?)");
        return p;
    }
    throw std::invalid_argument("scene volume \"" + name + "\" is in none of the --data folders (" + searched + ")");
}

} // namespace

int main(int argc, char **argv) {
    CLI::App app{"Render a volcast scene file (docs/design.md's scene contract) to an image."};
    std::string scenePath, outPath, comparePath, errorImagePath;
    bool reference = false, analytic = false;
    double tolerance = 1e-7;
    int threads = 0, repeat = 1;
    app.add_option("scene", scenePath, "Scene JSON file")->required()->check(CLI::ExistingFile);
    app.add_option("-o,--output", outPath, "Output image: .exr or .tif (premultiplied float RGBA), .png (8-bit)")
        ->required();
    std::string device = "auto", kernelCache;
    app.add_flag("--reference", reference, "Use the exact double-precision reference integrator instead of a ray caster");
    // auto, as the server: an OpenCL GPU where there is one, else the native path (every
    // switch, and faster than PoCL). remedies.py asks for opencl, the output its page describes.
    app.add_option("--device", device,
                   "Back end: cpu (native SIMD), opencl (OpenCL's choice: a GPU, else its CPU device), "
                   "opencl:<part of a device name, gpu or cpu>, or auto (an OpenCL GPU, else cpu)")
        ->capture_default_str();
    app.add_option("--kernel-cache", kernelCache, "Folder for PoCL's compiled-kernel cache (default: $VOLCAST_KERNEL_CACHE)");
    app.add_flag("--analytic", analytic,
                 "Reference only: integrate a built-in volume's continuous field instead of its samples");
    app.add_option("--tolerance", tolerance, "Reference only: per-pixel absolute tolerance")
        ->check(CLI::Range(1e-12, 1e-1));
    app.add_option("--threads", threads, "Reference only: render threads (0: all cores)")->check(CLI::NonNegativeNumber);
    app.add_option("--repeat", repeat, "Not with --reference: render this many times and report the later frames' times")
        ->check(CLI::Range(1, 1000));
    app.add_option("--compare", comparePath, "Print RMSE, PSNR and max error against this image")
        ->check(CLI::ExistingFile);
    app.add_option("--error-image", errorImagePath, "With --compare: write the per-pixel error here");
    std::vector<std::string> dataFolders;
    app.add_option("--data", dataFolders,
                   "Data folder the scene's volume name is relative to, as volcast-server's --data (repeatable, "
                   "searched in order); without it a relative name is relative to the scene file")
        ->check(CLI::ExistingDirectory);
    CLI11_PARSE(app, argc, argv);
    // Warnings (non-finite voxels replaced, a step raised) go to stderr: stdout is the JSON line.
    spdlog::set_default_logger(spdlog::stderr_color_mt("volcast-render"));

    try {
        nlohmann::json report;
        if (analytic) reference = true;
        volcast::Scene scene = volcast::loadSceneFile(scenePath);
        // A scene saved from the server keeps the server-relative name (an absolute server
        // path would tell every client the server's layout); --data finds it as the server does.
        if (!dataFolders.empty() && !scene.volume.starts_with("builtin:"))
            scene.volume = resolveInDataFolders(sceneVolumeName(scenePath), dataFolders).string();

        auto t = Clock::now();
        volcast::LoadedVolume loaded = volcast::loadSceneVolume(scene.volume);
        const double loadMs = msSince(t);
        if (analytic && !loaded.analyticField)
            throw std::invalid_argument("--analytic needs a built-in volume (builtin:NAME); " + scene.volume +
                                        " has no continuous field");
        const volcast::TransferFunction tf = volcast::resolvedTransferFunction(scene, loaded.volume.range);

        report["volume"] = scene.volume;
        report["dims"] = {loaded.volume.dims.x, loaded.volume.dims.y, loaded.volume.dims.z};
        report["image"] = {{"width", scene.width}, {"height", scene.height}};
        volcast::Image image;
        if (reference) {
            t = Clock::now();
            const auto reconstruction = analytic ? volcast::Reconstruction::Analytic
                                        : scene.quality.interpolation == volcast::Interpolation::Cubic
                                            ? volcast::Reconstruction::Cubic
                                            : volcast::Reconstruction::Linear;
            volcast::ReferenceRenderer renderer =
                analytic ? volcast::ReferenceRenderer(loaded.volume, tf, loaded.analyticField)
                         : volcast::ReferenceRenderer(loaded.volume, tf, reconstruction);
            renderer.setQuality(scene.quality); // shading, compositing, crop
            const double preprocessMs = msSince(t);
            volcast::ReferenceStats stats;
            volcast::ReferenceOptions options;
            options.tolerance = tolerance;
            options.threads = threads;
            image = renderer.render(scene.camera, scene.width, scene.height, scene.clipPlanes, options, &stats);
            report["renderer"] = "reference";
            report["reconstruction"] = reconstruction == volcast::Reconstruction::Analytic ? "analytic"
                                       : reconstruction == volcast::Reconstruction::Cubic  ? "cubic"
                                                                                           : "linear";
            report["timings_ms"] = {{"load", loadMs}, {"preprocess", preprocessMs}, {"render", stats.renderSeconds * 1e3}};
            report["tolerance_requested"] = stats.toleranceRequested;
            report["tolerance_reached"] = stats.toleranceReached;
            if (analytic) report["analytic_fit_error"] = stats.analyticFitError;
        } else {
            t = Clock::now();
            const volcast::DeviceChoice choice = volcast::DeviceChoice::parse(device);
            auto shared = std::make_shared<const volcast::Volume>(std::move(loaded.volume)); // no copy: not used below
            const auto renderer = volcast::makeFrameRenderer(choice, shared, kernelCache);
            const double uploadMs = msSince(t);
            const volcast::FrameRequest request{tf, scene.camera, scene.width, scene.height, scene.quality,
                                                scene.clipPlanes};
            volcast::RenderStats stats;
            image = renderer->render(request, &stats);
            // Later frames reuse the program and every table: the time a server pays per frame.
            std::vector<double> repeatMs;
            for (int i = 1; i < repeat; ++i) {
                volcast::RenderStats again;
                renderer->render(request, &again);
                repeatMs.push_back(again.renderSeconds * 1e3);
            }
            const std::string description = renderer->description();
            report["renderer"] = description.substr(0, description.find(':')); // "opencl" or "cpu"
            report["device"] = description.substr(description.find(':') + 2);
            report["build_options"] = stats.buildOptions;
            report["timings_ms"] = {{"load", loadMs},
                                    {"upload", uploadMs},
                                    {"kernel_build", stats.kernelBuildSeconds * 1e3},
                                    {"preprocess",
                                     {{"tf_table", stats.tfTableSeconds * 1e3},
                                      {"mip_levels", stats.mipSeconds * 1e3},
                                      {"bspline_coefficients", stats.coefficientSeconds * 1e3},
                                      {"brick_grid", stats.brickGridSeconds * 1e3},
                                      {"brick_classification", stats.brickClassifySeconds * 1e3},
                                      {"preintegration_table", stats.preintegrationSeconds * 1e3}}},
                                    {"render", stats.renderSeconds * 1e3}};
            if (!repeatMs.empty()) {
                std::sort(repeatMs.begin(), repeatMs.end());
                report["timings_ms"]["render_repeated"] = {{"count", repeatMs.size()},
                                                           {"min", repeatMs.front()},
                                                           {"median", repeatMs[repeatMs.size() / 2]},
                                                           {"max", repeatMs.back()}};
            }
            if (scene.quality.preintegrated)
                report["preintegration_table"] = {{"nodes", stats.preintegrationNodes},
                                                  {"max_error", stats.preintegrationError}};
            else
                report["tf_table"] = {{"entries", stats.tfTableEntries}, {"max_error", stats.tfTableError}};
            report["rays"] = {stats.raysWide, stats.raysHigh};
            if (stats.stepRaised) report["step_used"] = stats.stepUsed;
            report["mean_samples_per_ray"] = stats.meanSamplesPerRay;
            if (scene.quality.emptySpaceSkipping) {
                report["skipped_segments_per_ray"] = stats.skippedSegmentsPerRay;
                report["empty_brick_fraction"] = stats.emptyBrickFraction;
            }
            report["early_terminated_fraction"] = stats.earlyTerminatedFraction;
            if (stats.raysTruncated > 0) report["rays_truncated"] = stats.raysTruncated;
        }
        volcast::writeImage(outPath, image);
        report["output"] = outPath;

        if (!comparePath.empty()) {
            const volcast::Image other = volcast::readImage(comparePath);
            const volcast::ImageError e = volcast::compareImages(image, other);
            report["compare"] = {{"against", comparePath}, {"rmse", e.rmse}, {"psnr", finiteOrNull(e.psnr)},
                                 {"max_abs", e.maxAbs}};
            if (!errorImagePath.empty()) volcast::writeImage(errorImagePath, volcast::errorImage(image, other));
        }
        std::cout << report.dump() << std::endl;
        return 0;
    } catch (const std::exception &e) {
        std::cerr << "volcast-render: " << e.what() << std::endl;
        return 1;
    }
}
