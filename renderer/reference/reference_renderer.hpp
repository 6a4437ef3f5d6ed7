#pragma once
// The exact reference: the emission–absorption integral of docs/design.md evaluated in double
// precision to a requested tolerance, against which every fast configuration is measured.
//
//   I = ∫ c(v(t)) τ(v(t)) exp(−∫₀ᵗ τ(v(t')) dt') dt,   A = 1 − exp(−∫ τ dt)
//
// Along a ray, the reconstructed value v(t) is a polynomial between the grid's knot planes
// (degree 3 for trilinear, 9 for the tricubic B-spline), and the transfer function is
// linear between its control points. The integrator splits each ray at the knot planes and
// at every crossing of a control-point value (found on the polynomial's Bernstein form, so
// no crossing is missed), leaving pieces on which the integrand is smooth; there it
// integrates adaptively and keeps an error estimate weighted by the transmittance in front.

#include "renderer/model/camera.hpp"
#include "renderer/model/image.hpp"
#include "renderer/reference/reconstruction.hpp"
#include "renderer/model/scene.hpp"
#include "renderer/model/transfer_function.hpp"
#include "renderer/model/volume.hpp"

#include <functional>
#include <memory>
#include <optional>
#include <span>
#include <vector>

namespace volcast {

enum class Reconstruction { Linear, Cubic, Analytic };

struct ReferenceOptions {
    double tolerance = 1e-7; // per pixel and channel, absolute, on premultiplied RGBA in [0, 1]
    int threads = 0;         // 0: all hardware threads
};

struct ReferenceStats {
    double toleranceRequested = 0;
    double toleranceReached = 0;   // largest per-pixel error estimate
    double analyticFitError = 0;   // analytic fields: worst data-unit error of the crossing finder's polynomial
    uint64_t intervals = 0;        // accepted integration intervals, all rays
    double renderSeconds = 0;
};

struct RayIntegral {
    Rgba color;            // premultiplied RGB and alpha
    double errorEstimate = 0;
};

// What one ray shows at a picked pixel (ReferenceRenderer::pick).
struct RayPick {
    bool hit = false;     // the accumulated opacity reached the threshold
    double t = 0;         // ray parameter (world units along the unit direction) where it first did
    Vec3d point;          // world position there
    double opacity = 0;   // the ray's final accumulated opacity
};

class ReferenceRenderer {
  public:
    // A sampled volume, reconstructed trilinearly or by the prefiltered cubic B-spline
    // (prefiltered here, in double). The volume must outlive the renderer.
    ReferenceRenderer(const Volume &volume, TransferFunction tf, Reconstruction reconstruction);
    // An analytic field in world coordinates on the geometry (dims, spacing, origin,
    // direction) of `volume`, e.g. SyntheticVolume::field.
    ReferenceRenderer(const Volume &volume, TransferFunction tf,
                      std::function<double(const Vec3d &world)> analyticField);

    RayIntegral integrate(const Ray &ray, std::span<const ClipPlane> clipPlanes, double tolerance,
                          ReferenceStats *stats = nullptr) const;
    Image render(const Camera &camera, int width, int height, std::span<const ClipPlane> clipPlanes,
                 const ReferenceOptions &options, ReferenceStats *stats = nullptr) const;
    // Where the ray's accumulated opacity first reaches `threshold` (in (0, 1)): for
    // emission–absorption the point where the optical depth reaches −ln(1 − threshold), placed
    // within one accepted integration interval; for MIP / MinIP, whose pixel is the extreme
    // value's colour, the position of that extreme when its opacity reaches the threshold.
    RayPick pick(const Ray &ray, std::span<const ClipPlane> clipPlanes, double threshold, double tolerance) const;

    // Gradient Phong shading (quality.shading), off by default.
    void setShading(bool on) { shading_ = on; }
    // Maximum or minimum intensity projection instead of emission–absorption: the exact
    // extreme of the continuous field along the ray (see integrate), mapped through the
    // transfer function as (a·rgb, a). Default: emission–absorption.
    void setCompositing(Compositing compositing) { compositing_ = compositing; }
    // The crop box (quality.crop), normalised box coordinates; default the whole volume.
    void setCrop(const CropBox &crop) { crop_ = crop; }
    // Where the volume is drawn (quality.orientation_correction); default: as the file puts it.
    // An analytic field keeps its own world coordinates and moves with the volume.
    void setOrientationCorrection(const OrientationCorrection &correction);
    // All of them from a scene's quality; shading too.
    void setQuality(const Quality &quality) {
        setShading(quality.shading);
        setCompositing(quality.compositing);
        setCrop(quality.crop);
        setOrientationCorrection(quality.orientationCorrection);
    }

    double preprocessSeconds() const { return preprocessSeconds_; }
    // The ray's parameter interval inside the volume and all clip half-spaces; false if empty.
    bool clipRay(const Ray &ray, std::span<const ClipPlane> clipPlanes, double &t0, double &t1) const;

  private:
    double valueAtIndex(const Vec3d &indexPos) const;
    std::vector<double> splitPoints(const Vec3d &p0, const Vec3d &dq, double t0, double t1) const;
    RayIntegral project(const Ray &ray, double t0, double t1, double tolerance, ReferenceStats *stats,
                        double *where = nullptr) const;
    // Emission–absorption on [t0, t1]; with markDepth, *markT gets where the optical depth
    // first reaches it (nullopt: never).
    RayIntegral emission(const Ray &ray, double t0, double t1, double tolerance, ReferenceStats *stats,
                         std::optional<double> markDepth, std::optional<double> *markT) const;

    const Volume &volume_;
    TransferFunction tf_;
    double opacityUnit_;
    Reconstruction reconstruction_;
    std::unique_ptr<CubicBSplineField> cubic_;
    std::function<double(const Vec3d &)> analytic_;
    double preprocessSeconds_ = 0;
    bool shading_ = false;
    Compositing compositing_ = Compositing::EmissionAbsorption;
    CropBox crop_;
    VolumePlacement placement_ = correctedPlacement(volume_, {});   // the volume's, corrected
};

} // namespace volcast
