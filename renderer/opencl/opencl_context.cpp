#include "renderer/opencl/opencl_context.hpp"

#include <algorithm>
#include <chrono>
#include <cerrno>
#include <cstdlib>
#include <cstring>
#include <fcntl.h>
#include <filesystem>
#include <unistd.h>
#include <vector>

namespace volcast {

std::string describe(const cl::Error &e) {
    return std::string(e.what()) + " failed with OpenCL error " + std::to_string(e.err());
}

namespace {

std::string lower(std::string s) {
    std::transform(s.begin(), s.end(), s.begin(), [](unsigned char c) { return char(std::tolower(c)); });
    return s;
}

std::string fromEnv(const std::string &given, const char *variable, const std::string &fallback) {
    if (!given.empty()) return given;
    const char *v = std::getenv(variable);
    return v && *v ? std::string(v) : fallback;
}

// The folder PoCL keeps compiled kernels in: POCL_CACHE_DIR, else its default under the
// XDG cache folder or the home folder. Empty if none can be named.
std::string poclCacheFolder() {
    if (const char *v = std::getenv("POCL_CACHE_DIR"); v && *v) return v;
    if (const char *v = std::getenv("XDG_CACHE_HOME"); v && *v) return std::string(v) + "/pocl/kcache";
    if (const char *v = std::getenv("HOME"); v && *v) return std::string(v) + "/.cache/pocl/kcache";
    return "";
}

// PoCL given a cache folder it cannot write to finds no device at all, and the user would be
// told "no OpenCL device found"; checking first names the folder and the problem.
void checkKernelCache(const std::string &folder) {
    const auto refuse = [&](const std::string &problem) {
        throw OpenClError("kernel cache folder " + folder + " " + problem +
                          " (choose a writable folder with --kernel-cache or VOLCAST_KERNEL_CACHE)");
    };
    namespace fs = std::filesystem;
    std::error_code ec;
    fs::create_directories(folder, ec);
    if (ec) refuse("cannot be created: " + ec.message());
    if (!fs::is_directory(folder, ec)) refuse("is not a folder");
    // Permission bits do not tell (root ignores them, a read-only mount overrides them): try.
    const std::string probe = folder + "/.volcast-write-test-" + std::to_string(::getpid());
    const int fd = ::open(probe.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0600);
    if (fd < 0) refuse(std::string("is not writable: ") + std::strerror(errno));
    const bool written = ::write(fd, "x", 1) == 1;
    const int writeErrno = errno;
    ::close(fd);
    ::unlink(probe.c_str());
    if (!written) refuse(std::string("is not writable: ") + std::strerror(writeErrno));
}

} // namespace

OpenClContext::OpenClContext(const DeviceOptions &options) {
    // PoCL reads its cache folder when the platform is first opened.
    const std::string cacheDir = fromEnv(options.kernelCacheDir, "VOLCAST_KERNEL_CACHE", "");
    if (!cacheDir.empty()) setenv("POCL_CACHE_DIR", cacheDir.c_str(), 1);
    if (const std::string folder = poclCacheFolder(); !folder.empty()) checkKernelCache(folder);
    const std::string wanted = lower(fromEnv(options.device, "VOLCAST_DEVICE", "auto"));
    extraBuildOptions_ = fromEnv(options.extraBuildOptions, "VOLCAST_OPENCL_OPTIONS", "");

    std::vector<cl::Device> all;
    std::string seen;
    try {
        std::vector<cl::Platform> platforms;
        cl::Platform::get(&platforms);
        for (auto &p : platforms) {
            std::vector<cl::Device> devices;
            try {
                p.getDevices(CL_DEVICE_TYPE_ALL, &devices);
            } catch (const cl::Error &) {
                continue; // a platform without devices
            }
            for (auto &d : devices) {
                all.push_back(d);
                seen += (seen.empty() ? "" : ", ") + d.getInfo<CL_DEVICE_NAME>();
            }
        }
    } catch (const cl::Error &e) {
        throw OpenClError("no OpenCL platform found (is an ICD such as pocl-opencl-icd installed?): " + describe(e));
    }
    if (all.empty()) throw OpenClError("no OpenCL device found (is pocl-opencl-icd installed?)");

    auto ofType = [&](cl_device_type type) {
        return std::find_if(all.begin(), all.end(),
                            [&](const cl::Device &d) { return (d.getInfo<CL_DEVICE_TYPE>() & type) != 0; });
    };
    auto chosen = all.end();
    if (wanted == "auto") {
        chosen = ofType(CL_DEVICE_TYPE_GPU);
        if (chosen == all.end()) chosen = ofType(CL_DEVICE_TYPE_CPU);
        if (chosen == all.end()) chosen = all.begin();
    } else if (wanted == "gpu") {
        chosen = ofType(CL_DEVICE_TYPE_GPU);
    } else if (wanted == "cpu") {
        chosen = ofType(CL_DEVICE_TYPE_CPU);
    } else {
        chosen = std::find_if(all.begin(), all.end(), [&](const cl::Device &d) {
            return lower(d.getInfo<CL_DEVICE_NAME>()).find(wanted) != std::string::npos;
        });
    }
    if (chosen == all.end())
        throw OpenClError("no OpenCL device matches '" + wanted + "' (devices: " + seen + ")");
    device_ = *chosen;
    try {
        context_ = cl::Context(device_);
        // Profiling on: every frame reports its upload, kernel, conversion and read-back
        // times from the events' timestamps (RenderStats). Its cost is a few timestamps per
        // command, which the drivers record anyway for their own tools.
        queue_ = cl::CommandQueue(context_, device_, CL_QUEUE_PROFILING_ENABLE);
    } catch (const cl::Error &e) {
        throw OpenClError("cannot open OpenCL device " + deviceName() + ": " + describe(e));
    }
}

std::string OpenClContext::deviceName() const {
    std::string name = device_.getInfo<CL_DEVICE_NAME>();
    while (!name.empty() && (name.back() == '\0' || name.back() == ' ')) name.pop_back();
    return name;
}

bool OpenClContext::isGpu() const { return (device_.getInfo<CL_DEVICE_TYPE>() & CL_DEVICE_TYPE_GPU) != 0; }

OpenClContext::BuiltProgram OpenClContext::program(const std::string &source, const std::string &options) {
    const std::pair<std::string, std::string> key{source, options};
    std::promise<cl::Program> promise;
    std::shared_future<cl::Program> other;
    {
        std::lock_guard lock(mutex_);
        if (auto it = programs_.find(key); it != programs_.end()) return {it->second, 0};
        if (auto it = building_.find(key); it != building_.end())
            other = it->second;
        else
            building_.emplace(key, promise.get_future().share());
    }
    if (other.valid()) return {other.get(), 0};   // rethrows that build's error
    const auto start = std::chrono::steady_clock::now();
    cl::Program program(context_, source);
    const std::string allOptions = extraBuildOptions_.empty() ? options : options + " " + extraBuildOptions_;
    try {
        try {
            program.build({device_}, allOptions.c_str());
        } catch (const cl::Error &) {
            std::string log;
            for (auto &[device, text] : program.getBuildInfo<CL_PROGRAM_BUILD_LOG>())
                log += "\n--- build log for " + device.getInfo<CL_DEVICE_NAME>() + " ---\n" + text;
            throw OpenClError("OpenCL program failed to build with options '" + allOptions + "':" + log);
        }
    } catch (...) {
        std::lock_guard lock(mutex_);
        building_.erase(key);
        promise.set_exception(std::current_exception());
        throw;
    }
    {
        std::lock_guard lock(mutex_);
        programs_.emplace(key, program);
        building_.erase(key);
        ++programsBuilt_;
    }
    promise.set_value(program);
    return {program, std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count()};
}

} // namespace volcast
