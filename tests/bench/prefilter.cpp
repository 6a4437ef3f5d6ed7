// Table 2: the cubic B-spline prefilter (bspline_prefilter.hpp), simple against
// multithreaded against OpenCL, on 256³ and 512³, next to the memory-bandwidth floor:
// reading and writing the volume three times (one pass per axis), on the host and on the
// device. The OpenCL columns: with transfers (up, filter, back), on the device (the filter
// alone, its launches and waits recorded), and the renderer's path (the samples up as held,
// widened, filtered and padded on the device, nothing back: bsplinePaddedCoefficientsOpenCl).

#include "renderer/common/bspline_prefilter.hpp"
#include "renderer/opencl/bspline_prefilter_opencl.hpp"
#include "tests/bench/phantom.hpp"
#include "tests/bench/studies.hpp"
#include "tests/bench/svg_plot.hpp"

#include <algorithm>
#include <cmath>
#include <iostream>
#include <map>
#include <sstream>
#include <thread>

namespace volcast::bench {

namespace {

// One read-and-write pass over `data` on every hardware thread (x ← x·a + b, which the
// compiler cannot drop): the memory traffic of one prefilter axis with no arithmetic cost.
void readWritePass(std::vector<float> &data, float a, float b) {
    const unsigned threads = std::max(1u, std::thread::hardware_concurrency());
    std::vector<std::thread> pool;
    for (unsigned t = 0; t < threads; ++t)
        pool.emplace_back([&, t] {
            const size_t begin = data.size() * t / threads, end = data.size() * (t + 1) / threads;
            for (size_t i = begin; i < end; ++i) data[i] = data[i] * a + b;
        });
    for (auto &th : pool) th.join();
}

double maxAbsDiff(const std::vector<float> &a, const std::vector<float> &b) {
    double m = 0;
    for (size_t i = 0; i < a.size(); ++i) m = std::max(m, double(std::fabs(a[i] - b[i])));
    return m;
}

} // namespace

void prefilter(OpenClContext &cl, const StudyOptions &options) {
    const std::vector<int64_t> sides = options.quick ? std::vector<int64_t>{24, 32} : std::vector<int64_t>{256, 512};
    RepeatOptions repeat = options.repeat;
    repeat.warmup = 1;
    repeat.repeats = std::min(repeat.repeats, 3);

    nlohmann::json j;
    j["study"] = "table2_prefilter";
    j["machine"] = machineInfo(&cl);
    std::vector<std::vector<std::string>> rows;
    std::ostringstream md;
    md << "| volume | simple (1 thread) | multithreaded (" << std::thread::hardware_concurrency()
       << " threads) | OpenCL incl. transfers | OpenCL on the device | OpenCL, the renderer's coefficients (no read-back) "
          "| 3 read+write passes (bound) | 3 device copies (device bound) |\n"
       << "|---|---|---|---|---|---|---|---|\n";
    Plot plot;
    plot.title = "Table 2: cubic B-spline prefilter";
    plot.xLabel = "voxels (millions)";
    plot.yLabel = "seconds (median)";
    plot.logX = plot.logY = true;
    std::map<std::string, Series> series;
    const char *const names[] = {"simple", "multithreaded", "OpenCL incl. transfers", "OpenCL on the device",
                                 "OpenCL renderer's coefficients", "3 device copies", "3 read+write passes"};
    for (const char *name : names) series[name] = Series{name};

    for (const int64_t n : sides) {
        const Vec3i dims{n, n, n};
        std::cerr << "prefilter: " << n << "³\n";
        const Volume phantom = makePeerPhantom(dims, VoxelType::UInt8);
        const std::vector<float> input = phantom.samples().toFloats();
        const double mvox = double(input.size()) / 1e6;
        std::vector<float> work, simpleResult, mtResult, clResult;

        const auto freshCopy = [&] { work = input; };
        const Timing simple =
            bench::repeat(repeat, [&](int) { bsplinePrefilterSimple(work.data(), dims); }, freshCopy);
        simpleResult = work;
        const Timing mt =
            bench::repeat(repeat, [&](int) { bsplinePrefilterMultithreaded(work.data(), dims); }, freshCopy);
        mtResult = work;
        const Timing withTransfers = bench::repeat(repeat, [&](int) { clResult = bsplinePrefilterOpenCl(cl, input.data(), dims); });
        cl::Buffer buffer(cl.context(), CL_MEM_READ_WRITE, input.size() * sizeof(float));
        cl.queue().enqueueWriteBuffer(buffer, CL_TRUE, 0, input.size() * sizeof(float), input.data());
        PrefilterLaunchCounts launches;
        const Timing onDevice = bench::repeat(repeat, [&](int) { launches = bsplinePrefilterOpenCl(cl, buffer, dims); });
        // Both x passes, whichever the device gets by default (the choice is in docs/gpu.md).
        const auto xPassTiming = [&](PrefilterXPass xPass) {
            PrefilterLaunch launch;
            launch.xPass = xPass;
            return bench::repeat(repeat, [&](int) { bsplinePrefilterOpenCl(cl, buffer, dims, launch); });
        };
        const Timing tiledX = xPassTiming(PrefilterXPass::Tiled), linesX = xPassTiming(PrefilterXPass::Lines);
        // The renderer's path, from the phantom's 8-bit store to padded coefficients on the device.
        const Timing rendererPath = bench::repeat(repeat, [&](int) { bsplinePaddedCoefficientsOpenCl(cl, phantom.samples()); });
        // The device's own floor: three copies of the volume, each one read and one write per sample.
        cl::Buffer other(cl.context(), CL_MEM_READ_WRITE, input.size() * sizeof(float));
        const Timing deviceCopies = bench::repeat(repeat, [&](int) {
            for (int p = 0; p < 3; ++p)
                cl.queue().enqueueCopyBuffer(p % 2 ? other : buffer, p % 2 ? buffer : other, 0, 0,
                                             input.size() * sizeof(float));
            cl.queue().finish();
        });
        work = input;
        const Timing passes = bench::repeat(repeat, [&](int) {
            for (int p = 0; p < 3; ++p) readWritePass(work, 0.999f, 0.001f);
        });
        const double bytes = double(input.size()) * sizeof(float);
        const double bandwidth = 3 * 2 * bytes / (passes.median / 1e3); // bytes/s, read + write

        const double simpleS = simple.median / 1e3, mtS = mt.median / 1e3;
        const double clS = withTransfers.median / 1e3, devS = onDevice.median / 1e3, boundS = passes.median / 1e3;
        const double rendererS = rendererPath.median / 1e3, copiesS = deviceCopies.median / 1e3;
        const double diffMt = maxAbsDiff(simpleResult, mtResult), diffCl = maxAbsDiff(simpleResult, clResult);
        j["volumes"].push_back({{"dims", {n, n, n}},
                                {"simple_ms", toJson(simple)},
                                {"multithreaded_ms", toJson(mt)},
                                {"opencl_with_transfers_ms", toJson(withTransfers)},
                                {"opencl_on_device_ms", toJson(onDevice)},
                                {"opencl_on_device_launches", launches.launches},
                                {"opencl_on_device_waits", launches.waits},
                                {"opencl_on_device_largest_slab_samples", launches.largestSlabSamples},
                                {"opencl_on_device_x_tiled_ms", toJson(tiledX)},
                                {"opencl_on_device_x_lines_ms", toJson(linesX)},
                                {"opencl_renderer_coefficients_ms", toJson(rendererPath)},
                                {"device_three_copies_ms", toJson(deviceCopies)},
                                {"three_read_write_passes_ms", toJson(passes)},
                                {"measured_bandwidth_gb_per_s", bandwidth / 1e9},
                                {"max_abs_difference_multithreaded_vs_simple", diffMt},
                                {"max_abs_difference_opencl_vs_simple", diffCl},
                                {"target_s", 2 * boundS},
                                {"best_s", std::min({mtS, clS})}});
        std::cerr << "prefilter: " << n << "³ simple " << fmt(simpleS, 3) << " s, multithreaded " << fmt(mtS, 3)
                  << " s, OpenCL " << fmt(clS, 3) << " s (device " << fmt(devS, 3) << " s in " << launches.launches
                  << " launches, x tiled " << fmt(tiledX.median / 1e3, 3) << " s, x lines " << fmt(linesX.median / 1e3, 3)
                  << " s; renderer's coefficients " << fmt(rendererS, 3) << " s), 3 passes " << fmt(boundS, 3) << " s ("
                  << fmt(bandwidth / 1e9, 1) << " GB/s), 3 device copies " << fmt(copiesS, 4) << " s\n";
        rows.push_back({std::to_string(n), fmt(simpleS, 4), fmt(mtS, 4), fmt(clS, 4), fmt(devS, 4), fmt(rendererS, 4),
                        fmt(boundS, 4), fmt(copiesS, 5), fmt(bandwidth / 1e9, 2), fmt(diffMt, 8), fmt(diffCl, 8)});
        md << "| " << n << "³ | " << fmt(simpleS, 2) << " s | " << fmt(mtS, 2) << " s | " << fmt(clS, 2) << " s | "
           << fmt(devS, 3) << " s | " << fmt(rendererS, 3) << " s | " << fmt(boundS, 3) << " s ("
           << fmt(bandwidth / 1e9, 1) << " GB/s) | " << fmt(copiesS, 4) << " s |\n";
        const double values[] = {simpleS, mtS, clS, devS, rendererS, copiesS, boundS};
        for (int i = 0; i < 7; ++i) {
            series[names[i]].x.push_back(mvox);
            series[names[i]].y.push_back(values[i]);
        }
    }
    md << "\nPaper (Table 2, 2012–2016 hardware, volume size not stated): simple 6.3–9.1 s, OpenMP 1.6–2.7 s, "
          "OpenCL 1.0–3.4 s.\n";
    StudyOutput out(options.out, "table2_prefilter");
    out.writeJson(j);
    out.writeCsv({"side", "simple_s", "multithreaded_s", "opencl_with_transfers_s", "opencl_on_device_s",
                  "opencl_renderer_coefficients_s", "three_passes_s", "device_three_copies_s", "bandwidth_gb_per_s",
                  "max_diff_multithreaded", "max_diff_opencl"},
                 rows);
    out.writeMarkdown(md.str());
    std::cout << md.str();
    for (const char *name : names) plot.series.push_back(series[name]);
    plot.series.back().dashed = true;
    out.writeSvg(renderSvg(plot));
}

} // namespace volcast::bench
