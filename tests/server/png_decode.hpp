#pragma once
// A final frame's PNG as the client stores it, for the server tests that compare pixels:
// decoded with libpng's simplified reading API, which keeps 8-bit alpha straight (it
// premultiplies only linear, 16-bit output). The tests link libpng themselves rather than
// a general image library, whose ~250 shared libraries every test process would load.

#include <png.h>

#include <cstdint>
#include <stdexcept>
#include <string>
#include <vector>

namespace volcast::test {

// The PNG's samples as 8 bits each, in the channels it holds (grey, grey and alpha, RGB or
// RGBA); w, h and channels say which.
inline std::vector<uint8_t> decodePng(const std::vector<uint8_t> &png, int &w, int &h, int &channels) {
    png_image image{};
    image.version = PNG_IMAGE_VERSION;
    if (!png_image_begin_read_from_memory(&image, png.data(), png.size()))
        throw std::runtime_error(std::string("png decode: ") + image.message);
    const bool colour = (image.format & PNG_FORMAT_FLAG_COLOR) != 0, alpha = (image.format & PNG_FORMAT_FLAG_ALPHA) != 0;
    image.format = colour ? (alpha ? PNG_FORMAT_RGBA : PNG_FORMAT_RGB) : (alpha ? PNG_FORMAT_GA : PNG_FORMAT_GRAY);
    std::vector<uint8_t> pixels(PNG_IMAGE_SIZE(image));
    if (!png_image_finish_read(&image, nullptr, pixels.data(), 0, nullptr)) {
        const std::string message = image.message;
        png_image_free(&image);
        throw std::runtime_error("png decode: " + message);
    }
    w = int(image.width);
    h = int(image.height);
    channels = int(PNG_IMAGE_SAMPLE_CHANNELS(image.format));
    return pixels;
}

} // namespace volcast::test
