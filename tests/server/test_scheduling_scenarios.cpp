// A two-tab scheduling scenario on the real server and renderer, over loopback: two
// tabs, one asking for expensive quality on a large scan while the other drags. What is
// asserted is what holds on a loaded machine (2 shared cores): relations between times the
// test measures itself, with allowances that say where they come from; how fast PoCL renders
// is left to the slow-renderer tests in test_render_scheduler.cpp.

#include "client/cpp/ws_client.hpp"
#include "server/error_calibrator.hpp"
#include "server/server.hpp"
#include "tests/server/png_decode.hpp"

#include <gtest/gtest.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <map>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

namespace {

namespace fs = std::filesystem;
using namespace std::chrono_literals;
using nlohmann::json;
using volcast::client::Client;
using volcast::client::Message;
namespace protocol = volcast::protocol;
using Clock = std::chrono::steady_clock;
using Ms = std::chrono::duration<double, std::milli>;

const fs::path kDataDir = VOLCAST_DATA_DIR;

double percentile(std::vector<double> v, double p) {
    if (v.empty()) return 0;
    std::sort(v.begin(), v.end());
    return v[std::min(v.size() - 1, size_t(p * double(v.size())))];
}

std::string loadAverage() {
    std::ifstream in("/proc/loadavg");
    std::string line;
    std::getline(in, line);
    return line;
}

// hello, viewport and open_volume; returns the state's scene.
json openTab(Client &c, const std::string &volume, int side) {
    c.sendText(json{{"type", "hello"}, {"id", 1}, {"protocol", 1}, {"client", "two-tabs test"}}.dump());
    c.sendText(json{{"type", "viewport"}, {"id", 2}, {"image", {{"width", side}, {"height", side}}}}.dump());
    c.sendText(json{{"type", "open_volume"}, {"id", 3}, {"name", volume}}.dump());
    const Message state = volcast::client::waitForReply(c, 3, 60s);
    const json j = json::parse(state.text);
    if (j.value("type", "") != "state") throw std::runtime_error("opening " + volume + ": " + state.text);
    return j.at("scene");
}

// The scene's camera turned by `angle` around its up axis through the target.
json turned(const json &camera, double angle) {
    json c = camera;
    const auto v = [&](const char *k) { return camera.at(k).get<std::vector<double>>(); };
    const std::vector<double> eye = v("eye"), target = v("target"), up = v("up");
    std::vector<double> d{eye[0] - target[0], eye[1] - target[1], eye[2] - target[2]};
    // Rodrigues' rotation of d around the unit up axis.
    const double n = std::sqrt(up[0] * up[0] + up[1] * up[1] + up[2] * up[2]);
    const double k[3] = {up[0] / n, up[1] / n, up[2] / n};
    const double kd = k[0] * d[0] + k[1] * d[1] + k[2] * d[2];
    const double cross[3] = {k[1] * d[2] - k[2] * d[1], k[2] * d[0] - k[0] * d[2], k[0] * d[1] - k[1] * d[0]};
    const double cs = std::cos(angle), sn = std::sin(angle);
    for (int i = 0; i < 3; ++i) d[size_t(i)] = d[size_t(i)] * cs + cross[i] * sn + k[i] * kd * (1 - cs);
    c["eye"] = {target[0] + d[0], target[1] + d[1], target[2] + d[2]};
    return c;
}

// A frame's image as 8-bit RGB over black (the error estimate's metric, error_calibrator.hpp):
// JPEG frames are that already; PNG frames carry straight alpha, multiplied in here.
std::vector<double> rgbOverBlack(const volcast::client::Frame &f) {
    int w = 0, h = 0, ch = 3;
    std::vector<uint8_t> px;
    if (f.header.codec == protocol::Codec::Png) {
        px = volcast::test::decodePng(f.image, w, h, ch);
    } else {
        volcast::server::Rgb8 decoded = volcast::server::decodeJpegRgb8(f.image);
        w = decoded.width;
        h = decoded.height;
        px = std::move(decoded.rgb);
    }
    std::vector<double> rgb(size_t(w) * size_t(h) * 3);
    for (size_t p = 0; p < size_t(w) * size_t(h); ++p)
        for (size_t c = 0; c < 3; ++c) {
            const double a = ch == 4 ? px[p * 4 + 3] / 255.0 : 1.0;
            rgb[p * 3 + c] = std::round(px[p * size_t(ch) + c] * a) / 255.0;
        }
    return rgb;
}

double rmse(const std::vector<double> &a, const std::vector<double> &b) {
    if (a.size() != b.size() || a.empty()) return -1;
    double sum = 0;
    for (size_t i = 0; i < a.size(); ++i) sum += (a[i] - b[i]) * (a[i] - b[i]);
    return std::sqrt(sum / double(a.size()));
}

class SchedulingScenario : public ::testing::Test {
  protected:
    std::unique_ptr<volcast::server::Server> server;

