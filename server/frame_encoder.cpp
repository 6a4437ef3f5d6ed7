#include "server/frame_encoder.hpp"

#include <OpenImageIO/filesystem.h>
#include <OpenImageIO/imageio.h>

#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <string>

namespace volcast::server {

namespace {
uint8_t to8(float v) { return uint8_t(std::lround(std::clamp(v, 0.0f, 1.0f) * 255.0f)); }

std::vector<uint8_t> encode(const char *formatName, const std::vector<uint8_t> &pixels, int width, int height,
                            int channels, const OIIO::ImageSpec &extra) {
    std::vector<unsigned char> out;
    OIIO::Filesystem::IOVecOutput proxy(out);
    // The name only picks the format; the proxy receives the bytes.
    auto writer = OIIO::ImageOutput::create(formatName, &proxy);
    if (!writer) throw std::runtime_error(std::string("encoding ") + formatName + ": " + OIIO::geterror());
    OIIO::ImageSpec spec(width, height, channels, OIIO::TypeDesc::UINT8);
    spec.extra_attribs = extra.extra_attribs;
    // A PTR attribute holds the pointer's value: pass the address of a pointer to the proxy.
    OIIO::Filesystem::IOProxy *proxyPtr = &proxy;
    spec.attribute("oiio:ioproxy", OIIO::TypeDesc::PTR, &proxyPtr);
    if (!writer->open(std::string("frame.") + formatName, spec) ||
        !writer->write_image(OIIO::TypeDesc::UINT8, pixels.data()) || !writer->close())
        throw std::runtime_error(std::string("encoding ") + formatName + ": " + writer->geterror());
    return {out.begin(), out.end()};
}
} // namespace

std::vector<uint8_t> toRgb8OverBlack(const Image &image) {
    const size_t n = size_t(image.width) * size_t(image.height);
    std::vector<uint8_t> rgb(n * 3);
    for (size_t i = 0; i < n; ++i)
        for (size_t c = 0; c < 3; ++c) rgb[i * 3 + c] = to8(image.rgba[i * 4 + c]);
    return rgb;
}

std::vector<uint8_t> toStraightRgba8(const Image &image) {
    const size_t n = size_t(image.width) * size_t(image.height);
    std::vector<uint8_t> rgba(n * 4);
    for (size_t i = 0; i < n; ++i) {
        const float a = std::clamp(image.rgba[i * 4 + 3], 0.0f, 1.0f);
        for (size_t c = 0; c < 3; ++c) rgba[i * 4 + c] = a > 0 ? to8(image.rgba[i * 4 + c] / a) : 0;
        rgba[i * 4 + 3] = to8(a);
    }
    return rgba;
}

std::vector<uint8_t> encodeJpeg(const Image &image, int quality) {
    OIIO::ImageSpec extra;
    extra.attribute("Compression", "jpeg:" + std::to_string(quality));
    return encode("jpg", toRgb8OverBlack(image), image.width, image.height, 3, extra);
}

std::vector<uint8_t> encodePng(const Image &image, int compressionLevel) {
    OIIO::ImageSpec extra;
    extra.attribute("png:compressionLevel", compressionLevel);
    // Our bytes are straight already: without this OIIO would un-premultiply them again.
    extra.attribute("oiio:UnassociatedAlpha", 1);
    return encode("png", toStraightRgba8(image), image.width, image.height, 4, extra);
}

} // namespace volcast::server
