#pragma once
// Picks the back end that draws a volume's frames from a --device value:
//   cpu                 the native CPU ray caster (renderer/cpu/)
//   opencl              OpenCL's own choice of device: a GPU if there is one, else a CPU device
//   opencl:<name part>  the OpenCL device whose name contains it (or gpu, cpu)
//   auto                a GPU through OpenCL if there is one, else the native CPU ray caster
// PoCL is an OpenCL *CPU* device: auto never picks it, opencl:cpu or opencl:pthread do.

#include "renderer/common/frame_renderer.hpp"

#include <memory>
#include <string>
#include <string_view>

namespace volcast {

class OpenClContext;

struct DeviceChoice {
    enum class Kind { Auto, Cpu, OpenCl };
    Kind kind = Kind::Auto;
    std::string openClDevice; // OpenCl: the name part after "opencl:" ("" for plain "opencl")

    // Throws std::invalid_argument naming the value and the accepted forms.
    static DeviceChoice parse(std::string_view text);
    std::string text() const;
};

// What a choice stands for on this machine: auto becomes opencl:gpu where some OpenCL
// platform offers a GPU, else cpu; the other choices are themselves.
DeviceChoice resolveDeviceChoice(const DeviceChoice &choice);

// Opens the OpenCL context a choice needs: nullptr for cpu, and for auto when no OpenCL GPU
// exists. Throws OpenClError when an explicit opencl choice finds no such device, and when
// the chosen device's kernel cache folder is unusable (only then is the cache checked).
std::shared_ptr<OpenClContext> openContextFor(const DeviceChoice &choice, const std::string &kernelCacheDir = {});

// Whether some OpenCL platform offers a GPU (false without OpenCL at all).
bool openClGpuPresent();

// What description() of a renderer made by makeFrameRenderer(cl, …) says: "opencl: <device>"
// or the native path's "cpu: <instruction set>, …".
std::string backEndDescription(const std::shared_ptr<OpenClContext> &cl);

// A renderer for `volume` on `cl` (OpenCL) or, with cl null, on the native CPU path. The
// renderer keeps `cl` alive.
std::unique_ptr<FrameRenderer> makeFrameRenderer(std::shared_ptr<OpenClContext> cl,
                                                 std::shared_ptr<const Volume> volume);

// Both steps at once, for tools that render one volume.
std::unique_ptr<FrameRenderer> makeFrameRenderer(const DeviceChoice &choice, std::shared_ptr<const Volume> volume,
                                                 const std::string &kernelCacheDir = {});

} // namespace volcast
