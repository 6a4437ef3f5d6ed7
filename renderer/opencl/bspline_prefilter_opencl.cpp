#include "renderer/opencl/bspline_prefilter_opencl.hpp"

#include "renderer/opencl/embedded_kernels.hpp"

#include <algorithm>
#include <chrono>
#include <functional>

namespace volcast {

namespace {

using Clock = std::chrono::steady_clock;

// The program cache is keyed by source and options; the option names the program in logs.
constexpr const char *kPrefilterBuildOptions = "-DVOLCAST_PREFILTER";
// The kernel's TILE_LINES: the tiled x pass's work-group.
constexpr size_t kTileLines = 32;
// Work-group of the other kernels: one fixed size, so PoCL compiles one launch configuration
// per kernel (a new size costs it 0.25–2 s, docs/platform.md); 32 neighbouring work-items
// read 128 neighbouring bytes on a GPU. Ranges are rounded up to it; the kernels skip the rest.
constexpr size_t kGroup = 32;
size_t roundUp(size_t n, size_t to) { return (n + to - 1) / to * to; }

// Elements of a row one work-item of the copy kernels (widen, pad) moves: 1 on a GPU, so
// neighbouring work-items move neighbouring floats; on a CPU a run of contiguous memory per
// work-item (kernels/bspline_prefilter.cl), ≤ 4096 so that a z slice still spreads over the cores.
size_t copyRun(OpenClContext &cl, size_t row) { return cl.isGpu() ? 1 : std::clamp<size_t>(row, 1, 4096); }

cl::Kernel kernel(OpenClContext &cl, const char *name) {
    // A kernel of our own: setArg on a shared one would race with another caller.
    return cl::Kernel(cl.program(kBSplinePrefilterKernelSource, kPrefilterBuildOptions).program, name);
}

// Queues slabs and waits for each (PrefilterLaunch): the budget of samples queued before a
// wait grows while a slab's measured time stays well under the target.
class SlabQueue {
  public:
    SlabQueue(cl::CommandQueue &queue, const PrefilterLaunch &launch)
        : queue_(queue), launch_(launch), budget_(std::max<size_t>(1, launch.firstSlabSamples)) {}

    // Queues `units` units of `unitSamples` samples each, as enqueue(first, count) calls of
    // whole units, waiting whenever a slab's budget is queued.
    void run(size_t units, size_t unitSamples, const std::function<void(size_t first, size_t count)> &enqueue) {
        unitSamples = std::max<size_t>(1, unitSamples);
        for (size_t first = 0; first < units;) {
            const size_t room = budget_ > pending_ ? budget_ - pending_ : 0;
            const size_t count = std::min(units - first, std::max<size_t>(1, room / unitSamples));
            if (pending_ == 0) since_ = Clock::now();
            enqueue(first, count);
            ++counts_.launches;
            pending_ += count * unitSamples;
            first += count;
            if (pending_ >= budget_) wait();
        }
    }

    // Waits for what is queued and sizes the next slab by how long this one took.
    void wait() {
        if (pending_ == 0) return;
        queue_.finish();
        ++counts_.waits;
        counts_.largestSlabSamples = std::max(counts_.largestSlabSamples, pending_);
        const double seconds = std::chrono::duration<double>(Clock::now() - since_).count();
        // Only a full slab says how long the budget takes (the last one may be short).
        if (pending_ >= budget_) {
            if (seconds < launch_.slabTargetSeconds / 2 && budget_ <= SIZE_MAX / 2) budget_ *= 2;
            else if (seconds > launch_.slabTargetSeconds * 2)
                budget_ = std::max(std::max<size_t>(1, launch_.firstSlabSamples), budget_ / 2);
        }
        pending_ = 0;
    }

    const PrefilterLaunchCounts &counts() const { return counts_; }

