#pragma once
// Kernel sources compiled into the library from renderer/opencl/kernels/*.cl at build time.

namespace volcast {
extern const char *const kRaycastKernelSource;
extern const char *const kBSplinePrefilterKernelSource;
}
