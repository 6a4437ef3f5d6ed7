#include "renderer/model/camera.hpp"

#include "renderer/model/scene.hpp"

#include <cmath>
#include <numbers>
#include <stdexcept>
#include <string>

namespace volcast {

namespace {
bool finite(const Vec3d &v) { return std::isfinite(v.x) && std::isfinite(v.y) && std::isfinite(v.z); }
} // namespace

void Camera::validate() const {
    if (!finite(eye)) throw std::invalid_argument("camera.eye: must be three finite numbers");
    if (!finite(target)) throw std::invalid_argument("camera.target: must be three finite numbers");
    if (!finite(up)) throw std::invalid_argument("camera.up: must be three finite numbers");
    const Vec3d view = target - eye;
    if (!(length(view) > 0))
        throw std::invalid_argument("camera.target: equals camera.eye, the view direction has zero length");
    if (!(length(up) > 0)) throw std::invalid_argument("camera.up: has zero length");
    // Relative test: up must not be (nearly) parallel to the view direction.
    const double s = length(cross(normalize(view), normalize(up)));
    if (!(s > 1e-9)) throw std::invalid_argument("camera.up: is parallel to the view direction");
    if (projection == Projection::Perspective && !(fovYDeg > 0 && fovYDeg < 180))
        throw std::invalid_argument("camera.fov_y_deg: must be in (0, 180) degrees");
    if (projection == Projection::Orthographic && !(std::isfinite(height) && height > 0))
        throw std::invalid_argument("camera.height: must be a positive number");
}

void validateImageSize(int width, int height) {
    const std::string size = std::to_string(width) + "×" + std::to_string(height);
    if (width < 1 || height < 1 || width > kMaxImageSide || height > kMaxImageSide)
        throw std::invalid_argument("image: " + size + " is outside 1…" + std::to_string(kMaxImageSide) +
                                    " pixels per side");
    if (int64_t(width) * height > kMaxImagePixels)
        throw std::invalid_argument("image: " + size + " is " + std::to_string(int64_t(width) * height) +
                                    " pixels, more than the limit of " + std::to_string(kMaxImagePixels));
}

RayGenerator::RayGenerator(const Camera &camera, int width, int height)
    : camera_(camera), width_(width), height_(height) {
    camera.validate();
    validateImageSize(width, height);
    forward = normalize(camera.target - camera.eye);
    right = normalize(cross(forward, camera.up));
    up = cross(right, forward);
    const double aspect = double(width) / double(height);
    halfHeight_ = camera.projection == Projection::Perspective
                      ? std::tan(camera.fovYDeg * std::numbers::pi / 360.0)
                      : camera.height / 2;
    halfWidth_ = halfHeight_ * aspect;
}

Ray RayGenerator::rayThrough(double px, double py) const {
    // Image-plane coordinates in [-1, 1], y up (row 0 is the top of the image).
    const double u = 2 * px / width_ - 1;
    const double v = 1 - 2 * py / height_;
    const Vec3d offset = right * (u * halfWidth_) + up * (v * halfHeight_);
    if (camera_.projection == Projection::Perspective)
        return {camera_.eye, normalize(forward + offset)};
    return {camera_.eye + offset, forward};
}

} // namespace volcast
