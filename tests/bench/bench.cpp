#include "tests/bench/bench.hpp"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <ctime>
#include <fstream>
#include <limits>
#include <numbers>
#include <sstream>
#include <stdexcept>
#include <thread>

#include <sys/utsname.h>

namespace volcast::bench {

Timing summarize(std::vector<double> ms) {
    if (ms.empty()) throw std::invalid_argument("summarize: no timed runs");
    Timing t;
    t.samples = ms;
    std::sort(ms.begin(), ms.end());
    t.n = int(ms.size());
    t.min = ms.front();
    t.max = ms.back();
    const size_t h = ms.size() / 2;
    t.median = ms.size() % 2 ? ms[h] : 0.5 * (ms[h - 1] + ms[h]);
    return t;
}

nlohmann::json toJson(const Timing &t) {
    return {{"median", t.median}, {"min", t.min}, {"max", t.max}, {"n", t.n}, {"samples", t.samples}};
}

Timing repeat(const RepeatOptions &options, const std::function<void(int)> &once,
              const std::function<void()> &prepare) {
    using Clock = std::chrono::steady_clock;
    int k = 0;
    for (int i = 0; i < options.warmup; ++i) {
        if (prepare) prepare();
        once(k++);
    }
    std::vector<double> ms;
    double spent = 0;
    for (int i = 0; i < std::max(1, options.repeats); ++i) {
        if (prepare) prepare();
        const auto t0 = Clock::now();
        once(k++);
        const double dt = std::chrono::duration<double, std::milli>(Clock::now() - t0).count();
        ms.push_back(dt);
        spent += dt / 1e3;
        if (spent > options.maxSeconds) break;
    }
    return summarize(std::move(ms));
}

std::vector<Timing> repeatInterleaved(const RepeatOptions &options, const std::vector<std::function<void()>> &variants) {
    using Clock = std::chrono::steady_clock;
    const size_t n = variants.size();
    const auto order = [n](int round, size_t i) { return round % 2 ? n - 1 - i : i; };
    for (int r = 0; r < options.warmup; ++r)
        for (size_t i = 0; i < n; ++i) variants[order(r, i)]();
    std::vector<std::vector<double>> ms(n);
    double spent = 0;
    for (int r = 0; r < std::max(1, options.repeats); ++r) {
        for (size_t i = 0; i < n; ++i) {
            const size_t v = order(r, i);
            const auto t0 = Clock::now();
            variants[v]();
            const double dt = std::chrono::duration<double, std::milli>(Clock::now() - t0).count();
            ms[v].push_back(dt);
            spent += dt / 1e3;
        }
        if (spent > options.maxSeconds) break;
    }
    std::vector<Timing> out;
    for (auto &m : ms) out.push_back(summarize(std::move(m)));
    return out;
}

namespace {

std::string firstLineWith(const char *file, const std::string &key) {
    std::ifstream in(file);
    std::string line;
    while (std::getline(in, line))
        if (line.rfind(key, 0) == 0) {
            const auto colon = line.find_first_of(":=");
            std::string v = colon == std::string::npos ? line : line.substr(colon + 1);
            v.erase(0, v.find_first_not_of(" \t\""));
            v.erase(v.find_last_not_of(" \t\"") + 1);
            return v;
        }
    return "";
}

std::string nowUtc() {
    const std::time_t t = std::time(nullptr);
    char buf[32];
    std::strftime(buf, sizeof buf, "%Y-%m-%dT%H:%M:%SZ", std::gmtime(&t));
    return buf;
}

} // namespace

nlohmann::json machineInfo(const OpenClContext *cl) {
    nlohmann::json m;
    m["date"] = nowUtc();
    m["cpu"] = firstLineWith("/proc/cpuinfo", "model name");
    m["hardware_threads"] = std::thread::hardware_concurrency();
    m["memory"] = firstLineWith("/proc/meminfo", "MemTotal");
    utsname u{};
    if (uname(&u) == 0) m["kernel"] = std::string(u.sysname) + " " + u.release + " " + u.machine;
    m["os"] = firstLineWith("/etc/os-release", "PRETTY_NAME");
    if (cl) {
        m["opencl_device"] = cl->deviceName();
        m["opencl_device_version"] = cl->device().getInfo<CL_DEVICE_VERSION>();
        m["opencl_compute_units"] = cl->device().getInfo<CL_DEVICE_MAX_COMPUTE_UNITS>();
        m["opencl_is_gpu"] = cl->isGpu();
    }
    return m;
}

Camera peerCamera(const Volume &volume, int frame, double orbitDeg, double elevationDeg) {
    const Vec3d lo = volume.worldFromIndex({0, 0, 0});
    const Vec3d hi = volume.worldFromIndex(Vec3d(volume.dims - Vec3i{1, 1, 1}));
    const Vec3d center = (lo + hi) * 0.5;
    const double radius = 0.5 * length(hi - lo);
    constexpr double kViewAngleDeg = 30;
    const double deg = std::numbers::pi / 180;
    const double dist = radius / std::sin(kViewAngleDeg * deg / 2);
    const double el = elevationDeg * deg, az = frame * orbitDeg * deg;
    Camera c;
    c.projection = Projection::Perspective;
    c.fovYDeg = kViewAngleDeg;
    c.target = center;
    c.eye = center + Vec3d{dist * std::cos(el) * std::sin(az), -dist * std::cos(el) * std::cos(az), dist * std::sin(el)};
    c.up = {0, 0, 1};
    return c;
}

TransferFunction peerTransferFunction(ValueRange nominal, double opacityUnit, double rampLo, double rampHi,
                                      double maxOpacity) {
    const double vmin = nominal.min, vmax = nominal.max;
    const double span = vmax > vmin ? vmax - vmin : 1.0;
    const double lo = vmin + rampLo * span, hi = vmin + rampHi * span;
    // VTK keeps colour and opacity apart; ours are one list, so each carries the other's value
    // at its points (both are piecewise linear, so nothing changes in between).
    const auto grey = [&](double v) {
        if (v <= lo) return 0.25 * (v - vmin) / std::max(lo - vmin, 1e-30);
        return 0.25 + 0.75 * (v - lo) / std::max(vmax - lo, 1e-30);
    };
    TransferFunction tf;
    tf.opacityUnit = opacityUnit;
    const auto add = [&](double v, double a) { tf.points.push_back({v, grey(v), grey(v), grey(v), a}); };
    add(vmin, 0);
    add(lo, 0);
    add(hi, maxOpacity);
    if (hi < vmax) add(vmax, maxOpacity);
    tf.validate();
    return tf;
}

ValueRange nominalRange(const Volume &volume) {
    if (volume.sourceType == VoxelType::UInt8) return {0, 255};
    if ((volume.sourceType == VoxelType::UInt16 || volume.sourceType == VoxelType::Int16) && volume.range.min >= 0 &&
        volume.range.max <= 4095)
        return {0, 4095};
    return volume.range;
}

std::vector<bool> paretoFront(const std::vector<double> &time, const std::vector<double> &error) {
    if (time.size() != error.size()) throw std::invalid_argument("paretoFront: sizes differ");
    std::vector<bool> front(time.size(), true);
    for (size_t i = 0; i < time.size(); ++i)
        for (size_t j = 0; j < time.size() && front[i]; ++j)
            if (j != i && time[j] <= time[i] && error[j] <= error[i] && (time[j] < time[i] || error[j] < error[i]))
                front[i] = false;
    return front;
}

std::vector<bool> paretoFrontWithin(const std::vector<double> &cost, const std::vector<double> &error,
                                    const std::vector<std::string> &group) {
    if (cost.size() != error.size() || cost.size() != group.size())
        throw std::invalid_argument("paretoFrontWithin: sizes differ");
    std::vector<bool> front(cost.size(), false);
    std::vector<std::string> seen;
    for (const std::string &g : group) {
        if (std::find(seen.begin(), seen.end(), g) != seen.end()) continue;
        seen.push_back(g);
        std::vector<size_t> members;
        std::vector<double> c, e;
        for (size_t i = 0; i < group.size(); ++i)
            if (group[i] == g) {
                members.push_back(i);
                c.push_back(cost[i]);
                e.push_back(error[i]);
            }
        const std::vector<bool> f = paretoFront(c, e);
        for (size_t k = 0; k < members.size(); ++k) front[members[k]] = f[k];
    }
    return front;
}

double costAtError(std::vector<double> cost, std::vector<double> error, double target) {
    if (cost.size() != error.size()) throw std::invalid_argument("costAtError: sizes differ");
    std::vector<size_t> idx(cost.size());
    for (size_t i = 0; i < idx.size(); ++i) idx[i] = i;
    std::sort(idx.begin(), idx.end(), [&](size_t a, size_t b) { return cost[a] < cost[b]; });
    for (size_t k = 0; k + 1 < idx.size(); ++k) {
        const double c0 = cost[idx[k]], c1 = cost[idx[k + 1]], e0 = error[idx[k]], e1 = error[idx[k + 1]];
        if (!(c0 > 0 && c1 > 0 && e0 > 0 && e1 > 0 && target > 0)) continue;
        if (target > e0 || target < e1) continue; // not bracketed by this pair (or error rose)
        if (e0 == e1) return c0;
        const double f = (std::log(target) - std::log(e0)) / (std::log(e1) - std::log(e0));
        return std::exp(std::log(c0) + f * (std::log(c1) - std::log(c0)));
    }
    return std::numeric_limits<double>::quiet_NaN();
}

StudyOutput::StudyOutput(std::filesystem::path dir, std::string study) : dir_(std::move(dir)), study_(std::move(study)) {
    std::filesystem::create_directories(dir_);
}

namespace {
void writeText(const std::filesystem::path &p, const std::string &text) {
    std::ofstream out(p);
    out << text;
    if (!out) throw std::runtime_error("cannot write " + p.string());
}
} // namespace

void StudyOutput::writeJson(const nlohmann::json &j) const { writeText(dir_ / (study_ + ".json"), j.dump(2) + "\n"); }

void StudyOutput::writeCsv(const std::vector<std::string> &header, const std::vector<std::vector<std::string>> &rows,
                           const std::string &suffix) const {
    std::ostringstream s;
    const auto line = [&](const std::vector<std::string> &cells) {
        for (size_t i = 0; i < cells.size(); ++i) s << (i ? "," : "") << cells[i];
        s << "\n";
    };
    line(header);
    for (const auto &r : rows) line(r);
    writeText(dir_ / (study_ + suffix + ".csv"), s.str());
}

void StudyOutput::writeSvg(const std::string &svg, const std::string &suffix) const {
    writeText(dir_ / (study_ + suffix + ".svg"), svg);
}

void StudyOutput::writeMarkdown(const std::string &text) const { writeText(dir_ / (study_ + ".md"), text); }

std::string fmt(double v, int decimals) {
    if (!std::isfinite(v)) return v > 0 ? "inf" : "n/a";
    std::ostringstream s;
    s.setf(std::ios::fixed);
    s.precision(decimals);
    s << v;
    return s.str();
}

} // namespace volcast::bench
