#include "renderer/opencl_context.hpp"

#include <algorithm>
#include <chrono>
#include <cstdlib>
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

} // namespace

OpenClContext::OpenClContext(const DeviceOptions &options) {
    // PoCL reads its cache folder when the platform is first opened.
    const std::string cacheDir = fromEnv(options.kernelCacheDir, "VOLCAST_KERNEL_CACHE", "");
    if (!cacheDir.empty()) setenv("POCL_CACHE_DIR", cacheDir.c_str(), 1);
    const std::string wanted = lower(fromEnv(options.device, "VOLCAST_DEVICE", "auto"));

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
        queue_ = cl::CommandQueue(context_, device_);
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
    std::lock_guard lock(mutex_);
    if (auto it = programs_.find(options); it != programs_.end()) return {it->second, 0};
    const auto start = std::chrono::steady_clock::now();
    cl::Program program(context_, source);
    try {
        program.build({device_}, options.c_str());
    } catch (const cl::Error &) {
        std::string log;
        for (auto &[device, text] : program.getBuildInfo<CL_PROGRAM_BUILD_LOG>())
            log += "\n--- build log for " + device.getInfo<CL_DEVICE_NAME>() + " ---\n" + text;
        throw OpenClError("OpenCL program failed to build with options '" + options + "':" + log);
    }
    programs_.emplace(options, program);
    ++programsBuilt_;
    return {program, std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count()};
}

} // namespace volcast
