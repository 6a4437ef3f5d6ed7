#include "protocol/client_messages.hpp"

#include "protocol/read_error.hpp"
#include "protocol/utf8.hpp"
#include "protocol/version.hpp"

#include <algorithm>
#include <array>
#include <utility>

namespace volcast::protocol {

using json = nlohmann::json;
using detail::badField;
using detail::fail;
using detail::Fields;
using detail::ReadError;

namespace detail {

QualityPolicy readQualityPolicy(const Fields &f) {
    QualityPolicy policy;
    const std::string mode = string(f.require("mode"), f.pathOf("mode"), 64);
    if (mode == "automatic") {
        policy.mode = QualityMode::Automatic;
        if (const json *ms = f.find("target_frame_ms")) {
            policy.targetFrameMs = number(*ms, f.pathOf("target_frame_ms"));
            if (!(policy.targetFrameMs > 0 && policy.targetFrameMs <= kMaxTargetFrameMs))
                badField(f.pathOf("target_frame_ms"),
                         "must be in (0, " + json(kMaxTargetFrameMs).dump() + "] ms, got " + ms->dump());
        }
        if (const json *q = f.find("quality")) policy.quality = object(*q, f.pathOf("quality"));
    } else if (mode == "explicit") {
        policy.mode = QualityMode::Explicit;
        // An explicit policy renders every frame alike, so a frame-time target means nothing.
        if (f.find("target_frame_ms"))
            badField(f.pathOf("target_frame_ms"), "is only for mode \"automatic\"");
        policy.quality = object(f.require("quality"), f.pathOf("quality"));
    } else {
        badField(f.pathOf("mode"), "must be \"automatic\" or \"explicit\", got " + json(mode).dump());
    }
    return policy;
}

} // namespace detail

namespace {

// Each reader gets the whole message object; the id is already read. The known fields of
// each list "type" and "id" too, so that any other key is refused as unknown.
using Reader = ClientMessage (*)(const json &root, const RequestId &id, const Limits &limits);

ClientMessage readHello(const json &root, const RequestId &id, const Limits &limits) {
    const Fields f(root, "", {"type", "id", "protocol", "token", "client"});
    HelloRequest m;
    m.id = id;
    // Any integer is read first, so that "protocol": 2 gets unsupported_version, not bad_field.
    const int64_t version = detail::integer(f.require("protocol"), "protocol", 0, 1 << 30);
    if (version < kMinProtocolVersion || version > kProtocolVersion)
        fail(ErrorCode::UnsupportedVersion,
             "protocol version " + std::to_string(version) + " is not supported; this server speaks " +
                 (kMinProtocolVersion == kProtocolVersion
                      ? std::to_string(kProtocolVersion)
                      : std::to_string(kMinProtocolVersion) + " to " + std::to_string(kProtocolVersion)));
    m.protocol = int(version);
    if (const json *token = f.find("token")) m.token = detail::string(*token, "token", limits.maxTokenBytes);
    if (const json *client = f.find("client")) m.client = detail::string(*client, "client", 256);
    return m;
}

template <class Request>
ClientMessage readBare(const json &root, const RequestId &id, const Limits &) {
    const Fields f(root, "", {"type", "id"});
    Request m;
    m.id = id;
    return m;
}

ClientMessage readOpenVolume(const json &root, const RequestId &id, const Limits &limits) {
    const Fields f(root, "", {"type", "id", "name"});
    OpenVolumeRequest m;
    m.id = id;
    // The length is judged by validateVolumeName, with its own code; the bound here only
    // keeps an absurd string out of the error message.
    m.name = detail::string(f.require("name"), "name", std::string::npos);
    if (const auto problem = validateVolumeName(m.name, limits.maxVolumeNameBytes)) {
        fail(ErrorCode::BadVolumeName,
             "volume name " + json(quotableText(m.name, detail::kMaxQuotedBytes)).dump() + " " + *problem);
    }
    return m;
}

ClientMessage readCamera(const json &root, const RequestId &id, const Limits &) {
    const Fields f(root, "", {"type", "id", "camera"});
    return CameraRequest{id, detail::object(f.require("camera"), "camera")};
}

ClientMessage readViewport(const json &root, const RequestId &id, const Limits &) {
    const Fields f(root, "", {"type", "id", "image"});
    return ViewportRequest{id, detail::object(f.require("image"), "image")};
}

ClientMessage readTransferFunction(const json &root, const RequestId &id, const Limits &) {
    const Fields f(root, "", {"type", "id", "transfer_function"});
    return TransferFunctionRequest{id, detail::object(f.require("transfer_function"), "transfer_function")};
}

ClientMessage readQualityPolicyRequest(const json &root, const RequestId &id, const Limits &) {
    const Fields f(root, "", {"type", "id", "mode", "target_frame_ms", "quality"});
    return QualityPolicyRequest{id, detail::readQualityPolicy(f)};
}

ClientMessage readClipPlanes(const json &root, const RequestId &id, const Limits &) {
    const Fields f(root, "", {"type", "id", "clip_planes"});
    return ClipPlanesRequest{id, detail::array(f.require("clip_planes"), "clip_planes")};
}

ClientMessage readStill(const json &root, const RequestId &id, const Limits &) {
    const Fields f(root, "", {"type", "id", "image"});
    StillRequest m;
    m.id = id;
    if (const json *image = f.find("image")) m.image = detail::object(*image, "image");
    return m;
}

ClientMessage readSlice(const json &root, const RequestId &id, const Limits &) {
    return detail::readSliceRequest(root, id);
}

ClientMessage readProbe(const json &root, const RequestId &id, const Limits &) {
    const Fields f(root, "", {"type", "id", "point"});
    ProbeRequest m;
    m.id = id;
    m.point = detail::readVec3(f.require("point"), "point");
    return m;
}

ClientMessage readRoiStats(const json &root, const RequestId &id, const Limits &) {
    const Fields f(root, "", {"type", "id", "axis", "center", "radii", "shape"});
    RoiStatsRequest m;
    m.id = id;
    m.axis = detail::readSliceAxis(f.require("axis"), "axis");
    m.center = detail::readVec3(f.require("center"), "center");
    const json &radii = detail::array(f.require("radii"), "radii");
    if (radii.size() != 2) badField("radii", "must have 2 numbers (mm along the pane's column and row), got " +
                                                 std::to_string(radii.size()));
    for (size_t i = 0; i < 2; ++i) {
        m.radii[i] = detail::number(radii[i], detail::element("radii", i));
        if (!(m.radii[i] > 0)) badField(detail::element("radii", i), "must be > 0 mm, got " + radii[i].dump());
    }
    if (const json *shape = f.find("shape")) {
        m.shape = detail::string(*shape, "shape", 64);
        if (m.shape != "ellipse" && m.shape != "rectangle")
            badField("shape", "must be \"ellipse\" or \"rectangle\", got " +
                                  json(quotableText(m.shape, detail::kMaxQuotedBytes)).dump());
    }
    return m;
}

// The same bound as a scene's image side (renderer/model/scene.hpp's kMaxImageSide).
constexpr int kMaxPickImageSide = 16384;

ClientMessage readPick(const json &root, const RequestId &id, const Limits &) {
    const Fields f(root, "", {"type", "id", "x", "y", "width", "height"});
    PickRequest m;
    m.id = id;
    m.width = int(detail::integer(f.require("width"), "width", 1, kMaxPickImageSide));
    m.height = int(detail::integer(f.require("height"), "height", 1, kMaxPickImageSide));
    m.x = detail::number(f.require("x"), "x");
    m.y = detail::number(f.require("y"), "y");
    if (!(m.x >= 0 && m.x <= m.width))
        badField("x", "must be in [0, width] = [0, " + std::to_string(m.width) + "] pixels, got " + f.require("x").dump());
    if (!(m.y >= 0 && m.y <= m.height))
        badField("y", "must be in [0, height] = [0, " + std::to_string(m.height) + "] pixels, got " +
                          f.require("y").dump());
    return m;
}

bool isDigits(std::string_view s) {
    return std::all_of(s.begin(), s.end(), [](char c) { return c >= '0' && c <= '9'; });
}

// A DICOM date (DA): YYYYMMDD with a month 01-12 and a day 01-31.
bool isDicomDate(std::string_view s) {
    if (s.size() != 8 || !isDigits(s)) return false;
    const int month = (s[4] - '0') * 10 + (s[5] - '0'), day = (s[6] - '0') * 10 + (s[7] - '0');
    return month >= 1 && month <= 12 && day >= 1 && day <= 31;
}

// A filter value: printable text that a DICOM attribute of its kind can hold (64 bytes is the
// longest of them, LO and PN components), no control characters and no backslash (DICOM's
// value separator, which would turn one value into a list).
std::string filterText(const Fields &f, std::string_view key) {
    const json *value = f.find(key);
    if (!value) return {};
    const std::string path = f.pathOf(key);
    std::string text = detail::string(*value, path, 64);
    for (unsigned char c : text)
        if (c < 0x20 || c == 0x7f || c == '\\')
            badField(path, "must not hold control characters or backslashes");
    return text;
}

ClientMessage readFindStudies(const json &root, const RequestId &id, const Limits &) {
    const Fields f(root, "", {"type", "id", "source", "filters", "limit"});
    FindStudiesRequest m;
    m.id = id;
    m.source = detail::string(f.require("source"), "source", std::string::npos);
    if (const auto problem = validateSourceName(m.source))
        badField("source", json(quotableText(m.source, detail::kMaxQuotedBytes)).dump() + " " + *problem);
    if (const json *filters = f.find("filters")) {
        const Fields ff(detail::object(*filters, "filters"), "filters",
                        {"patient_name", "patient_id", "study_date", "modality", "accession_number"});
        m.filters.patientName = filterText(ff, "patient_name");
        m.filters.patientId = filterText(ff, "patient_id");
        m.filters.studyDate = filterText(ff, "study_date");
        m.filters.modality = filterText(ff, "modality");
        m.filters.accessionNumber = filterText(ff, "accession_number");
        const std::string &date = m.filters.studyDate;
        if (!date.empty()) {
            const size_t dash = date.find('-');
            const std::string_view from = std::string_view(date).substr(0, dash);
            const std::string_view to = dash == std::string::npos ? std::string_view() : std::string_view(date).substr(dash + 1);
            const bool ok = dash == std::string::npos ? isDicomDate(date)
                                                      : (from.empty() || isDicomDate(from)) &&
                                                            (to.empty() || isDicomDate(to)) && !(from.empty() && to.empty());
            if (!ok)
                badField(ff.pathOf("study_date"), "must be a date YYYYMMDD or a range YYYYMMDD-YYYYMMDD (either end may "
                                                  "be left out), got " + json(quotableText(date, 64)).dump());
        }
        for (char c : m.filters.modality)
            if (!((c >= 'A' && c <= 'Z') || (c >= '0' && c <= '9') || c == '_'))
                badField(ff.pathOf("modality"), "must be a DICOM modality code such as \"CT\" or \"MR\" (capitals, "
                                                "digits, _), got " + json(quotableText(m.filters.modality, 64)).dump());
    }
    if (const json *limit = f.find("limit")) m.limit = int(detail::integer(*limit, "limit", 1, kMaxStudiesLimit));
    return m;
}

struct ReaderEntry {
    std::string_view type;
    Reader read;
};

constexpr std::array<ReaderEntry, std::variant_size_v<ClientMessage>> kReaders{{
    {HelloRequest::kType, readHello},
    {ListVolumesRequest::kType, readBare<ListVolumesRequest>},
    {OpenVolumeRequest::kType, readOpenVolume},
    {CameraRequest::kType, readCamera},
    {InteractionStartRequest::kType, readBare<InteractionStartRequest>},
    {InteractionEndRequest::kType, readBare<InteractionEndRequest>},
    {ViewportRequest::kType, readViewport},
    {TransferFunctionRequest::kType, readTransferFunction},
    {QualityPolicyRequest::kType, readQualityPolicyRequest},
    {ClipPlanesRequest::kType, readClipPlanes},
    {StillRequest::kType, readStill},
    {GetStateRequest::kType, readBare<GetStateRequest>},
    {CloseRequest::kType, readBare<CloseRequest>},
    {SliceRequest::kType, readSlice},
    {FindStudiesRequest::kType, readFindStudies},
    {ProbeRequest::kType, readProbe},
    {RoiStatsRequest::kType, readRoiStats},
    {PickRequest::kType, readPick},
}};

std::string knownTypes() {
    std::string list;
    for (const ReaderEntry &entry : kReaders) list += (list.empty() ? "" : ", ") + std::string(entry.type);
    return list;
}

// The fields of each request besides "type" and "id".
json fieldsOf(const HelloRequest &m) {
    json j{{"protocol", m.protocol}};
    if (m.token) j["token"] = *m.token;
    if (!m.client.empty()) j["client"] = m.client;
    return j;
}
json fieldsOf(const OpenVolumeRequest &m) { return {{"name", m.name}}; }
json fieldsOf(const CameraRequest &m) { return {{"camera", m.camera}}; }
json fieldsOf(const ViewportRequest &m) { return {{"image", m.image}}; }
json fieldsOf(const TransferFunctionRequest &m) { return {{"transfer_function", m.transferFunction}}; }
json fieldsOf(const QualityPolicyRequest &m) { return qualityPolicyToJson(m.policy); }
json fieldsOf(const ClipPlanesRequest &m) { return {{"clip_planes", m.clipPlanes}}; }
json fieldsOf(const StillRequest &m) {
    json j = json::object();
    if (!m.image.is_null()) j["image"] = m.image;
    return j;
}
json fieldsOf(const SliceRequest &m) { return detail::sliceRequestFields(m); }
json fieldsOf(const FindStudiesRequest &m) {
    json filters = json::object();
    const auto add = [&](const char *key, const std::string &value) {
        if (!value.empty()) filters[key] = value;
    };
    add("patient_name", m.filters.patientName);
    add("patient_id", m.filters.patientId);
    add("study_date", m.filters.studyDate);
    add("modality", m.filters.modality);
    add("accession_number", m.filters.accessionNumber);
    return {{"source", m.source}, {"filters", std::move(filters)}, {"limit", m.limit}};
}
json fieldsOf(const ProbeRequest &m) { return {{"point", m.point}}; }
json fieldsOf(const RoiStatsRequest &m) {
    return {{"axis", m.axis}, {"center", m.center}, {"radii", m.radii}, {"shape", m.shape}};
}
json fieldsOf(const PickRequest &m) { return {{"x", m.x}, {"y", m.y}, {"width", m.width}, {"height", m.height}}; }
// The requests with no fields of their own.
template <class Request>
json fieldsOf(const Request &) {
    return json::object();
}

} // namespace

std::optional<std::string> validateSourceName(std::string_view name) {
    if (name.empty()) return "is empty";
    if (name.size() > kMaxSourceNameBytes) return "is longer than " + std::to_string(kMaxSourceNameBytes) + " bytes";
    for (char c : name)
        if (!((c >= 'A' && c <= 'Z') || (c >= 'a' && c <= 'z') || (c >= '0' && c <= '9') || c == '_' || c == '-'))
            return "may hold only letters, digits, _ and -";
    return std::nullopt;
}

std::string_view messageType(const ClientMessage &message) {
    return std::visit([](const auto &m) { return m.kType; }, message);
}

const RequestId &requestIdOf(const ClientMessage &message) {
    return std::visit([](const auto &m) -> const RequestId & { return m.id; }, message);
}

ParsedClientMessage parseClientMessage(std::string_view text, const Limits &limits) {
    RequestId id;
    std::string type;
    try {
        // Before parsing: an oversized message costs nothing but this comparison.
        if (text.size() > limits.maxMessageBytes)
            fail(ErrorCode::TooLarge, "message is " + std::to_string(text.size()) +
                                          " bytes; the limit is " + std::to_string(limits.maxMessageBytes));
        const detail::ParsedText parsed = detail::parseText(text, limits.maxDepth);
        const json &root = parsed.value;
        if (!root.is_object())
            fail(ErrorCode::BadMessage, "a message must be a JSON object, got " + detail::kindOf(root));
        // The id first, so that every later error can echo it.
        if (const auto it = root.find("id"); it != root.end())
            id = detail::requestId(*it, "id", limits.maxIdBytes);
        const auto typeIt = root.find("type");
        if (typeIt == root.end()) fail(ErrorCode::BadMessage, "a message needs a \"type\"");
        if (!typeIt->is_string())
            fail(ErrorCode::BadMessage, "\"type\" must be a string, got " + detail::kindOf(*typeIt));
        const std::string name = typeIt->get<std::string>();
        const ReaderEntry *entry = nullptr;
        for (const ReaderEntry &e : kReaders)
            if (e.type == name) entry = &e;
        if (!entry) {
            fail(ErrorCode::UnknownType,
                 "unknown message type " + json(quotableText(name, 64)).dump() + " (known: " + knownTypes() + ")");
        }
        type = name;
        if (!parsed.duplicateKey.empty()) badField(parsed.duplicateKey, "duplicate key");
        return entry->read(root, id, limits);
    } catch (const ReadError &e) {
        // Each message above quotes client text through quotableText already; this is the
        // last check that the answer is valid UTF-8 whatever a future message quotes.
        return ProtocolError{e.code, quotableText(e.what()), id, type};
    } catch (const detail::FieldError &e) {
        return ProtocolError{detail::codeOf(e), quotableText(detail::messageOf(e)), id, type};
    } catch (const std::exception &e) {
        // Out of memory or a bug in this file; still an answer, never a dropped connection.
        return ProtocolError{ErrorCode::Internal, "reading the message failed: " + quotableText(e.what()), id, type};
    }
}

ProtocolError binaryMessageError(size_t bytes) {
    return ProtocolError{ErrorCode::BadMessage,
                         "a binary message (" + std::to_string(bytes) +
                             " bytes) was sent; clients send JSON text messages only",
                         nullptr, ""};
}

std::string toJsonText(const ClientMessage &message) {
    json j = std::visit([](const auto &m) { return fieldsOf(m); }, message);
    j["type"] = messageType(message);
    if (const RequestId &id = requestIdOf(message); !id.is_null()) j["id"] = id;
    return j.dump();
}

std::string_view qualityModeName(QualityMode mode) {
    return mode == QualityMode::Explicit ? "explicit" : "automatic";
}

json qualityPolicyToJson(const QualityPolicy &policy) {
    json j{{"mode", qualityModeName(policy.mode)}};
    if (policy.mode == QualityMode::Automatic) j["target_frame_ms"] = policy.targetFrameMs;
    if (!policy.quality.is_null()) j["quality"] = policy.quality;
    return j;
}

} // namespace volcast::protocol
