#pragma once
// A float RGBA image, premultiplied, row 0 at the top, and its files: .exr and .tif keep
// premultiplied float RGBA; .png is 8-bit RGB for people to look at (the premultiplied
// colour, i.e. composited over black).

#include <filesystem>
#include <vector>

namespace volcast {

struct Image {
    int width = 0;
    int height = 0;
    std::vector<float> rgba; // width * height * 4

    Image() = default;
    Image(int w, int h) : width(w), height(h), rgba(size_t(w) * size_t(h) * 4, 0.0f) {}
    float *pixel(int x, int y) { return &rgba[(size_t(y) * size_t(width) + size_t(x)) * 4]; }
    const float *pixel(int x, int y) const { return &rgba[(size_t(y) * size_t(width) + size_t(x)) * 4]; }
};

// Bilinear resampling with pixel centres aligned ((x + ½)/W in both) and edges clamped:
// how image_scale < 1 brings its fewer rays back to the requested size.
Image resizeBilinear(const Image &image, int width, int height);

// Throws std::runtime_error naming the file on failure or an unknown extension.
void writeImage(const std::filesystem::path &path, const Image &image);
Image readImage(const std::filesystem::path &path);

} // namespace volcast
