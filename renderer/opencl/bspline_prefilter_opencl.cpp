#include "renderer/opencl/bspline_prefilter_opencl.hpp"

#include "renderer/opencl/embedded_kernels.hpp"

#include <algorithm>

namespace volcast {

namespace {

// The program cache is keyed by options alone: this one must differ from the ray caster's.
constexpr const char *kPrefilterBuildOptions = "-DVOLCAST_PREFILTER";
// Samples filtered by one kernel launch: ~10-30 ms on the 2-core PoCL machine under load
// (whole axes of iguana_microct, 9.6 M samples each, held another session's frames for up to 1.5 s in
// tests/server/test_scheduling_scenarios.cpp).
constexpr size_t kSlabSamples = size_t(1) << 18;

} // namespace

void bsplinePrefilterOpenCl(OpenClContext &cl, cl::Buffer &data, Vec3i dims) {
    const auto nx = size_t(dims.x), ny = size_t(dims.y), nz = size_t(dims.z);
    if (nx == 0 || ny == 0 || nz == 0) return;
    try {
        // A kernel of our own: setArg on a shared one would race with another caller.
        cl::Kernel kernel(cl.program(kBSplinePrefilterKernelSource, kPrefilterBuildOptions).program,
                          "bspline_prefilter_axis");
        // Per axis: samples, their stride, and the line grid (countB × countA, strides B, A).
        struct Axis {
            size_t n, stride, countB, strideB, countA, strideA;
        };
        const Axis axes[3] = {
            {nx, 1, ny, nx, nz, nx * ny},
            {ny, nx, nx, 1, nz, nx * ny},
            {nz, nx * ny, nx, 1, ny, nx},
        };
        cl::CommandQueue &queue = cl.queue();
        for (const Axis &a : axes) {
            if (a.n < 2) continue; // a one-sample axis is its own coefficient
            kernel.setArg(0, data);
            kernel.setArg(1, cl_uint(a.n));
            kernel.setArg(2, cl_ulong(a.stride));
            kernel.setArg(3, cl_ulong(a.strideB));
            kernel.setArg(4, cl_ulong(a.strideA));
            // The in-order queue runs the axes one after another, as the separable filter needs.
            // In slabs of about kSlabSamples samples, each finished before the next is queued:
            // the queue is the renderer's too, and a frame queued on another thread then waits
            // for one slab (milliseconds), not for a whole axis of a large volume (seconds).
            const size_t slab = std::max<size_t>(1, kSlabSamples / std::max<size_t>(1, a.n * a.countB));
            for (size_t first = 0; first < a.countA; first += slab) {
                const size_t count = std::min(slab, a.countA - first);
                queue.enqueueNDRangeKernel(kernel, cl::NDRange(0, first), cl::NDRange(a.countB, count));
                queue.finish();
            }
        }
    } catch (const cl::Error &e) {
        throw OpenClError("B-spline prefilter: " + describe(e));
    }
}

std::vector<float> bsplinePrefilterOpenCl(OpenClContext &cl, const float *data, Vec3i dims) {
    const size_t count = size_t(dims.x) * size_t(dims.y) * size_t(dims.z);
    std::vector<float> out(data, data + count);
    if (count == 0) return out; // OpenCL has no zero-size buffers
    try {
        cl::Buffer buffer(cl.context(), CL_MEM_READ_WRITE, count * sizeof(float));
        cl.queue().enqueueWriteBuffer(buffer, CL_TRUE, 0, count * sizeof(float), out.data());
        bsplinePrefilterOpenCl(cl, buffer, dims);
        cl.queue().enqueueReadBuffer(buffer, CL_TRUE, 0, count * sizeof(float), out.data());
    } catch (const cl::Error &e) {
        throw OpenClError("B-spline prefilter: " + describe(e));
    }
    return out;
}

} // namespace volcast
