#pragma once
// A float RGBA image, premultiplied, row 0 at the top, and its files: .exr and .tif keep
// premultiplied float RGBA; .png is 8-bit RGB for people to look at (the premultiplied
// colour, i.e. composited over black).

#include <filesystem>
#include <memory>
#include <new>
#include <utility>
#include <vector>

namespace volcast {

// std::allocator, but an element a vector value-initialises (resize, the size constructor) is
// left uninitialised: a frame read back from a device overwrites every byte, and zero-filling
// a 512² float frame's 4 MB first cost it as much as its read-back.
template <class T>
struct UninitialisedAllocator : std::allocator<T> {
    template <class U>
    struct rebind {
        using other = UninitialisedAllocator<U>;
    };
    UninitialisedAllocator() = default;
    template <class U>
    UninitialisedAllocator(const UninitialisedAllocator<U> &) noexcept {}
    template <class U>
    void construct(U *p) noexcept {
        ::new (static_cast<void *>(p)) U;
    }
    template <class U, class... Args>
    void construct(U *p, Args &&...args) {
        ::new (static_cast<void *>(p)) U(std::forward<Args>(args)...);
    }
};

// A frame's pixels: filled by whoever makes them (the constructors below zero-fill, unless
// asked not to).
template <class T>
using PixelVector = std::vector<T, UninitialisedAllocator<T>>;

struct Image {
    int width = 0;
    int height = 0;
    PixelVector<float> rgba; // width * height * 4

    Image() = default;
    Image(int w, int h) : width(w), height(h), rgba(size_t(w) * size_t(h) * 4, 0.0f) {}
    // Every pixel left for the caller to write (a device's read-back).
    static Image unfilled(int w, int h) {
        Image image;
        image.width = w;
        image.height = h;
        image.rgba.resize(size_t(w) * size_t(h) * 4);
        return image;
    }
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
