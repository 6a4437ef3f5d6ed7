#include "renderer/cpu/cpu_renderer.hpp"

#include "renderer/common/bspline_prefilter.hpp"
#include "renderer/common/frame_setup.hpp"
#include "renderer/common/parallel_for.hpp"
#include "renderer/common/preintegration.hpp"
#include "renderer/common/tf_table.hpp"
#include "renderer/cpu/cpu_march.hpp"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <limits>
#include <stdexcept>

namespace volcast {

namespace {

using Clock = std::chrono::steady_clock;
double secondsSince(Clock::time_point t) { return std::chrono::duration<double>(Clock::now() - t).count(); }

// Screen tiles handed to threads one at a time: small enough to balance a frame whose cost
// is concentrated where the volume is, large enough that a tile's rays share cache lines.
constexpr int kTileEdge = 16;

// The march indexes a level's samples (padded by `pad` on each axis) with int32.
void checkIndexable(Vec3i n, int pad) {
    const size_t count = size_t(n.x + pad) * size_t(n.y + pad) * size_t(n.z + pad);
    if (count > size_t(std::numeric_limits<int32_t>::max()))
        throw std::invalid_argument("volume of " + std::to_string(n.x) + "×" + std::to_string(n.y) + "×" +
                                    std::to_string(n.z) + " samples is too large for the cpu device's 32-bit "
                                    "voxel indices (at most 2^31 padded samples)");
}

// B-spline coefficients padded by one before and two after on each axis with the mirror
// boundary, so the 4×4×4 footprint around any clamped position stays inside (as the OpenCL
// back end's buffer).
std::vector<float> padMirror(const std::vector<float> &c, Vec3i n) {
    checkIndexable(n, 3);
    const Vec3i p{n.x + 3, n.y + 3, n.z + 3};
    std::vector<float> out(size_t(p.x) * size_t(p.y) * size_t(p.z));
    for (int64_t k = 0; k < p.z; ++k)
        for (int64_t j = 0; j < p.y; ++j)
            for (int64_t i = 0; i < p.x; ++i)
                out[(size_t(k) * size_t(p.y) + size_t(j)) * size_t(p.x) + size_t(i)] =
                    c[(size_t(mirrorIndex(k - 1, n.z)) * size_t(n.y) + size_t(mirrorIndex(j - 1, n.y))) * size_t(n.x) +
                      size_t(mirrorIndex(i - 1, n.x))];
    return out;
}

std::vector<float> unpadMirror(const std::vector<float> &padded, Vec3i n) {
    const size_t px = size_t(n.x) + 3, py = size_t(n.y) + 3;
    std::vector<float> c(size_t(n.x) * size_t(n.y) * size_t(n.z));
    for (size_t k = 0; k < size_t(n.z); ++k)
        for (size_t j = 0; j < size_t(n.y); ++j) {
            const float *src = padded.data() + ((k + 1) * py + (j + 1)) * px + 1;
            std::copy(src, src + n.x, c.data() + (k * size_t(n.y) + j) * size_t(n.x));
        }
    return c;
}

} // namespace

CpuRenderer::CpuRenderer(std::shared_ptr<const Volume> volume, CpuRendererOptions options)
    : volume_(std::move(volume)), options_(options), pyramid_(*volume_) {
    if (options_.brickSize < 1) throw std::invalid_argument("brick size must be at least 1");
    if (options_.threads < 0) throw std::invalid_argument("threads must be 0 (one per core) or more");
    threads_ = resolveThreadCount(options_.threads);
    // Level 0 now (nothing to copy for trilinear frames, but a float level is checked to fit
    // int32 indices): every frame but a coarser level's needs it.
    RenderStats unused;
    dataSet(0, false, unused);
}

CpuRenderer::CpuRenderer(const Volume &volume, CpuRendererOptions options)
    : CpuRenderer(std::make_shared<const Volume>(volume), options) {}

std::string CpuRenderer::description() const { return describe(options_); }

// As cpu_march.cpp lays packets out: up to 4 rays wide, the rest of the lanes in rows below.
int CpuRenderer::bandRows() const {
    const int lanes = std::max(1, cpu::raysPerPacket());
    return std::max(1, lanes / std::min(lanes, 4));
}

std::string CpuRenderer::describe(const CpuRendererOptions &options) {
    const int threads = resolveThreadCount(options.threads);
    return "cpu: " + cpu::marchTarget() + ", " + std::to_string(cpu::raysPerPacket()) + " rays per packet, " +
           std::to_string(threads) + " threads";
}

PreprocessCounts CpuRenderer::preprocessCounts() const { return counts_.get(); }

CpuRenderer::DataSet &CpuRenderer::dataSet(int level, bool cubic, RenderStats &st) {
    const auto key = std::make_pair(level, cubic);
    if (auto it = dataSets_.find(key); it != dataSets_.end()) return it->second;
    const auto t = Clock::now();
    const int levelsBefore = pyramid_.levelsBuilt();
    const SampleGrid samples = pyramid_.level(level);
    if (pyramid_.levelsBuilt() != levelsBefore) {
        for (int l = levelsBefore + 1; l <= pyramid_.levelsBuilt(); ++l)
            heldBytes_ += uint64_t(pyramid_.level(l).count()) * sizeof(float);
        st.mipSeconds = secondsSince(t);
        counts_.add(&PreprocessCounts::mipLevels, pyramid_.levelsBuilt() - levelsBefore);
    }
    DataSet data;
    data.dims = pyramid_.dims(level);
    data.cubic = cubic;
    if (!cubic) {
        // Sampled where it lies, float or narrow: no copy. Narrow samples are gathered at
        // byte offsets, which must fit int32 too; past that they are widened into a float copy.
        const uint64_t lastOffset = uint64_t(samples.count()) * uint64_t(samples.width.bytes) + kNarrowSlack;
        if (samples.isNarrow() && lastOffset <= uint64_t(INT32_MAX)) {
            data.narrow = samples.narrow;
            data.width = samples.width;
            if (bricksFit(data.dims, options_, samples.width.bytes)) {
                data.bricked = cpu::brickSamples(samples, threads_);
                heldBytes_ += uint64_t(data.bricked->store.size());
            }
        } else {
            checkIndexable(data.dims, 0);
            if (samples.isNarrow()) data.widened = samples.toFloats();
            data.floats = samples.isNarrow() ? data.widened.data() : samples.floats;
        }
    } else {
        const auto tc = Clock::now();
        std::vector<float> coefficients = samples.toFloats();
        bsplinePrefilterMultithreaded(coefficients.data(), data.dims, threads_);
        data.padded = padMirror(coefficients, data.dims);
        st.coefficientSeconds = secondsSince(tc);
        counts_.add(&PreprocessCounts::coefficientVolumes);
    }
    heldBytes_ += uint64_t(data.padded.size() + data.widened.size()) * sizeof(float);
    return dataSets_.emplace(key, std::move(data)).first->second;
}

// Whether a narrow level is held bricked: asked for, and its byte offsets fit int32 (the
// gathers'); else it is sampled where it lies.
bool CpuRenderer::bricksFit(Vec3i dims, const CpuRendererOptions &options, int bytes) {
    return options.layout == SampleLayout::Bricks && bytes < 4 &&
           cpu::BrickedSamples::plannedBytes(dims, bytes) <= uint64_t(INT32_MAX);
}

uint64_t CpuRenderer::plannedBytes(Vec3i dims, const CpuRendererOptions &options, int level0Bytes) {
    const auto count = [](Vec3i d, int pad) { return uint64_t(d.x + pad) * uint64_t(d.y + pad) * uint64_t(d.z + pad); };
    const int b = std::max(1, options.brickSize);
    // Trilinear frames sample every level where it lies; only a narrow level 0 too large for
    // int32 byte offsets is widened into a float copy (dataSet).
    uint64_t bytes = level0Bytes < 4 && count(dims, 0) * uint64_t(level0Bytes) + kNarrowSlack > uint64_t(INT32_MAX)
                         ? count(dims, 0) * sizeof(float)
                         : 0;
    if (bricksFit(dims, options, level0Bytes)) bytes += cpu::BrickedSamples::plannedBytes(dims, level0Bytes);
    for (int level = 0;; ++level) {
        const Vec3i d = mipLevelDims(dims, level);
        if (level > 0) bytes += count(d, 0) * sizeof(float);                  // the mip level
        bytes += count(d, 3) * sizeof(float);                                 // cubic copy
        const Vec3i bricks{(d.x + b - 1) / b, (d.y + b - 1) / b, (d.z + b - 1) / b};
        // Min-max, visible, and the adaptive step's gradient bounds and steps; trilinear and cubic.
        bytes += 2 * count(bricks, 0) * (2 * sizeof(float) + sizeof(int32_t) + 4 * sizeof(float));
        if (d.x == 1 && d.y == 1 && d.z == 1) break;
    }
    return bytes;
}

const MinMaxBricks &CpuRenderer::bricks(DataSet &data, int level, RenderStats &st) {
    if (!data.bricks) {
        const auto t = Clock::now();
        // Spline values are bounded by the coefficients around a brick, two on each side
        // (minmax_bricks.hpp); only the padded copy is kept, so its interior is taken out.
        if (data.cubic) data.bricks = buildMinMaxBricks(unpadMirror(data.padded, data.dims).data(), data.dims,
                                                        options_.brickSize, 2);
        else data.bricks = buildMinMaxBricks(pyramid_.level(level), options_.brickSize, 1);
        heldBytes_ += uint64_t(data.bricks->minmax.size()) * sizeof(float) +
                      uint64_t(data.bricks->brickCount()) * sizeof(int32_t); // and the classification's reach
        st.brickGridSeconds = secondsSince(t);
        counts_.add(&PreprocessCounts::brickGrids);
    }
    return *data.bricks;
}

void CpuRenderer::classify(DataSet &data, int level, const TransferFunction &tf, RenderStats &st) {
    if (!data.classification.update(bricks(data, level, st), tf, st)) return;
    counts_.add(&PreprocessCounts::brickClassifications);
}

void CpuRenderer::adaptSteps(DataSet &data, int level, const TransferFunction &tf, const FrameSetup &setup,
                             RenderStats &st) {
    const MinMaxBricks &grid = bricks(data, level, st);
    if (!data.gradients) {
        const auto t = Clock::now();
        // The differences a reconstruction's derivative blends: neighbouring samples
        // (trilinear) or coefficients (cubic), as the min-max grid reads them.
        if (data.cubic) {
            const std::vector<float> coefficients = unpadMirror(data.padded, data.dims);
            data.gradients = buildBrickGradients(SampleGrid::ofFloats(data.dims, coefficients.data()),
                                                 options_.brickSize, kCubicBSplineBorder, threads_);
        } else {
            data.gradients = buildBrickGradients(pyramid_.level(level), options_.brickSize, kTrilinearBorder, threads_);
        }
        // Held: the gradient bounds and the steps, per brick.
        heldBytes_ += uint64_t(grid.brickCount()) * 4 * sizeof(float);
        st.adaptiveStepSeconds = secondsSince(t);
    }
    data.adaptive.update(grid, *data.gradients, tf, tables_.tfTable(), setup,
                         setup.use.emptySpaceSkipping ? &data.classification.visible : nullptr, st);
}

Image CpuRenderer::render(const FrameRequest &request, RenderStats *stats) {
    const FrameSetup setup = setUpFrame(*volume_, request, pyramid_.maxLevel(), options_.brickSize);
    const Quality &quality = setup.quality;
    const TransferFunction &tf = request.transferFunction;
    RenderStats st = setup.stats;
    st.buildOptions = setup.features;

    std::lock_guard frameLock(mutex_);
    DataSet &data = dataSet(quality.mipLevel, setup.use.cubic, st);
    if (quality.emptySpaceSkipping) classify(data, quality.mipLevel, tf, st);
    const FrameTables::Rebuilt rebuilt = tables_.update(tf, setup, st);
    if (quality.adaptiveStep) adaptSteps(data, quality.mipLevel, tf, setup, st);
    counts_.add(&PreprocessCounts::tfTables, rebuilt.tfTable);
    counts_.add(&PreprocessCounts::preintegrationTables, rebuilt.preintegration);

    // The set-up as the march reads it.
    cpu::FrameParams p{};
    fillCommonParams(setup, p);
    p.features = setup.use;
    if (quality.preintegrated) {
        const PreintegrationTable &table = tables_.preintegration();
        p.preRgba = table.rgba.data();
        p.preNodes = table.nodes.data();
        p.preLocator = table.locator.data();
        p.preNodeCount = int(table.nodes.size());
        p.preLocatorSize = table.locatorBuckets;
        p.preLocatorMin = table.locatorMin;
        p.preLocatorScale = table.locatorScale;
    }
    // Cubic: the padded coefficients; trilinear: the level where it lies. dataSet and
    // padMirror checked that the indices (byte offsets, narrow) fit int32.
    p.voxels = setup.use.cubic ? data.padded.data() : data.floats;
    const int pad = setup.use.cubic ? 3 : 0;
    if (data.narrow) {
        p.narrowVoxels = data.narrow;
        p.narrowBytes = data.width.bytes;
        p.narrowOffset = data.width.offset;
        if (data.bricked) {
            p.brickedVoxels = data.bricked->store.data();
            p.layoutBricks[0] = int(data.bricked->bricks.x);
            p.layoutBricks[1] = int(data.bricked->bricks.y);
        }
    }
    p.rowStride = int(data.dims.x + pad);
    p.sliceStride = int((data.dims.x + pad) * (data.dims.y + pad));
    const TfTable &tfTable = tables_.tfTable();
    p.tf = tfTable.rgba.data();
    p.tfMin = float(tfTable.minValue);
    p.tfScale = float(tfTable.scale);
    p.tfEntries = tfTable.entries();
    p.brickReach = quality.emptySpaceSkipping && !quality.adaptiveStep
                       ? data.classification.reachFor(*data.bricks, st).data()
                       : nullptr;
    p.brickStep = quality.adaptiveStep ? data.adaptive.steps.step.data() : nullptr;
    // A window casts only its own rays, tiled from its corner; each ray is cast as in the
    // whole grid (its lanes do not depend on the other rays of its packet).
    const RayWindow &win = setup.cast;
    p.outX = win.x;
    p.outY = win.y;
    p.outWidth = win.width;

    const auto t = Clock::now();
    Image cast(win.width, win.height);
    cpu::Counters counters;
    const int tilesWide = (win.width + kTileEdge - 1) / kTileEdge, tilesHigh = (win.height + kTileEdge - 1) / kTileEdge;
    // Tiles handed out one at a time: a tile's cost depends on how much of the volume it sees.
    parallelFor(tilesWide * tilesHigh, threads_, [&](int i) {
        const int x0 = win.x + (i % tilesWide) * kTileEdge, y0 = win.y + (i / tilesWide) * kTileEdge;
        cpu::marchTile(p, x0, y0, std::min(x0 + kTileEdge, win.x + win.width),
                       std::min(y0 + kTileEdge, win.y + win.height), cast.rgba.data(), counters);
    });
    st.raysHit = counters.raysHit;
    const double hit = std::max<double>(double(counters.raysHit), 1);
    st.meanSamplesPerRay = double(counters.samples) / hit;
    st.skippedSegmentsPerRay = double(counters.segmentsSkipped) / hit;
    st.earlyTerminatedFraction = double(counters.terminatedEarly) / hit;
    st.raysTruncated = counters.truncated;
    Image image = setup.upsample ? resizeBilinear(cast, request.width, request.height) : std::move(cast);
    st.renderSeconds = secondsSince(t);
    if (stats) *stats = st;
    return image;
}

} // namespace volcast