    void SetUp() override {
        if (!fs::exists(kDataDir / "MANIFEST.md"))
            GTEST_SKIP() << "no scans in " << kDataDir << " (configure with -DVOLCAST_DATA_DIR, tests/README.md)";
        volcast::server::ServerConfig config;
        config.port = 0;
        config.dataDirs = {kDataDir};
        config.defaultVolume = "builtin:sphere";
        server = std::make_unique<volcast::server::Server>(config);
        server->start();
        const auto deadline = Clock::now() + 60s;
        while (!server->state().notReadyReason().empty() && Clock::now() < deadline) std::this_thread::sleep_for(20ms);
        ASSERT_TRUE(server->state().notReadyReason().empty()) << server->state().notReadyReason();
    }
};

// Tab A opens iguana_microct (210×256×179), ticks shading and tricubic;
// tab B opens headsq and drags meanwhile. B's frames keep coming, each within the frame-time
// target plus one unit plus an allowance for the loaded machine; A is told what is being
// prepared, keeps getting trilinear frames marked as such, and then gets its cubic, shaded
// final frame.
TEST_F(SchedulingScenario, TabBStaysInteractiveWhileTabAPreparesCubicShadedIguana) {
    const auto testStart = Clock::now();
    Client a("127.0.0.1", server->port()), b("127.0.0.1", server->port());
    const json sceneB = openTab(b, "headsq.nhdr", 256);
    openTab(a, "iguana_microct.nhdr", 256);
    b.sendText(json{{"type", "interaction_start"}, {"id", 10}}.dump());
    a.sendText(json{{"type", "quality_policy"},
                    {"id", 20},
                    {"mode", "automatic"},
                    {"quality", {{"interpolation", "cubic"}, {"shading", true}}}}
                   .dump());
    const auto policySent = Clock::now();

    // A's side, read between B's frames.
    std::vector<protocol::ProgressMessage> progress;
    Clock::time_point preparedAt{}, firstProgressAt{};
    std::vector<protocol::FrameHeader> aFrames;   // after the policy
    std::vector<std::pair<protocol::FrameHeader, Clock::time_point>> aFramesAt;
    std::vector<std::pair<protocol::ProgressMessage, Clock::time_point>> progressAt;
    bool aFinal = false;
    const auto drainA = [&] {
        while (auto m = a.next(0ms)) {
            if (m->isFrame) {
                const auto &h = m->frame.header;
                if (h.request != 20) continue;   // frames of the view before the policy
                aFrames.push_back(h);
                aFramesAt.emplace_back(h, m->received);
                aFinal = aFinal || (h.final && h.quality.value("interpolation", "") == "cubic");
            } else if (m->decoded) {
                if (const auto *p = std::get_if<protocol::ProgressMessage>(&*m->decoded);
                    p && p->stage == protocol::ProgressStage::Preprocessing) {
                    progress.push_back(*p);
                    progressAt.emplace_back(*p, m->received);
                    // The coefficients' preparation (other tasks, kernel variants, come and go before it).
                    if (p->task.find("bspline_coefficients") != std::string::npos) {
                        if (p->fraction == 0) firstProgressAt = m->received;
                        if (p->fraction == 1) preparedAt = m->received;
                    }
                } else if (const auto *e = std::get_if<protocol::ProtocolError>(&*m->decoded)) {
                    ADD_FAILURE() << "tab A got an error: " << e->message;
                }
            }
        }
    };

    // B drags: a new camera as soon as the previous frame arrived, until A's final frame is
    // there (at most 80 s: the whole test stays inside ctest's 120 s).
    const double target = 40;   // the server's default frame-time target (ms)
    const double unit = 40;     // SchedulerOptions::unitMs, the longest a unit is planned to take
    std::ostringstream slow;    // B's frames over the bound, for the failure message
    std::vector<double> latency;
    std::vector<double> duringPreparation;   // those sent while A's coefficients were computed
    int missed = 0;
    for (int k = 0; !aFinal && Clock::now() - testStart < 80s; ++k) {
        const int id = 1000 + k;
        const bool preparing = firstProgressAt != Clock::time_point{} && preparedAt == Clock::time_point{};
        const auto moved = Clock::now();
        b.sendText(json{{"type", "camera"}, {"id", id}, {"camera", turned(sceneB.at("camera"), 0.05 * k)}}.dump());
        bool got = false;
        while (!got && Clock::now() - moved < 10s) {
            auto m = b.next(20ms);
            drainA();
            if (m && m->isFrame && m->frame.header.request == id) {
                got = true;
                const double ms = Ms(m->received - moved).count();
                latency.push_back(ms);
                if (preparing) duringPreparation.push_back(ms);
                if (ms > target + unit + 250)
                    slow << "  B frame " << k << " (level " << m->frame.header.level << ") took " << ms
                         << " ms, sent " << Ms(moved - policySent).count() << " ms after A's policy\n";
            }
        }
        if (!got) ++missed;
    }
    b.sendText(json{{"type", "interaction_end"}, {"id", 11}}.dump());
    const auto end = Clock::now() + 5s;
    while (!aFinal && Clock::now() < end) {
        drainA();
        std::this_thread::sleep_for(20ms);
    }

    std::ostringstream report;
    report << "load " << loadAverage() << "; B frames " << latency.size() << " (" << duringPreparation.size()
           << " during A's preparation), p50 " << percentile(latency, 0.5) << " ms, p95 "
           << percentile(latency, 0.95) << " ms, max " << percentile(latency, 1.0)
           << " ms; longest unit " << server->state().scheduler().longestUnitMs() << " ms; A progress messages "
           << progress.size() << ", A frames " << aFrames.size() << ", preparation took "
           << (preparedAt == Clock::time_point{} ? -1.0 : Ms(preparedAt - firstProgressAt).count()) << " ms\n";
    for (const auto &[p, at] : progressAt)
        report << "  A progress " << p.task << " " << p.fraction << " at " << Ms(at - policySent).count() << " ms\n";
    for (const auto &[h, at] : aFramesAt)
        report << "  A frame level " << h.level << (h.final ? " final " : " ") << h.quality.value("interpolation", "")
               << (h.quality.value("shading", false) ? " shaded" : "") << " at " << Ms(at - policySent).count()
               << " ms, render " << h.renderMs << " ms\n";
    report << slow.str();
    std::cout << report.str() << std::endl;

    ASSERT_TRUE(aFinal) << "A's cubic final frame never came; " << report.str();
    EXPECT_EQ(missed, 0) << "B's frames stopped coming; " << report.str();
    // A: told what is prepared, from 0 to done; trilinear frames meanwhile, marked as such;
    // then its final frame cubic and shaded.
    ASSERT_FALSE(progress.empty()) << report.str();
    EXPECT_NE(firstProgressAt, Clock::time_point{}) << "A was not told of its B-spline coefficients; " << report.str();
    EXPECT_NE(preparedAt, Clock::time_point{}) << "A was not told its coefficients are ready; " << report.str();
    EXPECT_TRUE(std::any_of(aFrames.begin(), aFrames.end(), [](const protocol::FrameHeader &h) {
        return !h.final && h.quality.value("interpolation", "") == "linear";
    })) << "A got no trilinear stand-in while its coefficients were computed; " << report.str();
    const auto final = std::find_if(aFrames.begin(), aFrames.end(), [](const auto &h) { return h.final; });
    ASSERT_NE(final, aFrames.end());
    EXPECT_EQ(final->quality.value("interpolation", ""), "cubic");
    EXPECT_EQ(final->quality.value("shading", false), true);
    // B: its frames within the target plus one unit, plus 250 ms for the machine: on 2 cores
    // shared with other builds (load 7-13), a ready thread waits for a core for up to a few
    // time slices, and B's own frame is encoded and written after it is rendered. Before the
    // scheduler ran bounded units B waited for A's whole preparation (seconds): the median
    // and p95 would be seconds, not this.
    EXPECT_LT(percentile(latency, 0.5), target + unit + 250) << report.str();
    EXPECT_LT(percentile(latency, 0.95), target + unit + 250) << report.str();
    EXPECT_GT(duringPreparation.size(), 3u) << "B did not drag while A's coefficients were computed; " << report.str();
}

// Each frame's stated error is within a factor of 1.5 of its RMSE against the
// final frame of the same camera, in the same metric (8-bit RGB over black), over a drag of
// bonsai, for interactive and refinement levels. Each camera: one interactive frame, then
// the refinement to the final frame; the estimates come from earlier cameras' measurements.
TEST_F(SchedulingScenario, ErrorEstimatesAreWithinAFactorOf1Point5OfTheErrorAgainstTheFinalFrame) {
    Client c("127.0.0.1", server->port());
    const json scene = openTab(c, "bonsai.nhdr", 256);
    std::vector<std::string> misses;
    int compared = 0;
    std::map<int, std::pair<double, double>> ratios;   // level: lowest and highest stated / measured
    std::ostringstream levelsSeen;                      // per camera, its frames' levels (e: with an estimate)
    // Two drags, each at its own interactive level: at a frame-time target of 1 s, the level
    // just below the final (where the JPEG coding is most of the error), then at 2 ms, the
    // coarsest. Refinement after either goes straight to the final frame when the levels
    // between cost more than half of it, which is the usual case here; and at the default 40 ms
    // a loaded machine drags at the coarsest level too (both drags at level 0: one level).
    c.sendText(json{{"type", "quality_policy"}, {"id", 4}, {"mode", "automatic"}, {"target_frame_ms", 1000}}.dump());
    for (int k = 0; k < 24; ++k) {
        if (k == 12)
            c.sendText(json{{"type", "quality_policy"}, {"id", 5}, {"mode", "automatic"}, {"target_frame_ms", 2}}.dump());
        const int id = 100 + k;
        c.sendText(json{{"type", "interaction_start"}, {"id", 1000 + k}}.dump());
        c.sendText(json{{"type", "camera"}, {"id", id}, {"camera", turned(scene.at("camera"), 0.08 * (k % 12))}}.dump());
        c.sendText(json{{"type", "interaction_end"}, {"id", 2000 + k}}.dump());
        std::vector<volcast::client::Frame> frames;
        const auto until = Clock::now() + 30s;
        while (Clock::now() < until && (frames.empty() || !frames.back().header.final))
            if (auto m = c.next(50ms); m && m->isFrame && m->frame.header.request == id) frames.push_back(m->frame);
        ASSERT_TRUE(!frames.empty() && frames.back().header.final) << "no final frame for camera " << k;
        levelsSeen << "  camera " << k << ":";
        for (const auto &f : frames) levelsSeen << " " << f.header.level << (f.header.error ? "e" : "");
        levelsSeen << "\n";
        const auto final = rgbOverBlack(frames.back());
        for (size_t i = 0; i + 1 < frames.size(); ++i) {
            const auto &h = frames[i].header;
            if (!h.error) continue;   // not measured yet for this level
            const double actual = rmse(rgbOverBlack(frames[i]), final);
            if (actual < 0) continue;   // a different size (never for one view)
            ++compared;
            const double ratio = h.error->value / std::max(actual, 1e-6);
            auto [it, added] = ratios.try_emplace(h.level, ratio, ratio);
            it->second = {std::min(it->second.first, ratio), std::max(it->second.second, ratio)};
            if (ratio > 1.5 || ratio < 1 / 1.5) {
                std::ostringstream m;
                m << "camera " << k << " level " << h.level << ": stated " << h.error->value << " ("
                  << h.error->method << "), measured " << actual << ", ratio " << ratio;
                misses.push_back(m.str());
            }
        }
        std::this_thread::sleep_for(200ms);   // the calibration of this camera's levels, in the background
    }
    std::ostringstream all;
    for (const auto &m : misses) all << "  " << m << "\n";
    std::cout << compared << " frames compared, " << misses.size() << " outside 1.5x\n" << all.str();
    for (const auto &[level, r] : ratios)
        std::cout << "  level " << level << ": stated / measured " << r.first << " to " << r.second << "\n";
    EXPECT_GT(compared, 10) << "too few estimated frames to judge";
    // An interactive level and at least one refinement level (the drag's frames, then refinement).
    EXPECT_GE(ratios.size(), 2u) << "only one level had estimates; the levels each camera's frames came at:\n"
                                 << levelsSeen.str();
    EXPECT_TRUE(misses.empty()) << all.str();
}

} // namespace
