#include "renderer/model/image.hpp"

#include <OpenImageIO/imageio.h>

#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <string>

namespace volcast {

namespace {
std::string lowerExtension(const std::filesystem::path &p) {
    std::string e = p.extension().string();
    std::transform(e.begin(), e.end(), e.begin(), [](unsigned char c) { return char(std::tolower(c)); });
    return e;
}
[[noreturn]] void fail(const std::filesystem::path &p, const std::string &what) {
    throw std::runtime_error(p.string() + ": " + what);
}
} // namespace

void writeImage(const std::filesystem::path &path, const Image &image) {
    const std::string ext = lowerExtension(path);
    auto out = OIIO::ImageOutput::create(path.string());
    if (!out) fail(path, "cannot write this image type (" + OIIO::geterror() + ")");
    if (ext == ".exr" || ext == ".tif" || ext == ".tiff") {
        OIIO::ImageSpec spec(image.width, image.height, 4, OIIO::TypeDesc::FLOAT);
        spec.alpha_channel = 3;
        spec.attribute("oiio:UnassociatedAlpha", 0); // our colour is premultiplied
        if (!out->open(path.string(), spec) || !out->write_image(OIIO::TypeDesc::FLOAT, image.rgba.data()))
            fail(path, out->geterror());
    } else if (ext == ".png") {
        // 8-bit RGB over black: the premultiplied colour, rounded.
        std::vector<unsigned char> rgb(size_t(image.width) * size_t(image.height) * 3);
        for (size_t i = 0, n = size_t(image.width) * size_t(image.height); i < n; ++i)
            for (size_t c = 0; c < 3; ++c)
                rgb[i * 3 + c] = (unsigned char)std::lround(std::clamp(image.rgba[i * 4 + c], 0.0f, 1.0f) * 255.0f);
        OIIO::ImageSpec spec(image.width, image.height, 3, OIIO::TypeDesc::UINT8);
        if (!out->open(path.string(), spec) || !out->write_image(OIIO::TypeDesc::UINT8, rgb.data()))
            fail(path, out->geterror());
    } else {
        fail(path, "unknown image extension '" + ext + "' (use .exr, .tif or .png)");
    }
    if (!out->close()) fail(path, out->geterror());
}

Image readImage(const std::filesystem::path &path) {
    auto in = OIIO::ImageInput::open(path.string());
    if (!in) fail(path, "cannot read image (" + OIIO::geterror() + ")");
    const OIIO::ImageSpec &spec = in->spec();
    if (spec.nchannels < 3) fail(path, "needs RGB or RGBA, has " + std::to_string(spec.nchannels) + " channels");
    Image image(spec.width, spec.height);
    std::vector<float> pixels(size_t(spec.width) * size_t(spec.height) * size_t(spec.nchannels));
    if (!in->read_image(0, 0, 0, spec.nchannels, OIIO::TypeDesc::FLOAT, pixels.data())) fail(path, in->geterror());
    const size_t nc = size_t(spec.nchannels);
    for (size_t i = 0, n = size_t(spec.width) * size_t(spec.height); i < n; ++i) {
        for (size_t c = 0; c < 3; ++c) image.rgba[i * 4 + c] = pixels[i * nc + c];
        // An image without alpha (such as our PNGs) is read as opaque.
        image.rgba[i * 4 + 3] = nc >= 4 ? pixels[i * nc + 3] : 1.0f;
    }
    in->close();
    return image;
}

} // namespace volcast
