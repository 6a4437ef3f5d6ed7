#pragma once
// Camera of docs/design.md: eye, target, up; perspective (full vertical angle) or orthographic
// (full view height in world units). Image x = forward × up, y up, pixel centres sampled,
// row 0 at the top.

#include "renderer/model/math.hpp"

namespace volcast {

enum class Projection { Perspective, Orthographic };

struct Camera {
    Vec3d eye{0, 0, 1};
    Vec3d target{0, 0, 0};
    Vec3d up{0, 1, 0};
    Projection projection = Projection::Perspective;
    double fovYDeg = 30;  // perspective: full vertical angle, degrees
    double height = 1;    // orthographic: full view height, world units
    bool operator==(const Camera &) const = default;

    // Throws std::invalid_argument naming the key for a degenerate camera.
    void validate() const;
};

struct Ray {
    Vec3d origin;
    Vec3d dir; // unit length; t is distance in world units, rays start at t = 0
};

// Throws std::invalid_argument naming "image" unless 1 ≤ width, height ≤ kMaxImageSide and
// width·height ≤ kMaxImagePixels (scene.hpp): renderers call it before allocating anything.
void validateImageSize(int width, int height);

// Orthonormal view frame and per-pixel rays for one image size.
class RayGenerator {
  public:
    RayGenerator(const Camera &camera, int width, int height);
    // Ray through the centre of pixel (x, y), row 0 at the top; (x, y) may be fractional
    // offsets from the corner, e.g. (x + 0.5, y + 0.5) is the centre.
    Ray rayThrough(double px, double py) const;
    Ray pixelRay(int x, int y) const { return rayThrough(x + 0.5, y + 0.5); }

    // Half the image plane's extent: at distance 1 (perspective) or in world units (orthographic).
    double halfWidth() const { return halfWidth_; }
    double halfHeight() const { return halfHeight_; }

    Vec3d forward, right, up;

  private:
    Camera camera_;
    int width_, height_;
    double halfHeight_, halfWidth_; // of the image plane at distance 1 (perspective) or world
};

} // namespace volcast
