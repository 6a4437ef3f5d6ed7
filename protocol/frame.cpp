#include "protocol/frame.hpp"

#include "protocol/read_error.hpp"
#include "protocol/version.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <stdexcept>

namespace volcast::protocol {

using json = nlohmann::json;
using detail::Fields;

namespace {

constexpr int kMaxFrameSide = 1 << 16;   // pixels; JPEG's own limit is 65535
constexpr int kMaxRestPass = 64;         // passes at rest; the server makes at most a few

constexpr std::array<std::pair<Codec, std::string_view>, 2> kCodecs{{
    {Codec::Jpeg, "jpeg"},
    {Codec::Png, "png"},
}};

void requireFinite(double v, const char *what) {
    if (!std::isfinite(v) || v < 0)
        throw std::invalid_argument(std::string("frame header: ") + what +
                                    " must be a finite non-negative number");
}

json headerToJson(const FrameHeader &h, size_t imageBytes) {
    if (h.width <= 0 || h.height <= 0 || h.width > kMaxFrameSide || h.height > kMaxFrameSide)
        throw std::invalid_argument("frame header: width and height must be in [1, 65536]");
    const int viewWidth = h.viewWidth == 0 ? h.width : h.viewWidth, viewHeight = h.viewHeight == 0 ? h.height : h.viewHeight;
    if (viewWidth < h.width || viewHeight < h.height || viewWidth > kMaxFrameSide || viewHeight > kMaxFrameSide)
        throw std::invalid_argument("frame header: view_width and view_height must be in [width, 65536] and [height, 65536]");
    if (h.level < 0) throw std::invalid_argument("frame header: level must not be negative");
    if (h.restPass < 0 || h.restPass > kMaxRestPass)
        throw std::invalid_argument("frame header: rest_pass must be in [0, " + std::to_string(kMaxRestPass) + "]");
    requireFinite(h.renderMs, "render_ms");
    requireFinite(h.encodeMs, "encode_ms");
    json error = nullptr;
    if (h.error) {
        requireFinite(h.error->value, "error.value");
        if (h.error->method.empty()) throw std::invalid_argument("frame header: error.method is empty");
        error = {{"value", h.error->value}, {"method", h.error->method}};
    }
    json header{{"seq", h.seq},
            {"request", h.request},
            {"level", h.level},
            {"quality", h.quality},
            {"width", h.width},
            {"height", h.height},
            {"codec", codecName(h.codec)},
            {"render_ms", h.renderMs},
            {"encode_ms", h.encodeMs},
            {"error", error},
            {"final", h.final},
            {"camera", h.camera},
            {"image_bytes", imageBytes}};
    // The view's size where it is set (the server always sets it; older headers lack it).
    if (h.viewWidth != 0) header["view_width"] = viewWidth;
    if (h.viewHeight != 0) header["view_height"] = viewHeight;
    // Only on a level the server lowered to stay within its limits: older headers lack it.
    if (!h.limited.empty()) header["limited"] = h.limited;
    // Only on a pass at rest: older headers lack it.
    if (h.restPass != 0) header["rest_pass"] = h.restPass;
    return header;
}

uint32_t readUint32LE(std::span<const uint8_t> bytes) {
    return uint32_t(bytes[0]) | uint32_t(bytes[1]) << 8 | uint32_t(bytes[2]) << 16 |
           uint32_t(bytes[3]) << 24;
}

// A short, printable rendering of bytes that should have been the magic.
std::string shownBytes(std::span<const uint8_t> bytes) {
    std::string out;
    for (uint8_t b : bytes) {
        if (b >= 0x20 && b < 0x7f && b != '\\') {
            out += char(b);
        } else {
            static constexpr char kHex[] = "0123456789ABCDEF";
            out += "\\x";
            out += kHex[b >> 4];
            out += kHex[b & 15];
        }
    }
    return out;
}

// A time or an error estimate: finite (number) and not negative, as headerToJson requires,
// so that every header a client accepts is one a server could have sent.
double nonNegative(const json &j, const std::string &path) {
    const double v = detail::number(j, path);
    if (v < 0) detail::badField(path, "must not be negative, got " + json(v).dump());
    return v;
}

FrameHeader readHeader(const json &root, uint64_t &imageBytes) {
    // Clients ignore header fields they do not know: a newer server may add some.
    const Fields f(root, "", {}, Fields::Unknown::Ignore);
    FrameHeader h;
    h.seq = detail::unsignedInteger(f.require("seq"), "seq");
    if (const json *r = f.find("request")) h.request = detail::requestId(*r, "request", kMaxFrameHeaderBytes);
    h.level = int(detail::integer(f.require("level"), "level", 0, 1 << 20));
    if (const json *q = f.find("quality"); q && !q->is_null()) h.quality = detail::object(*q, "quality");
    h.width = int(detail::integer(f.require("width"), "width", 1, kMaxFrameSide));
    h.height = int(detail::integer(f.require("height"), "height", 1, kMaxFrameSide));
    // The view's size; absent (0) from older servers, which sent frames at it.
    if (const json *v = f.find("view_width"); v && !v->is_null())
        h.viewWidth = int(detail::integer(*v, "view_width", h.width, kMaxFrameSide));
    if (const json *v = f.find("view_height"); v && !v->is_null())
        h.viewHeight = int(detail::integer(*v, "view_height", h.height, kMaxFrameSide));
    const std::string codec = detail::string(f.require("codec"), "codec", 64);
    bool known = false;
    for (const auto &[c, name] : kCodecs)
        if (name == codec) h.codec = c, known = true;
    if (!known) detail::badField("codec", "unknown codec " + json(codec).dump() + " (known: jpeg, png)");
    h.renderMs = nonNegative(f.require("render_ms"), "render_ms");
    h.encodeMs = nonNegative(f.require("encode_ms"), "encode_ms");
    if (const json *e = f.find("error"); e && !e->is_null()) {
        const Fields ef(*e, "error", {}, Fields::Unknown::Ignore);
        h.error = ErrorEstimate{nonNegative(ef.require("value"), ef.pathOf("value")),
                                detail::string(ef.require("method"), ef.pathOf("method"), 256)};
        if (h.error->method.empty()) detail::badField(ef.pathOf("method"), "must not be empty");
    }
    h.final = detail::boolean(f.require("final"), "final");
    if (const json *c = f.find("camera"); c && !c->is_null()) h.camera = detail::object(*c, "camera");
    if (const json *l = f.find("limited"); l && !l->is_null()) h.limited = detail::string(*l, "limited", 1024);
    if (const json *r = f.find("rest_pass"); r && !r->is_null())
        h.restPass = int(detail::integer(*r, "rest_pass", 0, kMaxRestPass));
    imageBytes = detail::unsignedInteger(f.require("image_bytes"), "image_bytes");
    return h;
}

} // namespace

std::string_view codecName(Codec codec) {
    for (const auto &[c, name] : kCodecs)
        if (c == codec) return name;
    return "jpeg";
}

std::vector<uint8_t> encodeFrame(const FrameHeader &header, std::span<const uint8_t> image) {
    const std::string text = headerToJson(header, image.size()).dump();
    if (text.size() > kMaxFrameHeaderBytes)
        throw std::invalid_argument("frame header: " + std::to_string(text.size()) +
                                    " bytes, over the limit of " + std::to_string(kMaxFrameHeaderBytes));
    const auto length = uint32_t(text.size());
    // Sized once and filled by copy: g++ 12 misreads reserve + insert as an overflow.
    std::vector<uint8_t> out(kFramePreambleBytes + text.size() + image.size());
    std::copy(kFrameMagic.begin(), kFrameMagic.end(), out.begin());
    // Header length, little-endian whatever the host's byte order.
    for (size_t i = 0; i < 4; ++i) out[4 + i] = uint8_t(length >> (8 * i));
    std::copy(text.begin(), text.end(), out.begin() + kFramePreambleBytes);
    std::copy(image.begin(), image.end(), out.begin() + std::ptrdiff_t(kFramePreambleBytes + text.size()));
    return out;
}

DecodedFrame decodeFrame(std::span<const uint8_t> message) {
    if (message.size() < kFramePreambleBytes)
        throw DecodeError("frame: " + std::to_string(message.size()) + " bytes, shorter than the " +
                          std::to_string(kFramePreambleBytes) + "-byte preamble (magic and header length)");
    if (!std::equal(kFrameMagic.begin(), kFrameMagic.end(), message.begin()))
        throw DecodeError("frame: starts with \"" + shownBytes(message.first(4)) +
                          "\", not the magic \"VCF1\"");
    const uint32_t length = readUint32LE(message.subspan(4, 4));
    const size_t rest = message.size() - kFramePreambleBytes;
    if (length > kMaxFrameHeaderBytes)
        throw DecodeError("frame: header length " + std::to_string(length) + " is over the limit of " +
                          std::to_string(kMaxFrameHeaderBytes) + " bytes");
    if (length > rest)
        throw DecodeError("frame: header length " + std::to_string(length) + " runs past the message's end (" +
                          std::to_string(rest) + " bytes follow the preamble); truncated?");
    const auto headerBytes = message.subspan(kFramePreambleBytes, length);
    const std::string_view text(reinterpret_cast<const char *>(headerBytes.data()), headerBytes.size());
    DecodedFrame frame;
    uint64_t imageBytes = 0;
    try {
        frame.header = readHeader(detail::parseText(text, 64).value, imageBytes);
    } catch (const detail::ReadError &e) {
        throw DecodeError(std::string("frame header: ") + e.what());
    } catch (const detail::FieldError &e) {
        throw DecodeError("frame header: " + detail::messageOf(e));
    }
    frame.image = message.subspan(kFramePreambleBytes + length);
    if (frame.image.size() != imageBytes)
        throw DecodeError("frame: the header's image_bytes is " + std::to_string(imageBytes) + " but " +
                          std::to_string(frame.image.size()) + " bytes follow the header" +
                          (frame.image.size() < imageBytes ? "; truncated?" : ""));
    return frame;
}

} // namespace volcast::protocol
