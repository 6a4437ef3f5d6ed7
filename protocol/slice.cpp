#include "protocol/slice.hpp"

#include "protocol/frame.hpp"
#include "protocol/read_error.hpp"
#include "protocol/utf8.hpp"

#include <algorithm>
#include <cmath>
#include <stdexcept>

namespace volcast::protocol {

using json = nlohmann::json;
using detail::Fields;

namespace {

constexpr std::array<std::string_view, 3> kAxes = {"axial", "coronal", "sagittal"};

std::array<double, 3> vec3(const json &j, const std::string &path) {
    detail::array(j, path);
    if (j.size() != 3) detail::badField(path, "must have 3 numbers, got " + std::to_string(j.size()));
    std::array<double, 3> v{};
    for (size_t i = 0; i < 3; ++i) v[i] = detail::number(j[i], detail::element(path, i));
    return v;
}

void requireFinite(double v, const char *what) {
    if (!std::isfinite(v)) throw std::invalid_argument(std::string("slice header: ") + what + " must be finite");
}

uint32_t readUint32LE(std::span<const uint8_t> b) {
    return uint32_t(b[0]) | uint32_t(b[1]) << 8 | uint32_t(b[2]) << 16 | uint32_t(b[3]) << 24;
}

constexpr std::array<std::string_view, 3> kSlabModes = {"mip", "minip", "mean"};

} // namespace

namespace detail {

std::array<double, 3> readVec3(const json &j, const std::string &path) { return vec3(j, path); }

std::string readSliceAxis(const json &j, const std::string &path) {
    std::string axis = string(j, path, 64);
    if (std::find(kAxes.begin(), kAxes.end(), axis) == kAxes.end())
        badField(path, "must be \"axial\", \"coronal\" or \"sagittal\", got " +
                           json(quotableText(axis, kMaxQuotedBytes)).dump());
    return axis;
}

SliceRequest readSliceRequest(const json &root, const RequestId &id) {
    const Fields f(root, "",
                   {"type", "id", "axis", "point", "center", "width", "height", "pixel_spacing", "window", "level",
                    "slab"});
    SliceRequest m;
    m.id = id;
    m.axis = readSliceAxis(f.require("axis"), "axis");
    if (const json *p = f.find("point")) m.point = vec3(*p, "point");
    if (const json *c = f.find("center")) m.center = vec3(*c, "center");
    m.width = int(integer(f.require("width"), "width", 1, kMaxSliceSide));
    m.height = int(integer(f.require("height"), "height", 1, kMaxSliceSide));
    if (const json *s = f.find("pixel_spacing")) {
        m.pixelSpacing = number(*s, "pixel_spacing");
        if (!(*m.pixelSpacing > 0)) badField("pixel_spacing", "must be > 0, got " + s->dump());
    }
    if (const json *w = f.find("window")) {
        m.window = number(*w, "window");
        if (!(*m.window > 0)) badField("window", "must be > 0, got " + w->dump());
    }
    if (const json *l = f.find("level")) m.level = number(*l, "level");
    if (const json *slab = f.find("slab")) {
        const Fields sf(object(*slab, "slab"), "slab", {"thickness", "mode"});
        SliceSlab s;
        s.thickness = number(sf.require("thickness"), sf.pathOf("thickness"));
        if (!(s.thickness >= 0)) badField(sf.pathOf("thickness"), "must be >= 0 mm, got " + sf.require("thickness").dump());
        if (const json *mode = sf.find("mode")) {
            s.mode = string(*mode, sf.pathOf("mode"), 64);
            if (std::find(kSlabModes.begin(), kSlabModes.end(), s.mode) == kSlabModes.end())
                badField(sf.pathOf("mode"), "must be \"mip\", \"minip\" or \"mean\", got " +
                                                json(quotableText(s.mode, kMaxQuotedBytes)).dump());
        }
        m.slab = s;
    }
    return m;
}

json sliceRequestFields(const SliceRequest &m) {
    json j{{"axis", m.axis}, {"width", m.width}, {"height", m.height}};
    if (m.point) j["point"] = *m.point;
    if (m.center) j["center"] = *m.center;
    if (m.pixelSpacing) j["pixel_spacing"] = *m.pixelSpacing;
    if (m.window) j["window"] = *m.window;
    if (m.level) j["level"] = *m.level;
    if (m.slab) j["slab"] = {{"thickness", m.slab->thickness}, {"mode", m.slab->mode}};
    return j;
}

} // namespace detail

bool isSliceMessage(std::span<const uint8_t> message) {
    return message.size() >= 4 && std::equal(kSliceMagic.begin(), kSliceMagic.end(), message.begin());
}

std::vector<uint8_t> encodeSlice(const SliceHeader &h, std::span<const uint8_t> pixels) {
    if (h.width < 1 || h.height < 1 || h.width > kMaxSliceSide || h.height > kMaxSliceSide)
        throw std::invalid_argument("slice header: width and height must be in [1, " +
                                    std::to_string(kMaxSliceSide) + "]");
    if (pixels.size() != size_t(h.width) * size_t(h.height))
        throw std::invalid_argument("slice: " + std::to_string(pixels.size()) + " pixel bytes for " +
                                    std::to_string(h.width) + " x " + std::to_string(h.height));
    requireFinite(h.pixelSpacing, "pixel_spacing");
    requireFinite(h.window, "window");
    requireFinite(h.level, "level");
    requireFinite(h.renderMs, "render_ms");
    for (const auto *v : {&h.origin, &h.column, &h.row, &h.point})
        for (double x : *v) requireFinite(x, "origin, column, row and point");
    json header{{"request", h.request},   {"axis", h.axis},   {"width", h.width},
                {"height", h.height},     {"format", h.format}, {"pixel_spacing", h.pixelSpacing},
                {"origin", h.origin},     {"column", h.column}, {"row", h.row},
                {"point", h.point},       {"window", h.window}, {"level", h.level},
                {"render_ms", h.renderMs}, {"image_bytes", pixels.size()}};
    if (h.slab) {
        requireFinite(h.slab->thickness, "slab.thickness");
        header["slab"] = {{"thickness", h.slab->thickness}, {"mode", h.slab->mode}, {"planes", h.slabPlanes}};
    }
    const std::string text = header.dump();
    std::vector<uint8_t> out(kFramePreambleBytes + text.size() + pixels.size());
    std::copy(kSliceMagic.begin(), kSliceMagic.end(), out.begin());
    const auto length = uint32_t(text.size());
    for (size_t i = 0; i < 4; ++i) out[4 + i] = uint8_t(length >> (8 * i));
    std::copy(text.begin(), text.end(), out.begin() + kFramePreambleBytes);
    std::copy(pixels.begin(), pixels.end(), out.begin() + std::ptrdiff_t(kFramePreambleBytes + text.size()));
    return out;
}

DecodedSlice decodeSlice(std::span<const uint8_t> message) {
    if (message.size() < kFramePreambleBytes)
        throw DecodeError("slice: " + std::to_string(message.size()) + " bytes, shorter than the 8-byte preamble");
    if (!isSliceMessage(message)) throw DecodeError("slice: does not start with the magic \"VCS1\"");
    const uint32_t length = readUint32LE(message.subspan(4, 4));
    if (length > kMaxFrameHeaderBytes || length > message.size() - kFramePreambleBytes)
        throw DecodeError("slice: header length " + std::to_string(length) + " runs past the message's end or over " +
                          std::to_string(kMaxFrameHeaderBytes) + " bytes");
    const auto bytes = message.subspan(kFramePreambleBytes, length);
    DecodedSlice out;
    uint64_t imageBytes = 0;
    try {
        const json root =
            detail::parseText(std::string_view(reinterpret_cast<const char *>(bytes.data()), bytes.size()), 64).value;
        detail::object(root, "header");
        const Fields f(root, "", {}, Fields::Unknown::Ignore);
        SliceHeader &h = out.header;
        if (const json *r = f.find("request")) h.request = detail::requestId(*r, "request", kMaxFrameHeaderBytes);
        h.axis = detail::string(f.require("axis"), "axis", 64);
        h.width = int(detail::integer(f.require("width"), "width", 1, kMaxSliceSide));
        h.height = int(detail::integer(f.require("height"), "height", 1, kMaxSliceSide));
        h.format = detail::string(f.require("format"), "format", 64);
        if (h.format != "gray8") detail::badField("format", "unknown pixel format " + json(h.format).dump());
        h.pixelSpacing = detail::number(f.require("pixel_spacing"), "pixel_spacing");
        h.origin = vec3(f.require("origin"), "origin");
        h.column = vec3(f.require("column"), "column");
        h.row = vec3(f.require("row"), "row");
        h.point = vec3(f.require("point"), "point");
        h.window = detail::number(f.require("window"), "window");
        h.level = detail::number(f.require("level"), "level");
        h.renderMs = detail::number(f.require("render_ms"), "render_ms");
        imageBytes = detail::unsignedInteger(f.require("image_bytes"), "image_bytes");
        if (const json *slab = f.find("slab")) {
            const Fields sf(*slab, "slab", {}, Fields::Unknown::Ignore);
            SliceSlab s;
            s.thickness = detail::number(sf.require("thickness"), sf.pathOf("thickness"));
            s.mode = detail::string(sf.require("mode"), sf.pathOf("mode"), 64);
            h.slab = s;
            if (sf.find("planes"))
                h.slabPlanes = int(detail::integer(sf.require("planes"), sf.pathOf("planes"), 1, 1 << 20));
        }
    } catch (const detail::ReadError &e) {
        throw DecodeError(std::string("slice header: ") + e.what());
    } catch (const detail::FieldError &e) {
        throw DecodeError("slice header: " + detail::messageOf(e));
    }
    out.pixels = message.subspan(kFramePreambleBytes + length);
    const uint64_t expected = uint64_t(out.header.width) * uint64_t(out.header.height);
    if (imageBytes != expected || out.pixels.size() != expected)
        throw DecodeError("slice: " + std::to_string(out.pixels.size()) + " pixel bytes (header says " +
                          std::to_string(imageBytes) + ") for " + std::to_string(out.header.width) + " x " +
                          std::to_string(out.header.height) + " gray8 pixels");
    return out;
}

} // namespace volcast::protocol
