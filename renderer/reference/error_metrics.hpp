#pragma once
// Error of an image against a reference (docs/design.md): RMSE over premultiplied RGBA in
// [0, 1], PSNR = 20·log10(1 / RMSE), the largest absolute difference, and an error image.

#include "renderer/model/image.hpp"

namespace volcast {

struct ImageError {
    double rmse = 0;
    double psnr = 0;     // +inf for identical images
    double maxAbs = 0;
};

// Throws std::invalid_argument if the sizes differ.
ImageError compareImages(const Image &image, const Image &reference);
// Per pixel, the largest absolute channel difference, as opaque grey (scale multiplies it).
Image errorImage(const Image &image, const Image &reference, double scale = 1.0);

} // namespace volcast
