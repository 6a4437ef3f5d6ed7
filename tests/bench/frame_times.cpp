// Table 1 (frame time against output resolution) and the peers' side-by-side mode: both
// orbit the peers' camera over a volume at 1 sample per voxel and time whole frames
// (kernel, read-back to the host, and any upsampling: what a server pays before encoding).

#include "renderer/model/image.hpp"
#include "renderer/io/volume_io.hpp"
#include "renderer/cpu/cpu_renderer.hpp"
#include "renderer/make_frame_renderer.hpp"
#include "tests/bench/phantom.hpp"
#include "tests/bench/studies.hpp"
#include "tests/bench/svg_plot.hpp"

#include <algorithm>
#include <fstream>
#include <iostream>
#include <map>
#include <sstream>
#include <stdexcept>
#include <thread>

#include <sys/resource.h>
#include <unistd.h>

namespace volcast::bench {

namespace {

// The paper's Table 1 (NVIDIA Quadro 1000M, 2012), ms per frame.
const std::map<std::string, std::map<std::string, double>> kPaperTable1 = {
    {"small", {{"512x512", 31.67}, {"800x600", 34.20}, {"1024x768", 50.83}, {"1280x1024", 97.09}, {"1920x1080", 114.94}}},
    {"large", {{"512x512", 81.97}, {"800x600", 114.63}, {"1024x768", 163.93}, {"1280x1024", 218.34}, {"1920x1080", 280.90}}},
};

std::string sizeName(std::pair<int, int> s) { return std::to_string(s.first) + "x" + std::to_string(s.second); }

// CPUs kept busy by other processes while timing, as the peers' scripts report it (their
// '*' mark): all CPUs' busy time from /proc/stat minus this process's own CPU time.
class OtherLoad {
  public:
    OtherLoad() : busy0_(machineBusy()), own0_(ownCpu()), t0_(std::chrono::steady_clock::now()) {}
    double cpus() const {
        const double wall = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0_).count();
        const double other = (machineBusy() - busy0_) - (ownCpu() - own0_);
        return wall > 0 ? std::max(0.0, other / wall) : 0.0;
    }

  private:
    static double machineBusy() {
        std::ifstream in("/proc/stat");
        std::string cpu;
        double user = 0, nice = 0, system = 0, idle = 0, iowait = 0, irq = 0, softirq = 0, steal = 0;
        in >> cpu >> user >> nice >> system >> idle >> iowait >> irq >> softirq >> steal;
        return (user + nice + system + irq + softirq + steal) / double(sysconf(_SC_CLK_TCK));
    }
    static double ownCpu() {
        rusage u{};
        getrusage(RUSAGE_SELF, &u);
        return double(u.ru_utime.tv_sec + u.ru_stime.tv_sec) + 1e-6 * double(u.ru_utime.tv_usec + u.ru_stime.tv_usec);
    }
    double busy0_, own0_;
    std::chrono::steady_clock::time_point t0_;
};

// The parts of the timed frames (RenderStats), ms: the device's own times from OpenCL
// profiling events, 0 on the native path.
struct FrameParts {
    std::vector<double> setUp, kernel, readBack, hostConvert;
    void add(const RenderStats &st) {
        hostConvert.push_back(st.hostConvertSeconds * 1e3);
        setUp.push_back(st.hostSetUpSeconds * 1e3);
        kernel.push_back(st.deviceKernelSeconds * 1e3);
        readBack.push_back(st.deviceReadBackSeconds * 1e3);
    }
    static double median(std::vector<double> v) { return v.empty() ? 0 : summarize(std::move(v)).median; }
    nlohmann::json json(const Timing &frame) const {
        const double k = median(kernel);
        return {{"host_set_up_ms", median(setUp)},
                {"device_kernel_ms", k},
                {"device_read_back_ms", median(readBack)},
                {"host_convert_ms", median(hostConvert)},
                // The overhead target on a GPU: frame ≤ 1.2 × kernel (medians of the same frames; docs/gpu.md).
                {"frame_over_kernel", k > 0 ? nlohmann::json(frame.median / k) : nlohmann::json(nullptr)}};
    }
};

struct CellResult {
    Image last;
    Timing timing;
    double firstFrameMs = 0;
    double otherCpus = 0;
    RenderStats stats;
    FrameParts parts;
    // The same orbit as 8-bit RGBA (renderRgba8: what the server reads back for a frame it
    // encodes as JPEG); OpenCL only, where the conversion runs on the device.
    Timing rgba8;
    FrameParts rgba8Parts;
};

// First frame (program build, bricks, tables) at frame 0, then the camera orbits one step
// per timed frame, as in the peers' time_frames().
CellResult timeOrbit(FrameRenderer &renderer, const TransferFunction &tf, const Quality &quality, int width,
                     int height, const RepeatOptions &repeat, bool alsoRgba8) {
    CellResult r;
    const auto t0 = std::chrono::steady_clock::now();
    renderer.render({tf, peerCamera(renderer.volume(), 0), width, height, quality, {}}, &r.stats);
    r.firstFrameMs = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
    OtherLoad load;
    RepeatOptions timed = repeat;
    timed.warmup = 0;
    r.timing = bench::repeat(timed, [&](int k) {
        r.last = renderer.render({tf, peerCamera(renderer.volume(), k + 1), width, height, quality, {}}, &r.stats);
        r.parts.add(r.stats);
    });
    if (alsoRgba8) {
        RenderStats st;
        renderer.renderRgba8({tf, peerCamera(renderer.volume(), 0), width, height, quality, {}}, &st); // its kernel
        r.rgba8 = bench::repeat(timed, [&](int k) {
            renderer.renderRgba8({tf, peerCamera(renderer.volume(), k + 1), width, height, quality, {}}, &st);
            r.rgba8Parts.add(st);
        });
    }
    r.otherCpus = load.cpus();
    return r;
}

} // namespace

