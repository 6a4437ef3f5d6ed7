#include "renderer/cpu/cpu_renderer.hpp"

#include "renderer/common/bspline_prefilter.hpp"
#include "renderer/cpu/cpu_march.hpp"
#include "renderer/common/preintegration.hpp"
#include "renderer/common/tf_table.hpp"

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <limits>
#include <stdexcept>
#include <thread>

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

void set3(float *out, const Vec3d &v) {
    out[0] = float(v.x);
    out[1] = float(v.y);
    out[2] = float(v.z);
}

} // namespace

CpuRenderer::CpuRenderer(std::shared_ptr<const Volume> volume, CpuRendererOptions options)
    : volume_(std::move(volume)), options_(options), pyramid_(*volume_) {
    if (options_.brickSize < 1) throw std::invalid_argument("brick size must be at least 1");
    if (options_.threads < 0) throw std::invalid_argument("threads must be 0 (one per core) or more");
    threads_ = options_.threads > 0 ? options_.threads : int(std::max(1u, std::thread::hardware_concurrency()));
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
    const int threads = options.threads > 0 ? options.threads : int(std::max(1u, std::thread::hardware_concurrency()));
    return "cpu: " + cpu::marchTarget() + ", " + std::to_string(cpu::raysPerPacket()) + " rays per packet, " +
           std::to_string(threads) + " threads";
}

std::string CpuRenderer::featureNames(const Quality &q, bool hasClipPlanes) {
    std::string o;
    if (q.jitter) o += " JITTER";
    if (q.boundarySegment) o += " BOUNDARY_SEGMENT";
    if (q.earlyTermination < 1) o += " EARLY_TERMINATION";
    if (hasClipPlanes) o += " CLIP_PLANES";
    if (q.interpolation == Interpolation::Cubic) o += " CUBIC";
    if (q.preintegrated) o += " PREINTEGRATED";
    if (q.emptySpaceSkipping) o += " EMPTY_SPACE_SKIPPING";
    if (q.shading) o += " SHADING";
    if (q.compositing == Compositing::Maximum) o += " COMPOSITING_MAX";
    if (q.compositing == Compositing::Minimum) o += " COMPOSITING_MIN";
    return o.empty() ? o : o.substr(1);
}

PreprocessCounts CpuRenderer::preprocessCounts() const {
    std::lock_guard lock(countsMutex_);
    return counts_;
}

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
        std::lock_guard lock(countsMutex_);
        counts_.mipLevels += pyramid_.levelsBuilt() - levelsBefore;
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
        std::lock_guard lock(countsMutex_);
        ++counts_.coefficientVolumes;
    }
    heldBytes_ += uint64_t(data.padded.size() + data.widened.size()) * sizeof(float);
    return dataSets_.emplace(key, std::move(data)).first->second;
}

uint64_t CpuRenderer::plannedBytes(Vec3i dims, const CpuRendererOptions &options, int level0Bytes) {
    const auto count = [](Vec3i d, int pad) { return uint64_t(d.x + pad) * uint64_t(d.y + pad) * uint64_t(d.z + pad); };
    const int b = std::max(1, options.brickSize);
    // Trilinear frames sample every level where it lies; only a narrow level 0 too large for
    // int32 byte offsets is widened into a float copy (dataSet).
    uint64_t bytes = level0Bytes < 4 && count(dims, 0) * uint64_t(level0Bytes) + kNarrowSlack > uint64_t(INT32_MAX)
                         ? count(dims, 0) * sizeof(float)
                         : 0;
    for (int level = 0;; ++level) {
        const Vec3i d = mipLevelDims(dims, level);
        if (level > 0) bytes += count(d, 0) * sizeof(float);                  // the mip level
        bytes += count(d, 3) * sizeof(float);                                 // cubic copy
        const Vec3i bricks{(d.x + b - 1) / b, (d.y + b - 1) / b, (d.z + b - 1) / b};
        bytes += 2 * count(bricks, 0) * (2 * sizeof(float) + sizeof(int32_t)); // min-max and visible, both
        if (d.x == 1 && d.y == 1 && d.z == 1) break;
    }
    return bytes;
}

