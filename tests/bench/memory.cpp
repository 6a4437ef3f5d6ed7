// The memory a large scan takes on the native path (the target: "a 512×512×2000 16-bit CT
// fits in ~1 GiB plus mips and bricks", docs/cpu_renderer.md): what the volume holds, what its renderer adds, and the
// process's resident and peak memory, after loading and after frames.

#include "renderer/cpu/cpu_renderer.hpp"
#include "renderer/io/volume_io.hpp"
#include "tests/bench/studies.hpp"

#include <nlohmann/json.hpp>
#include <sys/resource.h>
#include <unistd.h>

#include <cmath>
#include <fstream>
#include <iostream>
#include <stdexcept>

namespace volcast::bench {
namespace {

double mib(uint64_t bytes) { return double(bytes) / double(uint64_t(1) << 20); }

// Resident now (/proc/self/statm) and the peak so far (getrusage), in MiB.
nlohmann::json residentMemory() {
    long pages = 0, resident = 0;
    std::ifstream("/proc/self/statm") >> pages >> resident;
    rusage usage{};
    getrusage(RUSAGE_SELF, &usage);
    return {{"rss_mib", mib(uint64_t(resident) * uint64_t(sysconf(_SC_PAGESIZE)))},
            {"peak_rss_mib", double(usage.ru_maxrss) / 1024.0}};
}

} // namespace

void writeSyntheticCt(const std::filesystem::path &header, Vec3i dims) {
    if (dims.x < 1 || dims.y < 1 || dims.z < 1) throw std::invalid_argument("CT dims must be at least 1 each");
    std::filesystem::path raw = header;
    raw.replace_extension(".raw");
    std::ofstream nhdr(header);
    nhdr << "NRRD0004\ntype: int16\ndimension: 3\nsizes: " << dims.x << " " << dims.y << " " << dims.z
         << "\nspacings: 0.7 0.7 0.5\nendian: little\nencoding: raw\ndata file: " << raw.filename().string() << "\n";
    if (!nhdr) throw std::runtime_error("cannot write " + header.string());
    // Air (−1024 HU) around a water cylinder (0 HU, with noise-like texture) in a bone ring
    // (1200 HU), slice by slice: the file is written without ever holding the volume.
    std::ofstream out(raw, std::ios::binary);
    std::vector<int16_t> slice(size_t(dims.x) * size_t(dims.y));
    for (int64_t k = 0; k < dims.z; ++k) {
        for (int64_t j = 0; j < dims.y; ++j)
            for (int64_t i = 0; i < dims.x; ++i) {
                const double x = 2.0 * double(i) / double(dims.x) - 1, y = 2.0 * double(j) / double(dims.y) - 1;
                const double r = std::sqrt(x * x + y * y);
                int v = -1024;
                if (r < 0.8) v = int(40 * std::sin(0.3 * double(i + 2 * j + 3 * k)));
                if (r >= 0.7 && r < 0.8) v = 1200;
                slice[size_t(j) * size_t(dims.x) + size_t(i)] = int16_t(v);
            }
        out.write(reinterpret_cast<const char *>(slice.data()), std::streamsize(slice.size() * sizeof(int16_t)));
    }
    if (!out) throw std::runtime_error("cannot write " + raw.string());
}

void memoryStudy(const std::filesystem::path &file, int size) {
    nlohmann::json j;
    j["before_load"] = residentMemory();
    auto volume = std::make_shared<const Volume>(loadVolume(file));
    j["volume"] = {{"file", file.filename().string()}, // no machine folders in recorded results
                   {"dims", {volume->dims.x, volume->dims.y, volume->dims.z}},
                   {"dtype", std::string(voxelTypeName(volume->sourceType))},
                   {"bytes_per_sample_held", volume->narrow.bytes},
                   {"sample_mib", mib(volume->sampleBytes())},
                   {"float32_mib", mib(volume->voxelCount() * sizeof(float))}};
    j["after_load"] = residentMemory();
    // What the server's budget counts for it (server/volume_registry.cpp, memoryOf): every
    // level, trilinear and cubic.
    j["budget_counts_mib"] = mib(volume->sampleBytes() + CpuRenderer::plannedBytes(volume->dims, {}, volume->narrow.bytes));
    CpuRenderer renderer(volume);
    const TransferFunction tf = peerTransferFunction(nominalRange(*volume), volume->smallestSpacing());
    Quality q = table1Quality();
    for (const int level : {0, 1}) {
        q.mipLevel = level;
        RenderStats st;
        renderer.render({tf, peerCamera(*volume, 0), size, size, q, {}}, &st);
        nlohmann::json frame = residentMemory();
        frame["renderer_mib"] = mib(renderer.memoryBytes());
        frame["held_mib"] = mib(volume->sampleBytes() + renderer.memoryBytes());
        frame["render_ms"] = st.renderSeconds * 1e3;
        j["after_trilinear_frame_mip_" + std::to_string(level)] = frame;
    }
    j["renderer"] = renderer.description();
    std::cout << j.dump() << std::endl;
}

} // namespace volcast::bench