std::unique_ptr<FrameRenderer> makeStudyRenderer(const std::shared_ptr<OpenClContext> &cl, const std::string &backEnd,
                                                 std::shared_ptr<const Volume> volume, const std::string &layout) {
    if (layout != "bricks" && layout != "slices")
        throw std::invalid_argument("layout '" + layout + "': expected bricks or slices");
    // The back ends as the server makes them: no OpenCL context is the native path.
    if (backEnd == "cpu" && layout == "bricks")
        return std::make_unique<CpuRenderer>(std::move(volume), CpuRendererOptions{.layout = SampleLayout::Bricks});
    if (backEnd == "cpu") return makeFrameRenderer(nullptr, std::move(volume));
    if (backEnd == "opencl") return makeFrameRenderer(cl, std::move(volume));
    throw std::invalid_argument("back end '" + backEnd + "': expected opencl or cpu");
}

std::string resolveBackEnd(const std::string &backEnd) {
    const DeviceChoice resolved = resolveDeviceChoice(DeviceChoice::parse(backEnd));
    return resolved.kind == DeviceChoice::Kind::Cpu ? "cpu" : "opencl";
}

std::vector<std::pair<int, int>> parseSizes(const std::string &text) {
    std::vector<std::pair<int, int>> sizes;
    std::stringstream s(text);
    std::string part;
    while (std::getline(s, part, ',')) {
        const auto x = part.find_first_of("xX");
        try {
            if (x == std::string::npos) throw std::invalid_argument("no x");
            const auto whole = [](const std::string &digits) {
                size_t used = 0;
                const int v = std::stoi(digits, &used);
                if (used != digits.size()) throw std::invalid_argument("trailing characters");
                return v;
            };
            const int w = whole(part.substr(0, x));
            const int h = whole(part.substr(x + 1));
            validateImageSize(w, h);
            sizes.emplace_back(w, h);
        } catch (const std::exception &) {
            throw std::invalid_argument("size '" + part + "' is not WIDTHxHEIGHT within the image limits");
        }
    }
    if (sizes.empty()) throw std::invalid_argument("no sizes in '" + text + "'");
    return sizes;
}

