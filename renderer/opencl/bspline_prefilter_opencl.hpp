#pragma once
// The cubic B-spline prefilter of bspline_prefilter.hpp on an OpenCL device
// (kernels/bspline_prefilter.cl), kept apart so that header stays free of OpenCL; and the
// renderer's coefficients made on the device from the samples, with no host round trip.

#include "renderer/common/narrow_samples.hpp"
#include "renderer/model/math.hpp"
#include "renderer/opencl/opencl_context.hpp"

#include <cstddef>
#include <vector>

namespace volcast {

// How the x lines (contiguous in memory) are filtered. Tiled: a work-group moves 32 lines
// through local memory 32 samples at a time, so its reads and writes are whole runs of
// neighbouring floats (what a GPU's memory wants). Lines: one work-item per line, reading
// its own contiguous line (what a CPU's caches want). Auto: Tiled on a GPU, Lines elsewhere
// (the measurements behind that choice are in docs/gpu.md).
enum class PrefilterXPass { Auto, Tiled, Lines };

// How the passes are cut into launches. The queue is the renderer's too: a frame queued on
// another thread waits for the launches already queued, so they are queued a slab at a time
// and the prefilter waits for each slab before queuing the next. A slab starts at
// firstSlabSamples and doubles while one takes under half of slabTargetSeconds (halves, down
// to the first size, while one takes over twice that), so a GPU does whole axes in a few
// launches and a slow device keeps slabs of milliseconds. Slabs hold whole lines (whole
// groups of 32 for the tiled x pass); an axis's last slab is topped up by the next axis's first.
struct PrefilterLaunch {
    // ~10 ms on the 2-core PoCL machine: whole axes of iguana_microct (9.6 M samples each)
    // held another renderer's frames for up to 1.5 s (tests/server/test_scheduling_scenarios.cpp).
    size_t firstSlabSamples = size_t(1) << 18;
    double slabTargetSeconds = 0.008; // a queued frame's wait behind the prefilter, at most ~one slab
    PrefilterXPass xPass = PrefilterXPass::Auto;
};

// What one prefilter did: kernel launches, waits for a slab (queue.finish), the largest slab.
struct PrefilterLaunchCounts {
    int launches = 0;
    int waits = 0;
    size_t largestSlabSamples = 0;
};

// In place on a device buffer of dims.x·dims.y·dims.z floats, x fastest. Returns when done.
PrefilterLaunchCounts bsplinePrefilterOpenCl(OpenClContext &cl, cl::Buffer &data, Vec3i dims,
                                             const PrefilterLaunch &launch = {});

// Copies `data` to the device, filters it there, and returns the coefficients.
std::vector<float> bsplinePrefilterOpenCl(OpenClContext &cl, const float *data, Vec3i dims,
                                          const PrefilterLaunch &launch = {});

// The renderer's coefficients, made on the device: the samples uploaded once as they are held
// (narrow ones widened there), filtered in place, and padded with the mirror boundary by one
// before and two after on each axis: (dims + 3)³ floats, x fastest, the layout padMirror gives.
// Nothing comes back to the host. Returns when the buffer is ready.
cl::Buffer bsplinePaddedCoefficientsOpenCl(OpenClContext &cl, const SampleGrid &samples,
                                           const PrefilterLaunch &launch = {});

// The pad of bsplinePaddedCoefficientsOpenCl on a device buffer of dims³ coefficients.
cl::Buffer padMirrorOpenCl(OpenClContext &cl, const cl::Buffer &coefficients, Vec3i dims);

} // namespace volcast
