#include "renderer/model/slice.hpp"

#include "renderer/reference/reconstruction.hpp"

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

bool insideCellBox(const Vec3d &q, const Vec3d &hiIndex) {
    return q.x >= -0.5 && q.y >= -0.5 && q.z >= -0.5 && q.x <= hiIndex.x && q.y <= hiIndex.y && q.z <= hiIndex.z;
}

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

std::string_view slabModeName(SlabMode mode) {
    switch (mode) {
    case SlabMode::Maximum: return "mip";
    case SlabMode::Minimum: return "minip";
    case SlabMode::Mean: return "mean";
    }
    return "?";
}

std::optional<SlabMode> parseSlabMode(std::string_view name) {
    for (SlabMode m : {SlabMode::Maximum, SlabMode::Minimum, SlabMode::Mean})
        if (slabModeName(m) == name) return m;
    return std::nullopt;
}

int slabPlaneCount(const Volume &volume, double thickness) {
    if (!(std::isfinite(thickness) && thickness >= 0))
        throw std::invalid_argument("slab.thickness: must be a finite number >= 0, got " + number(thickness));
    if (thickness == 0) return 1;
    const double gaps = std::ceil(thickness / (volume.smallestSpacing() / 2));
    // Compared as a double first: an absurd thickness must not overflow the int.
    if (!(gaps + 1 <= double(kMaxSlabPlanes))) return kMaxSlabPlanes + 1;
    return int(gaps) + 1;
}

SliceImage sampleSlab(const Volume &volume, const SlicePlane &plane, const Slab &slab,
                      const OrientationCorrection &correction) {
    const int planes = slabPlaneCount(volume, slab.thickness);
    if (planes == 1) return sampleSlice(volume, plane, correction);
    const double smallest = volume.smallestSpacing();
    if (planes > kMaxSlabPlanes)
        throw std::length_error("a slab of " + number(slab.thickness) + " mm needs more than " +
                                std::to_string(kMaxSlabPlanes) + " planes at " + number(smallest / 2) +
                                " mm apart (half the smallest voxel spacing); the limit is " +
                                std::to_string(kMaxSlabPlanes) + " planes, a slab of at most " +
                                number((kMaxSlabPlanes - 1) * smallest / 2) + " mm");
    const int64_t pixels = int64_t(plane.width) * plane.height;
    if (pixels * planes > kMaxSlabSamples)
        throw std::length_error("a slab of " + std::to_string(planes) + " planes of " + std::to_string(plane.width) +
                                " x " + std::to_string(plane.height) + " pixels is " + std::to_string(pixels * planes) +
                                " samples, over the limit of " + std::to_string(kMaxSlabSamples) +
                                "; ask for a smaller image or a thinner slab");
    const VolumePlacement placed = correctedPlacement(volume, correction);
    SliceImage out;
    out.width = plane.width;
    out.height = plane.height;
    const size_t n = size_t(pixels);
    out.values.assign(n, volume.range.min);
    out.inside.assign(n, 0);
    if (volume.voxelCount() == 0) return out;
    std::vector<double> acc(n, 0.0);
    std::vector<int32_t> count(n, 0);
    const TrilinearField field(volume);
    const Vec3d hiIndex = Vec3d(volume.dims) - Vec3d{0.5, 0.5, 0.5};
    const Vec3d start = placed.indexFromWorld(plane.origin);
    const Vec3d dc = placed.indexFromWorldDir(plane.column * plane.pixelSpacing);
    const Vec3d dr = placed.indexFromWorldDir(plane.row * plane.pixelSpacing);
    const Vec3d dn = placed.indexFromWorldDir(plane.normal);
    for (int k = 0; k < planes; ++k) {
        // Both faces are sampled: offsets −t/2 … +t/2 in planes − 1 equal gaps.
        const double offset = -slab.thickness / 2 + slab.thickness * double(k) / double(planes - 1);
        const Vec3d base = start + dn * offset;
        for (int r = 0; r < plane.height; ++r) {
            for (int c = 0; c < plane.width; ++c) {
                const Vec3d q = base + dc * double(c) + dr * double(r);
                if (!insideCellBox(q, hiIndex)) continue;
                const size_t at = size_t(r) * size_t(plane.width) + size_t(c);
                const double v = field(q);
                double &a = acc[at];
                if (count[at] == 0) a = v;
                else if (slab.mode == SlabMode::Maximum) a = std::max(a, v);
                else if (slab.mode == SlabMode::Minimum) a = std::min(a, v);
                else a += v;
                ++count[at];
            }
        }
    }
    for (size_t i = 0; i < n; ++i) {
        if (count[i] == 0) continue;
        out.inside[i] = 1;
        out.values[i] = float(slab.mode == SlabMode::Mean ? acc[i] / count[i] : acc[i]);
    }
    return out;
}

