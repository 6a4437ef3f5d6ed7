// volcast-stability: run the numerical-stability cases and print docs/accuracy.md's
// "Numerical stability" table (Markdown). Exit status 1 if any case fails its bound.
//
//   volcast-stability [--backend opencl|cpu] [--device cpu] [--case OpaqueMedia]

#include "tests/stability/stability_cases.hpp"

#include <CLI/CLI.hpp>
#include <spdlog/spdlog.h>

#include <iostream>
#include <memory>

int main(int argc, char **argv) {
    CLI::App app{"Run volcast's numerical-stability cases and print their table."};
    std::string device, only, backend = "opencl";
    app.add_option("--backend", backend, "Back end: opencl (the OpenCL ray caster) or cpu (the native SIMD one)")
        ->check(CLI::IsMember({"opencl", "cpu"}));
    app.add_option("--device", device, "OpenCL device: auto, gpu, cpu or part of its name (default: $VOLCAST_DEVICE or auto)");
    app.add_option("--case", only, "Run only the case with this id (e.g. OpaqueMedia)");
    CLI11_PARSE(app, argc, argv);
    // The cases provoke the renderer's warnings on purpose (a step raised, NaN voxels
    // replaced), and spdlog writes to stdout, where the table goes.
    spdlog::set_level(spdlog::level::err);
    try {
        std::shared_ptr<volcast::OpenClContext> cl;
        if (backend == "opencl") cl = std::make_shared<volcast::OpenClContext>(volcast::DeviceOptions{device, "", ""});
        const volcast::stability::Backend be =
            cl ? volcast::stability::openClBackend(cl) : volcast::stability::cpuBackend();
        std::vector<volcast::stability::Row> rows;
        bool found = false;
        for (const auto &c : volcast::stability::cases()) {
            if (!only.empty() && c.id != only) continue;
            found = true;
            for (auto &row : c.run(be)) rows.push_back(std::move(row));
        }
        if (!found) throw std::invalid_argument("--case: no case is called " + only);
        std::cout << "Device: " << (cl ? cl->deviceName() : "native CPU path") << "\n\n" << volcast::stability::markdownTable(rows);
        bool passed = true;
        for (const auto &row : rows) {
            passed = passed && row.passed();
            if (row.worst > row.bound)
                std::cerr << row.caseName << " [" << row.path << "]: worst error " << row.worst << " at " << row.worstAt
                          << "\n";
            for (const auto &f : row.failures) std::cerr << row.caseName << " [" << row.path << "]: " << f << "\n";
        }
        return passed ? 0 : 1;
    } catch (const std::exception &e) {
        std::cerr << "volcast-stability: " << e.what() << std::endl;
        return 2;
    }
}
