// Error against run time: every configuration at every step, with uniform and with adaptive
// stepping (quality.adaptive_step, step the longest), its median frame time and samples per ray
// next to its error against the exact reference (docs/design.md: RMSE over premultiplied RGBA,
// PSNR), on real scans, with each stepping's Pareto front (no other point of the same stepping
// both cheaper and more accurate) against time and against samples per ray. And the same
// comparison on synthetic volumes whose transfer functions are steep in few bricks, in every
// brick, or nowhere (errorSynthetic).

#include "renderer/model/synthetic.hpp"
#include "renderer/reference/error_metrics.hpp"
#include "renderer/reference/reference_renderer.hpp"
#include "renderer/io/volume_io.hpp"
#include "tests/bench/configurations.hpp"
#include "tests/bench/phantom.hpp"
#include "tests/bench/studies.hpp"
#include "tests/bench/svg_plot.hpp"

#include <algorithm>
#include <cmath>
#include <iostream>
#include <map>
#include <numeric>
#include <sstream>

namespace volcast::bench {

namespace {

struct Point {
    std::string scan, backEnd, config, label, stepping;
    double step = 0;
    Timing timing;
    ImageError error;
    double samplesPerRay = 0;    // over rays that hit (RenderStats::meanSamplesPerRay)
    double adaptiveMeanStep = 0; // voxels, adaptive stepping only (RenderStats::adaptiveMeanStep)
    bool pareto = false;         // on its stepping's front, error against time
    bool paretoSamples = false;  // on its stepping's front, error against samples per ray
    double uniformSamplesAtError = 0; // synthetic study: what uniform stepping needs for this error
};

// The reference's own error must sit far below what it measures: the coarsest fast
// configurations are at 1e-3 and above, the finest near 1e-4.
constexpr double kReferenceTolerance = 1e-5;

bool isAdaptive(const std::string &stepping) { return stepping == "adaptive"; }

// A step as written in the tables: 0.0625, 0.25, 1 (fmt's fixed decimals would cut 1/16).
std::string number(double v) {
    std::ostringstream o;
    o << v;
    return o.str();
}

// Each stepping's fronts, over all back ends: what a server holding either could choose.
void markFronts(std::vector<Point> &points) {
    std::vector<double> t, s, e;
    std::vector<std::string> g;
    for (const Point &p : points) {
        t.push_back(p.timing.median);
        s.push_back(p.samplesPerRay);
        e.push_back(p.error.rmse);
        g.push_back(p.stepping);
    }
    const std::vector<bool> ft = paretoFrontWithin(t, e, g), fs = paretoFrontWithin(s, e, g);
    for (size_t i = 0; i < points.size(); ++i) {
        points[i].pareto = ft[i];
        points[i].paretoSamples = fs[i];
    }
}

std::string frontMarks(const Point &p) { return std::string(p.pareto ? " ★" : "") + (p.paretoSamples ? " ◆" : ""); }

// Both steppings' fronts as one table, each point once: stepping, then time.
void frontsTable(std::ostream &md, std::vector<const Point *> front, bool named) {
    std::sort(front.begin(), front.end(), [](const Point *a, const Point *b) {
        return std::make_pair(isAdaptive(a->stepping), a->timing.median) < std::make_pair(isAdaptive(b->stepping), b->timing.median);
    });
    md << "\n| stepping | " << (named ? "configuration | " : "") << "step | back end | median ms | RMSE | PSNR dB | samples per ray | mean step (voxels) | front |\n"
       << "|---|" << (named ? "---|" : "") << "---:|---|---:|---:|---:|---:|---:|---|\n";
    for (const Point *p : front)
        md << "| " << p->stepping << " | " << (named ? p->config + " " + p->label + " | " : "") << p->step << " | "
           << p->backEnd << " | " << fmt(p->timing.median, 1) << " | " << fmt(p->error.rmse * 1e3, 3) << "e-3 | "
           << fmt(p->error.psnr, 1) << " | " << fmt(p->samplesPerRay, 1) << " | "
           << (isAdaptive(p->stepping) ? fmt(p->adaptiveMeanStep, 2) : fmt(p->step, 2)) << " |" << frontMarks(*p) << " |\n";
}

// The plots' series: one per configuration and stepping (the configuration's colour; adaptive
// dashed), and each stepping's front (no markers).
Plot errorPlot(const std::string &title, const std::string &xLabel, const std::vector<Point> &points,
               const std::vector<std::pair<std::string, std::string>> &configs, const std::vector<std::string> &backEnds,
               const std::vector<std::string> &steppings, bool samples) {
    Plot plot;
    plot.title = title;
    plot.xLabel = xLabel;
    plot.yLabel = "RMSE against the exact reference";
    plot.logX = plot.logY = true;
    const auto x = [samples](const Point &p) { return samples ? p.samplesPerRay : p.timing.median; };
    int colour = 0;
    for (const auto &[key, label] : configs) {
        for (const std::string &b : backEnds)
            for (const std::string &st : steppings) {
                Series s{key + (label.empty() ? "" : " " + label) + (isAdaptive(st) ? ", adaptive" : "") +
                         (backEnds.size() > 1 ? " (" + b + ")" : "")};
                s.dashed = isAdaptive(st);
                s.colour = colour;
                for (const Point &p : points)
                    if (p.backEnd == b && p.config == key && p.stepping == st) {
                        s.x.push_back(x(p));
                        s.y.push_back(p.error.rmse);
                    }
                plot.series.push_back(s);
            }
        ++colour;
    }
    for (const std::string &st : steppings) {
        std::vector<const Point *> front;
        for (const Point &p : points)
            if (p.stepping == st && (samples ? p.paretoSamples : p.pareto)) front.push_back(&p);
        std::sort(front.begin(), front.end(), [&](const Point *a, const Point *b) { return x(*a) < x(*b); });
        Series fs{"Pareto front, " + st};
        fs.dashed = isAdaptive(st);
        fs.markers = false;
        fs.colour = isAdaptive(st) ? 7 : 6; // yellow, black: no configuration's colour
        for (const Point *p : front) {
            fs.x.push_back(x(*p));
            fs.y.push_back(p->error.rmse);
        }
        plot.series.push_back(fs);
    }
    return plot;
}

nlohmann::json pointJson(const Point &p) {
    nlohmann::json j = {{"scan", p.scan},
                        {"backend", p.backEnd},
                        {"configuration", p.config},
                        {"label", p.label},
                        {"stepping", p.stepping},
                        {"step", p.step},
                        {"frame_ms", toJson(p.timing)},
                        {"rmse", p.error.rmse},
                        {"psnr", std::isfinite(p.error.psnr) ? nlohmann::json(p.error.psnr) : nlohmann::json(nullptr)},
                        {"max_abs", p.error.maxAbs},
                        {"samples_per_ray", p.samplesPerRay},
                        {"adaptive_mean_step_voxels", isAdaptive(p.stepping) ? nlohmann::json(p.adaptiveMeanStep) : nlohmann::json(nullptr)},
                        {"pareto", p.pareto},
                        {"pareto_samples", p.paretoSamples}};
    return j;
}

// One cell: each back end × stepping drawn once untimed (its image and stats), then timed side
// by side, round by round (repeatInterleaved), so that all see the same machine load.
std::vector<Point> timeCell(const StudyOptions &options, std::map<std::string, std::unique_ptr<FrameRenderer>> &renderers,
                            const TransferFunction &tf, const Camera &camera, int viewport, const Quality &base,
                            const Image &reference, Point proto, const std::vector<std::string> &steppings) {
    std::vector<Point> points;
    std::vector<std::function<void()>> runs;
    for (const std::string &b : options.backEnds)
        for (const std::string &st : steppings) {
            Quality q = base;
            q.adaptiveStep = isAdaptive(st);
            FrameRenderer *renderer = renderers.at(b).get();
            RenderStats stats;
            const Image image = renderer->render({tf, camera, viewport, viewport, q, {}}, &stats); // warm-up, and the image
            Point p = proto;
            p.backEnd = b;
            p.stepping = st;
            p.error = compareImages(image, reference);
            p.samplesPerRay = stats.meanSamplesPerRay;
            p.adaptiveMeanStep = stats.adaptiveMeanStep;
            // A back end that ignores the switch reports no adaptive step: its "adaptive" image
            // would be the uniform one under another name.
            if (q.adaptiveStep && !(stats.adaptiveMeanStep > 0))
                std::cerr << "error_vs_time: warning: " << b << " reported no adaptive step for " << p.scan << " "
                          << p.config << " step " << p.step << "\n";
            points.push_back(p);
            runs.push_back([renderer, q, &tf, &camera, viewport] { renderer->render({tf, camera, viewport, viewport, q, {}}); });
        }
    const std::vector<Timing> timings = repeatInterleaved(options.repeat, runs);
    for (size_t i = 0; i < points.size(); ++i) {
        points[i].timing = timings[i];
        const Point &p = points[i];
        std::cerr << "error_vs_time: " << p.scan << " " << p.backEnd << " " << p.config << " step " << p.step << " "
                  << p.stepping << ": " << fmt(p.timing.median) << " ms, " << fmt(p.samplesPerRay) << " samples per ray, RMSE "
                  << p.error.rmse << "\n";
    }
    return points;
}

std::string steppingNames(const std::vector<std::string> &steppings) {
    std::string s;
    for (const std::string &st : steppings) s += (s.empty() ? "" : ", ") + st;
    return s;
}

} // namespace

void errorVsTime(const std::shared_ptr<OpenClContext> &cl, const StudyOptions &options, int viewport, const std::vector<std::string> &scans) {
    // Uniform also at 1/8 and 1/16 voxel (adaptive stepping's shortest segments at steps 1 and
    // 0.5), so that its front reaches the errors adaptive stepping reaches and the two fronts
    // can be compared there; adaptive from 0.25, where its shortest is 1/32.
    const std::vector<double> steps = options.quick ? std::vector<double>{0.5, 1, 2}
                                                    : std::vector<double>{0.0625, 0.125, 0.25, 0.5, 1, 2, 4};
    const double adaptiveFrom = options.quick ? 1 : 0.25;
    if (options.quick) viewport = std::min(viewport, 24);
    // D is A on more voxels: the same image, so it adds nothing to error against time.
    std::vector<Configuration> configs;
    std::vector<std::pair<std::string, std::string>> configNames;
    for (const auto &c : paperConfigurations())
        if (!c.doubledVolume) {
            configs.push_back(c);
            configNames.emplace_back(c.key, c.label);
        }

    nlohmann::json j;
    j["study"] = "error_vs_time";
    j["machine"] = machineInfo(cl.get());
    j["viewport"] = {viewport, viewport};
    j["reference_tolerance"] = kReferenceTolerance;
    j["quality"] = "empty-space skipping on, early termination off, boundary segment on";
    j["steppings"] = options.steppings;
    j["timing"] = "each cell's back ends and steppings timed side by side, round by round, the order reversed every other round";
    std::vector<Point> all;
    std::ostringstream md;
    for (const std::string &name : scans) {
        auto volume = std::make_shared<Volume>(options.quick ? makePeerPhantom({16, 16, 16}, VoxelType::UInt8)
                                                             : loadVolume(options.data / (name + ".nhdr")));
        const TransferFunction tf = options.quick ? peerTransferFunction(nominalRange(*volume), 1)
                                                  : scanByName(name, *volume).tf;
        const Camera camera = peerCamera(*volume, 0);
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
            for (const double step : steps) {
                // Skipping on (it leaves the image as it is), early termination off: at 0.99 it
                // leaves up to 1 % of the light behind, an error floor (~2e-3 RMSE here) that
                // would hide every remedy's own error below it.
                Quality q = configurationQuality(c, step, true);
                q.earlyTermination = 1.0;
                Point proto;
                proto.scan = name;
                proto.config = c.key;
                proto.label = c.label;
                proto.step = step;
                std::vector<std::string> steppings;
                for (const std::string &st : options.steppings)
                    if (!isAdaptive(st) || step >= adaptiveFrom) steppings.push_back(st);
                const auto cell = timeCell(options, renderers, tf, camera, viewport, q, reference(c.cubic, c.shading), proto,
                                           steppings);
                points.insert(points.end(), cell.begin(), cell.end());
            }
        markFronts(points);

        // One table per back end; each stepping's fronts are over all back ends.
        for (const std::string &b : options.backEnds) {
            md << "\n**" << name << "** (" << volume->dims.x << "×" << volume->dims.y << "×" << volume->dims.z
               << ", " << viewport << "², " << b << ": " << renderers[b]->description()
               << "): median ms / RMSE (PSNR dB) / samples per ray; ★ = on its stepping's Pareto front of error "
                  "against time, ◆ = against samples per ray (each over all back ends)\n\n| step | stepping |";
            for (const auto &c : configs) md << " " << c.key << " " << c.label << " |";
            md << "\n|---|---|";
            for (size_t i = 0; i < configs.size(); ++i) md << "---|";
            md << "\n";
            for (const double step : steps)
                for (const std::string &st : options.steppings) {
                    if (std::none_of(points.begin(), points.end(), [&](const Point &p) { return p.step == step && p.stepping == st; }))
                        continue;
                    md << "| " << step << " | " << st << " |";
                    for (const auto &c : configs)
                        for (const Point &p : points)
                            if (p.backEnd == b && p.config == c.key && p.step == step && p.stepping == st)
                                md << " " << fmt(p.timing.median, 0) << " ms / " << fmt(p.error.rmse * 1e3, 2) << "e-3 ("
                                   << fmt(p.error.psnr, 1) << ") / " << fmt(p.samplesPerRay, 0) << frontMarks(p) << " |";
                    md << "\n";
                }
        }
        std::vector<const Point *> front;
        for (const Point &p : points)
            if (p.pareto || p.paretoSamples) front.push_back(&p);
        md << "\n**" << name << "**, the Pareto fronts of " << steppingNames(options.steppings)
           << " stepping, each alone (★ error against time, ◆ error against samples per ray):\n";
        frontsTable(md, front, true);

        const StudyOutput svg(options.out, "error_vs_time");
        svg.writeSvg(renderSvg(errorPlot("Error against run time: " + name, "median frame time, ms", points, configNames,
                                         options.backEnds, options.steppings, false)),
                     "_" + name);
        svg.writeSvg(renderSvg(errorPlot("Error against samples per ray: " + name, "mean samples per ray (rays that hit)",
                                         points, configNames, options.backEnds, options.steppings, true)),
                     "_" + name + "_samples");
        all.insert(all.end(), points.begin(), points.end());
    }

    std::vector<std::vector<std::string>> rows;
    for (const Point &p : all) {
        j["points"].push_back(pointJson(p));
        rows.push_back({p.scan, p.backEnd, p.config, number(p.step), fmt(p.timing.median, 2), fmt(p.timing.min, 2),
                        fmt(p.timing.max, 2), fmt(p.error.rmse, 6), fmt(p.error.psnr, 2), p.pareto ? "1" : "0",
                        p.stepping, fmt(p.samplesPerRay, 2), isAdaptive(p.stepping) ? fmt(p.adaptiveMeanStep, 3) : "",
                        p.paretoSamples ? "1" : "0"});
    }
    StudyOutput out(options.out, "error_vs_time");
    out.writeJson(j);
    out.writeCsv({"scan", "backend", "configuration", "step", "median_ms", "min_ms", "max_ms", "rmse", "psnr", "pareto",
                  "stepping", "samples_per_ray", "adaptive_mean_step", "pareto_samples"},
                 rows);
    out.writeMarkdown(md.str());
    std::cout << md.str();
}

namespace {

struct SyntheticCase {
    std::string name, what;
    std::shared_ptr<Volume> volume;
    TransferFunction tf;
};

// A tent of opacity `a` over [centre − half, centre + half] in colour `c`, onto `base` (another
// opacity and colour, linear in v, that the tent interrupts): the control points, sorted.
void addTent(std::vector<ControlPoint> &points, double centre, double half, double a, Rgba c, const std::function<ControlPoint(double)> &base) {
    points.push_back(base(centre - half));
    points.push_back({centre, c.r, c.g, c.b, a});
    points.push_back(base(centre + half));
}

// Values 0–255 as an 8-bit scan. The blob's σ puts its half-peak shell (v = 127.5) at 1.18σ from
// the centre, well inside the box; the narrow bands are 11 units wide, about 1.5 voxels of that
// shell at 128³ (the field's gradient there is 7.5 units per voxel), so a step of one voxel
// already misses part of a band.
std::vector<SyntheticCase> syntheticCases(int n) {
    const double sigma = 0.16 * n;
    auto blob = std::make_shared<Volume>(makeGaussianBlob({n, n, n}, {1, 1, 1}, sigma, 255).volume);
    auto ramp = std::make_shared<Volume>(makeLinearRamp({n, n, n}, {1, 1, 1}, 0, 255).volume);
    const Rgba orange{1, 0.6, 0.2, 0}, blue{0.2, 0.4, 1, 0};
    const double half = 5.5;
    const auto clear = [](double v) { return ControlPoint{v, 0, 0, 0, 0}; };
    std::vector<SyntheticCase> cases;

    TransferFunction narrow;
    narrow.points.push_back(clear(0));
    addTent(narrow.points, 127.5, half, 0.6, orange, clear);
    narrow.points.push_back(clear(255));
    cases.push_back({"narrow_band", "Gaussian blob, one narrow opaque band (steep only in the bricks of one shell)", blob, narrow});

    // A faint wide band (opacity 0 at v = 5 rising to 0.03 at 255, blue) with the same narrow band in it.
    const auto faint = [&](double v) { return ControlPoint{v, blue.r, blue.g, blue.b, 0.03 * std::clamp((v - 5) / 250, 0.0, 1.0)}; };
    TransferFunction both;
    both.points = {clear(0), faint(5)};
    addTent(both.points, 127.5, half, 0.6, orange, faint);
    both.points.push_back(faint(255));
    cases.push_back({"narrow_on_wide", "Gaussian blob, the narrow band inside a faint wide one (steep in few of the visible bricks)", blob, both});

    // Twelve narrow bands over the blob's whole range: steep in nearly every visible brick.
    TransferFunction comb;
    comb.points.push_back(clear(0));
    for (int k = 0; k < 12; ++k) addTent(comb.points, 15 + 20.0 * k, half, 0.3, k % 2 ? orange : blue, clear);
    comb.points.push_back(clear(255));
    cases.push_back({"comb", "Gaussian blob, twelve narrow bands over its whole range (steep everywhere)", blob, comb});

    // Opacity linear in v, one colour: smooth everywhere; the estimate follows the blob's gradient.
    TransferFunction wide;
    wide.points = {{0, 1, 1, 1, 0}, {255, 1, 1, 1, 0.3}};
    cases.push_back({"wide_constant_colour", "Gaussian blob, opacity linear in the value, one colour (smooth everywhere)", blob, wide});
    // The same on a linear ramp: every brick has the same slope, so every brick gets the
    // shortest step; and the midpoint rule integrates a linear extinction exactly.
    cases.push_back({"ramp_constant_colour", "linear ramp along x, opacity linear in the value, one colour (the same slope in every brick)", ramp, wide});
    return cases;
}

// Synthetic errors reach far below the scans' (the constant-colour ramp's are rounding only).
constexpr double kSyntheticReferenceTolerance = 1e-6;
// How far above uniform's smallest error (its floor) an adaptive point must lie to be placed on
// uniform's curve: on the smooth cases the curve's last halvings of the step gain under 10 %.
constexpr double kFloorMargin = 3;

} // namespace

void errorSynthetic(const std::shared_ptr<OpenClContext> &cl, const StudyOptions &options, int viewport, int side) {
    // Uniform also at the adaptive step's shortest segments (step / 8 down to 1/32 voxel), so that
    // its curve reaches the errors adaptive stepping reaches and they can be compared.
    const std::vector<double> steps = options.quick ? std::vector<double>{0.25, 1, 2}
                                                    : std::vector<double>{1.0 / 32, 1.0 / 16, 0.125, 0.25, 0.5, 1, 2, 4, 8};
    const double adaptiveFrom = options.quick ? 1 : 0.25;
    if (options.quick) {
        viewport = std::min(viewport, 24);
        side = std::min(side, 16);
    }
    const Configuration &simple = paperConfigurations().front(); // A: trilinear, sampled at segment centres

    nlohmann::json j;
    j["study"] = "error_synthetic";
    j["machine"] = machineInfo(cl.get());
    j["viewport"] = {viewport, viewport};
    j["side"] = side;
    j["reference_tolerance"] = kSyntheticReferenceTolerance;
    j["quality"] = "configuration A (trilinear), empty-space skipping on, early termination off, boundary segment on";
    j["steppings"] = options.steppings;
    std::vector<Point> all;
    std::ostringstream md, summary;
    summary << "\nAdaptive against uniform stepping at the same error (" << side << "³, " << viewport
            << "²; uniform's samples per ray and time at each adaptive point's RMSE, interpolated on the uniform "
               "curve in log–log, for adaptive errors at least " << fmt(kFloorMargin, 0)
            << "× uniform's smallest; > 1: adaptive needs fewer):\n\n"
            << "| case | uniform's smallest RMSE | adaptive points compared | uniform ÷ adaptive samples per ray | uniform ÷ adaptive time |\n"
            << "|---|---:|---:|---|---|\n";
    for (const SyntheticCase &sc : syntheticCases(side)) {
        const Camera camera = peerCamera(*sc.volume, 0);
        std::map<std::string, std::unique_ptr<FrameRenderer>> renderers;
        for (const std::string &b : options.backEnds) {
            renderers[b] = makeStudyRenderer(cl, b, sc.volume);
            j["devices"][b] = renderers[b]->description();
        }
        ReferenceRenderer ref(*sc.volume, sc.tf, Reconstruction::Linear);
        ReferenceOptions ro;
        ro.tolerance = kSyntheticReferenceTolerance;
        ReferenceStats rs;
        const Image reference = ref.render(camera, viewport, viewport, {}, ro, &rs);
        std::cerr << "error_synthetic: " << sc.name << " reference " << fmt(rs.renderSeconds, 1) << " s, reached "
                  << rs.toleranceReached << "\n";
        j["references"].push_back({{"case", sc.name}, {"seconds", rs.renderSeconds}, {"tolerance_reached", rs.toleranceReached}});

        std::vector<Point> points;
        for (const double step : steps) {
            Quality q = configurationQuality(simple, step, true);
            q.earlyTermination = 1.0;
            Point proto;
            proto.scan = sc.name;
            proto.config = simple.key;
            proto.label = simple.label;
            proto.step = step;
            std::vector<std::string> steppings;
            for (const std::string &st : options.steppings)
                if (!isAdaptive(st) || step >= adaptiveFrom) steppings.push_back(st);
            const auto cell = timeCell(options, renderers, sc.tf, camera, viewport, q, reference, proto, steppings);
            points.insert(points.end(), cell.begin(), cell.end());
        }
        markFronts(points);

        // Per back end: adaptive's points placed on uniform's curve of the same back end.
        std::vector<double> sampleGain, timeGain, floors;
        for (const std::string &b : options.backEnds) {
            std::vector<double> us, ut, ue;
            for (const Point &p : points)
                if (p.backEnd == b && !isAdaptive(p.stepping)) {
                    us.push_back(p.samplesPerRay);
                    ut.push_back(p.timing.median);
                    ue.push_back(p.error.rmse);
                }
            // Near uniform's smallest error its curve flattens (rounding and the tables' own error,
            // not the step), and placing a point on the flat part says nothing: only errors at
            // least kFloorMargin times that are compared.
            const double floor = ue.empty() ? 0 : *std::min_element(ue.begin(), ue.end());
            floors.push_back(floor);
            for (Point &p : points)
                if (p.backEnd == b && isAdaptive(p.stepping) && p.error.rmse >= kFloorMargin * floor) {
                    p.uniformSamplesAtError = costAtError(us, ue, p.error.rmse);
                    const double ms = costAtError(ut, ue, p.error.rmse);
                    if (std::isfinite(p.uniformSamplesAtError)) sampleGain.push_back(p.uniformSamplesAtError / p.samplesPerRay);
                    if (std::isfinite(ms)) timeGain.push_back(ms / p.timing.median);
                }
        }
        const auto range = [](std::vector<double> v) {
            if (v.empty()) return std::string("— (no adaptive error inside uniform's range)");
            std::sort(v.begin(), v.end());
            const double med = v.size() % 2 ? v[v.size() / 2] : 0.5 * (v[v.size() / 2 - 1] + v[v.size() / 2]);
            return fmt(v.front(), 2) + "–" + fmt(v.back(), 2) + " (median " + fmt(med, 2) + ")";
        };
        summary << "| " << sc.name << " | " << fmt(*std::min_element(floors.begin(), floors.end()) * 1e3, 4) << "e-3 | "
                << sampleGain.size() << " | " << range(sampleGain) << " | " << range(timeGain) << " |\n";

        md << "\n**" << sc.name << "**: " << sc.what << "; " << side << "³, " << viewport << "²; ★ = on its stepping's front "
           << "of error against time, ◆ = against samples per ray\n\n"
           << "| step | stepping | back end | samples per ray | mean step (voxels) | median ms | RMSE | PSNR dB | uniform samples per ray at this RMSE | front |\n"
           << "|---:|---|---|---:|---:|---:|---:|---:|---:|---|\n";
        for (const Point &p : points)
            md << "| " << p.step << " | " << p.stepping << " | " << p.backEnd << " | " << fmt(p.samplesPerRay, 1) << " | "
               << (isAdaptive(p.stepping) ? fmt(p.adaptiveMeanStep, 2) : fmt(p.step, 2)) << " | " << fmt(p.timing.median, 1)
               << " | " << fmt(p.error.rmse * 1e3, 4) << "e-3 | " << fmt(p.error.psnr, 1) << " | "
               << (isAdaptive(p.stepping) && std::isfinite(p.uniformSamplesAtError) ? fmt(p.uniformSamplesAtError, 1) : "")
               << " |" << frontMarks(p) << " |\n";

        StudyOutput(options.out, "error_synthetic")
            .writeSvg(renderSvg(errorPlot("Error against samples per ray: " + sc.name, "mean samples per ray (rays that hit)",
                                          points, {{"A", ""}}, options.backEnds, options.steppings, true)),
                      "_" + sc.name);
        all.insert(all.end(), points.begin(), points.end());
    }

    std::vector<std::vector<std::string>> rows;
    for (const Point &p : all) {
        nlohmann::json pj = pointJson(p);
        pj["case"] = p.scan;
        pj["uniform_samples_at_this_error"] =
            isAdaptive(p.stepping) && std::isfinite(p.uniformSamplesAtError) ? nlohmann::json(p.uniformSamplesAtError) : nlohmann::json(nullptr);
        j["points"].push_back(pj);
        rows.push_back({p.scan, p.backEnd, p.stepping, number(p.step), fmt(p.samplesPerRay, 2),
                        isAdaptive(p.stepping) ? fmt(p.adaptiveMeanStep, 3) : "", fmt(p.timing.median, 2),
                        fmt(p.timing.min, 2), fmt(p.timing.max, 2), fmt(p.error.rmse, 8), fmt(p.error.psnr, 2),
                        isAdaptive(p.stepping) && std::isfinite(p.uniformSamplesAtError) ? fmt(p.uniformSamplesAtError, 2) : "",
                        p.pareto ? "1" : "0", p.paretoSamples ? "1" : "0"});
    }
    StudyOutput out(options.out, "error_synthetic");
    out.writeJson(j);
    out.writeCsv({"case", "backend", "stepping", "step", "samples_per_ray", "adaptive_mean_step", "median_ms", "min_ms",
                  "max_ms", "rmse", "psnr", "uniform_samples_at_this_error", "pareto", "pareto_samples"},
                 rows);
    out.writeMarkdown(summary.str() + md.str());
    std::cout << summary.str() << md.str();
}

} // namespace volcast::bench
