// The benchmark helpers' invariants: what the studies' numbers rest on.

#include "renderer/make_frame_renderer.hpp"
#include "renderer/model/synthetic.hpp"
#include "server/quality_ladder.hpp"
#include "tests/bench/bench.hpp"
#include "tests/bench/ladder_choice.hpp"
#include "tests/bench/phantom.hpp"
#include "tests/bench/studies.hpp"
#include "tests/bench/svg_plot.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <numbers>

namespace volcast::bench {
namespace {

// The benchmarks' default ray caster is the one the server and volcast-render pick: auto
// names the same back end here as makeFrameRenderer's auto does.
TEST(Bench, AutoIsTheBackEndTheServerPicks) {
    EXPECT_EQ(resolveBackEnd("cpu"), "cpu");
    EXPECT_EQ(resolveBackEnd("opencl"), "opencl");
    EXPECT_EQ(StudyOptions{}.backEnd, "auto");
    EXPECT_EQ(PeerModeOptions{}.backEnd, "auto");
    const auto box = std::make_shared<const Volume>(makeConstantBox({4, 4, 4}, {1, 1, 1}, 1).volume);
    const std::string served = makeFrameRenderer(DeviceChoice::parse("auto"), box)->description();
    EXPECT_EQ(served.rfind(resolveBackEnd("auto") + ": ", 0), 0u) << served;
}

TEST(Bench, MedianIsTheMiddleOrTheMeanOfTheMiddleTwo) {
    EXPECT_EQ(summarize({5, 1, 3}).median, 3);
    EXPECT_EQ(summarize({4, 1, 3, 2}).median, 2.5); // Python's statistics.median, as the peers
    const Timing t = summarize({7, 2, 9});
    EXPECT_EQ(t.min, 2);
    EXPECT_EQ(t.max, 9);
    EXPECT_EQ(t.n, 3);
    EXPECT_THROW(summarize({}), std::invalid_argument);
}

TEST(Bench, RepeatStopsAtItsTimeBudgetButTimesAtLeastOnce) {
    int calls = 0;
    const Timing t = repeat({2, 100, 1e-9}, [&](int) { ++calls; });
    EXPECT_EQ(t.n, 1);
    EXPECT_EQ(calls, 3); // two warm-ups, one timed
}

TEST(Bench, ParetoFrontKeepsExactlyTheUndominatedPoints) {
    //               0    1    2    3    4    5 (duplicate of 1)
    const std::vector<double> time = {1, 2, 3, 2.5, 4, 2};
    const std::vector<double> error = {9, 5, 1, 6, 1, 5};
    // 3 is beaten by 1 (faster and better); 4 by 2 (same error, slower); 1 and 5 tie: both stay.
    EXPECT_EQ(paretoFront(time, error), (std::vector<bool>{true, true, true, false, false, true}));
}

// The error studies' uniform and adaptive stepping each have their own front: a point beaten
// only by the other stepping's points stays on its own front.
TEST(Bench, ParetoFrontWithinAGroupIgnoresTheOtherGroups) {
    //                                     0    1    2    3    4
    const std::vector<double> time = {1, 2, 3, 1.5, 2.5};
    const std::vector<double> error = {8, 4, 2, 3, 1};
    const std::vector<std::string> group = {"uniform", "uniform", "uniform", "adaptive", "adaptive"};
    // Over all points, 1 and 2 are beaten by 3 and 4 (faster and more accurate).
    EXPECT_EQ(paretoFront(time, error), (std::vector<bool>{true, false, false, true, true}));
    EXPECT_EQ(paretoFrontWithin(time, error, group), (std::vector<bool>{true, true, true, true, true}));
    // Within a group the usual rule holds: 5 (uniform) is beaten by 1.
    const std::vector<double> time6 = {1, 2, 3, 1.5, 2.5, 2.2};
    const std::vector<double> error6 = {8, 4, 2, 3, 1, 4.5};
    const std::vector<std::string> group6 = {"uniform", "uniform", "uniform", "adaptive", "adaptive", "uniform"};
    EXPECT_EQ(paretoFrontWithin(time6, error6, group6), (std::vector<bool>{true, true, true, true, true, false}));
    EXPECT_THROW(paretoFrontWithin(time, error, {"uniform"}), std::invalid_argument);
}

// Uniform's samples per ray at an adaptive point's error: on a curve error ∝ samples⁻², the
// log–log interpolation is exact (to rounding: 1e-12 relative), in any input order.
TEST(Bench, CostAtErrorInterpolatesInLogLogAndNamesWhatItCannotReach) {
    const std::vector<double> samples = {40, 10, 20};
    const std::vector<double> error = {6.25e-4, 1e-2, 2.5e-3};
    EXPECT_NEAR(costAtError(samples, error, 5e-3), 10 * std::sqrt(2.0), 1e-12 * 10 * std::sqrt(2.0));
    EXPECT_NEAR(costAtError(samples, error, 2.5e-3), 20, 1e-12 * 20);
    EXPECT_NEAR(costAtError(samples, error, 1e-3), 20 * std::pow(2.5, 0.5), 1e-12 * 40);
    EXPECT_TRUE(std::isnan(costAtError(samples, error, 2e-2)));  // above the cheapest point's error
    EXPECT_TRUE(std::isnan(costAtError(samples, error, 1e-4)));  // below every error reached
    EXPECT_TRUE(std::isnan(costAtError({}, {}, 1e-3)));
}

// Side by side: one run of each variant per round, the order reversed every other round,
// every variant timed as often as the others even when the time budget cuts the rounds short.
TEST(Bench, RepeatInterleavedAlternatesTheOrderAndTimesEveryVariantAlike) {
    std::string order;
    const auto variants = std::vector<std::function<void()>>{[&] { order += 'a'; }, [&] { order += 'b'; }, [&] { order += 'c'; }};
    const std::vector<Timing> t = repeatInterleaved({1, 3, 30}, variants);
    EXPECT_EQ(order, "abc" "abc" "cba" "abc"); // one warm-up round, then three timed
    ASSERT_EQ(t.size(), 3u);
    for (const Timing &ti : t) EXPECT_EQ(ti.n, 3);
    order.clear();
    const std::vector<Timing> cut = repeatInterleaved({0, 100, 1e-9}, variants);
    EXPECT_EQ(order, "abc");
    for (const Timing &ti : cut) EXPECT_EQ(ti.n, 1);
}

TEST(Bench, PeerCameraFitsTheBoundingSphereOfTheSamplePoints) {
    Volume v;
    v.dims = {129, 65, 33};
    v.spacing = {1, 2, 3};
    const Camera c = peerCamera(v, 0);
    const Vec3d center{64, 64, 48};
    const double radius = 0.5 * std::sqrt(128.0 * 128 + 128.0 * 128 + 96.0 * 96);
    EXPECT_NEAR(length(c.target - center), 0, 1e-12);
    // The sphere touches the top and bottom of a 30° view: distance · sin(15°) = radius.
    EXPECT_NEAR(length(c.eye - c.target) * std::sin(15 * std::numbers::pi / 180), radius, 1e-9);
    // 20° above the xy plane, in front (−y) at frame 0; frame 30 has turned 90° (3° a frame).
    EXPECT_NEAR(std::asin((c.eye.z - c.target.z) / length(c.eye - c.target)) * 180 / std::numbers::pi, 20, 1e-9);
    EXPECT_LT(c.eye.y, c.target.y);
    const Camera c30 = peerCamera(v, 30);
    EXPECT_NEAR(c30.eye.y, c30.target.y, 1e-9);
    EXPECT_GT(c30.eye.x, c30.target.x);
}

TEST(Bench, PeerTransferFunctionIsTheirRampAndGreyMap) {
    const TransferFunction tf = peerTransferFunction({0, 255}, 1.0);
    EXPECT_EQ(tf.evaluate(0.39 * 255).a, 0);
    EXPECT_NEAR(tf.evaluate(0.40 * 255).r, 0.25, 1e-12);
    EXPECT_NEAR(tf.evaluate(0.70 * 255).a, 0.125, 1e-12); // halfway up the ramp
    EXPECT_NEAR(tf.evaluate(255).a, 0.25, 1e-12);
    EXPECT_NEAR(tf.evaluate(255).g, 1.0, 1e-12);
    EXPECT_NEAR(tf.evaluate(0.2 * 255).b, 0.125, 1e-12); // black to 0.25 below the ramp
}

TEST(Bench, NominalRangeFollowsThePeers) {
    Volume v;
    v.sourceType = VoxelType::UInt8;
    v.range = {3, 200};
    EXPECT_EQ(nominalRange(v).max, 255);
    v.sourceType = VoxelType::UInt16;
    v.range = {0, 4095};
    EXPECT_EQ(nominalRange(v).max, 4095);
    v.range = {0, 60000}; // not 12-bit data: its own range
    EXPECT_EQ(nominalRange(v).max, 60000);
}

TEST(Bench, PhantomHasThePeersStructures) {
    const Volume v = makePeerPhantom({64, 64, 64}, VoxelType::UInt8);
    // Noise N(0, 0.02) of 255 is ~5 units: 5 sigma = 26 units is a safe band.
    EXPECT_NEAR(v.at(0, 0, 0), 0.04 * 255, 26);          // background corner
    EXPECT_NEAR(v.at(32, 32, 10), 0.80 * 255, 26);       // the tube along z, near the centre
    EXPECT_NEAR(v.at(32, 32, 1), 0.04 * 255, 26);        // the tube stops inside the ellipsoid
    const Volume w = makePeerPhantom({64, 64, 64}, VoxelType::UInt8);
    EXPECT_EQ(v.samples().toFloats(), w.samples().toFloats()) << "deterministic";
    const Volume big = makePeerPhantom({16, 16, 16}, VoxelType::UInt16);
    EXPECT_LE(big.range.max, 4095);
}

TEST(Bench, ResamplingTo2nMinus1KeepsEverySampleAndInterpolatesBetween) {
    const Volume v = makePeerPhantom({9, 7, 5}, VoxelType::UInt8);
    const Volume r = resampleTrilinear(v, {17, 13, 9});
    EXPECT_DOUBLE_EQ(r.spacing.x, 0.5);
    for (int64_t k = 0; k < 5; ++k)
        for (int64_t j = 0; j < 7; ++j)
            for (int64_t i = 0; i < 9; ++i) ASSERT_FLOAT_EQ(r.at(2 * i, 2 * j, 2 * k), v.at(i, j, k));
    EXPECT_FLOAT_EQ(r.at(3, 4, 2), 0.5f * (v.at(1, 2, 1) + v.at(2, 2, 1)));
}

TEST(Bench, SizesParseAndBadOnesAreNamed) {
    EXPECT_EQ(parseSizes("512x512,800x600"), (std::vector<std::pair<int, int>>{{512, 512}, {800, 600}}));
    try {
        parseSizes("512x512,800by600");
        FAIL();
    } catch (const std::invalid_argument &e) {
        EXPECT_NE(std::string(e.what()).find("800by600"), std::string::npos);
    }
    EXPECT_THROW(parseSizes("0x10"), std::invalid_argument);
    EXPECT_THROW(parseSizes("512x512px"), std::invalid_argument);
    EXPECT_THROW(parseSizes("512.5x512"), std::invalid_argument);
}

// The ladder study's per-session budget is the scheduler's: the target's render share split by
// count among the sessions dragging (the one asking counts when none is recorded), less the
// shown level's encoding and twice its deviation. Values exact in binary, so EXPECT_DOUBLE_EQ.
TEST(Bench, LadderBudgetIsTheTargetSharedByCountLessEncodingAndDeviation) {
    EXPECT_DOUBLE_EQ(server::interactiveBudgetMs(40, 1, 0, 0), server::kRenderShare * 40);
    EXPECT_DOUBLE_EQ(server::interactiveBudgetMs(40, 0, 0, 0), server::interactiveBudgetMs(40, 1, 0, 0));
    EXPECT_DOUBLE_EQ(server::interactiveBudgetMs(40, 4, 0, 0), server::kRenderShare * 10);
    EXPECT_DOUBLE_EQ(server::interactiveBudgetMs(40, 4, 1.5, 0.25), server::kRenderShare * 10 - 2);
    // 32 sessions at 40 ms leave ~1.1 ms each: a 2 ms encoder alone exceeds it.
    EXPECT_LT(server::interactiveBudgetMs(40, 32, 2, 0), 0);
}

TEST(Bench, SvgLeavesOutPointsALogAxisCannotShow) {
    Plot p;
    p.logX = p.logY = true;
    p.series.push_back({"s", {1, 10, 0, 100}, {1, 0.1, 5, NAN}});
    const std::string svg = renderSvg(p);
    EXPECT_EQ(svg.find("nan"), std::string::npos);
    EXPECT_EQ(svg.find("inf"), std::string::npos);
    EXPECT_NE(svg.find("<polyline"), std::string::npos);
}

// A configuration drawn twice (uniform solid, adaptive dashed) keeps its colour.
TEST(Bench, SvgSeriesWithAColourIndexShareIt) {
    Plot p;
    p.series.push_back({"A", {1, 2}, {1, 2}});
    p.series.push_back({"B", {1, 2}, {2, 3}});
    p.series.push_back({"A, adaptive", {1, 2}, {3, 4}});
    p.series.back().colour = 0;
    const std::string svg = renderSvg(p);
    const auto strokeOf = [&](size_t polyline) {
        size_t at = 0;
        for (size_t k = 0; k <= polyline; ++k) at = svg.find("<polyline", at + (k ? 1 : 0));
        const size_t s = svg.find("stroke=\"", at) + 8;
        return svg.substr(s, svg.find('"', s) - s);
    };
    EXPECT_EQ(strokeOf(2), strokeOf(0));
    EXPECT_NE(strokeOf(1), strokeOf(0));
}

} // namespace
} // namespace volcast::bench