  private:
    cl::CommandQueue &queue_;
    PrefilterLaunch launch_;
    size_t budget_;
    size_t pending_ = 0;
    Clock::time_point since_;
    PrefilterLaunchCounts counts_;
};

void checkDims(Vec3i dims) {
    if (dims.x < 0 || dims.y < 0 || dims.z < 0) throw std::invalid_argument("B-spline prefilter: negative dimensions");
}

// The three passes on `data`, queued through `slabs` (the caller waits for the last).
void prefilterPasses(OpenClContext &cl, cl::Buffer &data, Vec3i dims, PrefilterXPass xPass, SlabQueue &slabs) {
    const auto nx = size_t(dims.x), ny = size_t(dims.y), nz = size_t(dims.z);
    if (nx == 0 || ny == 0 || nz == 0) return;
    cl::Kernel axis = kernel(cl, "bspline_prefilter_axis");
    cl::CommandQueue &queue = cl.queue();
    // The in-order queue runs the axes one after another, as the separable filter needs.
    // One line per work-item (b, a) of the range (countB, countA): line start b·strideB + a·strideA.
    const auto lines = [&](size_t n, size_t stride, size_t countB, size_t strideB, size_t countA, size_t strideA) {
        if (n < 2) return; // a one-sample axis is its own coefficient
        axis.setArg(0, data);
        axis.setArg(1, cl_uint(n));
        axis.setArg(2, cl_ulong(stride));
        axis.setArg(3, cl_ulong(countB));
        axis.setArg(4, cl_ulong(strideB));
        axis.setArg(5, cl_ulong(strideA));
        // Units of the slabs: countB lines at one a.
        slabs.run(countA, n * countB, [&](size_t first, size_t count) {
            queue.enqueueNDRangeKernel(axis, cl::NDRange(0, first), cl::NDRange(roundUp(countB, kGroup), count),
                                       cl::NDRange(kGroup, 1));
        });
    };

    // x: contiguous lines. On a GPU through local-memory tiles: neighbouring work-items then
    // read neighbouring floats, where one work-item per line would put them nx floats apart (a
    // transaction per work-item and step). Tiles rather than transposing x and y into a second
    // buffer and back: that costs two more read+write passes and a second volume of device
    // memory. On a CPU one work-item per line reads its own line from cache.
    const bool tiled = xPass == PrefilterXPass::Tiled || (xPass == PrefilterXPass::Auto && cl.isGpu());
    if (nx >= 2 && tiled) {
        cl::Kernel rows = kernel(cl, "bspline_prefilter_rows");
        const size_t rowCount = ny * nz;
        rows.setArg(0, data);
        rows.setArg(1, cl_uint(nx));
        rows.setArg(2, cl_ulong(rowCount));
        slabs.run((rowCount + kTileLines - 1) / kTileLines, kTileLines * nx, [&](size_t first, size_t count) {
            rows.setArg(3, cl_ulong(first * kTileLines));
            queue.enqueueNDRangeKernel(rows, cl::NullRange, cl::NDRange(count * kTileLines), cl::NDRange(kTileLines));
        });
    } else {
        lines(nx, 1, ny, nx, nz, nx * ny);
    }
    // y and z: work-item b filters x column b, so neighbouring work-items read neighbouring floats.
    lines(ny, nx, nx, 1, nz, nx * ny);
    lines(nz, nx * ny, nx, 1, ny, nx);
}

// The mirror pad of `coefficients` into a new buffer, in slabs of z slices.
cl::Buffer padPasses(OpenClContext &cl, const cl::Buffer &coefficients, Vec3i dims, SlabQueue &slabs) {
    const size_t px = size_t(dims.x) + 3, py = size_t(dims.y) + 3, pz = size_t(dims.z) + 3;
    // Read and written by kernels (this one writes, the ray caster reads).
    cl::Buffer padded(cl.context(), CL_MEM_READ_WRITE, px * py * pz * sizeof(float));
    cl::Kernel pad = kernel(cl, "bspline_pad_mirror");
    pad.setArg(0, coefficients);
    pad.setArg(1, padded);
    pad.setArg(2, cl_int(dims.x));
    pad.setArg(3, cl_int(dims.y));
    pad.setArg(4, cl_int(dims.z));
    const size_t run = copyRun(cl, px);
    pad.setArg(7, cl_int(run));
    slabs.run(pz, px * py, [&](size_t first, size_t count) {
        pad.setArg(5, cl_int(first));
        pad.setArg(6, cl_int(count));
        cl.queue().enqueueNDRangeKernel(pad, cl::NullRange, cl::NDRange(roundUp((px + run - 1) / run, kGroup), py),
                                        cl::NDRange(kGroup, 1));
    });
    return padded;
}

} // namespace

PrefilterLaunchCounts bsplinePrefilterOpenCl(OpenClContext &cl, cl::Buffer &data, Vec3i dims,
                                             const PrefilterLaunch &launch) {
    checkDims(dims);
    try {
        SlabQueue slabs(cl.queue(), launch);
        prefilterPasses(cl, data, dims, launch.xPass, slabs);
        slabs.wait();
        return slabs.counts();
    } catch (const cl::Error &e) {
        throw OpenClError("B-spline prefilter: " + describe(e));
    }
}

std::vector<float> bsplinePrefilterOpenCl(OpenClContext &cl, const float *data, Vec3i dims,
                                          const PrefilterLaunch &launch) {
    checkDims(dims);
    const size_t count = size_t(dims.x) * size_t(dims.y) * size_t(dims.z);
    std::vector<float> out(data, data + count);
    if (count == 0) return out; // OpenCL has no zero-size buffers
    try {
        cl::Buffer buffer(cl.context(), CL_MEM_READ_WRITE, count * sizeof(float));
        cl.queue().enqueueWriteBuffer(buffer, CL_TRUE, 0, count * sizeof(float), out.data());
        bsplinePrefilterOpenCl(cl, buffer, dims, launch);
        cl.queue().enqueueReadBuffer(buffer, CL_TRUE, 0, count * sizeof(float), out.data());
    } catch (const cl::Error &e) {
        throw OpenClError("B-spline prefilter: " + describe(e));
    }
    return out;
}

cl::Buffer padMirrorOpenCl(OpenClContext &cl, const cl::Buffer &coefficients, Vec3i dims) {
    checkDims(dims);
    try {
        SlabQueue slabs(cl.queue(), {});
        cl::Buffer padded = padPasses(cl, coefficients, dims, slabs);
        slabs.wait();
        return padded;
    } catch (const cl::Error &e) {
        throw OpenClError("B-spline coefficients' mirror pad: " + describe(e));
    }
}

cl::Buffer bsplinePaddedCoefficientsOpenCl(OpenClContext &cl, const SampleGrid &samples,
                                           const PrefilterLaunch &launch) {
    checkDims(samples.dims);
    const size_t count = samples.count();
    if (count == 0) throw std::invalid_argument("B-spline coefficients of an empty volume");
    try {
        // One slab budget for the widening, the passes and the pad: all share the queue.
        SlabQueue slabs(cl.queue(), launch);
        cl::Buffer coefficients;
        if (!samples.isNarrow()) {
            coefficients = cl::Buffer(cl.context(), CL_MEM_READ_WRITE | CL_MEM_COPY_HOST_PTR, count * sizeof(float),
                                      const_cast<float *>(samples.floats));
        } else {
            // Up as held (a quarter or half of the floats' bytes), widened on the device, z slices as units.
            const size_t slice = size_t(samples.dims.x) * size_t(samples.dims.y);
            cl::Buffer narrow(cl.context(), CL_MEM_READ_ONLY | CL_MEM_COPY_HOST_PTR, count * size_t(samples.width.bytes),
                              const_cast<unsigned char *>(samples.narrow));
            coefficients = cl::Buffer(cl.context(), CL_MEM_READ_WRITE, count * sizeof(float));
            cl::Kernel widen = kernel(cl, samples.width.bytes == 1 ? "bspline_widen_uchar" : "bspline_widen_ushort");
            widen.setArg(0, narrow);
            widen.setArg(1, coefficients);
            widen.setArg(2, cl_ulong(slice));
            widen.setArg(3, samples.width.offset);
            const size_t run = copyRun(cl, slice);
            widen.setArg(6, cl_uint(run));
            slabs.run(size_t(samples.dims.z), slice, [&](size_t first, size_t n) {
                widen.setArg(4, cl_uint(first));
                widen.setArg(5, cl_uint(n));
                cl.queue().enqueueNDRangeKernel(widen, cl::NullRange, cl::NDRange(roundUp((slice + run - 1) / run, kGroup)),
                                                cl::NDRange(kGroup));
            });
        }
        prefilterPasses(cl, coefficients, samples.dims, launch.xPass, slabs);
        cl::Buffer padded = padPasses(cl, coefficients, samples.dims, slabs);
        slabs.wait();
        return padded;
    } catch (const cl::Error &e) {
        throw OpenClError("B-spline coefficients on " + cl.deviceName() + ": " + describe(e));
    }
}

} // namespace volcast
