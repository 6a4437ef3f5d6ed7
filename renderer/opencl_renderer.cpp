#include "renderer/opencl_renderer.hpp"

#include "renderer/camera.hpp"
#include "renderer/embedded_kernels.hpp"
#include "renderer/kernels/raycast_shared.h"
#include "renderer/tf_table.hpp"

#include <chrono>
#include <cmath>

namespace volcast {

static_assert(sizeof(RayCastParams) == 288, "RayCastParams must match the kernel's layout");

namespace {

using Clock = std::chrono::steady_clock;
double secondsSince(Clock::time_point t) { return std::chrono::duration<double>(Clock::now() - t).count(); }

cl_float4 f4(const Vec3d &v, double w = 0) { return {{float(v.x), float(v.y), float(v.z), float(w)}}; }

} // namespace

OpenClRenderer::OpenClRenderer(OpenClContext &cl, const Volume &volume)
    : cl_(cl), dims_(volume.dims), spacing_(volume.spacing), origin_(volume.origin), direction_(volume.direction) {
    try {
        volume_ = cl::Buffer(cl_.context(), CL_MEM_READ_ONLY | CL_MEM_COPY_HOST_PTR,
                             volume.voxels.size() * sizeof(float), const_cast<float *>(volume.voxels.data()));
    } catch (const cl::Error &e) {
        throw OpenClError("cannot upload volume " + volume.name + " to " + cl_.deviceName() + ": " + describe(e));
    }
}

std::string OpenClRenderer::buildOptions(const Quality &q, bool hasClipPlanes) {
    // No -cl-fast-relaxed-math: it would break the opacity correction's exactness for tiny
    // steps and opacities (expm1/log1p), which the stability cases rely on.
    std::string o;
    if (q.jitter) o += " -DJITTER";
    if (q.boundarySegment) o += " -DBOUNDARY_SEGMENT";
    if (q.earlyTermination < 1) o += " -DEARLY_TERMINATION";
    if (hasClipPlanes) o += " -DCLIP_PLANES";
    return o.empty() ? o : o.substr(1);
}

Image OpenClRenderer::render(const TransferFunction &tf, const Camera &camera, int width, int height,
                             const Quality &quality, const std::vector<ClipPlane> &clipPlanes, RenderStats *stats) {
    camera.validate();
    tf.validate();
    if (clipPlanes.size() > VC_MAX_CLIP_PLANES)
        throw std::invalid_argument("clip_planes: at most " + std::to_string(VC_MAX_CLIP_PLANES) + " are supported");
    RenderStats st;
    st.buildOptions = buildOptions(quality, !clipPlanes.empty());
    const auto built = cl_.program(kRaycastKernelSource, st.buildOptions);
    st.kernelBuildSeconds = built.buildSeconds;

    auto t = Clock::now();
    const TfTable table = buildTfTable(tf);
    st.tfTableSeconds = secondsSince(t);
    st.tfTableEntries = table.entries();
    st.tfTableError = table.maxError;

    // Camera frame exactly as RayGenerator builds it, so both renderers cast the same rays.
    const RayGenerator rays(camera, width, height);

    RayCastParams p{};
    p.eye = f4(camera.eye);
    p.forward = f4(rays.forward);
    p.right = f4(rays.right * rays.halfWidth());
    p.up = f4(rays.up * rays.halfHeight());
    // indexFromWorld(x) = Dᵀ(x − origin) / s, written as rows (linear part, translation).
    const Mat3d dt = direction_.transposed();
    for (int r = 0; r < 3; ++r) {
        const Vec3d row{dt(r, 0) / spacing_[r], dt(r, 1) / spacing_[r], dt(r, 2) / spacing_[r]};
        p.indexFromWorld[r] = f4(row, -dot(row, origin_));
    }
    for (size_t c = 0; c < clipPlanes.size(); ++c) {
        const Vec3d nrm = clipPlanes[c].normal;
        if (!(length(nrm) > 0)) throw std::invalid_argument("clip_planes[" + std::to_string(c) + "].normal: zero length");
        p.clipPlanes[c] = f4(nrm, -dot(nrm, clipPlanes[c].point));
    }
    p.clipPlaneCount = int(clipPlanes.size());
    p.dims[0] = int(dims_.x);
    p.dims[1] = int(dims_.y);
    p.dims[2] = int(dims_.z);
    p.tfMin = float(table.minValue);
    p.tfScale = float(table.scale);
    p.tfEntries = table.entries();
    p.width = width;
    p.height = height;
    p.orthographic = camera.projection == Projection::Orthographic;
    p.maxSamples = kMaxSamplesPerRay;
    const double smallest = minComponent(spacing_);
    p.step = float(quality.step * smallest);
    p.opacityUnit = float(tf.opacityUnit ? *tf.opacityUnit : smallest);
    p.terminationTransmittance = float(1 - quality.earlyTermination);
    p.seed = uint32_t(quality.seed ^ (quality.seed >> 32));

    t = Clock::now();
    Image image(width, height);
    try {
        auto &queue = cl_.queue();
        cl::Buffer tfBuffer(cl_.context(), CL_MEM_READ_ONLY | CL_MEM_COPY_HOST_PTR, table.rgba.size() * sizeof(float),
                            const_cast<float *>(table.rgba.data()));
        cl::Buffer params(cl_.context(), CL_MEM_READ_ONLY | CL_MEM_COPY_HOST_PTR, sizeof p, &p);
        cl::Buffer out(cl_.context(), CL_MEM_WRITE_ONLY, image.rgba.size() * sizeof(float));
        cl_uint zeros[VC_STAT_COUNT] = {};
        cl::Buffer counters(cl_.context(), CL_MEM_READ_WRITE | CL_MEM_COPY_HOST_PTR, sizeof zeros, zeros);
        cl::Kernel kernel(built.program, "raycast");
        kernel.setArg(0, volume_);
        kernel.setArg(1, tfBuffer);
        kernel.setArg(2, params);
        kernel.setArg(3, out);
        kernel.setArg(4, counters);
        queue.enqueueNDRangeKernel(kernel, cl::NullRange, cl::NDRange(size_t(width), size_t(height)));
        queue.enqueueReadBuffer(out, CL_FALSE, 0, image.rgba.size() * sizeof(float), image.rgba.data());
        cl_uint counts[VC_STAT_COUNT];
        queue.enqueueReadBuffer(counters, CL_TRUE, 0, sizeof counts, counts);
        const double hit = std::max<double>(counts[VC_STAT_RAYS_HIT], 1);
        st.meanSamplesPerRay = counts[VC_STAT_SAMPLES] / hit;
        st.earlyTerminatedFraction = counts[VC_STAT_TERMINATED_EARLY] / hit;
        st.raysTruncated = counts[VC_STAT_TRUNCATED];
    } catch (const cl::Error &e) {
        throw OpenClError("rendering on " + cl_.deviceName() + " failed: " + describe(e));
    }
    st.renderSeconds = secondsSince(t);
    if (stats) *stats = st;
    return image;
}

} // namespace volcast