void CpuRenderer::classify(DataSet &data, int level, const TransferFunction &tf, RenderStats &st) {
    if (!data.bricks) {
        const auto t = Clock::now();
        // Spline values are bounded by the coefficients around a brick, two on each side
        // (minmax_bricks.hpp); only the padded copy is kept, so its interior is taken out.
        if (data.cubic) data.bricks = buildMinMaxBricks(unpadMirror(data.padded, data.dims).data(), data.dims,
                                                        options_.brickSize, 2);
        else data.bricks = buildMinMaxBricks(pyramid_.level(level), options_.brickSize, 1);
        heldBytes_ += uint64_t(data.bricks->minmax.size()) * sizeof(float) +
                      uint64_t(data.bricks->brickCount()) * sizeof(int32_t); // and the visible flags below
        st.brickGridSeconds = secondsSince(t);
        std::lock_guard lock(countsMutex_);
        ++counts_.brickGrids;
    }
    if (data.classifiedFor && *data.classifiedFor == tf) {
        st.emptyBrickFraction = data.emptyFraction;
        return;
    }
    const auto t = Clock::now();
    const std::vector<uint8_t> visible = classifyBricks(*data.bricks, tf);
    data.brickVisible.assign(visible.begin(), visible.end());
    const size_t empty = size_t(std::count(visible.begin(), visible.end(), uint8_t(0)));
    data.emptyFraction = visible.empty() ? 0 : double(empty) / double(visible.size());
    data.classifiedFor = tf;
    st.brickClassifySeconds = secondsSince(t);
    st.emptyBrickFraction = data.emptyFraction;
    std::lock_guard lock(countsMutex_);
    ++counts_.brickClassifications;
}

Image CpuRenderer::render(const TransferFunction &tf, const Camera &camera, int width, int height,
                          const Quality &quality, const std::vector<ClipPlane> &clipPlanes, RenderStats *stats) {
    return castRays(tf, camera, width, height, quality, clipPlanes, nullptr, stats);
}

Image CpuRenderer::renderWindow(const TransferFunction &tf, const Camera &camera, int width, int height,
                                const Quality &quality, const std::vector<ClipPlane> &clipPlanes,
                                const RayWindow &window, RenderStats *stats) {
    return castRays(tf, camera, width, height, quality, clipPlanes, &window, stats);
}

