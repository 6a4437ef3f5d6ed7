#pragma once
// The OpenCL device volcast renders on, and the programs built for it. Programs are built
// per kernel source and feature set (a string of -D options) and cached for the life of the
// process; PoCL's own on-disk cache makes a restart cheap (its folder is set by
// kernelCacheDir).

#ifndef CL_HPP_TARGET_OPENCL_VERSION
#define CL_HPP_TARGET_OPENCL_VERSION 120
#define CL_HPP_MINIMUM_OPENCL_VERSION 120
#endif
#define CL_HPP_ENABLE_EXCEPTIONS
#include <CL/opencl.hpp>

#include <future>
#include <map>
#include <mutex>
#include <stdexcept>
#include <string>
#include <utility>

namespace volcast {

struct OpenClError : std::runtime_error {
    using std::runtime_error::runtime_error;
};

struct DeviceOptions {
    // "auto" (a GPU if there is one, else a CPU device), "gpu", "cpu", or a part of the
    // device's name. Empty: the VOLCAST_DEVICE environment variable, else "auto".
    std::string device;
    // Folder for PoCL's compiled-kernel cache. Empty: VOLCAST_KERNEL_CACHE, else PoCL's default
    // (POCL_CACHE_DIR, else ~/.cache/pocl/kcache). The folder is created if missing and must
    // be writable: the constructor checks, and its OpenClError names the folder.
    std::string kernelCacheDir;
    // Build options added to every program, for telling which of the liberties OpenCL C gives a
    // device (contraction, division to 2.5 ulp, denormal flushing) a case depends on, e.g.
    // "-cl-fp32-correctly-rounded-divide-sqrt" (docs/gpu.md). Empty: VOLCAST_OPENCL_OPTIONS.
    std::string extraBuildOptions;
};

class OpenClContext {
  public:
    explicit OpenClContext(const DeviceOptions &options = {});

    const cl::Context &context() const { return context_; }
    const cl::Device &device() const { return device_; }
    cl::CommandQueue &queue() { return queue_; }
    std::string deviceName() const;
    bool isGpu() const;

    struct BuiltProgram {
        cl::Program program;
        double buildSeconds = 0; // 0 when it came from this process's cache
    };
    // Build `source` with `options` (e.g. "-DCUBIC=1"), or return the program cached for both.
    // A failure becomes an OpenClError carrying every device's build log. A build (a second
    // or more on PoCL) holds up only callers that want the same program: a render on another
    // thread that finds its program cached is not made to wait for it.
    BuiltProgram program(const std::string &source, const std::string &options);
    size_t programsBuilt() const { return programsBuilt_; }
    const std::string &extraBuildOptions() const { return extraBuildOptions_; }

  private:
    cl::Context context_;
    cl::Device device_;
    cl::CommandQueue queue_;
    std::string extraBuildOptions_;
    std::mutex mutex_;
    // Keyed on (source, options): two kernels' sources may share an option string.
    std::map<std::pair<std::string, std::string>, cl::Program> programs_;
    // Builds under way, outside mutex_: a second caller for the same key waits for the first.
    std::map<std::pair<std::string, std::string>, std::shared_future<cl::Program>> building_;
    size_t programsBuilt_ = 0;
};

// Turn a cl::Error into a message naming the call and the error code.
std::string describe(const cl::Error &e);

} // namespace volcast