std::optional<double> probeValue(const Volume &volume, const Vec3d &world, const OrientationCorrection &correction) {
    if (!finite(world)) throw std::invalid_argument("point: must be three finite numbers");
    if (volume.voxelCount() == 0) return std::nullopt;
    const VolumePlacement placed = correctedPlacement(volume, correction);
    const Vec3d q = placed.indexFromWorld(world);
    if (!insideCellBox(q, Vec3d(volume.dims) - Vec3d{0.5, 0.5, 0.5})) return std::nullopt;
    return TrilinearField(volume)(q);
}

SliceAxes sliceAxes(SliceAxis axis) {
    const AxisFrame f = axisFrame(axis);
    return {f.column, f.row};
}

std::optional<RoiShape> parseRoiShape(std::string_view name) {
    if (name == "ellipse") return RoiShape::Ellipse;
    if (name == "rectangle") return RoiShape::Rectangle;
    return std::nullopt;
}

RoiStats roiStats(const Volume &volume, const RoiGeometry &roi, const OrientationCorrection &correction) {
    if (!finite(roi.center)) throw std::invalid_argument("center: must be three finite numbers");
    if (!(std::isfinite(roi.a) && roi.a > 0 && std::isfinite(roi.b) && roi.b > 0))
        throw std::invalid_argument("radii: must be two finite numbers > 0, got [" + number(roi.a) + ", " +
                                    number(roi.b) + "]");
    const VolumePlacement placed = correctedPlacement(volume, correction);
    const AxisFrame f = axisFrame(roi.axis);
    RoiStats out;
    out.spacing = std::min(volume.smallestSpacing() / 2, std::min(roi.a, roi.b) / 8);
    const double h = out.spacing;
    if (volume.voxelCount() == 0 || !(h > 0)) return out;
    // The part of the shape's bounding rectangle the volume's world bounding box covers, in
    // (column, row) offsets from the centre: no sample outside it can be inside the volume.
    double uLo = -roi.a, uHi = roi.a, vLo = -roi.b, vHi = roi.b;
    double boxULo = INFINITY, boxUHi = -INFINITY, boxVLo = INFINITY, boxVHi = -INFINITY;
    for (int corner = 0; corner < 8; ++corner) {
        const Vec3d idx{(corner & 1) ? double(volume.dims.x) - 0.5 : -0.5,
                        (corner & 2) ? double(volume.dims.y) - 0.5 : -0.5,
                        (corner & 4) ? double(volume.dims.z) - 0.5 : -0.5};
        const Vec3d w = placed.worldFromIndex(idx) - roi.center;
        boxULo = std::min(boxULo, dot(w, f.column));
        boxUHi = std::max(boxUHi, dot(w, f.column));
        boxVLo = std::min(boxVLo, dot(w, f.row));
        boxVHi = std::max(boxVHi, dot(w, f.row));
    }
    uLo = std::max(uLo, boxULo);
    uHi = std::min(uHi, boxUHi);
    vLo = std::max(vLo, boxVLo);
    vHi = std::min(vHi, boxVHi);
    if (!(uLo <= uHi && vLo <= vHi)) return out;
    // Cell centres at (i + 1/2)·h from the centre: a shape whose sides are whole cells is
    // counted exactly.
    const double iLo = std::floor(uLo / h - 0.5), iHi = std::ceil(uHi / h - 0.5);
    const double jLo = std::floor(vLo / h - 0.5), jHi = std::ceil(vHi / h - 0.5);
    const double cells = (iHi - iLo + 1) * (jHi - jLo + 1);
    if (!(cells <= double(kMaxRoiSamples)))
        throw std::length_error("radii: a region of " + number(2 * roi.a) + " x " + number(2 * roi.b) +
                                " mm sampled every " + number(h) + " mm takes " + number(cells) +
                                " samples, over the limit of " + std::to_string(kMaxRoiSamples));
    const TrilinearField field(volume);
    const Vec3d hiIndex = Vec3d(volume.dims) - Vec3d{0.5, 0.5, 0.5};
    double mean = 0, m2 = 0;   // Welford: stable for a million samples of large values
    out.min = INFINITY;
    out.max = -INFINITY;
    for (double j = jLo; j <= jHi; ++j) {
        const double v = (j + 0.5) * h;
        for (double i = iLo; i <= iHi; ++i) {
            const double u = (i + 0.5) * h;
            const double x = u / roi.a, y = v / roi.b;
            const bool inShape = roi.shape == RoiShape::Ellipse ? x * x + y * y <= 1
                                                                : std::abs(x) <= 1 && std::abs(y) <= 1;
            if (!inShape) continue;
            const Vec3d q = placed.indexFromWorld(roi.center + f.column * u + f.row * v);
            if (!insideCellBox(q, hiIndex)) continue;
            const double value = field(q);
            ++out.samples;
            const double delta = value - mean;
            mean += delta / double(out.samples);
            m2 += delta * (value - mean);
            out.min = std::min(out.min, value);
            out.max = std::max(out.max, value);
        }
    }
    out.area = double(out.samples) * h * h;
    if (out.samples > 0) {
        out.mean = mean;
        out.std = std::sqrt(std::max(m2 / double(out.samples), 0.0));
    } else {
        out.min = out.max = 0;
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
