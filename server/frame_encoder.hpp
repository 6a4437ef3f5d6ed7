#pragma once
// Frames encoded in memory for the wire: JPEG through libjpeg-turbo's TurboJPEG API (one
// compressor kept per thread), PNG through libpng at zlib level 1 with the Sub filter. Image
// files (volcast-render's EXR, TIFF, PNG) go through OpenImageIO instead, in the renderer.
// The renderer's images are premultiplied float RGBA.
//  - JPEG has no alpha: the premultiplied colour is the image composited over black, as
//    volcast-render's .png writer does (renderer/model/image.cpp).
//  - PNG (the final frame) is lossless RGBA: protocol/README.md's "premultiplied RGBA as 8-bit
//    straight RGBA", so a client can composite it over any background. toStraightRgba8 is the
//    conversion, exposed so tests can reproduce it byte for byte.

#include "renderer/common/frame_renderer.hpp"
#include "renderer/model/image.hpp"

#include <cstdint>
#include <string>
#include <vector>

namespace volcast::server {

// 8-bit RGB over black: round(clamp(c) · 255), as renderer/model/image.cpp writes .png files.
std::vector<uint8_t> toRgb8OverBlack(const Image &image);
// 8-bit straight RGBA: A = round(a · 255), C = round(min(c / a, 1) · 255) (0 where a = 0).
std::vector<uint8_t> toStraightRgba8(const Image &image);

// The libraries that encode, with their versions (for benchmark records).
std::string encoderDescription();

// Throw std::runtime_error with the library's message on failure.
std::vector<uint8_t> encodeJpeg(const Image &image, int quality);
// The same JPEG from the frame's 8-bit RGBA (FrameRenderer::renderRgba8: the bytes the float
// image's encoding converts to), alpha ignored: over black.
std::vector<uint8_t> encodeJpeg(const Rgba8Image &image, int quality);
// zlib level 1: ~5x faster than the default for ~20 % more bytes (docs/platform.md).
std::vector<uint8_t> encodePng(const Image &image, int compressionLevel = 1);

} // namespace volcast::server
