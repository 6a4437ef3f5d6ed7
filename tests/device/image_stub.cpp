// For the GPU machine's bundle only (make-bundle.sh): image files as raw float RGBA ("VRAW",
// int32 width, int32 height, then width*height*4 floats, row 0 at the top) in place of
// renderer/model/image.cpp, so the bundle needs neither OpenImageIO nor its libraries.
#include "renderer/model/image.hpp"

#include <cstdint>
#include <fstream>
#include <stdexcept>

namespace volcast {

void writeImage(const std::filesystem::path &path, const Image &image) {
    std::ofstream f(path, std::ios::binary);
    if (!f) throw std::runtime_error("cannot write " + path.string());
    f.write("VRAW", 4);
    const int32_t wh[2] = {image.width, image.height};
    f.write(reinterpret_cast<const char *>(wh), 8);
    f.write(reinterpret_cast<const char *>(image.rgba.data()), std::streamsize(image.rgba.size() * 4));
}

Image readImage(const std::filesystem::path &path) {
    throw std::runtime_error("reading images is left out of the GPU machine's bundle: " + path.string());
}

} // namespace volcast
