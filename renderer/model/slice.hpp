#pragma once
// Planar slices of a volume in the patient frame: the axial, coronal and sagittal planes of
// the world (ITK's LPS) axes of docs/design.md. A volume without orientation has the identity
// direction, so its slices are its own axes. Each slice is resampled with the trilinear field
// of renderer/reference/reconstruction.hpp (clamp-to-edge inside the cell box); a pixel whose centre
// lies outside the volume's cell box [-1/2, n - 1/2] is background.
//
// Image layout, as radiologists read them (the patient's right on the image's left):
//   axial     columns +x (towards patient left), rows +y (towards posterior): anterior on top
//   coronal   columns +x (towards patient left), rows -z: superior on top
//   sagittal  columns +y (towards posterior),    rows -z: anterior on the left, superior on top
// Pixel (c, r) samples world = origin + c·s·column + r·s·row, row 0 at the top.

#include "renderer/model/orientation_correction.hpp"
#include "renderer/model/volume.hpp"

#include <cstdint>
#include <optional>
#include <string_view>
#include <vector>

namespace volcast {

enum class SliceAxis { Axial, Coronal, Sagittal };

std::string_view sliceAxisName(SliceAxis axis);            // "axial", ...
std::optional<SliceAxis> parseSliceAxis(std::string_view name);

// The most pixels one slice may have; far above any screen, far below memory trouble.
inline constexpr int64_t kMaxSlicePixels = int64_t(1) << 26;
inline constexpr int kMaxSliceSide = 16384;

struct SlicePlane {
    SliceAxis axis = SliceAxis::Axial;
    int width = 0;               // pixels
    int height = 0;
    double pixelSpacing = 1;     // world units (mm) between pixel centres
    Vec3d origin;                // world position of pixel (0, 0)'s centre
    Vec3d column;                // unit world direction of +column
    Vec3d row;                   // unit world direction of +row (down the image)
    Vec3d normal;                // column × row
    // World position of the centre of pixel (c, r), fractional pixels allowed.
    Vec3d worldAt(double c, double r) const {
        return origin + column * (c * pixelSpacing) + row * (r * pixelSpacing);
    }
};

// What a client asks for. `point` places the plane (its coordinate along the normal; the
// crosshair point). `center` is the world point shown at the image's centre (default: the
// volume's centre). `pixelSpacing` defaults to the largest that fits the volume's world
// bounding box into width x height.
struct SliceRequestGeometry {
    SliceAxis axis = SliceAxis::Axial;
    Vec3d point;
    int width = 0;
    int height = 0;
    std::optional<double> pixelSpacing;
    std::optional<Vec3d> center;
};

// Throws std::invalid_argument naming the field for a size outside [1, kMaxSliceSide] or over
// kMaxSlicePixels, a non-finite point or centre, or a spacing not finite and > 0.
// `correction` places the volume as the session's frames do (quality.orientation_correction):
// a slice of a flipped volume is the flipped slice.
SlicePlane slicePlane(const Volume &volume, const SliceRequestGeometry &geometry,
                      const OrientationCorrection &correction = {});

// The volume's values on the plane; outside the cell box `inside` is 0 and the value is the
// volume's minimum (never NaN: non-finite voxels were replaced by the loader).
struct SliceImage {
    int width = 0;
    int height = 0;
    std::vector<float> values;     // row-major, row 0 at the top
    std::vector<uint8_t> inside;   // 1 where the pixel centre lies in the cell box
};
SliceImage sampleSlice(const Volume &volume, const SlicePlane &plane, const OrientationCorrection &correction = {});

// 8-bit grey of the values under window/level (data units): level - window/2 -> 0,
// level + window/2 -> 255, linear between, rounded to nearest, clamped; background -> 0.
// Throws std::invalid_argument for a window not finite and > 0 or a non-finite level.
std::vector<uint8_t> windowToGray8(const SliceImage &image, double window, double level);
uint8_t windowValue(double value, double window, double level);

// A thick slab (a slice's `slab`): the planes parallel to the slice across
// [−thickness/2, +thickness/2] along its normal, at a spacing of at most half the volume's
// smallest voxel spacing, combined per pixel over the samples inside the volume: their
// maximum (MIP), minimum (MinIP) or mean. A pixel is inside when any of its samples is.
enum class SlabMode { Maximum, Minimum, Mean };
std::string_view slabModeName(SlabMode mode);              // "mip", "minip", "mean"
std::optional<SlabMode> parseSlabMode(std::string_view name);

inline constexpr int kMaxSlabPlanes = 1024;
// The most samples (planes x pixels) one slab may take: a 512 x 512 slab of 1024 planes.
inline constexpr int64_t kMaxSlabSamples = int64_t(1) << 28;

struct Slab {
    double thickness = 0;   // world units (mm), >= 0; 0 is the plane itself
    SlabMode mode = SlabMode::Maximum;
};

// Planes a slab of this thickness takes on this volume: 1 for thickness 0, else
// ceil(thickness / (smallest spacing / 2)) + 1 (both faces sampled). Throws
// std::invalid_argument for a thickness not finite and >= 0; the count may exceed
// kMaxSlabPlanes (then it is kMaxSlabPlanes + 1), which sampleSlab refuses.
int slabPlaneCount(const Volume &volume, double thickness);

// The slab's values on the plane (sampleSlice for thickness 0). Throws std::length_error for
// more than kMaxSlabPlanes planes or kMaxSlabSamples samples, naming the numbers.
SliceImage sampleSlab(const Volume &volume, const SlicePlane &plane, const Slab &slab,
                      const OrientationCorrection &correction = {});

// The volume's value at a world point by the slices' trilinear reconstruction, the volume
// placed as `correction` puts it; nullopt outside the cell box. Throws std::invalid_argument
// for a non-finite point.
std::optional<double> probeValue(const Volume &volume, const Vec3d &world, const OrientationCorrection &correction = {});

// The in-plane directions of a slice pane (the layout above): column, then row.
struct SliceAxes {
    Vec3d column, row;
};
SliceAxes sliceAxes(SliceAxis axis);

// Statistics of the volume's values over a region of a slice pane's plane: an ellipse with
// semi-axes (a, b), or a rectangle of half sides (a, b), centred on `center`, a along the
// pane's column direction and b along its row direction (world units). Sampled on a square
// grid of cell centres, spacing h = min(smallest voxel spacing / 2, min(a, b) / 8), limited to
// the part of the plane the volume's bounding box covers; a sample counts when it lies inside
// the shape and inside the volume's cell box. area = samples · h².
enum class RoiShape { Ellipse, Rectangle };
std::optional<RoiShape> parseRoiShape(std::string_view name);   // "ellipse", "rectangle"
inline constexpr int64_t kMaxRoiSamples = int64_t(1) << 24;

struct RoiGeometry {
    SliceAxis axis = SliceAxis::Axial;
    Vec3d center;
    double a = 0, b = 0;
    RoiShape shape = RoiShape::Ellipse;
};
struct RoiStats {
    int64_t samples = 0;
    double area = 0;       // world units squared
    double spacing = 0;    // the grid's h
    double mean = 0, std = 0, min = 0, max = 0;   // meaningful when samples > 0; std is the population's
};
// Throws std::invalid_argument naming the field ("center", "radii") for a non-finite centre or
// radii not finite and > 0, and std::length_error when the grid would pass kMaxRoiSamples.
RoiStats roiStats(const Volume &volume, const RoiGeometry &roi, const OrientationCorrection &correction = {});

// The default window/level of a volume: its value range (window 1 for a constant volume).
struct WindowLevel {
    double window = 1;
    double level = 0;
};
WindowLevel defaultWindowLevel(const Volume &volume);

} // namespace volcast
