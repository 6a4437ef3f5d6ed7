// volcast-bench: the paper's Table 1, Table 2 and Figure 5, error against run time, and the
// peers' side-by-side interface. See tests/bench/README.md.
//
//   volcast-bench all --out out/bench
//   volcast-bench peers --volume phantom.nrrd --size 512x512,800x600 --frames 5
//   volcast-bench byos --out out/bench      # needs Debian's orthanc and orthanc-dicomweb
//   volcast-bench encode --sizes 512x512,1920x1080

#include "renderer/make_frame_renderer.hpp"
#include "tests/bench/byos.hpp"
#include "tests/bench/ladder_choice.hpp"
#include "tests/bench/studies.hpp"

#include <CLI/CLI.hpp>
#include <spdlog/sinks/stdout_color_sinks.h>
#include <spdlog/spdlog.h>

#include <cstdio>
#include <iostream>

int main(int argc, char **argv) {
    using namespace volcast::bench;
    CLI::App app{"volcast benchmarks: warm-up, repeats, medians with min and max; JSON, CSV, Markdown and SVG "
                 "per study, with the machine and OpenCL device."};
    app.require_subcommand(1);
    StudyOptions options;
    options.data = VOLCAST_DATA_DIR;
    volcast::DeviceOptions device;
    int viewportFigure5 = 1000, viewportError = 256;
    std::vector<std::string> scans = {"bonsai", "aneurism", "cranium_ct"};
    const auto common = [&](CLI::App *sub) {
        sub->add_option("--out", options.out, "Output folder")->capture_default_str();
        sub->add_option("--data", options.data, "Folder of the real scans")->capture_default_str();
        sub->add_option("--device", device.device, "OpenCL device: auto, gpu, cpu or part of its name");
        sub->add_option("--kernel-cache", device.kernelCacheDir, "PoCL's compiled-kernel cache folder");
        sub->add_option("--repeats", options.repeat.repeats, "Timed runs per cell at most")
            ->check(CLI::Range(1, 1000))
            ->capture_default_str();
        sub->add_option("--max-seconds", options.repeat.maxSeconds, "Stop a cell's timed runs after this long")
            ->check(CLI::PositiveNumber)
            ->capture_default_str();
        sub->add_flag("--quick", options.quick, "Tiny sizes: checks that the study runs; its times mean nothing");
    };
    auto *t1 = app.add_subcommand("table1", "Table 1: frame time against output resolution, 4 MB and 200 MB volumes");
    auto *t2 = app.add_subcommand("prefilter", "Table 2: B-spline prefilter, simple / multithreaded / OpenCL, 256³ and 512³");
    auto *f5 = app.add_subcommand("figure5", "Figure 5: frame rate against samples per voxel, configurations A–F");
    auto *ev = app.add_subcommand("error", "Error against run time on real scans, with the Pareto front");
    auto *es = app.add_subcommand("error-synthetic", "Uniform against adaptive stepping on synthetic volumes: error "
                                                     "against samples per ray and time");
    auto *all = app.add_subcommand("all", "Every study above, in turn");
    for (auto *sub : {t1, t2, f5, ev, es, all}) common(sub);
    for (auto *sub : {t1, all}) {
        sub->add_option("--volumes", options.volumes, "Table 1's volumes: small, tooth, large")
            ->delimiter(',')
            ->capture_default_str();
        sub->add_option("--sizes", options.sizes, "Table 1's output sizes, WxH,...")->capture_default_str();
        sub->add_option("--backend", options.backEnd,
                        "Table 1's ray caster: auto (an OpenCL GPU, else cpu), opencl (on --device) or cpu (native)")
            ->check(CLI::IsMember({"auto", "opencl", "cpu"}))
            ->capture_default_str();
        sub->add_option("--layout", options.layout,
                        "Table 1's native path: its 8- and 16-bit samples in the volume's slices (as served) or in a bricked copy")
            ->check(CLI::IsMember({"bricks", "slices"}))
            ->capture_default_str();
    }
    for (auto *sub : {f5, all})
        sub->add_option("--viewport", viewportFigure5, "Figure 5's square viewport")->capture_default_str();
    for (auto *sub : {f5, ev, es, all})
        sub->add_option("--backends", options.backEnds,
                        "Figure 5's and the error study's ray casters, timed in turn cell by cell: auto, opencl, cpu")
            ->delimiter(',')
            ->check(CLI::IsMember({"auto", "opencl", "cpu"}))
            ->capture_default_str();
    int syntheticSide = 128;
    for (auto *sub : {ev, es, all}) {
        sub->add_option("--error-viewport", viewportError, "The error studies' square viewport")->capture_default_str();
        sub->add_option("--steppings", options.steppings,
                        "The error studies' stepping, each cell timed with each side by side: uniform, adaptive")
            ->delimiter(',')
            ->check(CLI::IsMember({"uniform", "adaptive"}))
            ->capture_default_str();
    }
    for (auto *sub : {ev, all})
        sub->add_option("--scans", scans, "Scans of the error study")->delimiter(',')->capture_default_str();
    for (auto *sub : {es, all})
        sub->add_option("--side", syntheticSide, "The synthetic volumes' side in voxels")
            ->check(CLI::Range(8, 1024))
            ->capture_default_str();

    // The quality ladder's choice while dragging, on this device (ladder_choice.hpp).
    std::string ladderSizes = "512x512,1920x1080";
    std::vector<int> ladderSessions = {1, 4, 16, 32};
    auto *ladder = app.add_subcommand("ladder", "The level the server's quality ladder picks while 1, 4, 16, 32 "
                                                "sessions drag bonsai on this device, with each level's time and error");
    common(ladder);
    ladder->add_option("--backend", options.backEnd, "Ray caster: auto (an OpenCL GPU, else cpu), opencl (on --device) or cpu (native)")
        ->check(CLI::IsMember({"auto", "opencl", "cpu"}))
        ->capture_default_str();
    ladder->add_option("--sizes", ladderSizes, "Output sizes, WxH,...")->capture_default_str();
    ladder->add_option("--sessions", ladderSessions, "Numbers of sessions dragging at once")
        ->delimiter(',')
        ->check(CLI::Range(1, 1000))
        ->capture_default_str();

    PeerModeOptions peer;
    std::string sizes = "512x512";
    auto *peers = app.add_subcommand("peers", "the peers' run_table.py --extra interface: one JSON line per size");
    peers->add_option("--volume", peer.volume, "Volume file (NRRD)")->required()->check(CLI::ExistingFile);
    peers->add_option("--size", sizes, "Comma list of WxH")->capture_default_str();
    peers->add_option("--frames", peer.frames, "Frames per size, the first a warm-up")->check(CLI::Range(2, 1000));
    peers->add_option("--sample-distance", peer.sampleDistance, "Step in voxels")->check(CLI::PositiveNumber);
    peers->add_option("--max-seconds", peer.maxSeconds, "Stop a size's timed frames after this long")
        ->check(CLI::PositiveNumber);
    peers->add_option("--png", peer.png, "Write each size's last frame to PNG_WxH.png");
    peers->add_option("--device", device.device, "OpenCL device: auto, gpu, cpu or part of its name");
    peers->add_option("--kernel-cache", device.kernelCacheDir, "PoCL's compiled-kernel cache folder");
    peers->add_option("--backend", peer.backEnd, "Ray caster: auto (an OpenCL GPU, else cpu), opencl (on --device) or cpu (native)")
        ->check(CLI::IsMember({"auto", "opencl", "cpu"}))
        ->capture_default_str();
    peers->add_option("--layout", peer.layout, "The native path's 8- and 16-bit samples: in the volume's slices (as served) or in a bricked copy")
        ->check(CLI::IsMember({"bricks", "slices"}))
        ->capture_default_str();

    std::filesystem::path memoryVolume;
    std::string writeCt;
    int memorySize = 512;
    auto *memory = app.add_subcommand("memory", "Memory a scan takes on the native path: samples, copies, RSS");
    memory->add_option("--volume", memoryVolume, "Volume file to load (with --write-ct: the NRRD header to write)")
        ->required();
    memory->add_option("--write-ct", writeCt, "Write a CT-like int16 NRRD of WxHxD to --volume instead, and stop");
    memory->add_option("--size", memorySize, "Square frame size")->check(CLI::Range(1, 8192))->capture_default_str();

    std::filesystem::path encodeVolume = std::filesystem::path(VOLCAST_DATA_DIR) / "bonsai.nhdr";
    std::string encodeSizes = "512x512,1920x1080,2048x1536";
    int encodeRounds = 5;
    auto *encode = app.add_subcommand("encode", "Frame encoding beside rendering: JPEG and PNG at viewport sizes");
    encode->add_option("--volume", encodeVolume, "Volume file to draw")->capture_default_str();
    encode->add_option("--sizes", encodeSizes, "Sizes, WxH,...")->capture_default_str();
    encode->add_option("--rounds", encodeRounds, "Timed rounds, each encoding every size once in turn")
        ->check(CLI::Range(1, 1000))
        ->capture_default_str();

    ByosOptions byos;
    auto *byosCommand = app.add_subcommand(
        "byos", "Bring your own scan: first frame of a DICOMweb series against Orthanc serving it, and of an "
                "uploaded .nii.gz against its parse time (a real Orthanc is started)");
    byosCommand->add_option("--out", byos.out, "Output folder")->capture_default_str();
    byosCommand->add_option("--rounds", byos.rounds, "Rounds, each timing every measurement once in turn")
        ->check(CLI::Range(1, 100))
        ->capture_default_str();
    byosCommand->add_flag("--quick", byos.quick, "Tiny volumes, one round: checks that the study runs; its times mean nothing");

    CLI11_PARSE(app, argc, argv);
    if (byosCommand->parsed()) {
        // No OpenCL context of its own: the servers it starts open their own back end.
        spdlog::set_default_logger(spdlog::stderr_color_mt("volcast-bench"));
        spdlog::set_level(spdlog::level::warn);   // the servers' info lines would bury the progress
        try {
            byosStudy(byos);
            return 0;
        } catch (const std::exception &e) {
            std::cerr << "volcast-bench: " << e.what() << std::endl;
            return 1;
        }
    }
    if (encode->parsed()) {
        spdlog::set_default_logger(spdlog::stderr_color_mt("volcast-bench"));
        try {
            encodeStudy(encodeVolume, parseSizes(encodeSizes), encodeRounds);
            return 0;
        } catch (const std::exception &e) {
            std::cerr << "volcast-bench: " << e.what() << std::endl;
            return 1;
        }
    }
    if (memory->parsed()) {
        // No OpenCL: the memory study is the native path's.
        spdlog::set_default_logger(spdlog::stderr_color_mt("volcast-bench"));
        try {
            if (!writeCt.empty()) {
                int x = 0, y = 0, z = 0;
                char tail = 0;
                if (std::sscanf(writeCt.c_str(), "%dx%dx%d%c", &x, &y, &z, &tail) != 3 || x < 1 || y < 1 || z < 1)
                    throw std::invalid_argument("--write-ct '" + writeCt + "': expected WxHxD, each at least 1");
                writeSyntheticCt(memoryVolume, volcast::Vec3i{x, y, z});
            } else {
                memoryStudy(memoryVolume, memorySize);
            }
            return 0;
        } catch (const std::exception &e) {
            std::cerr << "volcast-bench: " << e.what() << std::endl;
            return 1;
        }
    }
    // stdout carries the tables (and the peers' JSON lines); progress and warnings go to stderr.
    spdlog::set_default_logger(spdlog::stderr_color_mt("volcast-bench"));
    try {
        // The prefilter study and the machine record use the OpenCL device whatever ray caster runs.
        const auto cl = std::make_shared<volcast::OpenClContext>(device);
        std::cerr << "volcast-bench: OpenCL device " << cl->deviceName() << "\n";
        const auto announce = [&](const std::string &backEnd) {
            std::cerr << "volcast-bench: ray caster " << backEnd << " ("
                      << volcast::backEndDescription(backEnd == "cpu" ? nullptr : cl) << ")\n";
        };
        if (peers->parsed()) {
            peer.backEnd = resolveBackEnd(peer.backEnd);
            announce(peer.backEnd);
            peer.sizes = parseSizes(sizes);
            peerMode(cl, peer);
            return 0;
        }
        options.backEnd = resolveBackEnd(options.backEnd);
        for (std::string &b : options.backEnds) b = resolveBackEnd(b);
        if (t1->parsed() || all->parsed() || ladder->parsed()) announce(options.backEnd);
        if (f5->parsed() || ev->parsed() || es->parsed() || all->parsed())
            for (const std::string &b : options.backEnds) announce(b);
        if (t1->parsed() || all->parsed()) table1(cl, options);
        if (t2->parsed() || all->parsed()) prefilter(*cl, options);
        if (f5->parsed() || all->parsed()) figure5(cl, options, viewportFigure5);
        if (ev->parsed() || all->parsed()) errorVsTime(cl, options, viewportError, scans);
        if (es->parsed() || all->parsed()) errorSynthetic(cl, options, viewportError, syntheticSide);
        if (ladder->parsed()) ladderChoice(cl, options, parseSizes(options.quick ? "48x40" : ladderSizes), ladderSessions);
        std::cerr << "volcast-bench: results in " << options.out << "\n";
        return 0;
    } catch (const std::exception &e) {
        std::cerr << "volcast-bench: " << e.what() << std::endl;
        return 1;
    }
}
