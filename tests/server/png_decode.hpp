#pragma once
// A final frame's PNG as the client stores it, for the server tests that compare pixels.

#include <OpenImageIO/filesystem.h>
#include <OpenImageIO/imageio.h>

#include <cstdint>
#include <stdexcept>
#include <vector>

namespace volcast::test {

// The PNG's samples as 8 bits each, alpha as stored (straight): by default OIIO would
// premultiply them.
inline std::vector<uint8_t> decodePng(const std::vector<uint8_t> &png, int &w, int &h, int &channels) {
    OIIO::Filesystem::IOMemReader reader(png.data(), png.size());
    OIIO::ImageSpec config;
    config.attribute("oiio:UnassociatedAlpha", 1);
    OIIO::Filesystem::IOProxy *proxy = &reader;
    config.attribute("oiio:ioproxy", OIIO::TypeDesc::PTR, &proxy);
    auto in = OIIO::ImageInput::open("frame.png", &config, &reader);
    if (!in) throw std::runtime_error("png decode: " + OIIO::geterror());
    const auto &spec = in->spec();
    w = spec.width;
    h = spec.height;
    channels = spec.nchannels;
    std::vector<uint8_t> pixels(size_t(w) * size_t(h) * size_t(channels));
    in->read_image(0, 0, 0, channels, OIIO::TypeDesc::UINT8, pixels.data());
    return pixels;
}

} // namespace volcast::test
