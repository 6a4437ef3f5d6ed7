#include "renderer/slice.hpp"

#include "renderer/reconstruction.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <stdexcept>
#include <string>

namespace volcast {

namespace {

struct AxisFrame {
    Vec3d column, row;
};

AxisFrame axisFrame(SliceAxis axis) {
    switch (axis) {
    case SliceAxis::Axial: return {{1, 0, 0}, {0, 1, 0}};
    case SliceAxis::Coronal: return {{1, 0, 0}, {0, 0, -1}};
    case SliceAxis::Sagittal: return {{0, 1, 0}, {0, 0, -1}};
    }
    throw std::invalid_argument("slice: unknown axis");
}

bool finite(const Vec3d &v) { return std::isfinite(v.x) && std::isfinite(v.y) && std::isfinite(v.z); }

std::string number(double v) {
    char buf[32];
    std::snprintf(buf, sizeof buf, "%.6g", v);
    return buf;
}

} // namespace

std::string_view sliceAxisName(SliceAxis axis) {
    switch (axis) {
    case SliceAxis::Axial: return "axial";
    case SliceAxis::Coronal: return "coronal";
    case SliceAxis::Sagittal: return "sagittal";
    }
    return "?";
}

std::optional<SliceAxis> parseSliceAxis(std::string_view name) {
    for (SliceAxis a : {SliceAxis::Axial, SliceAxis::Coronal, SliceAxis::Sagittal})
        if (sliceAxisName(a) == name) return a;
    return std::nullopt;
}

SlicePlane slicePlane(const Volume &volume, const SliceRequestGeometry &g, const OrientationCorrection &correction) {
    const VolumePlacement placed = correctedPlacement(volume, correction);
    if (g.width < 1 || g.width > kMaxSliceSide)
        throw std::invalid_argument("width: must be in [1, " + std::to_string(kMaxSliceSide) + "], got " +
                                    std::to_string(g.width));
    if (g.height < 1 || g.height > kMaxSliceSide)
        throw std::invalid_argument("height: must be in [1, " + std::to_string(kMaxSliceSide) + "], got " +
                                    std::to_string(g.height));
    if (int64_t(g.width) * int64_t(g.height) > kMaxSlicePixels)
        throw std::invalid_argument("width x height: " + std::to_string(int64_t(g.width) * g.height) +
                                    " pixels, over the limit of " + std::to_string(kMaxSlicePixels));
    if (!finite(g.point)) throw std::invalid_argument("point: must be three finite numbers");
    if (g.center && !finite(*g.center)) throw std::invalid_argument("center: must be three finite numbers");
    if (g.pixelSpacing && !(std::isfinite(*g.pixelSpacing) && *g.pixelSpacing > 0))
        throw std::invalid_argument("pixel_spacing: must be a finite number > 0, got " + number(*g.pixelSpacing));

    const AxisFrame f = axisFrame(g.axis);
    SlicePlane p;
    p.axis = g.axis;
    p.width = g.width;
    p.height = g.height;
    p.column = f.column;
    p.row = f.row;
    p.normal = cross(f.column, f.row);

    // The world bounding box of the cell box, from its eight corners (an oblique volume's
    // box is larger than its extent).
    Vec3d lo{INFINITY, INFINITY, INFINITY}, hi{-INFINITY, -INFINITY, -INFINITY};
    for (int corner = 0; corner < 8; ++corner) {
        const Vec3d idx{(corner & 1) ? double(volume.dims.x) - 0.5 : -0.5,
                        (corner & 2) ? double(volume.dims.y) - 0.5 : -0.5,
                        (corner & 4) ? double(volume.dims.z) - 0.5 : -0.5};
        const Vec3d w = placed.worldFromIndex(idx);
        for (int a = 0; a < 3; ++a) {
            lo[a] = std::min(lo[a], w[a]);
            hi[a] = std::max(hi[a], w[a]);
        }
    }
    const Vec3d size = hi - lo;
    if (g.pixelSpacing) {
        p.pixelSpacing = *g.pixelSpacing;
    } else {
        const double across = std::abs(dot(size, f.column)), down = std::abs(dot(size, f.row));
        p.pixelSpacing = std::max(across / g.width, down / g.height);
        if (!(p.pixelSpacing > 0)) p.pixelSpacing = volume.smallestSpacing();
    }
    // The image's centre: the requested centre (or the box's), moved along the normal into
    // the plane through the point.
    const Vec3d c0 = g.center ? *g.center : (lo + hi) * 0.5;
    const Vec3d centre = c0 + p.normal * dot(g.point - c0, p.normal);
    p.origin = centre - p.column * (p.pixelSpacing * (g.width - 1) * 0.5) -
               p.row * (p.pixelSpacing * (g.height - 1) * 0.5);
    if (!finite(p.origin) || !finite(p.worldAt(g.width - 1, g.height - 1)))
        throw std::invalid_argument("pixel_spacing: " + number(p.pixelSpacing) +
                                    " puts the image beyond finite coordinates");
    return p;
}

SliceImage sampleSlice(const Volume &volume, const SlicePlane &plane, const OrientationCorrection &correction) {
    const VolumePlacement placed = correctedPlacement(volume, correction);
    SliceImage out;
    out.width = plane.width;
    out.height = plane.height;
    const size_t n = size_t(plane.width) * size_t(plane.height);
    out.values.assign(n, volume.range.min);
    out.inside.assign(n, 0);
    if (volume.voxelCount() == 0) return out;
    const TrilinearField field(volume);
    const Vec3d hiIndex = Vec3d(volume.dims) - Vec3d{0.5, 0.5, 0.5};
    // Index space is affine in the pixel position: one start and two steps.
    const Vec3d start = placed.indexFromWorld(plane.origin);
    const Vec3d dc = placed.indexFromWorldDir(plane.column * plane.pixelSpacing);
    const Vec3d dr = placed.indexFromWorldDir(plane.row * plane.pixelSpacing);
    for (int r = 0; r < plane.height; ++r) {
        for (int c = 0; c < plane.width; ++c) {
            const Vec3d q = start + dc * double(c) + dr * double(r);
            if (!(q.x >= -0.5 && q.y >= -0.5 && q.z >= -0.5 && q.x <= hiIndex.x && q.y <= hiIndex.y &&
                  q.z <= hiIndex.z))
                continue;
            const size_t at = size_t(r) * size_t(plane.width) + size_t(c);
            out.values[at] = float(field(q));
            out.inside[at] = 1;
        }
    }
    return out;
}

uint8_t windowValue(double value, double window, double level) {
    const double t = (value - (level - window / 2)) / window;
    if (!(t > 0)) return 0;   // below the window, or NaN from infinite inputs
    if (!(t < 1)) return 255;
    return uint8_t(std::round(t * 255.0));
}

std::vector<uint8_t> windowToGray8(const SliceImage &image, double window, double level) {
    if (!(std::isfinite(window) && window > 0))
        throw std::invalid_argument("window: must be a finite number > 0, got " + number(window));
    if (!std::isfinite(level)) throw std::invalid_argument("level: must be a finite number");
    std::vector<uint8_t> grey(image.values.size(), 0);
    for (size_t i = 0; i < grey.size(); ++i)
        if (image.inside[i]) grey[i] = windowValue(image.values[i], window, level);
    return grey;
}

WindowLevel defaultWindowLevel(const Volume &volume) {
    const double lo = volume.range.min, hi = volume.range.max;
    WindowLevel wl;
    wl.window = hi > lo ? hi - lo : 1.0;
    wl.level = hi > lo ? (lo + hi) / 2 : lo;
    return wl;
}

} // namespace volcast
