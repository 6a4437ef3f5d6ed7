#pragma once
// The fast path: ray casting in OpenCL with the paper's remedies as switches. Each scene
// builds (or reuses) a program with only the features it uses.

#include "renderer/image.hpp"
#include "renderer/opencl_context.hpp"
#include "renderer/scene.hpp"
#include "renderer/volume.hpp"

#include <string>

namespace volcast {

struct RenderStats {
    std::string buildOptions;       // the feature set the program was built with
    double kernelBuildSeconds = 0;  // 0 when the program was already built
    double tfTableSeconds = 0;
    int tfTableEntries = 0;
    double tfTableError = 0;
    double renderSeconds = 0;       // kernel and read-back
    double meanSamplesPerRay = 0;   // over rays that hit the volume
    double earlyTerminatedFraction = 0;
    uint64_t raysTruncated = 0;     // rays that hit the per-ray sample bound
};

class OpenClRenderer {
  public:
    // Uploads the volume; it is not kept on the host side.
    OpenClRenderer(OpenClContext &cl, const Volume &volume);

    Image render(const TransferFunction &tf, const Camera &camera, int width, int height, const Quality &quality,
                 const std::vector<ClipPlane> &clipPlanes, RenderStats *stats = nullptr);

    // The -D options a scene's program is built with: only the features it uses.
    static std::string buildOptions(const Quality &quality, bool hasClipPlanes);
    // Samples a ray may take at most; rays past it stop and are counted.
    static constexpr int kMaxSamplesPerRay = 1 << 20;

  private:
    OpenClContext &cl_;
    Vec3i dims_;
    Vec3d spacing_, origin_;
    Mat3d direction_;
    cl::Buffer volume_;
};

} // namespace volcast
