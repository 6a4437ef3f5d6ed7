// What a frame costs to encode beside what it costs to render: a scan drawn by the native
// path at the sizes users' viewports have, then encoded as the server sends it (the
// interactive frame, cast at half scale and sent at that size for the client to scale up, as
// JPEG at the ladder's qualities; the final frame as lossless PNG). Beside them the half-scale
// frame upsampled to the viewport first, as servers that scaled frames up sent it. Rounds
// interleave every size and encoding; one JSON line per size with medians, minima and maxima.

#include "renderer/cpu/cpu_renderer.hpp"
#include "renderer/io/volume_io.hpp"
#include "server/frame_encoder.hpp"
#include "tests/bench/studies.hpp"

#include <nlohmann/json.hpp>

#include <chrono>
#include <iostream>

namespace volcast::bench {

void encodeStudy(const std::filesystem::path &scan, const std::vector<std::pair<int, int>> &sizes, int rounds) {
    auto volume = std::make_shared<const Volume>(loadVolume(scan));
    CpuRenderer renderer(volume);
    const TransferFunction tf = peerTransferFunction(nominalRange(*volume), volume->smallestSpacing());
    struct Cell {
        int width = 0, height = 0;
        Image interactive, upsampled, final;
        double interactiveRenderMs = 0, finalRenderMs = 0;
        size_t jpeg50Bytes = 0, jpeg80Bytes = 0, pngBytes = 0;
        size_t upsampledBytes = 0;
        std::vector<double> jpeg50Ms, jpeg80Ms, upsampledMs, pngMs;
    };
    std::vector<Cell> cells;
    const auto msSince = [](std::chrono::steady_clock::time_point t0) {
        return std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
    };
    for (const auto &[w, h] : sizes) {
        Cell c;
        c.width = w;
        c.height = h;
        Quality q = table1Quality();
        RenderStats st;
        c.final = renderer.render({tf, peerCamera(*volume, 0), w, h, q, {}}, &st);
        c.finalRenderMs = st.renderSeconds * 1e3;
        q.imageScale = 0.5;
        // The grid alone (a window of all its rays is not upsampled), and upsampled.
        const RayWindow grid{0, 0, raysForScale(w, q.imageScale), raysForScale(h, q.imageScale)};
        c.interactive = renderer.render({tf, peerCamera(*volume, 0), w, h, q, {}, grid}, &st);
        c.interactiveRenderMs = st.renderSeconds * 1e3;
        c.upsampled = renderer.render({tf, peerCamera(*volume, 0), w, h, q, {}});
        cells.push_back(std::move(c));
    }
    for (int r = 0; r < rounds + 1; ++r)   // round 0 warms the encoders up, untimed
        for (Cell &c : cells) {
            auto t0 = std::chrono::steady_clock::now();
            c.jpeg50Bytes = server::encodeJpeg(c.interactive, 50).size();
            if (r > 0) c.jpeg50Ms.push_back(msSince(t0));
            t0 = std::chrono::steady_clock::now();
            c.jpeg80Bytes = server::encodeJpeg(c.interactive, 80).size();
            if (r > 0) c.jpeg80Ms.push_back(msSince(t0));
            t0 = std::chrono::steady_clock::now();
            c.upsampledBytes = server::encodeJpeg(c.upsampled, 80).size();
            if (r > 0) c.upsampledMs.push_back(msSince(t0));
            t0 = std::chrono::steady_clock::now();
            c.pngBytes = server::encodePng(c.final).size();
            if (r > 0) c.pngMs.push_back(msSince(t0));
        }
    for (Cell &c : cells) {
        nlohmann::json j;
        j["scan"] = scan.filename().string();   // no machine folders in recorded results
        j["size"] = std::to_string(c.width) + "x" + std::to_string(c.height);
        j["encoder"] = server::encoderDescription();
        j["render_ms"] = {{"interactive_half_scale", c.interactiveRenderMs}, {"final", c.finalRenderMs}};
        j["jpeg_q50"] = {{"bytes", c.jpeg50Bytes}, {"ms", toJson(summarize(c.jpeg50Ms))}};
        j["jpeg_q80"] = {{"bytes", c.jpeg80Bytes}, {"ms", toJson(summarize(c.jpeg80Ms))}};
        j["jpeg_q80_upsampled"] = {{"bytes", c.upsampledBytes}, {"ms", toJson(summarize(c.upsampledMs))}};
        j["png"] = {{"bytes", c.pngBytes}, {"ms", toJson(summarize(c.pngMs))}};
        std::cout << j.dump() << std::endl;
    }
}

} // namespace volcast::bench
