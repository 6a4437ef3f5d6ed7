#include "server/frame_encoder.hpp"

#include "renderer/common/frame_renderer.hpp"

#include <jconfig.h>   // LIBJPEG_TURBO_VERSION_NUMBER
#include <png.h>
#include <turbojpeg.h>
#include <zlib.h>

#include <algorithm>
#include <cmath>
#include <csetjmp>
#include <cstdio>
#include <cstring>
#include <memory>
#include <new>
#include <stdexcept>
#include <string>

namespace volcast::server {

namespace {

// Bytes come from the one float-to-byte conversion (clampUnit, byteFromUnit in
// renderer/common/frame_renderer.hpp), which a device's conversion kernel reproduces bit for bit.

// Buffers up to a 2560×1600 viewport's are kept per thread; larger ones (a still's) are let go.
constexpr int kKeptWidth = 2560, kKeptHeight = 1600;

// A buffer kept per thread between frames: a fresh one per 1080p frame (8 MB) cost more in
// page faults and zeroing than encoding the JPEG does. Viewport-sized buffers are kept; one
// grown for a large still is let go after it.
class Scratch {
  public:
    uint8_t *get(size_t bytes) {
        if (bytes > size_) {
            data_ = std::make_unique_for_overwrite<uint8_t[]>(bytes);
            size_ = bytes;
        }
        return data_.get();
    }
    void trim() {
        if (size_ > kKeptBytes) {
            data_.reset();
            size_ = 0;
        }
    }