Image CpuRenderer::castRays(const TransferFunction &tf, const Camera &camera, int width, int height,
                            const Quality &requested, const std::vector<ClipPlane> &clipPlanes, const RayWindow *window,
                            RenderStats *stats) {
    validateFrameRequest(*volume_, tf, camera, width, height, requested, clipPlanes, pyramid_.maxLevel());
    if (window) validateRayWindow(*window, width, height, requested);
    const Quality quality = compositedQuality(requested);

    std::lock_guard frameLock(mutex_);
    RenderStats st;
    st.buildOptions = featureNames(quality, !clipPlanes.empty());
    const bool cubic = quality.interpolation == Interpolation::Cubic;
    DataSet &data = dataSet(quality.mipLevel, cubic, st);
    if (quality.emptySpaceSkipping) classify(data, quality.mipLevel, tf, st);

    const double smallest = minComponent(volume_->spacing);
    const double step = frameStep(*volume_, quality, st);
    const double opacityUnit = tf.opacityUnit ? *tf.opacityUnit : smallest;
    if (!tfTableFor_ || !(*tfTableFor_ == tf)) {
        const auto t = Clock::now();
        TfTable table = buildTfTable(tf);
        tfTable_ = std::move(table.rgba);
        tfMin_ = table.minValue;
        tfScale_ = table.scale;
        tfEntries_ = int(tfTable_.size() / 4);
        tfError_ = table.maxError;
        tfTableFor_ = tf;
        st.tfTableSeconds = secondsSince(t);
        std::lock_guard lock(countsMutex_);
        ++counts_.tfTables;
    }
    if (!quality.preintegrated) {
        st.tfTableEntries = tfEntries_;
        st.tfTableError = tfError_;
    }
    if (quality.preintegrated) {
        // Rebuilt when the transfer function or the step changes (the table holds whole steps).
        if (!preintegration_ || !(preintegrationFor_ == tf) || preintegration_->step != step ||
            preintegration_->opacityUnit != opacityUnit) {
            const auto t = Clock::now();
            // A constant volume has no range to tabulate; any range starting at its value
            // serves, with that value exactly on the first node (as the OpenCL back end).
            const double lo = volume_->range.min;
            const double hi = volume_->range.max > lo ? double(volume_->range.max)
                                                      : lo + std::max(1.0, std::fabs(lo)) * 1e-3;
            preintegration_ = std::make_shared<PreintegrationTable>(
                buildPreintegrationTable(tf, step, opacityUnit, lo, hi));
            preintegrationFor_ = tf;
            st.preintegrationSeconds = secondsSince(t);
            std::lock_guard lock(countsMutex_);
            ++counts_.preintegrationTables;
        }
        st.preintegrationNodes = int(preintegration_->nodes.size());
        st.preintegrationError = preintegration_->maxError;
    }

    const int raysWide = raysForScale(width, quality.imageScale);
    const int raysHigh = raysForScale(height, quality.imageScale);
    st.raysWide = raysWide;
    st.raysHigh = raysHigh;
    // Camera frame exactly as RayGenerator builds it, as the OpenCL back end does.
    const RayGenerator rays(camera, width, height);

    cpu::FrameParams p{};
    p.features.jitter = quality.jitter;
    p.features.boundarySegment = quality.boundarySegment;
    p.features.earlyTermination = quality.earlyTermination < 1;
    p.features.clipPlanes = !clipPlanes.empty();
    p.features.emptySpaceSkipping = quality.emptySpaceSkipping;
    p.features.shading = quality.shading;
    p.features.cubic = cubic;
    p.features.preintegrated = quality.preintegrated;
    p.features.intensityProjection = quality.compositing == Compositing::Maximum   ? 1
                                     : quality.compositing == Compositing::Minimum ? -1
                                                                                   : 0;
    if (quality.preintegrated) {
        const PreintegrationTable &table = *preintegration_;
        p.preRgba = table.rgba.data();
        p.preNodes = table.nodes.data();
        p.preLocator = table.locator.data();
        p.preNodeCount = int(table.nodes.size());
        p.preLocatorSize = table.locatorBuckets;
        p.preLocatorMin = table.locatorMin;
        p.preLocatorScale = table.locatorScale;
    }
    set3(p.eye, camera.eye);
    set3(p.forward, rays.forward);
    set3(p.right, rays.right * rays.halfWidth());
    set3(p.up, rays.up * rays.halfHeight());
    // The volume where this frame's orientation correction puts it (orientation_correction.hpp).
    const VolumePlacement placed = correctedPlacement(*volume_, quality.orientationCorrection);
    const Mat3d dt = placed.direction.transposed();
    for (int r = 0; r < 3; ++r) {
        const Vec3d row{dt(r, 0) / volume_->spacing[r], dt(r, 1) / volume_->spacing[r],
                        dt(r, 2) / volume_->spacing[r]};
        set3(p.indexFromWorld[r], row);
        p.indexFromWorld[r][3] = float(-dot(row, placed.origin));
    }
    for (size_t c = 0; c < clipPlanes.size(); ++c) {
        const Vec3d nrm = clipPlanes[c].normal;
        set3(p.clipPlanes[c], nrm);
        p.clipPlanes[c][3] = float(-dot(nrm, clipPlanes[c].point));
    }
    p.clipPlaneCount = int(clipPlanes.size());
    double boxLo[3], boxHi[3];
    cropBoxInIndexSpace(*volume_, quality.crop, boxLo, boxHi);
    for (int a = 0; a < 3; ++a) {
        p.boxLo[a] = float(boxLo[a]);
        p.boxHi[a] = float(boxHi[a]);
    }
    for (int a = 0; a < 3; ++a) {
        p.dims[a] = int(volume_->dims[a]);
        p.levelDims[a] = int(data.dims[a]);
        p.bricks[a] = data.bricks ? int(data.bricks->bricks[a]) : 0;
    }
    p.width = raysWide;
    p.height = raysHigh;
    p.orthographic = camera.projection == Projection::Orthographic;
    p.levelScale = float(std::ldexp(1.0, -quality.mipLevel));
    p.step = float(step);
    p.opacityUnit = float(opacityUnit);
    p.terminationDepth = quality.earlyTermination < 1 ? float(-std::log1p(-quality.earlyTermination))
                                                      : std::numeric_limits<float>::infinity();
    p.seed = uint32_t(quality.seed ^ (quality.seed >> 32));
    p.maxSamples = kMaxSamplesPerRay;
    // Cubic: the padded coefficients; trilinear: the level where it lies. dataSet and
    // padMirror checked that the indices (byte offsets, narrow) fit int32.
    p.voxels = cubic ? data.padded.data() : data.floats;
    const int pad = cubic ? 3 : 0;
    if (data.narrow) {
        p.narrowVoxels = data.narrow;
        p.narrowBytes = data.width.bytes;
        p.narrowOffset = data.width.offset;
    }
    p.rowStride = int(data.dims.x + pad);
    p.sliceStride = int((data.dims.x + pad) * (data.dims.y + pad));
    p.tf = tfTable_.data();
    p.tfMin = float(tfMin_);
    p.tfScale = float(tfScale_);
    p.tfEntries = tfEntries_;
    p.brickVisible = quality.emptySpaceSkipping ? data.brickVisible.data() : nullptr;
    p.brickSize = options_.brickSize;

    // A window casts only its own rays, tiled from its corner; each ray is cast as in the
    // whole grid (its lanes do not depend on the other rays of its packet).
    const RayWindow all{0, 0, raysWide, raysHigh};
    const RayWindow &win = window ? *window : all;
    p.outX = win.x;
    p.outY = win.y;
    p.outWidth = win.width;

    const auto t = Clock::now();
    Image cast(win.width, win.height);
    cpu::Counters counters;
    const int tilesWide = (win.width + kTileEdge - 1) / kTileEdge, tilesHigh = (win.height + kTileEdge - 1) / kTileEdge;
    const int tiles = tilesWide * tilesHigh;
    std::atomic<int> next{0};
    auto work = [&] {
        for (int i; (i = next.fetch_add(1)) < tiles;) {
            const int x0 = win.x + (i % tilesWide) * kTileEdge, y0 = win.y + (i / tilesWide) * kTileEdge;
            cpu::marchTile(p, x0, y0, std::min(x0 + kTileEdge, win.x + win.width),
                           std::min(y0 + kTileEdge, win.y + win.height), cast.rgba.data(), counters);
        }
    };
    {
        std::vector<std::jthread> pool;
        for (int i = 1; i < std::min(threads_, tiles); ++i) pool.emplace_back(work);
        work();
    }
    st.raysHit = counters.raysHit;
    const double hit = std::max<double>(double(counters.raysHit), 1);
    st.meanSamplesPerRay = double(counters.samples) / hit;
    st.skippedSegmentsPerRay = double(counters.segmentsSkipped) / hit;
    st.earlyTerminatedFraction = double(counters.terminatedEarly) / hit;
    st.raysTruncated = counters.truncated;
    Image image = window || (raysWide == width && raysHigh == height) ? std::move(cast)
                                                                       : resizeBilinear(cast, width, height);
    st.renderSeconds = secondsSince(t);
    if (stats) *stats = st;
    return image;
}

} // namespace volcast
