#include "renderer/make_frame_renderer.hpp"

#include "renderer/cpu/cpu_renderer.hpp"
#include "renderer/opencl/opencl_renderer.hpp"

#include <stdexcept>

namespace volcast {

DeviceChoice DeviceChoice::parse(std::string_view text) {
    DeviceChoice c;
    if (text == "auto" || text.empty()) c.kind = Kind::Auto;
    else if (text == "cpu") c.kind = Kind::Cpu;
    else if (text == "opencl") c.kind = Kind::OpenCl;
    else if (text.starts_with("opencl:") && text.size() > 7) {
        c.kind = Kind::OpenCl;
        c.openClDevice = std::string(text.substr(7));
    } else {
        throw std::invalid_argument("device '" + std::string(text) +
                                    "': expected cpu, opencl, opencl:<part of an OpenCL device's name>, or auto");
    }
    return c;
}

std::string DeviceChoice::text() const {
    switch (kind) {
    case Kind::Cpu: return "cpu";
    case Kind::OpenCl: return openClDevice.empty() ? "opencl" : "opencl:" + openClDevice;
    case Kind::Auto: break;
    }
    return "auto";
}

DeviceChoice resolveDeviceChoice(const DeviceChoice &choice) {
    if (choice.kind != DeviceChoice::Kind::Auto) return choice;
    // No OpenCL, or no GPU among its devices: the native path is faster than PoCL.
    DeviceChoice resolved;
    if (openClGpuPresent()) {
        resolved.kind = DeviceChoice::Kind::OpenCl;
        resolved.openClDevice = "gpu";
    } else {
        resolved.kind = DeviceChoice::Kind::Cpu;
    }
    return resolved;
}

std::shared_ptr<OpenClContext> openContextFor(const DeviceChoice &choice, const std::string &kernelCacheDir) {
    // With a GPU, a failure to open it (its kernel cache, say) is an error, not a silent
    // fall-back to the native path.
    const DeviceChoice resolved = resolveDeviceChoice(choice);
    if (resolved.kind == DeviceChoice::Kind::Cpu) return nullptr;
    // Plain "opencl" is OpenCL's own choice, not $VOLCAST_DEVICE: the server reads that
    // variable as its --device, so it holds "opencl" itself there.
    return std::make_shared<OpenClContext>(
        DeviceOptions{resolved.openClDevice.empty() ? "auto" : resolved.openClDevice, kernelCacheDir, ""});
}

bool openClGpuPresent() {
    try {
        std::vector<cl::Platform> platforms;
        cl::Platform::get(&platforms);
        for (auto &p : platforms) {
            std::vector<cl::Device> devices;
            try {
                p.getDevices(CL_DEVICE_TYPE_GPU, &devices);
            } catch (const cl::Error &) {
                continue; // CL_DEVICE_NOT_FOUND: a platform without GPUs
            }
            if (!devices.empty()) return true;
        }
    } catch (const cl::Error &) {
        // no platform at all (no ICD installed)
    }
    return false;
}

std::string backEndDescription(const std::shared_ptr<OpenClContext> &cl) {
    return cl ? "opencl: " + cl->deviceName() : CpuRenderer::describe();
}

std::unique_ptr<FrameRenderer> makeFrameRenderer(std::shared_ptr<OpenClContext> cl,
                                                 std::shared_ptr<const Volume> volume) {
    if (!cl) return std::make_unique<CpuRenderer>(std::move(volume));
    return std::make_unique<OpenClRenderer>(std::move(cl), std::move(volume));
}

std::unique_ptr<FrameRenderer> makeFrameRenderer(const DeviceChoice &choice, std::shared_ptr<const Volume> volume,
                                                 const std::string &kernelCacheDir) {
    return makeFrameRenderer(openContextFor(choice, kernelCacheDir), std::move(volume));
}

} // namespace volcast
