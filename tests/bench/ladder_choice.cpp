// The quality ladder on the device the study runs on: each level of the server's automatic
// ladder for its default final quality, timed and measured against the final frame, and the
// level the scheduler would show while 1, 4, 16, 32 sessions drag on the same device.
//
// Each frame is rendered as the scheduler renders it (a TiledFrame, its whole pass in one
// unit, 8-bit RGBA where the server reads back bytes), timed by the frame's own renderMs()
// (what the scheduler records in the session's LevelTimer), and encoded as the server sends
// it (JPEG at the level's quality). A level's error is the server's calibration metric
// (ErrorCalibrator::calibrateLevels): RMSE over 8-bit RGB in [0, 1] of its decoded JPEG,
// scaled up to the view as a client shows it where the frame is smaller, against the final
// frame at the same camera.

#include "tests/bench/ladder_choice.hpp"

#include "renderer/io/volume_io.hpp"
#include "renderer/make_frame_renderer.hpp"
#include "server/config.hpp"
#include "server/error_calibrator.hpp"
#include "server/frame_encoder.hpp"
#include "server/quality_ladder.hpp"
#include "server/tiled_frame.hpp"
#include "tests/bench/configurations.hpp"
#include "tests/bench/phantom.hpp"

#include <algorithm>
#include <chrono>
#include <iostream>
#include <sstream>

namespace volcast::bench {

namespace {

using server::Level;

struct LevelResult {
    Level level;
    double samples = 0;           // predictedSamples at the view's size, all passes
    Timing frameMs;               // TiledFrame::renderMs of the timed frames
    double predictedMs = 0;       // the LevelTimer's prediction after those frames
    double deviationMs = 0;       // the LevelTimer's deviation, this level's frames alone
    Timing finishMs;              // the frame's finish (averaging passes), budgeted nowhere
    Timing encodeMs;              // JPEG at the level's quality (the final: PNG, not timed)
    std::optional<double> error;  // RMSE against the final frame; none for the final itself
};

// A level a drag settles on, with the budget it was chosen under.
struct Choice {
    int sessions = 0;
    double budgetMs = 0;
    size_t level = 0;
};

// One frame as the scheduler renders it: every cell of each pass in one unit.
struct RenderedFrame {
    double ms = 0;
    double finishMs = 0;          // TiledFrame::finish / finishRgba8: averaging jittered passes
    double encodeMs = 0;
    std::vector<uint8_t> jpeg;    // non-final levels
    Image image;                  // the final level
};

RenderedFrame renderAsServer(FrameRenderer &renderer, const FrameRequest &request, const Level &level, bool final) {
    server::TiledFrame frame(request, level.passes, renderer.bandRows(), !final);
    while (!frame.done()) frame.renderUnit(renderer, frame.cellsLeftInPass());
    RenderedFrame out;
    out.ms = frame.renderMs();
    // As RenderScheduler::renderUnit: the frame finished, then encoded (only the encoding timed
    // as the frame's encodeMs; the finish is in neither its render nor its encode time).
    const auto msSince = [](std::chrono::steady_clock::time_point t) {
        return std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t).count();
    };
    auto t0 = std::chrono::steady_clock::now();
    Rgba8Image bytes;
    if (frame.rgba8())
        bytes = frame.finishRgba8();
    else
        out.image = frame.finish();
    out.finishMs = msSince(t0);
    if (!final) {
        t0 = std::chrono::steady_clock::now();
        out.jpeg = frame.rgba8() ? server::encodeJpeg(bytes, level.jpegQuality) : server::encodeJpeg(out.image, level.jpegQuality);
        out.encodeMs = msSince(t0);
    }
    return out;
}

std::string sizeText(std::pair<int, int> s) { return std::to_string(s.first) + "×" + std::to_string(s.second); }

std::string levelText(const Quality &q) {
    std::ostringstream s;
    s << "scale " << fmt(q.imageScale, 2) << ", mip " << q.mipLevel << ", step " << fmt(q.step, 2);
    return s.str();
}

} // namespace

