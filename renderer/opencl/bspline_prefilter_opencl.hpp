#pragma once
// The cubic B-spline prefilter of bspline_prefilter.hpp on an OpenCL device
// (kernels/bspline_prefilter.cl), kept apart so that header stays free of OpenCL.

#include "renderer/model/math.hpp"
#include "renderer/opencl/opencl_context.hpp"

#include <vector>

namespace volcast {

// In place on a device buffer of dims.x·dims.y·dims.z floats, x fastest. Returns when done.
void bsplinePrefilterOpenCl(OpenClContext &cl, cl::Buffer &data, Vec3i dims);

// Copies `data` to the device, filters it there, and returns the coefficients.
std::vector<float> bsplinePrefilterOpenCl(OpenClContext &cl, const float *data, Vec3i dims);

} // namespace volcast