  private:
    static constexpr size_t kKeptBytes = size_t(kKeptWidth) * kKeptHeight * 4;
    std::unique_ptr<uint8_t[]> data_;
    size_t size_ = 0;
};

// Every float to 8 bits, in order: RGBA stays RGBA (JPEG reads it as RGBX).
void toRgbx8OverBlack(const Image &image, uint8_t *out) {
    const float *in = image.rgba.data();
    for (size_t i = 0, n = image.rgba.size(); i < n; ++i) out[i] = byteFromUnit(clampUnit(in[i]));
}

void toStraightRgba8(const Image &image, uint8_t *out) {
    const float *in = image.rgba.data();
    for (size_t i = 0, n = size_t(image.width) * size_t(image.height); i < n; ++i) {
        const float a = clampUnit(in[i * 4 + 3]);
        const float divisor = a > 0.0f ? a : 1.0f;   // where a is 0 the quotient is not used
        for (size_t c = 0; c < 3; ++c) out[i * 4 + c] = a > 0.0f ? byteFromUnit(clampUnit(in[i * 4 + c] / divisor)) : 0;
        out[i * 4 + 3] = byteFromUnit(a);
    }
}

// One TurboJPEG compressor per thread, kept, with its output buffer: making one allocates
// its tables (trame keeps one too). Frames are encoded on the render workers, never two at
// once on one thread.
struct Compressor {
    tjhandle handle = tjInitCompress();
    unsigned char *out = nullptr;   // tjAlloc'd, tjBufSize bytes for the last size
    unsigned long capacity = 0;
    ~Compressor() {
        tjFree(out);
        if (handle) tjDestroy(handle);
    }
};

// libpng reports errors by longjmp: no C++ object with a destructor may live between the
// setjmp and the calls that can jump, so the PNG is written by this C-style function.
struct PngSink {
    std::vector<uint8_t> *out;
    char error[200];
};
void pngWrite(png_structp png, png_bytep data, png_size_t n) {
    auto *sink = static_cast<PngSink *>(png_get_io_ptr(png));
    bool stored = true;
    try {
        sink->out->insert(sink->out->end(), data, data + n);
    } catch (const std::bad_alloc &) {
        stored = false;   // png_error jumps: not from inside the handler, where an exception is live
    }
    if (!stored) png_error(png, "out of memory");
}
void pngFlush(png_structp) {}
[[noreturn]] void pngError(png_structp png, png_const_charp message) {
    auto *sink = static_cast<PngSink *>(png_get_error_ptr(png));
    std::snprintf(sink->error, sizeof sink->error, "%s", message);
    png_longjmp(png, 1);
}
void pngWarning(png_structp, png_const_charp) {}

// Returns false with sink.error set on failure.
bool writePng(PngSink &sink, const uint8_t *rgba, int width, int height, int level, png_bytep *rows) {
    png_structp png = png_create_write_struct(PNG_LIBPNG_VER_STRING, &sink, pngError, pngWarning);
    if (!png) {
        std::snprintf(sink.error, sizeof sink.error, "cannot create the PNG writer");
        return false;
    }
    png_infop info = png_create_info_struct(png);
    if (!info || setjmp(png_jmpbuf(png))) {
        png_destroy_write_struct(&png, info ? &info : nullptr);
        if (!sink.error[0]) std::snprintf(sink.error, sizeof sink.error, "cannot create the PNG header");
        return false;
    }
    png_set_write_fn(png, &sink, pngWrite, pngFlush);
    png_set_IHDR(png, info, png_uint_32(width), png_uint_32(height), 8, PNG_COLOR_TYPE_RGB_ALPHA, PNG_INTERLACE_NONE,
                 PNG_COMPRESSION_TYPE_DEFAULT, PNG_FILTER_TYPE_DEFAULT);
    png_set_compression_level(png, level);
    // One filter, Sub, for every row: libpng's default tries all five per row and keeps the
    // best, which costs more than the deflate at level 1 does.
    png_set_filter(png, PNG_FILTER_TYPE_BASE, PNG_FILTER_SUB);
    for (int y = 0; y < height; ++y) rows[y] = const_cast<png_bytep>(rgba + size_t(y) * size_t(width) * 4);
    png_set_rows(png, info, rows);
    png_write_png(png, info, PNG_TRANSFORM_IDENTITY, nullptr);
    png_destroy_write_struct(&png, &info);
    return true;
}

} // namespace

std::vector<uint8_t> toRgb8OverBlack(const Image &image) {
    const size_t n = size_t(image.width) * size_t(image.height);
    std::vector<uint8_t> rgb(n * 3);
    const float *in = image.rgba.data();
    uint8_t *out = rgb.data();
    for (size_t i = 0; i < n; ++i)
        for (size_t c = 0; c < 3; ++c) out[i * 3 + c] = byteFromUnit(clampUnit(in[i * 4 + c]));
    return rgb;
}

std::vector<uint8_t> toStraightRgba8(const Image &image) {
    std::vector<uint8_t> rgba(size_t(image.width) * size_t(image.height) * 4);
    toStraightRgba8(image, rgba.data());
    return rgba;
}

std::string encoderDescription() {
    return std::string("libjpeg-turbo ") + std::to_string(LIBJPEG_TURBO_VERSION_NUMBER / 1000000) + "." +
           std::to_string(LIBJPEG_TURBO_VERSION_NUMBER / 1000 % 1000) + "." +
           std::to_string(LIBJPEG_TURBO_VERSION_NUMBER % 1000) + " (TurboJPEG, 4:2:0); libpng " + PNG_LIBPNG_VER_STRING +
           " (Sub filter) on zlib " + zlibVersion();
}

namespace {

// JPEG of 8-bit RGBX (the alpha byte ignored) through the thread's kept compressor.
std::vector<uint8_t> encodeJpegRgbx(const uint8_t *pixels, int width, int height, int quality) {
    thread_local Compressor compressor;
    if (!compressor.handle) throw std::runtime_error("encoding a JPEG: " + std::string(tjGetErrorStr2(nullptr)));
    const unsigned long worst = tjBufSize(width, height, TJSAMP_420);
    if (worst == static_cast<unsigned long>(-1) || worst > unsigned(INT32_MAX)) throw std::runtime_error("encoding a JPEG: the image is too large");
    if (worst > compressor.capacity) {
        tjFree(compressor.out);
        compressor.out = tjAlloc(int(worst));
        compressor.capacity = compressor.out ? worst : 0;
        if (!compressor.out) throw std::runtime_error("encoding a JPEG: out of memory");
    }
    unsigned long bytes = compressor.capacity;
    // libjpeg's defaults: 4:2:0 chroma and the accurate integer DCT.
    const int failed = tjCompress2(compressor.handle, pixels, width, 0, height, TJPF_RGBX, &compressor.out, &bytes,
                                   TJSAMP_420, quality, TJFLAG_ACCURATEDCT | TJFLAG_NOREALLOC);
    if (failed) throw std::runtime_error("encoding a JPEG: " + std::string(tjGetErrorStr2(compressor.handle)));
    std::vector<uint8_t> out(compressor.out, compressor.out + bytes);
    if (compressor.capacity > tjBufSize(kKeptWidth, kKeptHeight, TJSAMP_420)) {
        tjFree(compressor.out);
        compressor.out = nullptr;
        compressor.capacity = 0;
    }
    return out;
}

} // namespace

std::vector<uint8_t> encodeJpeg(const Rgba8Image &image, int quality) {
    if (image.width < 1 || image.height < 1) throw std::runtime_error("encoding a JPEG: the image is empty");
    if (image.rgba.size() != size_t(image.width) * size_t(image.height) * 4)
        throw std::runtime_error("encoding a JPEG: the pixels do not match the image's size");
    return encodeJpegRgbx(image.rgba.data(), image.width, image.height, quality);
}

std::vector<uint8_t> encodeJpeg(const Image &image, int quality) {
    if (image.width < 1 || image.height < 1) throw std::runtime_error("encoding a JPEG: the image is empty");
    thread_local Scratch rgbx;
    uint8_t *pixels = rgbx.get(image.rgba.size());
    toRgbx8OverBlack(image, pixels);
    std::vector<uint8_t> out;
    try {
        out = encodeJpegRgbx(pixels, image.width, image.height, quality);
    } catch (...) {
        rgbx.trim();
        throw;
    }
    rgbx.trim();
    return out;
}

std::vector<uint8_t> encodePng(const Image &image, int compressionLevel) {
    if (image.width < 1 || image.height < 1) throw std::runtime_error("encoding a PNG: the image is empty");
    thread_local Scratch rgba;
    const size_t bytes = size_t(image.width) * size_t(image.height) * 4;
    uint8_t *pixels = rgba.get(bytes);
    toStraightRgba8(image, pixels);
    std::vector<png_bytep> rows(size_t(image.height));
    std::vector<uint8_t> out;
    out.reserve(bytes / 4);
    PngSink sink{&out, {}};
    const bool written = writePng(sink, pixels, image.width, image.height, compressionLevel, rows.data());
    rgba.trim();
    if (!written) throw std::runtime_error(std::string("encoding a PNG: ") + sink.error);
    return out;
}

} // namespace volcast::server