Quality table1Quality(double step) {
    Quality q;
    q.step = step;
    q.interpolation = Interpolation::Linear;
    q.emptySpaceSkipping = true;
    q.earlyTermination = 0.99;
    q.boundarySegment = true;
    return q;
}

void table1(const std::shared_ptr<OpenClContext> &cl, const StudyOptions &options) {
    // paper: the row of the paper's Table 1 to set it beside. The peers place their ramp on a
    // phantom's nominal range and on a scan's own range.
    struct Entry {
        std::string key, label, paper;
        std::shared_ptr<const Volume> volume;
        ValueRange range;
    };
    const bool quick = options.quick;
    std::vector<Entry> volumes;
    const auto wanted = [&](const char *key) {
        return std::find(options.volumes.begin(), options.volumes.end(), key) != options.volumes.end();
    };
    const auto phantom = [&](const char *key, const char *label, Vec3i dims, Vec3i quickDims, VoxelType type) {
        auto v = std::make_shared<Volume>(makePeerPhantom(quick ? quickDims : dims, type));
        volumes.push_back({key, label, key, v, nominalRange(*v)});
    };
    if (wanted("small")) phantom("small", "phantom 128×128×256 uint8 (4 MiB)", {128, 128, 256}, {32, 32, 64}, VoxelType::UInt8);
    const auto tooth = options.data / "tooth.nhdr";
    if (wanted("tooth") && std::filesystem::exists(tooth)) {
        auto v = std::make_shared<Volume>(loadVolume(tooth));
        volumes.push_back({"tooth", "tooth 103×94×161 uint16 (3 MiB, real micro-CT)", "small", v, v->range});
    }
    if (wanted("large"))
        phantom("large", "phantom 512×512×400 uint16 (200 MiB)", {512, 512, 400}, {64, 64, 50}, VoxelType::UInt16);
    const auto sizes = parseSizes(quick ? "64x64,80x60" : options.sizes);
    const Quality quality = table1Quality();

    nlohmann::json j;
    j["study"] = "table1";
    j["machine"] = machineInfo(cl.get());
    j["quality"] = {{"step", quality.step}, {"interpolation", "linear"}, {"empty_space_skipping", true},
                    {"early_termination", quality.earlyTermination}};
    j["camera"] = "peers' framing: bounding sphere fits a 30° view, 20° elevation, 3° orbit per frame";
    j["transfer_function"] = "peers' ramp: opacity 0 below 40 % of the nominal range, 0.25 per voxel at 100 %, grey";
    std::vector<std::vector<std::string>> rows;
    std::map<std::string, std::map<std::string, CellResult>> cells;
    j["renderer"] = options.backEnd;
    const bool openCl = options.backEnd == "opencl";
    if (!openCl) j["layout"] = options.layout;
    std::vector<std::vector<std::string>> partRows;
    for (const Entry &e : volumes) {
        const std::unique_ptr<FrameRenderer> renderer = makeStudyRenderer(cl, options.backEnd, e.volume, options.layout);
        j["device"] = renderer->description();
        const TransferFunction tf = peerTransferFunction(e.range, e.volume->smallestSpacing());
        for (const auto &s : sizes) {
            const CellResult r = timeOrbit(*renderer, tf, quality, s.first, s.second, options.repeat, openCl);
            cells[e.key][sizeName(s)] = r;
            const auto &paper = kPaperTable1.at(e.paper);
            const double paperMs = paper.count(sizeName(s)) ? paper.at(sizeName(s)) : 0;
            std::cerr << "table1: " << e.key << " " << sizeName(s) << " " << fmt(r.timing.median) << " ms (first "
                      << fmt(r.firstFrameMs) << " ms, other load " << fmt(r.otherCpus, 2) << " CPUs)\n";
            if (openCl) {
                const double kernelMs = FrameParts::median(r.parts.kernel), kernel8Ms = FrameParts::median(r.rgba8Parts.kernel);
                std::cerr << "table1: " << e.key << " " << sizeName(s) << " kernel " << fmt(kernelMs, 2)
                          << " ms, frame ÷ kernel " << fmt(r.timing.median / std::max(kernelMs, 1e-9), 2)
                          << "; 8-bit frame " << fmt(r.rgba8.median, 2) << " ms, ÷ kernel "
                          << fmt(r.rgba8.median / std::max(kernel8Ms, 1e-9), 2) << "\n";
                partRows.push_back({e.key, sizeName(s), fmt(r.timing.median, 2), fmt(kernelMs, 2),
                                    fmt(r.timing.median / std::max(kernelMs, 1e-9), 2), fmt(r.rgba8.median, 2),
                                    fmt(kernel8Ms, 2), fmt(r.rgba8.median / std::max(kernel8Ms, 1e-9), 2)});
            }
            j["cells"].push_back({{"volume", e.key},
                                  {"volume_label", e.label},
                                  {"resolution", {s.first, s.second}},
                                  {"render_ms", toJson(r.timing)},
                                  {"first_frame_ms", r.firstFrameMs},
                                  {"cpus_busy_with_other_processes", r.otherCpus},
                                  {"mean_samples_per_ray", r.stats.meanSamplesPerRay},
                                  {"rays_hit", r.stats.raysHit},
                                  // The kernel's cost per sample on all cores: the profile's unit.
                                  {"core_ns_per_sample", r.timing.median * 1e6 * std::thread::hardware_concurrency() /
                                                             std::max(1.0, double(r.stats.raysHit) * r.stats.meanSamplesPerRay)},
                                  {"empty_brick_fraction", r.stats.emptyBrickFraction},
                                  {"paper_ms", paperMs > 0 ? nlohmann::json(paperMs) : nlohmann::json(nullptr)}});
            if (openCl) {
                j["cells"].back()["parts"] = r.parts.json(r.timing);
                j["cells"].back()["rgba8_ms"] = toJson(r.rgba8);
                j["cells"].back()["rgba8_parts"] = r.rgba8Parts.json(r.rgba8);
            }
            rows.push_back({e.key, sizeName(s), fmt(r.timing.median, 2), fmt(r.timing.min, 2), fmt(r.timing.max, 2),
                            fmt(r.firstFrameMs, 1), paperMs > 0 ? fmt(paperMs, 2) : "", fmt(r.otherCpus, 2)});
        }
    }
    StudyOutput out(options.out, "table1");
    out.writeJson(j);
    out.writeCsv({"volume", "resolution", "median_ms", "min_ms", "max_ms", "first_frame_ms", "paper_ms",
                  "cpus_busy_with_other_processes"},
                 rows);

    std::ostringstream md;
    md << "| resolution |";
    for (const Entry &e : volumes) md << " " << e.label << " |";
    md << " paper 4 MB | paper 200 MB |\n|---|";
    for (size_t i = 0; i < volumes.size() + 2; ++i) md << "---|";
    md << "\n";
    for (const auto &s : sizes) {
        md << "| " << sizeName(s) << " |";
        for (const Entry &e : volumes) {
            const Timing &t = cells[e.key][sizeName(s)].timing;
            md << " " << fmt(t.median, 0) << " (" << fmt(t.min, 0) << "–" << fmt(t.max, 0) << ") |";
        }
        for (const char *k : {"small", "large"}) {
            const auto &p = kPaperTable1.at(k);
            md << " " << (p.count(sizeName(s)) ? fmt(p.at(sizeName(s)), 2) : "") << " |";
        }
        md << "\n";
    }
    if (openCl) {
        // The frame's parts: the whole frame (float RGBA read back, Table 1's time) and the
        // 8-bit one a server encodes, each beside its kernel's device time.
        out.writeCsv({"volume", "resolution", "frame_ms", "kernel_ms", "frame_over_kernel", "rgba8_frame_ms",
                      "rgba8_kernel_ms", "rgba8_frame_over_kernel"},
                     partRows, "_parts");
        md << "\n| volume | resolution | frame ms | kernel ms | frame ÷ kernel | 8-bit frame ms | its kernel ms | 8-bit ÷ kernel |\n"
              "|---|---|---:|---:|---:|---:|---:|---:|\n";
        for (const auto &row : partRows) {
            md << "|";
            for (const std::string &cell : row) md << " " << cell << " |";
            md << "\n";
        }
    }
    out.writeMarkdown(md.str());
    std::cout << md.str();

    Plot plot;
    plot.title = "Table 1: frame time against output resolution";
    plot.xLabel = "pixels (millions)";
    plot.yLabel = "ms per frame (median)";
    plot.logY = true;
    for (const Entry &e : volumes) {
        Series s{"volcast " + e.key};
        for (const auto &sz : sizes) {
            s.x.push_back(double(sz.first) * sz.second / 1e6);
            s.y.push_back(cells[e.key][sizeName(sz)].timing.median);
        }
        plot.series.push_back(s);
    }
    for (const char *k : {"small", "large"}) {
        Series s{std::string("paper ") + (std::string(k) == "small" ? "4 MB" : "200 MB") + " (GPU 2012)"};
        s.dashed = true;
        for (const auto &sz : sizes)
            if (kPaperTable1.at(k).count(sizeName(sz))) {
                s.x.push_back(double(sz.first) * sz.second / 1e6);
                s.y.push_back(kPaperTable1.at(k).at(sizeName(sz)));
            }
        plot.series.push_back(s);
    }
    out.writeSvg(renderSvg(plot));
}

