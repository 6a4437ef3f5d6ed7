// The server's small parts on their own: the quality ladder and its policy, MIME types and
// volume-file extensions.

#include "renderer/cpu/cpu_renderer.hpp"
#include "renderer/synthetic.hpp"
#include "server/quality_ladder.hpp"
#include "server/static_files.hpp"
#include "server/volume_registry.hpp"

#include <gtest/gtest.h>

namespace {

using namespace volcast;
using namespace volcast::server;

TEST(QualityLadder, RisesFromCheapToTheFinalQualityExactly) {
    Quality final;
    final.step = 0.25;
    final.interpolation = Interpolation::Cubic;
    final.preintegrated = true;
    const auto ladder = automaticLadder(final, 4);
    ASSERT_GE(ladder.size(), 2u);
    EXPECT_EQ(ladder.back().quality, final);
    EXPECT_EQ(ladder.back().passes, 1);   // no jitter asked: one exact pass
    for (size_t i = 0; i + 1 < ladder.size(); ++i) {
        // Each cheaper level samples no finer and no more rays than the next.
        EXPECT_GE(ladder[i].quality.step, ladder[i + 1].quality.step);
        EXPECT_LE(ladder[i].quality.imageScale, ladder[i + 1].quality.imageScale);
        EXPECT_GE(ladder[i].quality.mipLevel, ladder[i + 1].quality.mipLevel);
        EXPECT_EQ(ladder[i].quality.interpolation, Interpolation::Linear);
    }
    final.jitter = true;
    EXPECT_EQ(automaticLadder(final, 4).back().passes, 4);
    EXPECT_EQ(explicitLadder(final, 3).size(), 1u);
}

TEST(LevelTimer, PicksTheFinestLevelThatFitsAndAdaptsToMeasurements) {
    LevelTimer timer;
    timer.reset(3);
    const std::vector<double> samples{1e5, 1e6, 1e7};
    // Before measurements: the 50 M samples/s guess, so 1e6 samples = 20 ms fits 40 ms.
    EXPECT_EQ(timer.choose(3, 40, samples), 1u);
    // Level 0 measured 10x slower than the guess: every level borrows its cost.
    timer.record(0, 20, 1e5);
    EXPECT_EQ(timer.choose(3, 40, samples), 0u);
    // Level 1 measured fast: it is chosen again.
    timer.record(1, 10, 1e6);
    EXPECT_EQ(timer.choose(3, 40, samples), 1u);
    EXPECT_EQ(timer.choose(3, 1000, samples), 2u);
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
        renderer.render(tf, cam, 48, 48, q, {}, &st);
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

TEST(QualityLadder, RefinementSkipsALevelCostingMoreThanHalfTheFinal) {
    // bonsai at 512² (README): 19, 184, 312, 804, 938 ms.
    const std::vector<double> ms = {19, 184, 312, 804, 938};
    EXPECT_EQ(nextRefinementLevel(0, ms), 1u);
    EXPECT_EQ(nextRefinementLevel(1, ms), 2u);
    EXPECT_EQ(nextRefinementLevel(2, ms), 4u); // 804 > 938 / 2: straight to the final
    EXPECT_EQ(nextRefinementLevel(4, ms), 4u);
    EXPECT_EQ(nextRefinementLevel(0, {5, 6}), 1u);
    EXPECT_EQ(nextRefinementLevel(0, {7}), 0u);
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

} // namespace