void ladderChoice(const std::shared_ptr<OpenClContext> &cl, const StudyOptions &options,
                  const std::vector<std::pair<int, int>> &sizes, const std::vector<int> &sessions) {
    std::shared_ptr<const Volume> volume;
    TransferFunction tf;
    if (options.quick) {   // no data folder needed: a small phantom
        volume = std::make_shared<Volume>(makePeerPhantom({24, 24, 24}, VoxelType::UInt8));
        tf = peerTransferFunction(nominalRange(*volume), 1);
    } else {
        volume = std::make_shared<Volume>(loadVolume(options.data / "bonsai.nhdr"));
        tf = scanByName("bonsai", *volume).tf;
    }
    const Camera camera0 = peerCamera(*volume, 0);
    const std::unique_ptr<FrameRenderer> renderer = makeStudyRenderer(cl, options.backEnd, volume);

    // The server's defaults: an automatic policy without switches renders Quality{} as its
    // final level (SessionScene::setPolicy), its ladder fitted to the admission limits
    // (websocket_session.cpp, ladderOf), the target frame time ServerConfig's.
    const server::ServerConfig config;
    const Quality finalQuality{};
    const double targetMs = config.defaultTargetFrameMs;
    const server::AdmissionLimits limits{double(config.maxSamplesPerFrame), double(config.maxRequestBytes)};

    nlohmann::json j;
    j["study"] = "ladder";
    j["machine"] = machineInfo(cl.get());
    j["renderer"] = options.backEnd;
    j["device"] = renderer->description();
    j["volume"] = volume->name;
    j["camera"] = "peers' framing (bounding sphere fits a 30° view, 20° elevation), 3° orbit per timed frame";
    j["final_quality"] = qualityToJson(finalQuality);
    j["target_frame_ms"] = targetMs;
    j["render_share"] = server::kRenderShare;
    j["budget"] = "render_share · target_frame_ms / sessions − encode_ms − 2 · deviation_ms (the chosen level's)";
    std::vector<std::vector<std::string>> levelRows, choiceRows;
    std::ostringstream md;
    md << volume->name << ", " << renderer->description() << "; final quality the server's default (" << qualityToJson(finalQuality).dump()
       << "), target " << fmt(targetMs, 0) << " ms.\n";

    std::ostringstream choicesMd;
    choicesMd << "\n| size | sessions dragging | budget ms | level | image scale | mip | step | predicted ms | RMSE | full resolution |\n"
                 "|---|---:|---:|---:|---:|---:|---:|---:|---:|---|\n";
    for (const auto &size : sizes) {
        const auto [width, height] = size;
        const std::vector<Level> ladder =
            server::fitToLimits(server::automaticLadder(finalQuality, config.jitterPasses), volume.get(), width, height, limits);
        const size_t last = ladder.size() - 1;
        std::vector<LevelResult> results(ladder.size());
        // The final frame first: every level's error is against it.
        const Image finalImage = renderAsServer(*renderer, {tf, camera0, width, height, ladder[last].quality, {}}, ladder[last], true).image;
        const server::Rgb8 final8 = server::toRgb8(finalImage);
        for (size_t l = 0; l < ladder.size(); ++l) {
            LevelResult &r = results[l];
            r.level = ladder[l];
            r.samples = server::predictedSamples(*volume, r.level.quality, width, height) * r.level.passes;
            const bool isFinal = l == last;
            // The untimed first frame (tables, kernels, caches) at camera 0: the error's frame.
            const RenderedFrame first = renderAsServer(*renderer, {tf, camera0, width, height, r.level.quality, {}}, r.level, isFinal);
            if (!isFinal) r.error = server::rmseRgb8(server::scaledRgb8(server::decodeJpegRgb8(first.jpeg), width, height), final8);
            server::LevelTimer timer;
            timer.reset(1);
            std::vector<double> encodes, finishes;
            RepeatOptions timed = options.repeat;
            timed.warmup = 0;
            std::vector<double> frameMs;
            (void)bench::repeat(timed, [&](int k) {
                const Camera camera = peerCamera(*volume, k + 1);
                const RenderedFrame f = renderAsServer(*renderer, {tf, camera, width, height, r.level.quality, {}}, r.level, isFinal);
                frameMs.push_back(f.ms);
                encodes.push_back(f.encodeMs);
                finishes.push_back(f.finishMs);
                timer.record(0, f.ms, r.samples);
            });
            r.frameMs = summarize(frameMs);
            r.encodeMs = summarize(encodes);
            r.finishMs = summarize(finishes);
            r.predictedMs = timer.predictMs(0, r.samples);
            r.deviationMs = timer.deviationMs();
            std::cerr << "ladder: " << width << "x" << height << " level " << l << " (" << levelText(r.level.quality)
                      << "): " << fmt(r.frameMs.median, 2) << " ms"
                      << (r.error ? ", RMSE " + fmt(*r.error, 4) : std::string()) << "\n";
        }
        std::vector<server::LevelOutlook> outlook(ladder.size());
        for (size_t l = 0; l < ladder.size(); ++l) outlook[l] = {results[l].predictedMs, results[l].error};

        nlohmann::json cell;
        cell["resolution"] = {width, height};
        md << "\n" << sizeText(size) << ", " << ladder.size() << " levels:\n\n"
           << "| level | image scale | mip | step | jitter | JPEG q | frame ms (median, min–max) | predicted ms | deviation ms | finish ms | encode ms | RMSE vs final |\n"
              "|---:|---:|---:|---:|---|---:|---:|---:|---:|---:|---:|---:|\n";
        for (size_t l = 0; l < ladder.size(); ++l) {
            const LevelResult &r = results[l];
            const Quality &q = r.level.quality;
            const bool isFinal = l == last;
            cell["levels"].push_back({{"level", l},
                                      {"quality", qualityToJson(q)},
                                      {"passes", r.level.passes},
                                      {"jpeg_quality", isFinal ? nlohmann::json(nullptr) : nlohmann::json(r.level.jpegQuality)},
                                      {"limited", r.level.limited},
                                      {"predicted_samples", r.samples},
                                      {"frame_ms", toJson(r.frameMs)},
                                      {"predicted_ms", r.predictedMs},
                                      {"deviation_ms", r.deviationMs},
                                      {"finish_ms", toJson(r.finishMs)},
                                      {"encode_ms", toJson(r.encodeMs)},
                                      {"encoding", isFinal ? "png (not timed)" : "jpeg"},
                                      {"rmse_vs_final", r.error ? nlohmann::json(*r.error) : nlohmann::json(nullptr)}});
            levelRows.push_back({std::to_string(width) + "x" + std::to_string(height), std::to_string(l), fmt(q.imageScale, 2),
                                 std::to_string(q.mipLevel), fmt(q.step, 2), q.jitter ? "1" : "0",
                                 isFinal ? "" : std::to_string(r.level.jpegQuality), fmt(r.frameMs.median, 3),
                                 fmt(r.frameMs.min, 3), fmt(r.frameMs.max, 3), fmt(r.predictedMs, 3), fmt(r.deviationMs, 3),
                                 fmt(r.finishMs.median, 3), isFinal ? "" : fmt(r.encodeMs.median, 3), r.error ? fmt(*r.error, 5) : ""});
            md << "| " << l << (isFinal ? " (final)" : "") << " | " << fmt(q.imageScale, 2) << " | " << q.mipLevel << " | "
               << fmt(q.step, 2) << " | " << (q.jitter ? "yes" : "no") << " | "
               << (isFinal ? std::string("PNG") : std::to_string(r.level.jpegQuality)) << " | " << fmt(r.frameMs.median, 2)
               << " (" << fmt(r.frameMs.min, 2) << "–" << fmt(r.frameMs.max, 2) << ") | " << fmt(r.predictedMs, 2) << " | "
               << fmt(r.deviationMs, 2) << " | " << fmt(r.finishMs.median, 2) << " | " << (isFinal ? std::string("") : fmt(r.encodeMs.median, 2)) << " | "
               << (r.error ? fmt(*r.error, 4) : std::string("")) << " |\n";
        }

        for (const int n : sessions) {
            // Steady dragging: the budget takes the encode time and deviation of the level
            // being shown (the session's EMAs follow the frames it renders), so the choice is
            // made again from each level chosen, starting from the cheapest, until a level comes
            // back: from there on the drag stays on one level or alternates among a few.
            std::vector<size_t> shownSeq{0};
            std::vector<double> budgets;   // budgets[i]: with shownSeq[i] shown
            std::vector<Choice> settled;
            for (;;) {
                const LevelResult &shown = results[shownSeq.back()];
                budgets.push_back(server::interactiveBudgetMs(targetMs, size_t(std::max(n, 1)), shown.encodeMs.median, shown.deviationMs));
                const size_t next = last == 0 ? 0 : server::chooseInteractiveLevel(outlook, budgets.back());
                const auto again = std::find(shownSeq.begin(), shownSeq.end(), next);
                if (again == shownSeq.end()) {
                    shownSeq.push_back(next);
                    continue;
                }
                for (auto i = size_t(again - shownSeq.begin()); i < shownSeq.size(); ++i)
                    settled.push_back({n, i == size_t(again - shownSeq.begin()) ? budgets.back() : budgets[i - 1], shownSeq[i]});
                break;
            }
            const bool alternates = settled.size() > 1;
            for (const Choice &c : settled) {
                const LevelResult &r = results[c.level];
                const Quality &q = r.level.quality;
                const bool full = q.imageScale == 1;
                cell["choices"].push_back({{"sessions_dragging", n},
                                           {"budget_ms", c.budgetMs},
                                           {"alternates", alternates},
                                           {"level", c.level},
                                           {"quality", qualityToJson(q)},
                                           {"predicted_ms", r.predictedMs},
                                           {"frame_ms_median", r.frameMs.median},
                                           {"rmse_vs_final", r.error ? nlohmann::json(*r.error) : nlohmann::json(nullptr)},
                                           {"full_resolution", full}});
                choiceRows.push_back({std::to_string(width) + "x" + std::to_string(height), std::to_string(n),
                                      fmt(c.budgetMs, 3), std::to_string(c.level), fmt(q.imageScale, 2),
                                      std::to_string(q.mipLevel), fmt(q.step, 2), fmt(r.predictedMs, 3),
                                      r.error ? fmt(*r.error, 5) : "", full ? "1" : "0", alternates ? "1" : "0"});
                choicesMd << "| " << sizeText(size) << " | " << n << " | " << fmt(c.budgetMs, 1) << " | " << c.level
                          << (alternates ? " (alternating)" : "") << " | " << fmt(q.imageScale, 2) << " | " << q.mipLevel
                          << " | " << fmt(q.step, 2) << " | " << fmt(r.predictedMs, 2) << " | "
                          << (r.error ? fmt(*r.error, 4) : std::string("")) << " | " << (full ? "yes" : "no") << " |\n";
                std::cerr << "ladder: " << width << "x" << height << ", " << n << " dragging: budget " << fmt(c.budgetMs, 2)
                          << " ms, level " << c.level << " (" << levelText(q) << ")" << (full ? ", full resolution" : "")
                          << (alternates ? ", alternating" : "") << "\n";
            }
        }
        j["cells"].push_back(cell);
    }
    md << "\nFrame ms: TiledFrame::renderMs, what the scheduler's LevelTimer records; finish ms (TiledFrame::finish: "
          "averaging jittered passes) is in neither the frame's render nor its encode time.\n";
    md << "\nThe level chosen while dragging (budget = " << server::kRenderShare << " × " << fmt(targetMs, 0)
       << " ms ÷ sessions − the shown level's encode ms − 2 × its deviation):\n"
       << choicesMd.str();

    StudyOutput out(options.out, "ladder");
    out.writeJson(j);
    out.writeCsv({"size", "level", "image_scale", "mip_level", "step", "jitter", "jpeg_quality", "median_ms", "min_ms",
                  "max_ms", "predicted_ms", "deviation_ms", "finish_ms", "encode_ms", "rmse_vs_final"},
                 levelRows);
    out.writeCsv({"size", "sessions_dragging", "budget_ms", "level", "image_scale", "mip_level", "step", "predicted_ms",
                  "rmse_vs_final", "full_resolution", "alternates"},
                 choiceRows, "_choices");
    out.writeMarkdown(md.str());
    std::cout << md.str();
}

} // namespace volcast::bench