void peerMode(const std::shared_ptr<OpenClContext> &cl, const PeerModeOptions &options) {
    auto volume = std::make_shared<Volume>(loadVolume(options.volume));
    const std::unique_ptr<FrameRenderer> frameRenderer = makeStudyRenderer(cl, options.backEnd, volume, options.layout);
    FrameRenderer &renderer = *frameRenderer;
    const ValueRange nominal = nominalRange(*volume);
    const TransferFunction tf = peerTransferFunction(nominal, volume->smallestSpacing());
    const Quality quality = table1Quality(options.sampleDistance);
    RepeatOptions repeat{0, std::max(1, options.frames - 1), options.maxSeconds};
    for (const auto &s : options.sizes) {
        const CellResult r = timeOrbit(renderer, tf, quality, s.first, s.second, repeat, false);
        nlohmann::json line = {
            {"peer", "volcast"},
            {"renderer", options.backEnd == "cpu" ? "volcast native CPU ray caster" : "volcast OpenCL ray caster"},
            {"device", renderer.description()},
            {"resolution", {s.first, s.second}},
            {"render_ms", {{"median", r.timing.median}, {"min", r.timing.min}, {"max", r.timing.max}, {"n", r.timing.n}}},
            {"first_frame", {{"render_ms", r.firstFrameMs}}},
            {"frames_rendered", r.timing.n + 1},
            {"per_frame_render_ms", r.timing.samples},
            {"threads", {{"cpu_count", std::thread::hardware_concurrency()},
                         {"cpus_busy_with_other_processes", r.otherCpus}}},
            // The file's name only: recorded results must not name this machine's folders.
            {"volume", {{"file", options.volume.filename().string()},
                        {"dims", {volume->dims.x, volume->dims.y, volume->dims.z}},
                        {"dtype", std::string(voxelTypeName(volume->sourceType))},
                        {"bytes", volume->voxelCount() * voxelTypeSize(volume->sourceType)},
                        {"spacing", {volume->spacing.x, volume->spacing.y, volume->spacing.z}}}},
            {"sample_distance_voxels", options.sampleDistance},
            {"interpolation", "linear"},
            {"value_range", {nominal.min, nominal.max}},
            {"empty_space_skipping", quality.emptySpaceSkipping},
            {"early_termination", quality.earlyTermination},
            {"mean_samples_per_ray", r.stats.meanSamplesPerRay},
            {"timing", "whole frames: kernel, read-back to host memory"}};
        if (!options.png.empty()) {
            auto file = options.png;
            file.replace_filename(file.stem().string() + "_" + sizeName(s) + ".png");
            writeImage(file, r.last);
            line["png"] = file.filename().string();
        }
        std::cout << line.dump() << std::endl;
    }
}

} // namespace volcast::bench
