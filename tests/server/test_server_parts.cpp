// The server's small parts on their own: the quality ladder and its policy, the frame
// encoders, MIME types and volume-file extensions.

#include "renderer/cpu/cpu_renderer.hpp"
#include "renderer/model/synthetic.hpp"
#include "server/error_calibrator.hpp"
#include "server/frame_encoder.hpp"
#include "server/preprocess_worker.hpp"
#include "server/quality_ladder.hpp"
#include "server/static_files.hpp"
#include "server/volume_registry.hpp"
#include "tests/server/png_decode.hpp"

#include <gtest/gtest.h>

#include <chrono>
#include <cmath>
#include <limits>
#include <random>
#include <thread>

namespace {

using namespace volcast;
using namespace volcast::server;

TEST(QualityLadder, CandidatesAreCheaperThanTheFinalOrderedByCostAndEndInItExactly) {
    Quality final;
    final.step = 0.25;
    final.interpolation = Interpolation::Cubic;
    final.preintegrated = true;
    const auto ladder = automaticLadder(final, 4);
    ASSERT_GE(ladder.size(), 2u);
    EXPECT_EQ(ladder.back().quality, final);
    EXPECT_EQ(ladder.back().passes, 1);   // no jitter asked: one exact pass
    const auto cost = [](const Quality &q) { return q.imageScale * q.imageScale / q.step; };
    for (size_t i = 0; i + 1 < ladder.size(); ++i) {
        const Quality &q = ladder[i].quality;
        // Never finer than the final on any axis of cost, trilinear, one pass.
        EXPECT_GE(q.step, final.step);
        EXPECT_LE(q.imageScale, final.imageScale);
        EXPECT_GE(q.mipLevel, final.mipLevel);
        EXPECT_EQ(q.interpolation, Interpolation::Linear);
        EXPECT_EQ(ladder[i].passes, 1);
        // A coarse mip level is not sampled finer than its voxels (2^m level-0 voxels).
        if (q.mipLevel > 0) {
            EXPECT_GE(q.step, double(1 << q.mipLevel)) << "level " << i;
        }
        if (i + 2 < ladder.size()) {
            EXPECT_LE(cost(q), cost(ladder[i + 1].quality)) << "level " << i;
        }
        for (size_t j = 0; j < i; ++j) EXPECT_FALSE(ladder[j].quality == q) << "levels " << j << " and " << i;
    }
    // The 3 image scales × (3 steps at mip 0, 2 at mip 1, 1 at mip 2), and the jittered level.
    EXPECT_EQ(ladder.size(), 3u * 6u + 1u + 1u);
    final.jitter = true;
    EXPECT_EQ(automaticLadder(final, 4).back().passes, 4);
    EXPECT_EQ(explicitLadder(final, 3).size(), 1u);

    // A coarse final leaves out the levels that would equal it or be finer than it.
    Quality coarse;
    coarse.step = 4;
    coarse.mipLevel = 2;
    coarse.imageScale = 0.5;
    const auto few = automaticLadder(coarse, 1);
    for (const Level &l : few) {
        EXPECT_GE(l.quality.step, 4);
        EXPECT_EQ(l.quality.mipLevel, 2);
        EXPECT_LE(l.quality.imageScale, 0.5);
    }
}

TEST(LevelTimer, PredictsFromItsOwnMeasurementsThenTheBackgroundCostsScaledThenTheNearest) {
    LevelTimer timer;
    timer.reset(3);
    // Before measurements: the 50 M samples/s guess.
    EXPECT_DOUBLE_EQ(timer.predictMs(1, 1e6), 20);
    // Level 0 measured 10x slower than the guess: every level borrows its cost.
    timer.record(0, 20, 1e5);
    EXPECT_DOUBLE_EQ(timer.predictMs(2, 1e6), 200);
    // Background costs stand in for the unmeasured levels, scaled by level 0's ratio of its
    // own cost to its background one (here 2e-4 / 1e-4 = 2). Level 2 (the final) has none.
    timer.setBackgroundCosts({1e-4, 5e-6, 0});
    EXPECT_DOUBLE_EQ(timer.predictMs(1, 1e6), 5e-6 * 2 * 1e6);
    // A level measured itself keeps its own cost, and is now the latest measured both ways:
    // 3e-5 / 5e-6 = 6 scales the others.
    timer.record(1, 30, 1e6);
    EXPECT_DOUBLE_EQ(timer.predictMs(1, 1e6), 30);
    // The final level, measured last, has no background cost: the latest level that has one scales.
    timer.record(2, 100, 1e6);
    timer.forget(0);
    EXPECT_DOUBLE_EQ(timer.predictMs(0, 1e5), 1e-4 * 6 * 1e5);
    timer.forget(1);
    // Nothing measured both ways any more: the background costs as they are.
    EXPECT_DOUBLE_EQ(timer.predictMs(1, 1e6), 5e-6 * 1e6);
    // How far a measured level's frames come from their prediction: level 2 predicted 100 ms,
    // measured 106 ms, a miss of 6 ms.
    EXPECT_EQ(timer.deviationMs(), 0);
    timer.record(2, 106, 1e6);
    EXPECT_DOUBLE_EQ(timer.deviationMs(), 6);
}

TEST(QualityLadder, WhileInteractingTheLowestMeasuredErrorWithinTheTargetIsShown) {
    // Levels in cost order, the last the final. Unmeasured: the costliest that fits.
    std::vector<LevelOutlook> levels = {{5, {}}, {20, {}}, {35, {}}, {60, {}}, {900, {}}};
    EXPECT_EQ(chooseInteractiveLevel(levels, 40), 2u);
    EXPECT_EQ(chooseInteractiveLevel(levels, 1), 0u);   // none fits: the cheapest
    EXPECT_EQ(chooseInteractiveLevel(levels, 1e6), 3u); // never the final while interacting
    // Measured: a cheaper level with a lower error (half size at step 1 beats full size at step 4).
    levels[0].error = 0.08;
    levels[1].error = 0.02;
    levels[2].error = 0.03;
    levels[3].error = 0.01;
    EXPECT_EQ(chooseInteractiveLevel(levels, 40), 1u);
    EXPECT_EQ(chooseInteractiveLevel(levels, 100), 3u);
    levels[2].error = 0.02;   // a tie: the cheaper
    EXPECT_EQ(chooseInteractiveLevel(levels, 40), 1u);
    levels[1].error.reset();  // one unmeasured among those that fit: the costliest
    EXPECT_EQ(chooseInteractiveLevel(levels, 40), 2u);
    EXPECT_EQ(chooseInteractiveLevel({{7, {}}}, 40), 0u);   // an explicit policy's one level
}

TEST(QualityLadder, AtRestOneStepBelowTheShownErrorWithinHalfTheFinalThenTheFinal) {
    // bonsai at 512² on PoCL (README): 19, 184, 312, 804, 938 ms. Unmeasured: the costliest
    // within half the final (804 > 938 / 2 is left out).
    std::vector<LevelOutlook> levels = {{19, {}}, {184, {}}, {312, {}}, {804, {}}, {938, {}}};
    EXPECT_EQ(nextRefinementLevel(0, levels), 2u);
    EXPECT_EQ(nextRefinementLevel(2, levels), 4u);
    EXPECT_EQ(nextRefinementLevel(3, levels), 4u);
    EXPECT_EQ(nextRefinementLevel(4, levels), 4u);
    // Measured: the lowest error below the shown one's, not the costliest.
    levels[0].error = 0.05;
    levels[1].error = 0.01;
    levels[2].error = 0.03;
    levels[3].error = 0.005;
    EXPECT_EQ(nextRefinementLevel(0, levels), 1u);
    EXPECT_EQ(nextRefinementLevel(1, levels), 4u);   // nothing below 0.01 within 469 ms
    EXPECT_EQ(nextRefinementLevel(2, levels), 1u);   // a cheaper level with a lower error
    EXPECT_EQ(nextRefinementLevel(0, {{5, {}}, {6, {}}}), 1u);
    EXPECT_EQ(nextRefinementLevel(0, {{7, {}}}), 0u);
    // A level shown already in this view is not chosen again: from 2, level 1 came; from 1,
    // with 1 and 0 shown, nothing else is better and cheap enough: the final.
    EXPECT_EQ(nextRefinementLevel(1, levels, {true, true, true}), 4u);
}

// Walked as the scheduler walks it (the level shown last, the levels shown so far), the
// refinement reaches the final within as many steps as there are levels, whatever the
// measured errors: a cheaper level with a lower error must not send the view back to the
// costlier one it came from, over and over, never final (seen after a quick volume switch,
// when the reopened volume's errors were measured and not monotonic in cost).
TEST(QualityLadder, EveryRefinementReachesTheFinalWhateverTheErrors) {
    uint32_t seed = 12345;
    const auto next = [&] { return seed = seed * 1664525u + 1013904223u; };
    for (int trial = 0; trial < 2000; ++trial) {
        const size_t n = 2 + next() % 8;
        std::vector<LevelOutlook> levels(n);
        for (size_t i = 0; i < n; ++i) {
            levels[i].predictedMs = double(1 + i * 10);
            if (next() % 4 != 0) levels[i].error = double(next() % 1000) / 1000.0;   // some unmeasured
        }
        size_t sent = next() % (n - 1);
        std::vector<bool> shown(n, false);
        shown[sent] = true;
        size_t steps = 0;
        while (sent != n - 1) {
            ASSERT_LE(++steps, n) << "trial " << trial << ": refinement did not reach the final within " << n
                                  << " steps";
            sent = nextRefinementLevel(sent, levels, shown);
            shown[sent] = true;
        }
    }
}

// The step is in level-0 voxels whatever the mip level (frameStep), so a ray takes as many
// samples on a coarse level as on level 0: the prediction must not shrink with the level. It
// once divided by 2^mip, so every finer level, priced from a coarse level's measured cost per
// (under-counted) sample, looked 2–4× too slow and the ladder stayed at its coarsest level.
TEST(QualityLadder, PredictedSamplesFollowWhatTheRendererTakesAtEveryMipLevel) {
    const SyntheticVolume box = makeSphere({64, 48, 40}, {1, 1, 1}, 100, 0.5, 100); // a ball filling the box
    TransferFunction tf;
    tf.points = {{0, 0, 0, 0, 0}, {100, 1, 1, 1, 0.01}}; // faint: no ray ends early
    Camera cam;
    cam.target = box.volume.center();
    cam.eye = cam.target + Vec3d(30, 40, 3 * length(box.volume.extent()));
    CpuRenderer renderer(box.volume);
    const auto taken = [&](int mip) {
        Quality q;
        q.step = 1;
        q.mipLevel = mip;
        RenderStats st;
        renderer.render({tf, cam, 48, 48, q, {}}, &st);
        return st.meanSamplesPerRay * double(st.raysHit);
    };
    const auto predicted = [&](int mip) {
        Quality q;
        q.step = 1;
        q.mipLevel = mip;
        return predictedSamples(box.volume, q, 48, 48);
    };
    for (int mip : {1, 2}) {
        // The prediction is a bound from the diagonal, the renderer's count what the rays
        // really cross; their ratios between levels must agree. 5 %: the rays' entry points
        // on a coarser level's box differ by up to half a coarse voxel over ~70 samples.
        EXPECT_NEAR(predicted(mip) / predicted(0), taken(mip) / taken(0), 0.05) << "mip level " << mip;
    }
}

// The automatic policy within the server's limits: every level of a 3840×2160 view of a
// 256² × 133 volume (the 8-bit chest CT's size) fits --max-samples-per-frame and
// --max-request-mib, lowered by image scale first, then step; a level that fits is untouched.
TEST(QualityLadder, TheAutomaticLadderIsFittedWithinTheLimitsImageScaleFirst) {
    Volume v;
    v.dims = {256, 256, 133};
    Quality f;
    f.step = 0.5;
    f.shading = true;
    f.jitter = true;
    const int w = 3840, h = 2160;
    const AdmissionLimits limits{double(int64_t(1) << 32), double(uint64_t(1) << 30)};
    const auto ladder = automaticLadder(f, 4);
    const auto fitted = fitToLimits(ladder, &v, w, h, limits);
    ASSERT_FALSE(fitted.empty());
    const auto fits = [&](const Level &l) {
        return predictedSamples(v, l.quality, w, h) <= limits.maxSamplesPerFrame &&
               requestBytes(l, w, h) <= limits.maxRequestBytes;
    };
    for (const Level &l : fitted) EXPECT_TRUE(fits(l)) << qualityToJson(l.quality).dump() << " " << l.limited;
    // The final level: 8.3 M rays × 385 voxels / 0.5 × 3 (shading) = 1.9e10 samples, 4.4× the
    // 2^32 limit: scale √(1/4.4) = 0.47 at the same step, in hundredths below.
    const Level &last = fitted.back();
    const double over = predictedSamples(v, f, w, h) / limits.maxSamplesPerFrame;
    EXPECT_NEAR(last.quality.imageScale, std::floor(100 / std::sqrt(over)) / 100, 1e-12);
    EXPECT_EQ(last.quality.step, f.step) << "the image scale alone sufficed: the step is kept";
    EXPECT_EQ(last.passes, 4);
    EXPECT_NE(last.limited.find("image scale 0.47"), std::string::npos) << last.limited;
    EXPECT_NE(last.limited.find("per-frame limit"), std::string::npos) << last.limited;
    // Levels that fitted as they were are unchanged and say nothing.
    for (const Level &l : ladder)
        if (fits(l)) {
            bool kept = false;
            for (const Level &g : fitted) kept = kept || (g.quality == l.quality && g.limited.empty());
            EXPECT_TRUE(kept) << qualityToJson(l.quality).dump();
        }
    // No two levels are the same.
    for (size_t i = 0; i < fitted.size(); ++i)
        for (size_t j = i + 1; j < fitted.size(); ++j)
            EXPECT_FALSE(fitted[i].quality == fitted[j].quality && fitted[i].passes == fitted[j].passes) << i << " " << j;

    // A limit 20× tighter: a quarter scale is not enough (it would need 0.10), so the step
    // doubles (with the mip level it allows) until the samples fit, at scale 0.25: ×5.7 more
    // than at 0.10, so step 0.5 × 8.
    const AdmissionLimits tight{limits.maxSamplesPerFrame / 20, limits.maxRequestBytes};
    const Level coarse = fitToLimits(ladder, &v, w, h, tight).back();
    EXPECT_EQ(coarse.quality.imageScale, kMinFittedImageScale);
    EXPECT_EQ(coarse.quality.step, 8 * f.step);
    EXPECT_EQ(coarse.quality.mipLevel, 2);
    EXPECT_LE(predictedSamples(v, coarse.quality, w, h), tight.maxSamplesPerFrame);
    EXPECT_GT(predictedSamples(v, [&] { Quality q = coarse.quality; q.step /= 2; return q; }(), w, h),
              tight.maxSamplesPerFrame) << "the step is the finest that fits (doubling from the final's)";
    EXPECT_GE(coarse.quality.step, double(1 << coarse.quality.mipLevel)) << "a mip level only with a step that allows it";
    EXPECT_NE(coarse.limited.find("step"), std::string::npos) << coarse.limited;

    // Image memory alone (no volume open yet): 3840×2160 × 16 B × 4 passes = 506 MiB over a
    // 128 MiB limit: scale √(128/506) = 0.50 → 0.5 at most.
    const AdmissionLimits memory{limits.maxSamplesPerFrame, double(128 << 20)};
    const Level small = fitToLimits(ladder, nullptr, w, h, memory).back();
    EXPECT_LE(requestBytes(small, w, h), memory.maxRequestBytes);
    EXPECT_GT(small.quality.imageScale, 0.49);
    EXPECT_NE(small.limited.find("image-memory limit"), std::string::npos) << small.limited;

    // A view within the limits is not touched at all.
    const auto inside = fitToLimits(ladder, &v, 512, 512, limits);
    ASSERT_EQ(inside.size(), ladder.size());
    for (size_t i = 0; i < inside.size(); ++i) {
        EXPECT_TRUE(inside[i].quality == ladder[i].quality);
        EXPECT_TRUE(inside[i].limited.empty());
    }
}

// The front the ladder chooses from: once a view's final frame is in, every level below it is
// rendered in the background, JPEG-coded as it would be sent (at its ray grid's size) and
// scaled up to the view as a client shows it, and its RMSE against the final frame recorded,
// with its cost. Checked against the same measurement made here, and against
// what the levels are: the coarsest level is further from the final than the finest one.
// A frame of fewer rays is compared as the client shows it: scaled up bilinearly between pixel
// centres, clamped at the edges. A 2×1 image of a 4×2 view: the view's pixel centres fall at
// −0.25, 0.25, 0.75 and 1.25 of the image's along x, so red 0 → 200 becomes 0, 50, 150, 200.
TEST(ErrorCalibrator, ScalesASmallerFrameAsTheClientShowsIt) {
    const Rgb8 small{2, 1, {0, 10, 20, 200, 10, 20}};
    const Rgb8 view = scaledRgb8(small, 4, 2);
    ASSERT_EQ(view.width, 4);
    ASSERT_EQ(view.height, 2);
    for (int y = 0; y < 2; ++y) {
        const uint8_t *row = &view.rgb[size_t(y) * 12];
        EXPECT_EQ((std::vector<int>{row[0], row[3], row[6], row[9]}), (std::vector<int>{0, 50, 150, 200})) << "row " << y;
        EXPECT_EQ(row[4], 10);
        EXPECT_EQ(row[5], 20);
    }
    EXPECT_EQ(scaledRgb8(small, 2, 1).rgb, small.rgb) << "its own size: unchanged";
}

TEST(ErrorCalibrator, MeasuresEveryLevelAsDeliveredAgainstTheFinalFrame) {
    const SyntheticVolume blob = makeGaussianBlob({48, 48, 48}, {1, 1, 1}, 5, 200);
    auto renderer = std::make_shared<CpuRenderer>(blob.volume);
    auto view = std::make_shared<CalibrationView>();
    view->key = "blob";
    view->renderer = renderer;
    view->transferFunction.points = {{0, 0, 0, 0, 0}, {60, 0.9, 0.5, 0.2, 0.05}, {200, 1, 1, 1, 0.4}};
    view->camera.target = blob.volume.center();
    view->camera.eye = view->camera.target + Vec3d(20, 30, 3 * length(blob.volume.extent()));
    view->width = view->height = 64;
    Quality final;
    final.step = 0.5;
    view->ladder = automaticLadder(final, 1);
    const size_t count = view->ladder.size();
    const Rgb8 finalRgb = toRgb8(renderer->render({view->transferFunction, view->camera, 64, 64, final, {}}));

    PreprocessWorker worker;
    ErrorCalibrator calibrator(worker, true);
    EXPECT_FALSE(calibrator.levels("blob", count).errors[0].has_value()) << "measured before any final frame";
    calibrator.finalRendered(view, {}, finalRgb, 1);
    const auto until = std::chrono::steady_clock::now() + std::chrono::seconds(60);
    while (worker.busy() && std::chrono::steady_clock::now() < until) std::this_thread::sleep_for(std::chrono::milliseconds(10));
    ASSERT_FALSE(worker.busy()) << "the calibration did not finish in 60 s";

    const auto measured = calibrator.levels("blob", count);
    EXPECT_FALSE(measured.errors[count - 1].has_value()) << "the final level is not compared with itself";
    for (size_t l = 0; l + 1 < count; ++l) {
        ASSERT_TRUE(measured.errors[l].has_value()) << "level " << l << " not measured";
        EXPECT_GT(measured.backgroundMsPerSample[l], 0) << "level " << l;
        const Level &level = view->ladder[l];
        const int side = raysForScale(64, level.quality.imageScale);
        const Image image = renderer->render({view->transferFunction, view->camera, 64, 64, level.quality, {},
                                              RayWindow{0, 0, side, side}});
        ASSERT_EQ(image.width, side);
        // The renderer, the JPEG coder and the scaling are deterministic: the same measurement, to the bit.
        EXPECT_DOUBLE_EQ(*measured.errors[l],
                         rmseRgb8(scaledRgb8(decodeJpegRgb8(encodeJpeg(image, level.jpegQuality)), 64, 64), finalRgb))
            << "level " << l;
    }
    // Level 0 is the cheapest (quarter size, mip 2, step 4); the finest plain level (full
    // size, mip 0, step 1) is the last but one or two, before or after the jittered level.
    size_t finest = count;
    for (size_t l = 0; l + 1 < count; ++l) {
        const Quality &q = view->ladder[l].quality;
        if (q.imageScale == 1 && q.mipLevel == 0 && q.step == 1 && !q.jitter) finest = l;
    }
    ASSERT_LT(finest, count) << "no full-size level at step 1 on mip level 0";
    // Measured here: 0.0245 against 0.0075 (3.3×; both include their JPEG coding). 2×
    // leaves room for another JPEG library's rounding; equal or swapped errors fail it. The
    // blob is narrow (sigma 5 voxels) so that a quarter-size, mip-2 view of it loses detail.
    EXPECT_GT(*measured.errors[0], 2 * *measured.errors[finest])
        << "the quarter-size, mip-2 level (" << *measured.errors[0] << ") is not clearly further from the final "
        << "than the finest level (" << *measured.errors[finest] << ")";
}

TEST(StaticFiles, MimeTypes) {
    EXPECT_EQ(mimeType("a/index.html"), "text/html; charset=utf-8");
    EXPECT_EQ(mimeType("main.mjs"), "text/javascript; charset=utf-8");
    EXPECT_EQ(mimeType("x.CSS"), "text/css; charset=utf-8");
    EXPECT_EQ(mimeType("logo.svg"), "image/svg+xml");
    EXPECT_EQ(mimeType("blob.bin"), "application/octet-stream");
}

TEST(VolumeRegistry, KnownExtensions) {
    for (const char *name : {"a.nrrd", "ct/b.NHDR", "c.mha", "d.mhd", "e.nii", "f.nii.gz"})
        EXPECT_TRUE(hasVolumeExtension(name)) << name;
    for (const char *name : {"a.raw", "b.gz", ".nrrd", "c.txt"}) EXPECT_FALSE(hasVolumeExtension(name)) << name;
}

// ---- frame encoding ------------------------------------------------------------------

// An image with every case the conversions meet: alpha 0, 1 and between, colour above alpha
// (a renderer's rounding), negative and over-range values, NaN; odd sizes (JPEG's 4:2:0
// chroma halves them).
Image encoderTestImage(int width, int height) {
    Image image(width, height);
    std::mt19937 random(7);
    std::uniform_real_distribution<float> any(-0.1f, 1.1f);
    for (size_t p = 0; p < size_t(width) * size_t(height); ++p) {
        const float a = p % 7 == 0 ? 0.0f : p % 5 == 0 ? 1.0f : std::clamp(any(random), 0.0f, 1.0f);
        for (size_t c = 0; c < 3; ++c) image.rgba[p * 4 + c] = a * any(random);
        image.rgba[p * 4 + 3] = a;
    }
    float *last = image.pixel(width - 1, height - 1);
    last[0] = std::numeric_limits<float>::quiet_NaN();
    last[1] = 2.0f;
    last[3] = 0.5f;
    return image;
}

TEST(FrameEncoder, EightBitValuesRoundHalfAwayFromZeroAsLroundDoesAndNanIsZero) {
    // Every 8-bit boundary: the exact halves (k + 0.5) / 255 and the floats either side.
    std::vector<float> values;
    for (int k = 0; k < 256; ++k) {
        const float half = (float(k) + 0.5f) / 255.0f;
        values.insert(values.end(), {float(k) / 255.0f, half, std::nextafter(half, 0.0f), std::nextafter(half, 2.0f)});
    }
    values.insert(values.end(), {-1.0f, -0.0f, 1.5f, std::numeric_limits<float>::infinity(),
                                 -std::numeric_limits<float>::infinity(), std::numeric_limits<float>::quiet_NaN()});
    Image image(int(values.size()), 1);
    for (size_t i = 0; i < values.size(); ++i)
        image.rgba[i * 4 + 0] = image.rgba[i * 4 + 1] = image.rgba[i * 4 + 2] = image.rgba[i * 4 + 3] = values[i];
    const std::vector<uint8_t> rgb = toRgb8OverBlack(image);
    for (size_t i = 0; i < values.size(); ++i) {
        const float v = values[i];
        const long expected = std::isnan(v) ? 0 : std::lround(std::clamp(v, 0.0f, 1.0f) * 255.0f);
        EXPECT_EQ(int(rgb[i * 3]), int(expected)) << "value " << v;
    }
}

TEST(FrameEncoder, PngHoldsTheStraightRgbaBytesExactly) {
    for (const auto &[w, h] : std::vector<std::pair<int, int>>{{1, 1}, {37, 23}, {256, 3}}) {
        const Image image = encoderTestImage(w, h);
        int dw = 0, dh = 0, channels = 0;
        // Decoded by libpng's simplified reader, not the write path that made it.
        const std::vector<uint8_t> got = volcast::test::decodePng(encodePng(image), dw, dh, channels);
        ASSERT_EQ(dw, w);
        ASSERT_EQ(dh, h);
        ASSERT_EQ(channels, 4);
        EXPECT_EQ(got, toStraightRgba8(image)) << w << "x" << h;
    }
}

TEST(FrameEncoder, JpegDecodesCloseToTheImageOverBlackAtEachLaddersQuality) {
    // A smooth picture, as frames are: JPEG's error on it is small and falls with quality.
    const int w = 97, h = 61;
    Image image(w, h);
    for (int y = 0; y < h; ++y)
        for (int x = 0; x < w; ++x) {
            float *p = image.pixel(x, y);
            const float a = 0.5f + 0.5f * std::sin(0.07f * float(x)) * std::cos(0.05f * float(y));
            p[0] = a * float(x) / float(w);
            p[1] = a * float(y) / float(h);
            p[2] = a * 0.5f;
            p[3] = a;
        }
    const Rgb8 exact = toRgb8(image);
    double previous = 1;
    for (const int quality : {50, 70, 80, 95}) {
        const Rgb8 decoded = decodeJpegRgb8(encodeJpeg(image, quality));
        ASSERT_EQ(decoded.width, w);
        ASSERT_EQ(decoded.height, h);
        const double rmse = rmseRgb8(decoded, exact);
        // Measured 0.0037-0.0094 (q 95-50) with libjpeg-turbo 2.1 here; 0.02 is twice the worst.
        EXPECT_LT(rmse, 0.02) << "quality " << quality;
        EXPECT_LE(rmse, previous * 1.05) << "quality " << quality << " is no closer than a lower one";
        previous = rmse;
    }
}

TEST(FrameEncoder, AnEmptyImageIsRefusedByName) {
    const Image empty(0, 0);
    try {
        encodeJpeg(empty, 80);
        ADD_FAILURE() << "an empty JPEG was encoded";
    } catch (const std::runtime_error &e) {
        EXPECT_NE(std::string(e.what()).find("empty"), std::string::npos) << e.what();
    }
    try {
        encodePng(empty);
        ADD_FAILURE() << "an empty PNG was encoded";
    } catch (const std::runtime_error &e) {
        EXPECT_NE(std::string(e.what()).find("empty"), std::string::npos) << e.what();
    }
}

} // namespace
