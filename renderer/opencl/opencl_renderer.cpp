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

#include <algorithm>
#include <cstring>
#include <chrono>
#include <cmath>
#include <cstdlib>
#include <mutex>
#include <string_view>

namespace volcast {

static_assert(sizeof(RayCastParams) == 384, "RayCastParams must match the kernel's layout");
static_assert(VC_MAX_CLIP_PLANES == FrameRenderer::kMaxClipPlanes);

namespace {

using Clock = OpenClRenderer::Clock;
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

OpenClRenderer::~OpenClRenderer() {
    if (!pinnedHost_) return;
    try {
        cl_->queue().enqueueUnmapMemObject(pinned_, pinnedHost_);
        cl_->queue().finish();
    } catch (const cl::Error &) {
        // The context goes with its memory; nothing else to give back.
    }
}

ReadBack OpenClRenderer::readBack() const {
    if (options_.readBack != ReadBack::Auto) return options_.readBack;
    const char *v = std::getenv("VOLCAST_OPENCL_READBACK");
    const std::string how = v ? v : "";
    if (how == "counters-first") return ReadBack::CountersFirst;
    if (how == "pinned") return ReadBack::Pinned;
    // A misspelt choice would otherwise measure the default under another name.
    static std::once_flag warned;
    if (!how.empty() && how != "direct")
        std::call_once(warned, [&] {
            spdlog::warn("VOLCAST_OPENCL_READBACK={} is none of direct, counters-first, pinned: reading back direct", how);
        });
    return ReadBack::Direct;
}

void *OpenClRenderer::pinnedHost(size_t bytes) {
    if (bytes <= pinnedBytes_) return pinnedHost_;
    auto &queue = cl_->queue();
    if (pinnedHost_) queue.enqueueUnmapMemObject(pinned_, pinnedHost_);
    pinnedHost_ = nullptr;
    pinnedBytes_ = 0;
    pinned_ = cl::Buffer(cl_->context(), CL_MEM_READ_WRITE | CL_MEM_ALLOC_HOST_PTR, bytes);
    pinnedHost_ = queue.enqueueMapBuffer(pinned_, CL_TRUE, CL_MAP_READ | CL_MAP_WRITE, 0, bytes);
    pinnedBytes_ = bytes;
    return pinnedHost_;
}

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
    // Split by hand: every frame asks, and a stringstream took about 20 µs of a frame here
    // (timed inside one PoCL run, not side by side).
    std::string o;
    if (voxelBytes == 1 || voxelBytes == 2) o += " -DVOXEL_BYTES=" + std::to_string(voxelBytes);
    const std::string names = featureNames(q, hasClipPlanes);
    for (size_t at = 0; at < names.size();) {
        const size_t end = std::min(names.find(' ', at), names.size());
        const std::string_view name = std::string_view(names).substr(at, end - at);
        o += " -D";
        o += name == "CUBIC" && cubicFromImage() ? std::string_view("CUBIC_IMAGE") : name;
        at = end + 1;
    }
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

const MinMaxBricks &OpenClRenderer::bricks(DataSet &data, RenderStats &st) {
    if (!data.bricks) {
        // Built the first time skipping or the adaptive step is asked for: trilinear values are
        // bounded by the voxels around a brick, spline values by the coefficients
        // (minmax_bricks.hpp), which live on the device only, so they are read back once for
        // this: one transfer of the volume, and the brick grid stays the one host code both back
        // ends build (buildMinMaxBricks's footprint rules are not written twice).
        const auto t = Clock::now();
        if (data.cubic)
            data.bricks = buildMinMaxBricks(readBackCoefficients(data).data(), data.dims, options_.brickSize, 2);
        else
            data.bricks = buildMinMaxBricks(pyramid_.level(data.level), options_.brickSize, 1);
        st.brickGridSeconds = secondsSince(t);
        counts_.add(&PreprocessCounts::brickGrids);
    }
    return *data.bricks;
}

void OpenClRenderer::classify(DataSet &data, const Quality &quality, const TransferFunction &tf, RenderStats &st) {
    if (data.classification.update(bricks(data, st), tf, st)) {
        data.brickReach = cl::Buffer(); // the last classification's
        counts_.add(&PreprocessCounts::brickClassifications);
    }
    // The adaptive step's walk reads its steps instead.
    if (!quality.adaptiveStep && !data.brickReach())
        data.brickReach = upload(*cl_, data.classification.reachFor(*data.bricks, st), "the brick classification");
}

void OpenClRenderer::adaptSteps(DataSet &data, const TransferFunction &tf, const FrameSetup &setup, RenderStats &st) {
    const MinMaxBricks &grid = bricks(data, st);
    if (!data.gradients) {
        // The differences a reconstruction's derivative blends: neighbouring samples
        // (trilinear) or coefficients (cubic, read back once as for the min-max grid).
        const auto t = Clock::now();
        if (data.cubic) {
            const std::vector<float> coefficients = readBackCoefficients(data);
            data.gradients = buildBrickGradients(SampleGrid::ofFloats(data.dims, coefficients.data()),
                                                 options_.brickSize, kCubicBSplineBorder);
        } else {
            data.gradients = buildBrickGradients(pyramid_.level(data.level), options_.brickSize, kTrilinearBorder);
        }
        st.adaptiveStepSeconds = secondsSince(t);
    }
    if (data.adaptive.update(grid, *data.gradients, tf, tables_.tfTable(), setup,
                             setup.use.emptySpaceSkipping ? &data.classification.visible : nullptr, st))
        data.brickStep = upload(*cl_, data.adaptive.steps.step, "the adaptive step's bricks");
}

Image OpenClRenderer::render(const FrameRequest &request, RenderStats *stats) {
    const auto start = Clock::now();
    const FrameSetup setup = setUpFrame(*volume_, request, pyramid_.maxLevel(), options_.brickSize);
    std::lock_guard frameLock(mutex_);
    RenderStats st = setup.stats;
    Image cast = Image::unfilled(setup.cast.width, setup.cast.height); // the read-back fills it
    const Clock::time_point launched = castRays(request, setup, st, start, cast.rgba.data(), nullptr);
    Image image = setup.upsample ? resizeBilinear(cast, request.width, request.height) : std::move(cast);
    st.renderSeconds = secondsSince(launched);
    if (stats) *stats = st;
    return image;
}

Rgba8Image OpenClRenderer::renderRgba8(const FrameRequest &request, RenderStats *stats) {
    const auto start = Clock::now();
    const Rgba8Conversion where = options_.rgba8Conversion == Rgba8Conversion::Auto
                                      ? (cl_->isGpu() ? Rgba8Conversion::Device : Rgba8Conversion::Host)
                                      : options_.rgba8Conversion;
    if (where == Rgba8Conversion::Host) return FrameRenderer::renderRgba8(request, stats);
    const FrameSetup setup = setUpFrame(*volume_, request, pyramid_.maxLevel(), options_.brickSize);
    // image_scale < 1 on a whole frame: the bilinear upsampling is the host's, on floats
    // (resizeBilinear), so the conversion after it is too.
    if (setup.upsample) return FrameRenderer::renderRgba8(request, stats);
    std::lock_guard frameLock(mutex_);
    RenderStats st = setup.stats;
    Rgba8Image image;
    image.width = setup.cast.width;
    image.height = setup.cast.height;
    image.rgba.resize(size_t(image.width) * size_t(image.height) * 4); // unfilled: the read-back fills it
    const Clock::time_point launched = castRays(request, setup, st, start, nullptr, image.rgba.data());
    st.renderSeconds = secondsSince(launched);
    if (stats) *stats = st;
    return image;
}

namespace {

// Seconds the device spent on a completed command (the queue profiles: opencl_context.cpp).
double deviceSeconds(const cl::Event &e) {
    return 1e-9 * double(e.getProfilingInfo<CL_PROFILING_COMMAND_END>() - e.getProfilingInfo<CL_PROFILING_COMMAND_START>());
}

// A buffer of at least `bytes`, grown (never shrunk) so that frames of one size reuse it.
void ensureBuffer(OpenClContext &cl, cl::Buffer &buffer, size_t &capacity, size_t bytes, cl_mem_flags flags) {
    if (bytes <= capacity && buffer()) return;
    buffer = cl::Buffer(cl.context(), flags, bytes);
    capacity = bytes;
}

// Sets a memory argument unless the kernel holds that object there already. The kept
// references hold each object alive, so a handle cannot be freed and reused by another.
void setMemoryArg(cl::Kernel &kernel, std::vector<cl::Memory> &set, cl_uint index, const cl::Memory &memory) {
    if (set.size() <= index) set.resize(index + 1);
    if (set[index]() == memory()) return;
    kernel.setArg(index, memory);
    set[index] = memory;
}

} // namespace

OpenClRenderer::Clock::time_point OpenClRenderer::castRays(const FrameRequest &request, const FrameSetup &setup,
                                                           RenderStats &st, Clock::time_point start, float *floats,
                                                           uint8_t *bytes) {
    const Quality &quality = setup.quality;
    const TransferFunction &tf = request.transferFunction;
    DataSet &data = dataSet(quality.mipLevel, setup.use.cubic, st);
    st.buildOptions = buildOptions(quality, setup.clipPlaneCount > 0, data.width.bytes);
    // The program is looked up (its source is the key) only for a feature set this renderer
    // has no kernel of yet; after that the frame's kernel is one map lookup.
    FrameKernels &k = kernels_[st.buildOptions];
    if (!k.raycast()) {
        const auto built = cl_->program(kRaycastKernelSource, st.buildOptions);
        st.kernelBuildSeconds = built.buildSeconds;
        try {
            k.raycast = cl::Kernel(built.program, "raycast");
        } catch (const cl::Error &e) {
            throw OpenClError("the ray-casting kernel on " + cl_->deviceName() + ": " + describe(e));
        }
    }

    if (quality.emptySpaceSkipping) classify(data, quality, tf, st);

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
    if (quality.adaptiveStep) adaptSteps(data, tf, setup, st);

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

    // A window casts only its own rays (the launch offset places them on the full grid, the
    // kernel writes them into a buffer of the window's size), and the frame's commands queue
    // without a wait: the last read is the one blocking call.
    const RayWindow &win = setup.cast;
    const size_t rays = size_t(win.width) * size_t(win.height);
    Clock::time_point launched;
    auto &queue = cl_->queue();
    try {
        if (!counters_()) {
            // Running totals from here on: zeroed once, when made (see the read below).
            std::fill(std::begin(hostCounts_), std::end(hostCounts_), 0u);
            counters_ = cl::Buffer(cl_->context(), CL_MEM_READ_WRITE | CL_MEM_COPY_HOST_PTR, sizeof hostCounts_,
                                   hostCounts_);
        }
        if (bytes)
            ensureBuffer(*cl_, byteOut_, byteOutBytes_, rays * 4, CL_MEM_WRITE_ONLY);
        else
            ensureBuffer(*cl_, floatOut_, floatOutBytes_, rays * 4 * sizeof(float), CL_MEM_WRITE_ONLY);

        // Arguments in the order of the kernel's signature for this feature set.
        cl_uint arg = 0;
        if (setup.use.cubic && cubicFromImage()) setMemoryArg(k.raycast, k.raycastArgs, arg++, data.image);
        else setMemoryArg(k.raycast, k.raycastArgs, arg++, data.buffer);
        setMemoryArg(k.raycast, k.raycastArgs, arg++, tfTable_);
        if (quality.preintegrated) {
            setMemoryArg(k.raycast, k.raycastArgs, arg++, preRgba_);
            setMemoryArg(k.raycast, k.raycastArgs, arg++, preNodes_);
            setMemoryArg(k.raycast, k.raycastArgs, arg++, preLocator_);
        }
        // The adaptive step's walk reads the steps, which mark the skipped bricks too.
        if (quality.emptySpaceSkipping && !quality.adaptiveStep)
            setMemoryArg(k.raycast, k.raycastArgs, arg++, data.brickReach);
        if (quality.adaptiveStep) setMemoryArg(k.raycast, k.raycastArgs, arg++, data.brickStep);
        k.raycast.setArg(arg++, sizeof p, &p); // copied by the call: p need not outlive it
        const cl_int4 window{{win.x, win.y, win.width, win.height}};
        k.raycast.setArg(arg++, window);
        setMemoryArg(k.raycast, k.raycastArgs, arg++, bytes ? byteOut_ : floatOut_);
        k.raycast.setArg(arg++, cl_int(bytes ? 1 : 0));
        setMemoryArg(k.raycast, k.raycastArgs, arg++, counters_);

        // The kernel, the image's read and the counters' read, the last queued the one
        // blocking call (in order on the queue: once it ends, every command of the frame
        // has). Each command costs a GPU tens of microseconds of latency, as much as a small
        // frame's kernel: the parameters go with the launch (by value), the counters are
        // running totals (no fill), and the ray caster writes the bytes (no conversion kernel).
        const ReadBack how = readBack();
        const cl::Buffer &out = bytes ? byteOut_ : floatOut_;
        const size_t outBytes = bytes ? rays * 4 : rays * 4 * sizeof(float);
        void *const frame = bytes ? static_cast<void *>(bytes) : static_cast<void *>(floats);
        void *const landing = how == ReadBack::Pinned ? pinnedHost(outBytes) : frame;
        launched = Clock::now();
        st.hostSetUpSeconds = std::chrono::duration<double>(launched - start).count();
        cl_uint before[VC_STAT_COUNT];
        std::copy(std::begin(hostCounts_), std::end(hostCounts_), before);
        cl::Event kernel, readImage, readCounters;
        queue.enqueueNDRangeKernel(k.raycast, cl::NDRange(size_t(win.x), size_t(win.y)),
                                   cl::NDRange(roundUp(win.width), roundUp(win.height)),
                                   cl::NDRange(kGroupEdge, kGroupEdge), nullptr, &kernel);
        if (how == ReadBack::Direct) {
            queue.enqueueReadBuffer(out, CL_FALSE, 0, outBytes, landing, nullptr, &readImage);
            queue.enqueueReadBuffer(counters_, CL_TRUE, 0, sizeof hostCounts_, hostCounts_, nullptr, &readCounters);
        } else {
            queue.enqueueReadBuffer(counters_, CL_FALSE, 0, sizeof hostCounts_, hostCounts_, nullptr, &readCounters);
            queue.enqueueReadBuffer(out, CL_TRUE, 0, outBytes, landing, nullptr, &readImage);
        }
        readImage.wait();
        readCounters.wait();
        if (landing != frame) std::memcpy(frame, landing, outBytes);

        st.deviceKernelSeconds = deviceSeconds(kernel);
        st.deviceReadBackSeconds = deviceSeconds(readImage) + deviceSeconds(readCounters);
        // This frame's counts: the totals' growth, modulo 2^32 per word. A 64-bit count's high
        // word took the carries of its low word's wraps (raycast.cl), so the pair's growth
        // modulo 2^64 is the count.
        cl_uint counts[VC_STAT_COUNT];
        for (int i = 0; i < VC_STAT_COUNT; ++i) counts[i] = hostCounts_[i] - before[i];
        st.raysHit = counts[VC_STAT_RAYS_HIT];
        const double hit = std::max<double>(counts[VC_STAT_RAYS_HIT], 1);
        const auto wide = [&](int low, int high) {
            const uint64_t now = uint64_t(hostCounts_[high]) << 32 | hostCounts_[low];
            const uint64_t then = uint64_t(before[high]) << 32 | before[low];
            return double(now - then);
        };
        st.meanSamplesPerRay = wide(VC_STAT_SAMPLES, VC_STAT_SAMPLES_HIGH) / hit;
        st.skippedSegmentsPerRay = wide(VC_STAT_SEGMENTS_SKIPPED, VC_STAT_SEGMENTS_SKIPPED_HIGH) / hit;
        st.earlyTerminatedFraction = counts[VC_STAT_TERMINATED_EARLY] / hit;
        st.raysTruncated = counts[VC_STAT_TRUNCATED];
    } catch (const cl::Error &e) {
        // Commands queued before the failure may still write the caller's image: let them end
        // before it goes.
        try {
            queue.finish();
        } catch (const cl::Error &) {
        }
        counters_ = cl::Buffer(); // their totals are unknown now: the next frame makes them anew
        throw OpenClError("rendering on " + cl_->deviceName() + " failed: " + describe(e));
    }
    return launched;
}

} // namespace volcast
