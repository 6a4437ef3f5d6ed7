#include "renderer/opencl/opencl_renderer.hpp"

#include "renderer/common/bspline_prefilter.hpp"
#include "renderer/opencl/bspline_prefilter_opencl.hpp"
#include "renderer/model/camera.hpp"
#include "renderer/opencl/embedded_kernels.hpp"
#include "renderer/opencl/kernels/raycast_shared.h"
#include "renderer/common/preintegration.hpp"
#include "renderer/common/tf_table.hpp"

#include <spdlog/spdlog.h>

#include <chrono>
#include <cmath>

namespace volcast {

static_assert(sizeof(RayCastParams) == 384, "RayCastParams must match the kernel's layout");
static_assert(VC_MAX_CLIP_PLANES == FrameRenderer::kMaxClipPlanes);

namespace {

using Clock = std::chrono::steady_clock;
double secondsSince(Clock::time_point t) { return std::chrono::duration<double>(Clock::now() - t).count(); }

cl_float4 f4(const Vec3d &v, double w = 0) { return {{float(v.x), float(v.y), float(v.z), float(w)}}; }

// Work-group edge: one fixed size, so PoCL compiles one launch configuration per program
// (a new size costs it 0.25–2 s, docs/platform.md) and the global size is rounded up to it.
constexpr size_t kGroupEdge = 8;
size_t roundUp(int n) { return (size_t(n) + kGroupEdge - 1) / kGroupEdge * kGroupEdge; }

// Coefficients padded by one before and two after on each axis with the mirror boundary,
// so the kernel's 4×4×4 footprint around any clamped position stays inside.
std::vector<float> padMirror(const std::vector<float> &c, Vec3i n) {
    const Vec3i p{n.x + 3, n.y + 3, n.z + 3};
    std::vector<float> out(size_t(p.x) * size_t(p.y) * size_t(p.z));
    for (int k = 0; k < p.z; ++k)
        for (int j = 0; j < p.y; ++j)
            for (int i = 0; i < p.x; ++i) {
                const int64_t si = mirrorIndex(i - 1, n.x), sj = mirrorIndex(j - 1, n.y), sk = mirrorIndex(k - 1, n.z);
                out[(size_t(k) * size_t(p.y) + size_t(j)) * size_t(p.x) + size_t(i)] =
                    c[(size_t(sk) * size_t(n.y) + size_t(sj)) * size_t(n.x) + size_t(si)];
            }
    return out;
}

cl::Buffer upload(OpenClContext &cl, const void *data, size_t bytes, const std::string &what) {
    try {
        return cl::Buffer(cl.context(), CL_MEM_READ_ONLY | CL_MEM_COPY_HOST_PTR, bytes, const_cast<void *>(data));
    } catch (const cl::Error &e) {
        throw OpenClError("cannot upload " + what + " to " + cl.deviceName() + ": " + describe(e));
    }
}

template <typename T>
cl::Buffer upload(OpenClContext &cl, const std::vector<T> &data, const std::string &what) {
    return upload(cl, data.data(), data.size() * sizeof(T), what);
}

} // namespace

struct OpenClRenderer::PreintegrationCache {
    TransferFunction tf;
    double step = 0, opacityUnit = 0;
    PreintegrationTable table;
    cl::Buffer rgba, nodes, locator;
};

OpenClRenderer::OpenClRenderer(std::shared_ptr<OpenClContext> cl, std::shared_ptr<const Volume> volume,
                               OpenClRendererOptions options)
    : cl_(std::move(cl)), volume_(std::move(volume)), options_(options), pyramid_(*volume_) {
    if (!cl_) throw std::invalid_argument("OpenClRenderer: no OpenCL context");
    if (options_.brickSize < 1) throw std::invalid_argument("brick size must be at least 1");
    // Level 0's voxels go to the device now: every frame needs them unless it asks for
    // cubic or a coarser level, and an upload failure is best reported when a volume opens.
    RenderStats unused;
    dataSet(0, false, unused);
}

OpenClRenderer::OpenClRenderer(std::shared_ptr<OpenClContext> cl, const Volume &volume, OpenClRendererOptions options)
    : OpenClRenderer(std::move(cl), std::make_shared<const Volume>(volume), options) {}

bool OpenClRenderer::cubicFromImage() const {
    if (options_.cubicFetch == CubicFetch::Auto) return cl_->isGpu();
    return options_.cubicFetch == CubicFetch::Trilinear8;
}

std::string OpenClRenderer::buildOptions(const Quality &q, bool hasClipPlanes, int voxelBytes) const {
    // No -cl-fast-relaxed-math: it would break the opacity correction's exactness for tiny
    // steps and opacities (expm1/log1p), which the stability cases rely on.
    std::string o;
    if (voxelBytes == 1 || voxelBytes == 2) o += " -DVOXEL_BYTES=" + std::to_string(voxelBytes);
    if (q.jitter) o += " -DJITTER";
    if (q.boundarySegment) o += " -DBOUNDARY_SEGMENT";
    if (q.earlyTermination < 1) o += " -DEARLY_TERMINATION";
    if (hasClipPlanes) o += " -DCLIP_PLANES";
    if (q.interpolation == Interpolation::Cubic) o += cubicFromImage() ? " -DCUBIC_IMAGE" : " -DCUBIC";
    if (q.preintegrated) o += " -DPREINTEGRATED";
    if (q.emptySpaceSkipping) o += " -DEMPTY_SPACE_SKIPPING";
    if (q.shading) o += " -DSHADING";
    if (q.compositing == Compositing::Maximum) o += " -DCOMPOSITING_MAX";
    if (q.compositing == Compositing::Minimum) o += " -DCOMPOSITING_MIN";
    return o.empty() ? o : o.substr(1);
}

std::string OpenClRenderer::description() const { return "opencl: " + cl_->deviceName(); }

int OpenClRenderer::bandRows() const { return int(kGroupEdge); }

PreprocessCounts OpenClRenderer::preprocessCounts() const {
    std::lock_guard lock(countsMutex_);
    return counts_;
}

OpenClRenderer::DataSet &OpenClRenderer::dataSet(int level, bool cubic, RenderStats &st) {
    const auto key = std::make_pair(level, cubic);
    if (auto it = dataSets_.find(key); it != dataSets_.end()) return it->second;

    auto t = Clock::now();
    const int levelsBefore = pyramid_.levelsBuilt();
    const SampleGrid samples = pyramid_.level(level);
    const Vec3i dims = pyramid_.dims(level);
    if (pyramid_.levelsBuilt() != levelsBefore) {
        st.mipSeconds = secondsSince(t);
        std::lock_guard lock(countsMutex_);
        counts_.mipLevels += pyramid_.levelsBuilt() - levelsBefore;
    }

    DataSet data;
    data.level = level;
    data.cubic = cubic;
    data.dims = dims;
    if (!cubic) {
        // As the volume holds it: a narrow store goes up as uchar or ushort, without its slack.
        data.width = samples.width;
        const size_t bytes = samples.count() * size_t(samples.width.bytes); // 4 for float
        data.buffer = upload(*cl_, samples.isNarrow() ? static_cast<const void *>(samples.narrow) : samples.floats, bytes,
                             "volume " + volume_->name);
    } else {
        // Prefilter on the device (the paper's Table 2), pad on the host, upload.
        t = Clock::now();
        const std::vector<float> coefficients = bsplinePrefilterOpenCl(*cl_, samples.toFloats().data(), dims);
        const std::vector<float> padded = padMirror(coefficients, dims);
        if (cubicFromImage()) {
            try {
                data.image = cl::Image3D(cl_->context(), CL_MEM_READ_ONLY | CL_MEM_COPY_HOST_PTR,
                                         cl::ImageFormat(CL_R, CL_FLOAT), size_t(dims.x + 3), size_t(dims.y + 3),
                                         size_t(dims.z + 3), 0, 0, const_cast<float *>(padded.data()));
            } catch (const cl::Error &e) {
                throw OpenClError("cannot upload B-spline coefficients of " + volume_->name + " as a 3-D image to " +
                                  cl_->deviceName() + ": " + describe(e));
            }
        } else {
            data.buffer = upload(*cl_, padded, "B-spline coefficients of " + volume_->name);
        }
        st.coefficientSeconds = secondsSince(t);
        std::lock_guard lock(countsMutex_);
        ++counts_.coefficientVolumes;
    }
    return dataSets_.emplace(key, std::move(data)).first->second;
}

std::vector<float> OpenClRenderer::readBackCoefficients(const DataSet &data) {
    const Vec3i n = data.dims, p{n.x + 3, n.y + 3, n.z + 3};
    std::vector<float> padded(size_t(p.x) * size_t(p.y) * size_t(p.z));
    try {
        if (cubicFromImage())
            cl_->queue().enqueueReadImage(data.image, CL_TRUE, {0, 0, 0}, {size_t(p.x), size_t(p.y), size_t(p.z)}, 0, 0,
                                         padded.data());
        else
            cl_->queue().enqueueReadBuffer(data.buffer, CL_TRUE, 0, padded.size() * sizeof(float), padded.data());
    } catch (const cl::Error &e) {
        throw OpenClError("cannot read back the B-spline coefficients: " + describe(e));
    }
    std::vector<float> c(size_t(n.x) * size_t(n.y) * size_t(n.z));
    for (int k = 0; k < n.z; ++k)
        for (int j = 0; j < n.y; ++j)
            for (int i = 0; i < n.x; ++i)
                c[(size_t(k) * size_t(n.y) + size_t(j)) * size_t(n.x) + size_t(i)] =
                    padded[(size_t(k + 1) * size_t(p.y) + size_t(j + 1)) * size_t(p.x) + size_t(i + 1)];
    return c;
}

void OpenClRenderer::classify(DataSet &data, const TransferFunction &tf, RenderStats &st) {
    if (!data.bricks) {
        // Built the first time skipping is asked for: trilinear values are bounded by the
        // voxels around a brick, spline values by the coefficients (minmax_bricks.hpp), which
        // live on the device only, so they are read back once for this.
        const auto t = Clock::now();
        if (data.cubic)
            data.bricks = buildMinMaxBricks(readBackCoefficients(data).data(), data.dims, options_.brickSize, 2);
        else
            data.bricks = buildMinMaxBricks(pyramid_.level(data.level), options_.brickSize, 1);
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
    size_t empty = 0;
    for (uint8_t v : visible) empty += v == 0;
    data.emptyFraction = visible.empty() ? 0 : double(empty) / double(visible.size());
    try {
        data.brickVisible = cl::Buffer(cl_->context(), CL_MEM_READ_ONLY | CL_MEM_COPY_HOST_PTR, visible.size(),
                                       const_cast<uint8_t *>(visible.data()));
    } catch (const cl::Error &e) {
        throw OpenClError("cannot upload the brick classification to " + cl_->deviceName() + ": " + describe(e));
    }
    data.classifiedFor = tf;
    st.brickClassifySeconds = secondsSince(t);
    st.emptyBrickFraction = data.emptyFraction;
    std::lock_guard lock(countsMutex_);
    ++counts_.brickClassifications;
}

Image OpenClRenderer::render(const TransferFunction &tf, const Camera &camera, int width, int height,
                             const Quality &quality, const std::vector<ClipPlane> &clipPlanes, RenderStats *stats) {
    return castRays(tf, camera, width, height, quality, clipPlanes, nullptr, stats);
}

Image OpenClRenderer::renderWindow(const TransferFunction &tf, const Camera &camera, int width, int height,
                                   const Quality &quality, const std::vector<ClipPlane> &clipPlanes,
                                   const RayWindow &window, RenderStats *stats) {
    return castRays(tf, camera, width, height, quality, clipPlanes, &window, stats);
}

Image OpenClRenderer::castRays(const TransferFunction &tf, const Camera &camera, int width, int height,
                           const Quality &requested, const std::vector<ClipPlane> &clipPlanes, const RayWindow *window,
                           RenderStats *stats) {
    validateFrameRequest(*volume_, tf, camera, width, height, requested, clipPlanes, pyramid_.maxLevel());
    const Quality quality = compositedQuality(requested);
    if (window) validateRayWindow(*window, width, height, quality);

    std::lock_guard frameLock(mutex_);
    RenderStats st;
    const bool cubic = quality.interpolation == Interpolation::Cubic;
    DataSet &data = dataSet(quality.mipLevel, cubic, st);
    st.buildOptions = buildOptions(quality, !clipPlanes.empty(), data.width.bytes);
    const auto built = cl_->program(kRaycastKernelSource, st.buildOptions);
    st.kernelBuildSeconds = built.buildSeconds;

    if (quality.emptySpaceSkipping) classify(data, tf, st);

    const double smallest = minComponent(volume_->spacing);
    const double step = frameStep(*volume_, quality, st);
    const double opacityUnit = tf.opacityUnit ? *tf.opacityUnit : smallest;
    if (quality.preintegrated) {
        if (!preintegration_ || !(preintegration_->tf == tf) || preintegration_->step != step ||
            preintegration_->opacityUnit != opacityUnit) {
            auto t = Clock::now();
            auto cache = std::make_shared<PreintegrationCache>();
            cache->tf = tf;
            cache->step = step;
            cache->opacityUnit = opacityUnit;
            // A constant volume has no range to tabulate; any range starting at its value
            // serves, with that value exactly on the first node.
            const double lo = volume_->range.min;
            const double hi = volume_->range.max > lo ? double(volume_->range.max)
                                                      : lo + std::max(1.0, std::fabs(lo)) * 1e-3;
            cache->table = buildPreintegrationTable(tf, step, opacityUnit, lo, hi);
            cache->rgba = upload(*cl_, cache->table.rgba, "the pre-integration table");
            cache->nodes = upload(*cl_, cache->table.nodes, "the pre-integration nodes");
            try {
                cache->locator = cl::Buffer(cl_->context(), CL_MEM_READ_ONLY | CL_MEM_COPY_HOST_PTR,
                                            cache->table.locator.size() * sizeof(int),
                                            const_cast<int *>(cache->table.locator.data()));
            } catch (const cl::Error &e) {
                throw OpenClError("cannot upload the pre-integration locator: " + describe(e));
            }
            preintegration_ = cache;
            st.preintegrationSeconds = secondsSince(t);
            std::lock_guard lock(countsMutex_);
            ++counts_.preintegrationTables;
        }
        st.preintegrationNodes = int(preintegration_->table.nodes.size());
        st.preintegrationError = preintegration_->table.maxError;
    }
    // The 1-D table: every segment without pre-integration, and with it the partial segments
    // whose full step is too opaque for its alpha to hold its depth (raycast.cl).
    if (!tfTableFor_ || !(*tfTableFor_ == tf)) {
        const auto t = Clock::now();
        const TfTable table = buildTfTable(tf);
        tfTable_ = upload(*cl_, table.rgba, "the transfer-function table");
        tfMin_ = table.minValue;
        tfScale_ = table.scale;
        tfEntries_ = table.entries();
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

    // Fewer rays for image_scale < 1, on the full image's plane, then upsampled.
    const int raysWide = raysForScale(width, quality.imageScale);
    const int raysHigh = raysForScale(height, quality.imageScale);
    st.raysWide = raysWide;
    st.raysHigh = raysHigh;
    // Camera frame exactly as RayGenerator builds it, so both renderers cast the same rays.
    const RayGenerator rays(camera, width, height);

    RayCastParams p{};
    p.eye = f4(camera.eye);
    p.forward = f4(rays.forward);
    p.right = f4(rays.right * rays.halfWidth());
    p.up = f4(rays.up * rays.halfHeight());
    // indexFromWorld(x) = Dᵀ(x − origin) / s, written as rows (linear part, translation).
    // The volume where this frame's orientation correction puts it (orientation_correction.hpp).
    const VolumePlacement placed = correctedPlacement(*volume_, quality.orientationCorrection);
    const Mat3d dt = placed.direction.transposed();
    for (int r = 0; r < 3; ++r) {
        const Vec3d row{dt(r, 0) / volume_->spacing[r], dt(r, 1) / volume_->spacing[r],
                        dt(r, 2) / volume_->spacing[r]};
        p.indexFromWorld[r] = f4(row, -dot(row, placed.origin));
    }
    for (size_t c = 0; c < clipPlanes.size(); ++c) {
        const Vec3d nrm = clipPlanes[c].normal;
        p.clipPlanes[c] = f4(nrm, -dot(nrm, clipPlanes[c].point));
    }
    p.clipPlaneCount = int(clipPlanes.size());
    double boxLo[3], boxHi[3];
    cropBoxInIndexSpace(*volume_, quality.crop, boxLo, boxHi);
    p.boxLo = {{float(boxLo[0]), float(boxLo[1]), float(boxLo[2]), 0.0f}};
    p.boxHi = {{float(boxHi[0]), float(boxHi[1]), float(boxHi[2]), 0.0f}};
    for (int a = 0; a < 3; ++a) {
        p.dims[a] = int(volume_->dims[a]);
        p.levelDims[a] = int(data.dims[a]);
        p.bricks[a] = data.bricks ? int(data.bricks->bricks[a]) : 0;
    }
    p.levelScale = float(std::ldexp(1.0, -quality.mipLevel));
    p.narrowOffset = data.width.offset;
    p.brickSize = options_.brickSize;
    p.tfMin = float(tfMin_);
    p.tfScale = float(tfScale_);
    p.tfEntries = tfEntries_;
    p.width = raysWide;
    p.height = raysHigh;
    p.orthographic = camera.projection == Projection::Orthographic;
    p.maxSamples = kMaxSamplesPerRay;
    p.step = float(step);
    p.opacityUnit = float(opacityUnit);
    // Early termination compares optical depths: no exp per sample.
    p.terminationDepth = quality.earlyTermination < 1 ? float(-std::log1p(-quality.earlyTermination)) : INFINITY;
    p.seed = uint32_t(quality.seed ^ (quality.seed >> 32));
    if (quality.preintegrated) {
        const PreintegrationTable &table = preintegration_->table;
        p.preNodes = int(table.nodes.size());
        p.preLocatorSize = table.locatorBuckets;
        p.preLocatorMin = float(table.locatorMin);
        p.preLocatorScale = float(table.locatorScale);
    }

    const auto t = Clock::now();
    // A window casts only its own rays (the launch offset places them on the full grid) and
    // reads back only its rows; the output buffer spans the grid so the kernel's indexing holds.
    const RayWindow all{0, 0, raysWide, raysHigh};
    const RayWindow &win = window ? *window : all;
    Image cast(win.width, win.height);
    try {
        auto &queue = cl_->queue();
        cl::Buffer params(cl_->context(), CL_MEM_READ_ONLY | CL_MEM_COPY_HOST_PTR, sizeof p, &p);
        const size_t rowBytes = size_t(raysWide) * 4 * sizeof(float);
        cl::Buffer out(cl_->context(), CL_MEM_WRITE_ONLY, size_t(raysHigh) * rowBytes);
        cl_uint zeros[VC_STAT_COUNT] = {};
        cl::Buffer counters(cl_->context(), CL_MEM_READ_WRITE | CL_MEM_COPY_HOST_PTR, sizeof zeros, zeros);
        // Arguments in the order of the kernel's signature for this feature set.
        cl::Kernel kernel(built.program, "raycast");
        cl_uint arg = 0;
        if (cubic && cubicFromImage()) kernel.setArg(arg++, data.image);
        else kernel.setArg(arg++, data.buffer);
        kernel.setArg(arg++, tfTable_);
        if (quality.preintegrated) {
            kernel.setArg(arg++, preintegration_->rgba);
            kernel.setArg(arg++, preintegration_->nodes);
            kernel.setArg(arg++, preintegration_->locator);
        }
        if (quality.emptySpaceSkipping) kernel.setArg(arg++, data.brickVisible);
        kernel.setArg(arg++, params);
        kernel.setArg(arg++, out);
        kernel.setArg(arg++, counters);
        queue.enqueueNDRangeKernel(kernel, cl::NDRange(size_t(win.x), size_t(win.y)),
                                   cl::NDRange(roundUp(win.width), roundUp(win.height)),
                                   cl::NDRange(kGroupEdge, kGroupEdge));
        if (win.width == raysWide) {
            queue.enqueueReadBuffer(out, CL_FALSE, size_t(win.y) * rowBytes, size_t(win.height) * rowBytes,
                                    cast.rgba.data());
        } else {
            const size_t pixel = 4 * sizeof(float);
            queue.enqueueReadBufferRect(out, CL_FALSE, {size_t(win.x) * pixel, size_t(win.y), 0}, {0, 0, 0},
                                        {size_t(win.width) * pixel, size_t(win.height), 1}, rowBytes, 0,
                                        size_t(win.width) * pixel, 0, cast.rgba.data());
        }
        cl_uint counts[VC_STAT_COUNT];
        queue.enqueueReadBuffer(counters, CL_TRUE, 0, sizeof counts, counts);
        st.raysHit = counts[VC_STAT_RAYS_HIT];
        const double hit = std::max<double>(counts[VC_STAT_RAYS_HIT], 1);
        const auto wide = [&](int low, int high) { return double(uint64_t(counts[high]) << 32 | counts[low]); };
        st.meanSamplesPerRay = wide(VC_STAT_SAMPLES, VC_STAT_SAMPLES_HIGH) / hit;
        st.skippedSegmentsPerRay = wide(VC_STAT_SEGMENTS_SKIPPED, VC_STAT_SEGMENTS_SKIPPED_HIGH) / hit;
        st.earlyTerminatedFraction = counts[VC_STAT_TERMINATED_EARLY] / hit;
        st.raysTruncated = counts[VC_STAT_TRUNCATED];
    } catch (const cl::Error &e) {
        throw OpenClError("rendering on " + cl_->deviceName() + " failed: " + describe(e));
    }
    Image image = window || (raysWide == width && raysHigh == height) ? std::move(cast)
                                                                      : resizeBilinear(cast, width, height);
    st.renderSeconds = secondsSince(t);
    if (stats) *stats = st;
    return image;
}

} // namespace volcast
