#include "renderer/opencl/opencl_renderer.hpp"

#include "renderer/common/bspline_prefilter.hpp"
#include "renderer/common/frame_setup.hpp"
#include "renderer/opencl/bspline_prefilter_opencl.hpp"
#include "renderer/model/camera.hpp"
#include "renderer/opencl/embedded_kernels.hpp"
#include "renderer/opencl/kernels/raycast_shared.h"
#include "renderer/common/preintegration.hpp"
#include "renderer/common/tf_table.hpp"

#include <spdlog/spdlog.h>

#include <chrono>
#include <cmath>
#include <cstdlib>
#include <sstream>

namespace volcast {

static_assert(sizeof(RayCastParams) == 384, "RayCastParams must match the kernel's layout");
static_assert(VC_MAX_CLIP_PLANES == FrameRenderer::kMaxClipPlanes);

namespace {

using Clock = std::chrono::steady_clock;
double secondsSince(Clock::time_point t) { return std::chrono::duration<double>(Clock::now() - t).count(); }

// Work-group edge: one fixed size, so PoCL compiles one launch configuration per program
// (a new size costs it 0.25–2 s, docs/platform.md) and the global size is rounded up to it.
constexpr size_t kGroupEdge = 8;
size_t roundUp(int n) { return (size_t(n) + kGroupEdge - 1) / kGroupEdge * kGroupEdge; }

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
    if (options_.cubicFetch == CubicFetch::Auto) {
        const char *v = std::getenv("VOLCAST_CUBIC_FETCH");
        return v && std::string(v) == "image";
    }
    return options_.cubicFetch == CubicFetch::Trilinear8;
}

std::string OpenClRenderer::buildOptions(const Quality &q, bool hasClipPlanes, int voxelBytes) const {
    // No -cl-fast-relaxed-math: it would break the opacity correction's exactness for tiny
    // steps and opacities (expm1/log1p), which the stability cases rely on.
    // Each switch in use is the kernel's macro of its name (featureNames); the cubic path
    // reads a 3-D image where the device filters it (CUBIC_IMAGE).
    std::string o;
    if (voxelBytes == 1 || voxelBytes == 2) o += " -DVOXEL_BYTES=" + std::to_string(voxelBytes);
    std::istringstream names(featureNames(q, hasClipPlanes));
    for (std::string name; names >> name;) o += " -D" + (name == "CUBIC" && cubicFromImage() ? "CUBIC_IMAGE" : name);
    return o.empty() ? o : o.substr(1);
}

std::string OpenClRenderer::description() const { return "opencl: " + cl_->deviceName(); }

int OpenClRenderer::bandRows() const { return int(kGroupEdge); }

PreprocessCounts OpenClRenderer::preprocessCounts() const { return counts_.get(); }

OpenClRenderer::DataSet &OpenClRenderer::dataSet(int level, bool cubic, RenderStats &st) {
    const auto key = std::make_pair(level, cubic);
    if (auto it = dataSets_.find(key); it != dataSets_.end()) return it->second;

    auto t = Clock::now();
    const int levelsBefore = pyramid_.levelsBuilt();
    const SampleGrid samples = pyramid_.level(level);
    const Vec3i dims = pyramid_.dims(level);
    if (pyramid_.levelsBuilt() != levelsBefore) {
        st.mipSeconds = secondsSince(t);
        counts_.add(&PreprocessCounts::mipLevels, pyramid_.levelsBuilt() - levelsBefore);
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
        // The samples go up once as held; prefilter (the paper's Table 2) and mirror pad run
        // on the device, and the coefficients never come back (bspline_prefilter_opencl.hpp).
        t = Clock::now();
        cl::Buffer padded = bsplinePaddedCoefficientsOpenCl(*cl_, samples);
        if (cubicFromImage()) {
            const size_t px = size_t(dims.x) + 3, py = size_t(dims.y) + 3, pz = size_t(dims.z) + 3;
            try {
                data.image = cl::Image3D(cl_->context(), CL_MEM_READ_ONLY, cl::ImageFormat(CL_R, CL_FLOAT), px, py, pz);
                cl_->queue().enqueueCopyBufferToImage(padded, data.image, 0, {0, 0, 0}, {px, py, pz});
                cl_->queue().finish();
            } catch (const cl::Error &e) {
                throw OpenClError("cannot copy B-spline coefficients of " + volume_->name + " to a 3-D image on " +
                                  cl_->deviceName() + ": " + describe(e));
            }
        } else {
            data.buffer = std::move(padded);
        }
        st.coefficientSeconds = secondsSince(t);
        counts_.add(&PreprocessCounts::coefficientVolumes);
    }
    return dataSets_.emplace(key, std::move(data)).first->second;
}

std::vector<float> OpenClRenderer::readBackCoefficients(const DataSet &data) {
    // The padded coefficients' interior (offset 1 on each axis), read as a box: no padded
    // copy on the host.
    const Vec3i n = data.dims;
    const size_t px = size_t(n.x) + 3, py = size_t(n.y) + 3;
    std::vector<float> c(size_t(n.x) * size_t(n.y) * size_t(n.z));
    try {
        if (cubicFromImage())
            cl_->queue().enqueueReadImage(data.image, CL_TRUE, {1, 1, 1}, {size_t(n.x), size_t(n.y), size_t(n.z)}, 0, 0,
                                         c.data());
        else
            cl_->queue().enqueueReadBufferRect(data.buffer, CL_TRUE, {sizeof(float), 1, 1}, {0, 0, 0},
                                               {size_t(n.x) * sizeof(float), size_t(n.y), size_t(n.z)},
                                               px * sizeof(float), px * py * sizeof(float), 0, 0, c.data());
    } catch (const cl::Error &e) {
        throw OpenClError("cannot read back the B-spline coefficients: " + describe(e));
    }
    return c;
}

void OpenClRenderer::classify(DataSet &data, const TransferFunction &tf, RenderStats &st) {
    if (!data.bricks) {
        // Built the first time skipping is asked for: trilinear values are bounded by the
        // voxels around a brick, spline values by the coefficients (minmax_bricks.hpp), which
        // live on the device only, so they are read back once for this: one transfer of the
        // volume, and the brick grid stays the one host code both back ends build
        // (buildMinMaxBricks's footprint rules are not written twice).
        const auto t = Clock::now();
        if (data.cubic)
            data.bricks = buildMinMaxBricks(readBackCoefficients(data).data(), data.dims, options_.brickSize, 2);
        else
            data.bricks = buildMinMaxBricks(pyramid_.level(data.level), options_.brickSize, 1);
        st.brickGridSeconds = secondsSince(t);
        counts_.add(&PreprocessCounts::brickGrids);
    }
    if (!data.classification.update(*data.bricks, tf, st)) return;
    data.brickVisible = upload(*cl_, data.classification.visible, "the brick classification");
    counts_.add(&PreprocessCounts::brickClassifications);
}

Image OpenClRenderer::render(const FrameRequest &request, RenderStats *stats) {
    const FrameSetup setup = setUpFrame(*volume_, request, pyramid_.maxLevel(), options_.brickSize);
    const Quality &quality = setup.quality;
    const TransferFunction &tf = request.transferFunction;

    std::lock_guard frameLock(mutex_);
    RenderStats st = setup.stats;
    DataSet &data = dataSet(quality.mipLevel, setup.use.cubic, st);
    st.buildOptions = buildOptions(quality, setup.clipPlaneCount > 0, data.width.bytes);
    const auto built = cl_->program(kRaycastKernelSource, st.buildOptions);
    st.kernelBuildSeconds = built.buildSeconds;

    if (quality.emptySpaceSkipping) classify(data, tf, st);

    // The tables, uploaded when rebuilt: the 1-D table for every frame (with pre-integration,
    // its partial segments too opaque for the table's alpha read it: raycast.cl).
    const FrameTables::Rebuilt rebuilt = tables_.update(tf, setup, st);
    if (rebuilt.tfTable) {
        const auto t = Clock::now();
        tfTable_ = upload(*cl_, tables_.tfTable().rgba, "the transfer-function table");
        st.tfTableSeconds += secondsSince(t);
    }
    if (rebuilt.preintegration) {
        const auto t = Clock::now();
        const PreintegrationTable &table = tables_.preintegration();
        preRgba_ = upload(*cl_, table.rgba, "the pre-integration table");
        preNodes_ = upload(*cl_, table.nodes, "the pre-integration nodes");
        preLocator_ = upload(*cl_, table.locator, "the pre-integration locator");
        st.preintegrationSeconds += secondsSince(t);
    }
    counts_.add(&PreprocessCounts::tfTables, rebuilt.tfTable);
    counts_.add(&PreprocessCounts::preintegrationTables, rebuilt.preintegration);

    // The set-up as the kernel reads it.
    RayCastParams p{};
    fillCommonParams(setup, p);
    p.narrowOffset = data.width.offset;
    const TfTable &tfTable = tables_.tfTable();
    p.tfMin = float(tfTable.minValue);
    p.tfScale = float(tfTable.scale);
    p.tfEntries = tfTable.entries();
    if (quality.preintegrated) {
        const PreintegrationTable &table = tables_.preintegration();
        p.preNodes = int(table.nodes.size());
        p.preLocatorSize = table.locatorBuckets;
        p.preLocatorMin = float(table.locatorMin);
        p.preLocatorScale = float(table.locatorScale);
    }

    const auto t = Clock::now();
    // A window casts only its own rays (the launch offset places them on the full grid) and
    // reads back only its rows; the output buffer spans the grid so the kernel's indexing holds.
    const RayWindow &win = setup.cast;
    const int raysWide = setup.raysWide, raysHigh = setup.raysHigh;
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
        if (setup.use.cubic && cubicFromImage()) kernel.setArg(arg++, data.image);
        else kernel.setArg(arg++, data.buffer);
        kernel.setArg(arg++, tfTable_);
        if (quality.preintegrated) {
            kernel.setArg(arg++, preRgba_);
            kernel.setArg(arg++, preNodes_);
            kernel.setArg(arg++, preLocator_);
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
    Image image = setup.upsample ? resizeBilinear(cast, request.width, request.height) : std::move(cast);
    st.renderSeconds = secondsSince(t);
    if (stats) *stats = st;
    return image;
}

} // namespace volcast
