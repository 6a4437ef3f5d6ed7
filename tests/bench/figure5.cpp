// Figure 5: frame rate against samples per voxel for the paper's configurations A–F, first
// as the paper measured (no empty-space skipping, no early termination), then with both.

#include "renderer/io/volume_io.hpp"
#include "tests/bench/configurations.hpp"
#include "tests/bench/phantom.hpp"
#include "tests/bench/studies.hpp"
#include "tests/bench/svg_plot.hpp"

#include <iostream>
#include <map>
#include <sstream>

namespace volcast::bench {

void figure5(const std::shared_ptr<OpenClContext> &cl, const StudyOptions &options, int viewport) {
    // The paper's 256³ dataset: bonsai (256³, 8-bit CT); D doubles it to 511³ (phantom.hpp).
    // Quick runs use a small phantom instead, so they need no data folder.
    std::shared_ptr<const Volume> base, doubled;
    TransferFunction tf;
    if (options.quick) {
        base = std::make_shared<Volume>(makePeerPhantom({24, 24, 24}, VoxelType::UInt8));
        tf = peerTransferFunction(nominalRange(*base), 1);
    } else {
        base = std::make_shared<Volume>(loadVolume(options.data / "bonsai.nhdr"));
        tf = scanByName("bonsai", *base).tf;
    }
    std::cerr << "figure5: resampling " << base->name << " to 2n − 1\n";
    doubled = std::make_shared<Volume>(resampleTrilinear(*base, base->dims * int64_t(2) - Vec3i{1, 1, 1}));
    const std::vector<double> spvs = options.quick ? std::vector<double>{1, 2} : std::vector<double>{0.5, 1, 2, 4, 8};
    if (options.quick) viewport = std::min(viewport, 48);

    nlohmann::json j;
    j["study"] = "figure5";
    j["machine"] = machineInfo(cl.get());
    j["volume"] = base->name;
    j["viewport"] = {viewport, viewport};
    j["camera"] = "peers' framing (bounding sphere fits a 30° view, 20° elevation), frame 0";
    std::vector<std::vector<std::string>> rows;
    std::ostringstream md;
    // Each back end's renderers of the base and the doubled volume; every cell is timed on
    // each back end in turn, so that both see the same machine load.
    std::map<std::string, std::pair<std::unique_ptr<FrameRenderer>, std::unique_ptr<FrameRenderer>>> renderers;
    for (const std::string &b : options.backEnds) {
        renderers[b] = {makeStudyRenderer(cl, b, base), makeStudyRenderer(cl, b, doubled)};
        j["devices"][b] = renderers[b].first->description();
    }
    const Camera camera = peerCamera(*base, 0);
    for (const bool accelerated : {false, true}) {
        const std::string variant = accelerated ? "accelerated" : "paper";
        Plot plot;
        plot.title = std::string("Figure 5: frame rate against samples per voxel (") +
                     (accelerated ? "skipping + early termination" : "as the paper: neither") + ")";
        plot.xLabel = "samples per voxel";
        plot.yLabel = "frames per second";
        plot.logX = plot.logY = true;
        std::map<std::string, std::map<std::string, std::map<double, Timing>>> cells; // [back end][config][spv]
        for (const auto &c : paperConfigurations()) {
            std::map<std::string, Series> series;
            for (const std::string &b : options.backEnds)
                series[b].label = c.key + " " + c.label + (options.backEnds.size() > 1 ? " (" + b + ")" : "");
            for (const double spv : spvs)
                for (const std::string &b : options.backEnds) {
                    FrameRenderer &renderer = c.doubledVolume ? *renderers[b].second : *renderers[b].first;
                    const Quality q = configurationQuality(c, 1 / spv, accelerated);
                    // A small frame first builds the program and this step's tables.
                    renderer.render({tf, camera, 32, 32, q, {}});
                    RenderStats stats;
                    const Timing t = bench::repeat(options.repeat, [&](int) {
                        renderer.render({tf, camera, viewport, viewport, q, {}}, &stats);
                    });
                    cells[b][c.key][spv] = t;
                    std::cerr << "figure5: " << variant << " " << b << " " << c.key << " spv " << spv << ": "
                              << fmt(t.median) << " ms\n";
                    series[b].x.push_back(spv);
                    series[b].y.push_back(1e3 / t.median);
                    j["cells"].push_back({{"variant", variant},
                                          {"backend", b},
                                          {"configuration", c.key},
                                          {"label", c.label},
                                          {"samples_per_voxel", spv},
                                          {"step", 1 / spv},
                                          {"frame_ms", toJson(t)},
                                          {"fps", 1e3 / t.median},
                                          {"mean_samples_per_ray", stats.meanSamplesPerRay},
                                          {"volume_dims", {renderer.volume().dims.x, renderer.volume().dims.y,
                                                           renderer.volume().dims.z}}});
                    rows.push_back({variant, b, c.key, fmt(spv, 2), fmt(t.median, 2), fmt(t.min, 2), fmt(t.max, 2),
                                    fmt(1e3 / t.median, 3), fmt(stats.meanSamplesPerRay, 1)});
                }
            for (const std::string &b : options.backEnds) plot.series.push_back(series[b]);
        }
        const auto header = [&](const std::string &what) {
            md << "\n" << (accelerated ? "With empty-space skipping and early termination (0.99)" :
                                         "As in the paper: no empty-space skipping, no early termination")
               << ", " << viewport << "² viewport, " << what << ":\n\n| samples per voxel |";
            for (const auto &c : paperConfigurations()) md << " " << c.key << " " << c.label << " |";
            md << "\n|---|";
            for (size_t i = 0; i < paperConfigurations().size(); ++i) md << "---|";
            md << "\n";
        };
        for (const std::string &b : options.backEnds) {
            header(b + " (" + renderers[b].first->description() + "), frames per second (median frame time in ms)");
            for (const double spv : spvs) {
                md << "| " << spv << " |";
                for (const auto &c : paperConfigurations()) {
                    const Timing &t = cells[b][c.key][spv];
                    md << " " << fmt(1e3 / t.median, 2) << " (" << fmt(t.median, 0) << " ms) |";
                }
                md << "\n";
            }
        }
        if (cells.count("cpu") && cells.count("opencl")) {
            header("native CPU frame time ÷ OpenCL frame time, same cell, timed in turn");
            for (const double spv : spvs) {
                md << "| " << spv << " |";
                for (const auto &c : paperConfigurations())
                    md << " " << fmt(cells["cpu"][c.key][spv].median / cells["opencl"][c.key][spv].median, 2) << " |";
                md << "\n";
            }
        }
        StudyOutput(options.out, "figure5").writeSvg(renderSvg(plot), "_" + variant);
    }
    StudyOutput out(options.out, "figure5");
    out.writeJson(j);
    out.writeCsv({"variant", "backend", "configuration", "samples_per_voxel", "median_ms", "min_ms", "max_ms", "fps",
                  "mean_samples_per_ray"},
                 rows);
    out.writeMarkdown(md.str());
    std::cout << md.str();
}

} // namespace volcast::bench
