// Error against run time: every configuration at every step, its median frame time next to
// its error against the exact reference (docs/design.md: RMSE over premultiplied RGBA, PSNR), on
// real scans, with the Pareto front (no other point both faster and more accurate) marked.

#include "renderer/reference/error_metrics.hpp"
#include "renderer/reference/reference_renderer.hpp"
#include "renderer/io/volume_io.hpp"
#include "tests/bench/configurations.hpp"
#include "tests/bench/phantom.hpp"
#include "tests/bench/studies.hpp"
#include "tests/bench/svg_plot.hpp"

#include <algorithm>
#include <iostream>
#include <map>
#include <numeric>
#include <sstream>

namespace volcast::bench {

namespace {

struct Point {
    std::string scan, backEnd, config, label;
    double step = 0;
    Timing timing;
    ImageError error;
    bool pareto = false;
};

// The reference's own error must sit far below what it measures: the coarsest fast
// configurations are at 1e-3 and above, the finest near 1e-4.
constexpr double kReferenceTolerance = 1e-5;

} // namespace

void errorVsTime(const std::shared_ptr<OpenClContext> &cl, const StudyOptions &options, int viewport, const std::vector<std::string> &scans) {
    const std::vector<double> steps = options.quick ? std::vector<double>{1, 2} : std::vector<double>{0.25, 0.5, 1, 2, 4};
    if (options.quick) viewport = std::min(viewport, 24);
    // D is A on more voxels: the same image, so it adds nothing to error against time.
    std::vector<Configuration> configs;
    for (const auto &c : paperConfigurations())
        if (!c.doubledVolume) configs.push_back(c);

    nlohmann::json j;
    j["study"] = "error_vs_time";
    j["machine"] = machineInfo(cl.get());
    j["viewport"] = {viewport, viewport};
    j["reference_tolerance"] = kReferenceTolerance;
    j["quality"] = "empty-space skipping on, early termination off, boundary segment on";
    std::vector<Point> all;
    std::ostringstream md;
    for (const std::string &name : scans) {
        auto volume = std::make_shared<Volume>(options.quick ? makePeerPhantom({16, 16, 16}, VoxelType::UInt8)
                                                             : loadVolume(options.data / (name + ".nhdr")));
        const TransferFunction tf = options.quick ? peerTransferFunction(nominalRange(*volume), 1)
                                                  : scanByName(name, *volume).tf;
        const Camera camera = peerCamera(*volume, 0);
        // Every configuration is timed on each back end in turn (the same machine load).
        std::map<std::string, std::unique_ptr<FrameRenderer>> renderers;
        for (const std::string &b : options.backEnds) {
            renderers[b] = makeStudyRenderer(cl, b, volume);
            j["devices"][b] = renderers[b]->description();
        }

        // One reference per reconstruction and lighting, shared by the configurations using it.
        std::map<std::pair<bool, bool>, Image> references;
        const auto reference = [&](bool cubic, bool shading) -> const Image & {
            auto key = std::make_pair(cubic, shading);
            if (!references.count(key)) {
                ReferenceRenderer ref(*volume, tf, cubic ? Reconstruction::Cubic : Reconstruction::Linear);
                ref.setShading(shading);
                ReferenceOptions ro;
                ro.tolerance = kReferenceTolerance;
                ReferenceStats rs;
                references[key] = ref.render(camera, viewport, viewport, {}, ro, &rs);
                std::cerr << "error_vs_time: " << name << " reference " << (cubic ? "cubic" : "linear")
                          << (shading ? " shaded" : "") << " " << fmt(rs.renderSeconds, 1) << " s, reached "
                          << rs.toleranceReached << "\n";
                j["references"].push_back({{"scan", name},
                                           {"reconstruction", cubic ? "cubic" : "linear"},
                                           {"shading", shading},
                                           {"seconds", rs.renderSeconds},
                                           {"tolerance_reached", rs.toleranceReached}});
            }
            return references[key];
        };

        std::vector<Point> points;
        for (const auto &c : configs)
            for (const double step : steps)
                for (const std::string &b : options.backEnds) {
                    FrameRenderer &renderer = *renderers[b];
                    // Skipping on (it leaves the image as it is), early termination off: at 0.99 it
                    // leaves up to 1 % of the light behind, an error floor (~2e-3 RMSE here) that
                    // would hide every remedy's own error below it.
                    Quality q = configurationQuality(c, step, true);
                    q.earlyTermination = 1.0;
                    Image image = renderer.render({tf, camera, viewport, viewport, q, {}}); // warm-up, and the image
                    Point p;
                    p.scan = name;
                    p.backEnd = b;
                    p.config = c.key;
                    p.label = c.label;
                    p.step = step;
                    p.timing = bench::repeat(options.repeat, [&](int) { renderer.render({tf, camera, viewport, viewport, q, {}}); });
                    p.error = compareImages(image, reference(c.cubic, c.shading));
                    std::cerr << "error_vs_time: " << name << " " << b << " " << c.key << " step " << step << ": "
                              << fmt(p.timing.median) << " ms, RMSE " << p.error.rmse << "\n";
                    points.push_back(p);
                }
        std::vector<double> t, e;
        for (const Point &p : points) {
            t.push_back(p.timing.median);
            e.push_back(p.error.rmse);
        }
        const std::vector<bool> front = paretoFront(t, e);
        for (size_t i = 0; i < points.size(); ++i) points[i].pareto = front[i];

        // One table per back end; the front is over both: what a server holding either could choose.
        for (const std::string &b : options.backEnds) {
            md << "\n**" << name << "** (" << volume->dims.x << "×" << volume->dims.y << "×" << volume->dims.z
               << ", " << viewport << "², " << b << ": " << renderers[b]->description()
               << "): median ms / RMSE (PSNR dB); ★ = on the Pareto front of all back ends\n\n| step |";
            for (const auto &c : configs) md << " " << c.key << " " << c.label << " |";
            md << "\n|---|";
            for (size_t i = 0; i < configs.size(); ++i) md << "---|";
            md << "\n";
            for (const double step : steps) {
                md << "| " << step << " |";
                for (const auto &c : configs)
                    for (const Point &p : points)
                        if (p.backEnd == b && p.config == c.key && p.step == step)
                            md << " " << fmt(p.timing.median, 0) << " ms / " << fmt(p.error.rmse * 1e3, 2) << "e-3 ("
                               << fmt(p.error.psnr, 1) << ")" << (p.pareto ? " ★" : "") << " |";
                md << "\n";
            }
        }

        Plot plot;
        plot.title = "Error against run time: " + name;
        plot.xLabel = "median frame time, ms";
        plot.yLabel = "RMSE against the exact reference";
        plot.logX = plot.logY = true;
        for (const std::string &b : options.backEnds)
            for (const auto &c : configs) {
                Series s{c.key + " " + c.label + (options.backEnds.size() > 1 ? " (" + b + ")" : "")};
                for (const Point &p : points)
                    if (p.backEnd == b && p.config == c.key) {
                        s.x.push_back(p.timing.median);
                        s.y.push_back(p.error.rmse);
                    }
                plot.series.push_back(s);
            }
        std::vector<const Point *> frontPoints;
        for (const Point &p : points)
            if (p.pareto) frontPoints.push_back(&p);
        std::sort(frontPoints.begin(), frontPoints.end(),
                  [](const Point *a, const Point *b) { return a->timing.median < b->timing.median; });
        Series fs{"Pareto front"};
        fs.dashed = true;
        fs.markers = false;
        for (const Point *p : frontPoints) {
            fs.x.push_back(p->timing.median);
            fs.y.push_back(p->error.rmse);
        }
        plot.series.push_back(fs);
        StudyOutput(options.out, "error_vs_time").writeSvg(renderSvg(plot), "_" + name);
        all.insert(all.end(), points.begin(), points.end());
    }

    std::vector<std::vector<std::string>> rows;
    for (const Point &p : all) {
        j["points"].push_back({{"scan", p.scan},
                               {"backend", p.backEnd},
                               {"configuration", p.config},
                               {"label", p.label},
                               {"step", p.step},
                               {"frame_ms", toJson(p.timing)},
                               {"rmse", p.error.rmse},
                               {"psnr", std::isfinite(p.error.psnr) ? nlohmann::json(p.error.psnr) : nlohmann::json(nullptr)},
                               {"max_abs", p.error.maxAbs},
                               {"pareto", p.pareto}});
        rows.push_back({p.scan, p.backEnd, p.config, fmt(p.step, 2), fmt(p.timing.median, 2), fmt(p.timing.min, 2),
                        fmt(p.timing.max, 2), fmt(p.error.rmse, 6), fmt(p.error.psnr, 2), p.pareto ? "1" : "0"});
    }
    StudyOutput out(options.out, "error_vs_time");
    out.writeJson(j);
    out.writeCsv({"scan", "backend", "configuration", "step", "median_ms", "min_ms", "max_ms", "rmse", "psnr", "pareto"}, rows);
    out.writeMarkdown(md.str());
    std::cout << md.str();
}

} // namespace volcast::bench
