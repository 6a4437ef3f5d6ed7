#include "protocol/server_messages.hpp"

#include "protocol/read_error.hpp"

#include <limits>
#include <utility>

namespace volcast::protocol {

using json = nlohmann::json;
using detail::Fields;

namespace {

constexpr auto kIgnore = Fields::Unknown::Ignore;
// Server-sent strings are not bounded by the client's limits; the message size is.
constexpr size_t kAnyLength = std::numeric_limits<size_t>::max();

constexpr std::array<std::pair<ProgressStage, std::string_view>, 4> kStages{{
    {ProgressStage::Loading, "loading"},
    {ProgressStage::Preprocessing, "preprocessing"},
    {ProgressStage::Uploading, "uploading"},
    {ProgressStage::Retrieving, "retrieving"},
}};

json volumeToJson(const VolumeInfo &v) {
    json j{{"name", v.name}, {"loaded", v.loaded}};
    if (v.dims) j["dims"] = *v.dims;
    if (v.spacing) j["spacing"] = *v.spacing;
    if (v.origin) j["origin"] = *v.origin;
    if (v.direction) j["direction"] = *v.direction;
    if (!v.voxelType.empty()) j["voxel_type"] = v.voxelType;
    if (v.valueRange) j["value_range"] = *v.valueRange;
    if (v.histogram) j["histogram"] = {{"range", v.histogram->range}, {"counts", v.histogram->counts}};
    if (v.orientationKnown) j["orientation_known"] = *v.orientationKnown;
    if (v.modality) {
        json presets = json::array();
        for (const PresetInfo &p : v.modality->presets)
            presets.push_back({{"name", p.name}, {"label", p.label}, {"window", p.window}, {"level", p.level},
                               {"points", p.points}, {"shading", p.shading}, {"modality", p.modality}});
        j["modality"] = {{"name", v.modality->name}, {"source", v.modality->source},
                         {"reason", v.modality->reason}, {"default_preset", v.modality->defaultPreset},
                         {"presets", std::move(presets)}, {"modalities", v.modality->modalities},
                         {"hounsfield", v.modality->hounsfield}};
    }
    return j;
}

// The fields of each message besides "type" and "id".
json fieldsOf(const ServerHello &m) {
    json limits{{"max_message_bytes", m.limits.maxMessageBytes},
                {"max_image_side", m.limits.maxImageSide},
                {"max_image_pixels", m.limits.maxImagePixels},
                {"max_volume_name_bytes", m.limits.maxVolumeNameBytes}};
    // The admission limits, added later: 0 means not stated, and is left out.
    if (m.limits.maxSamplesPerFrame) limits["max_samples_per_frame"] = m.limits.maxSamplesPerFrame;
    if (m.limits.maxStillPixels) limits["max_still_pixels"] = m.limits.maxStillPixels;
    if (m.limits.maxRequestBytes) limits["max_request_bytes"] = m.limits.maxRequestBytes;
    return {{"protocol", m.protocol},
            {"server", m.server},
            {"device", {{"name", m.device.name}, {"type", m.device.type}}},
            {"limits", std::move(limits)}};
}

json fieldsOf(const VolumesMessage &m) {
    json list = json::array();
    for (const VolumeInfo &v : m.volumes) list.push_back(volumeToJson(v));
    json sources = json::array();
    for (const SourceInfo &s : m.sources) sources.push_back({{"name", s.name}, {"kind", s.kind}});
    return {{"volumes", std::move(list)}, {"sources", std::move(sources)}};
}

json fieldsOf(const ProgressMessage &m) {
    json j{{"volume", m.volume}, {"stage", progressStageName(m.stage)}, {"fraction", m.fraction}};
    if (!m.task.empty()) j["task"] = m.task;
    if (m.instances) j["instances"] = *m.instances;
    if (m.bytes) j["bytes"] = *m.bytes;
    return j;
}

json fieldsOf(const StudiesMessage &m) {
    json studies = json::array();
    for (const StudyInfo &s : m.studies) {
        json series = json::array();
        for (const SeriesInfo &r : s.series)
            series.push_back({{"series_uid", r.seriesUid},
                              {"modality", r.modality},
                              {"description", r.description},
                              {"instances", r.instances},
                              {"volume", r.volume}});
        studies.push_back({{"study_uid", s.studyUid},
                           {"patient_name", s.patientName},
                           {"patient_id", s.patientId},
                           {"study_date", s.studyDate},
                           {"description", s.description},
                           {"accession_number", s.accessionNumber},
                           {"modalities", s.modalities},
                           {"series", std::move(series)}});
    }
    return {{"source", m.source}, {"studies", std::move(studies)}};
}

json fieldsOf(const StateMessage &m) {
    return {{"volume", m.volume ? volumeToJson(*m.volume) : json(nullptr)},
            {"scene", m.scene},
            {"quality_policy", qualityPolicyToJson(m.qualityPolicy)},
            {"interacting", m.interacting}};
}

json nullable(const std::optional<double> &v) { return v ? json(*v) : json(nullptr); }
json nullable(const std::optional<std::string> &v) { return v ? json(*v) : json(nullptr); }

json fieldsOf(const ProbeMessage &m) {
    return {{"point", m.point}, {"inside", m.inside}, {"value", nullable(m.value)}, {"unit", nullable(m.unit)}};
}

json fieldsOf(const RoiStatsMessage &m) {
    return {{"samples", m.samples},      {"area_mm2", m.areaMm2},      {"mean", nullable(m.mean)},
            {"std", nullable(m.std)},    {"min", nullable(m.min)},     {"max", nullable(m.max)},
            {"unit", nullable(m.unit)}};
}

json fieldsOf(const PickMessage &m) {
    return {{"hit", m.hit}, {"point", m.point ? json(*m.point) : json(nullptr)}, {"opacity", m.opacity}};
}

json fieldsOf(const ProtocolError &m) {
    json j{{"code", errorCodeName(m.code)},
           {"message", m.message},
           {"request_type", m.requestType.empty() ? json(nullptr) : json(m.requestType)}};
    if (!m.stacks.empty()) {
        json stacks = json::array();
        for (const StackOffer &s : m.stacks)
            stacks.push_back({{"volume", s.volume}, {"slices", s.slices}, {"rows", s.rows}, {"columns", s.columns},
                              {"orientation", s.orientation}, {"localizer", s.localizer}});
        j["stacks"] = std::move(stacks);
    }
    return j;
}

const RequestId &idOf(const ServerMessage &message) {
    return std::visit(
        [](const auto &m) -> const RequestId & {
            if constexpr (std::is_same_v<std::decay_t<decltype(m)>, ProtocolError>)
                return m.requestId;
            else
                return m.id;
        },
        message);
}

// Readers for clients: unknown fields are ignored, known ones must have the right kind.
template <size_t N>
std::array<double, N> numbers(const json &j, const std::string &path) {
    detail::array(j, path);
    if (j.size() != N) detail::badField(path, "must have " + std::to_string(N) + " numbers, got " + std::to_string(j.size()));
    std::array<double, N> out{};
    for (size_t i = 0; i < N; ++i) out[i] = detail::number(j[i], detail::element(path, i));
    return out;
}

VolumeInfo readVolume(const json &j, const std::string &path) {
    const Fields f(j, path, {}, kIgnore);
    VolumeInfo v;
    v.name = detail::string(f.require("name"), f.pathOf("name"), kAnyLength);
    if (const json *loaded = f.find("loaded")) v.loaded = detail::boolean(*loaded, f.pathOf("loaded"));
    if (const json *dims = f.find("dims")) {
        const std::string at = f.pathOf("dims");
        detail::array(*dims, at);
        if (dims->size() != 3) detail::badField(at, "must have 3 integers");
        std::array<int64_t, 3> d{};
        for (size_t i = 0; i < 3; ++i)
            d[i] = detail::integer((*dims)[i], detail::element(at, i), 1, std::numeric_limits<int64_t>::max());
        v.dims = d;
    }
    if (const json *s = f.find("spacing")) v.spacing = numbers<3>(*s, f.pathOf("spacing"));
    if (const json *o = f.find("origin")) v.origin = numbers<3>(*o, f.pathOf("origin"));
    if (const json *d = f.find("direction")) {
        const std::string at = f.pathOf("direction");
        detail::array(*d, at);
        if (d->size() != 3) detail::badField(at, "must have 3 rows, got " + std::to_string(d->size()));
        std::array<std::array<double, 3>, 3> rows{};
        for (size_t r = 0; r < 3; ++r) rows[r] = numbers<3>((*d)[r], detail::element(at, r));
        v.direction = rows;
    }
    if (const json *t = f.find("voxel_type")) v.voxelType = detail::string(*t, f.pathOf("voxel_type"), kAnyLength);
    if (const json *r = f.find("value_range")) v.valueRange = numbers<2>(*r, f.pathOf("value_range"));
    if (const json *h = f.find("histogram")) {
        const Fields hf(*h, f.pathOf("histogram"), {}, kIgnore);
        HistogramInfo histogram;
        histogram.range = numbers<2>(hf.require("range"), hf.pathOf("range"));
        const json &counts = detail::array(hf.require("counts"), hf.pathOf("counts"));
        for (size_t i = 0; i < counts.size(); ++i)
            histogram.counts.push_back(detail::unsignedInteger(counts[i], detail::element(hf.pathOf("counts"), i)));
        v.histogram = std::move(histogram);
    }
    if (const json *o = f.find("orientation_known")) v.orientationKnown = detail::boolean(*o, f.pathOf("orientation_known"));
    if (const json *m = f.find("modality")) {
        const Fields mf(*m, f.pathOf("modality"), {}, kIgnore);
        ModalityInfo modality;
        modality.name = detail::string(mf.require("name"), mf.pathOf("name"), kAnyLength);
        modality.source = detail::string(mf.require("source"), mf.pathOf("source"), kAnyLength);
        modality.reason = detail::string(mf.require("reason"), mf.pathOf("reason"), kAnyLength);
        modality.defaultPreset = detail::string(mf.require("default_preset"), mf.pathOf("default_preset"), kAnyLength);
        const json &presets = detail::array(mf.require("presets"), mf.pathOf("presets"));
        for (size_t i = 0; i < presets.size(); ++i) {
            const Fields pf(presets[i], detail::element(mf.pathOf("presets"), i), {}, kIgnore);
            PresetInfo p;
            p.name = detail::string(pf.require("name"), pf.pathOf("name"), kAnyLength);
            p.label = detail::string(pf.require("label"), pf.pathOf("label"), kAnyLength);
            p.window = detail::number(pf.require("window"), pf.pathOf("window"));
            p.level = detail::number(pf.require("level"), pf.pathOf("level"));
            p.shading = detail::boolean(pf.require("shading"), pf.pathOf("shading"));
            if (const json *pm = pf.find("modality")) p.modality = detail::string(*pm, pf.pathOf("modality"), kAnyLength);
            const json &points = detail::array(pf.require("points"), pf.pathOf("points"));
            for (size_t k = 0; k < points.size(); ++k)
                p.points.push_back(numbers<5>(points[k], detail::element(pf.pathOf("points"), k)));
            modality.presets.push_back(std::move(p));
        }
        if (const json *ms = mf.find("modalities")) {
            const json &names = detail::array(*ms, mf.pathOf("modalities"));
            for (size_t i = 0; i < names.size(); ++i)
                modality.modalities.push_back(
                    detail::string(names[i], detail::element(mf.pathOf("modalities"), i), kAnyLength));
        }
        if (const json *h = mf.find("hounsfield")) modality.hounsfield = detail::boolean(*h, mf.pathOf("hounsfield"));
        v.modality = std::move(modality);
    }
    return v;
}

ServerMessage readHello(const Fields &f, RequestId id) {
    ServerHello m;
    m.id = std::move(id);
    m.protocol = int(detail::integer(f.require("protocol"), "protocol", 0, 1 << 30));
    m.server = detail::string(f.require("server"), "server", kAnyLength);
    const Fields device(f.require("device"), "device", {}, kIgnore);
    m.device.name = detail::string(device.require("name"), device.pathOf("name"), kAnyLength);
    m.device.type = detail::string(device.require("type"), device.pathOf("type"), kAnyLength);
    const Fields limits(f.require("limits"), "limits", {}, kIgnore);
    const auto count = [&](std::string_view key) {
        return detail::integer(limits.require(key), limits.pathOf(key), 0, std::numeric_limits<int64_t>::max());
    };
    m.limits.maxMessageBytes = size_t(count("max_message_bytes"));
    m.limits.maxImageSide = int(detail::integer(limits.require("max_image_side"),
                                                limits.pathOf("max_image_side"), 0, 1 << 30));
    m.limits.maxImagePixels = count("max_image_pixels");
    m.limits.maxVolumeNameBytes = size_t(count("max_volume_name_bytes"));
    // Added later: absent from older servers' hello.
    const auto optionalCount = [&](std::string_view key) { return limits.find(key) ? count(key) : 0; };
    m.limits.maxSamplesPerFrame = optionalCount("max_samples_per_frame");
    m.limits.maxStillPixels = optionalCount("max_still_pixels");
    m.limits.maxRequestBytes = optionalCount("max_request_bytes");
    return m;
}

ServerMessage readVolumes(const Fields &f, RequestId id) {
    VolumesMessage m;
    m.id = std::move(id);
    const json &list = detail::array(f.require("volumes"), "volumes");
    for (size_t i = 0; i < list.size(); ++i) m.volumes.push_back(readVolume(list[i], detail::element("volumes", i)));
    if (const json *sources = f.find("sources")) {
        detail::array(*sources, "sources");
        for (size_t i = 0; i < sources->size(); ++i) {
            const Fields sf((*sources)[i], detail::element("sources", i), {}, kIgnore);
            m.sources.push_back({detail::string(sf.require("name"), sf.pathOf("name"), kAnyLength),
                                 detail::string(sf.require("kind"), sf.pathOf("kind"), kAnyLength)});
        }
    }
    return m;
}

ServerMessage readStudies(const Fields &f, RequestId id) {
    StudiesMessage m;
    m.id = std::move(id);
    m.source = detail::string(f.require("source"), "source", kAnyLength);
    const json &studies = detail::array(f.require("studies"), "studies");
    const auto text = [](const Fields &of, std::string_view key) {
        return detail::string(of.require(key), of.pathOf(key), kAnyLength);
    };
    for (size_t i = 0; i < studies.size(); ++i) {
        const Fields sf(studies[i], detail::element("studies", i), {}, kIgnore);
        StudyInfo s;
        s.studyUid = text(sf, "study_uid");
        s.patientName = text(sf, "patient_name");
        s.patientId = text(sf, "patient_id");
        s.studyDate = text(sf, "study_date");
        s.description = text(sf, "description");
        if (sf.find("accession_number")) s.accessionNumber = text(sf, "accession_number");
        const json &modalities = detail::array(sf.require("modalities"), sf.pathOf("modalities"));
        for (size_t k = 0; k < modalities.size(); ++k)
            s.modalities.push_back(
                detail::string(modalities[k], detail::element(sf.pathOf("modalities"), k), kAnyLength));
        const json &series = detail::array(sf.require("series"), sf.pathOf("series"));
        for (size_t k = 0; k < series.size(); ++k) {
            const Fields rf(series[k], detail::element(sf.pathOf("series"), k), {}, kIgnore);
            SeriesInfo r;
            r.seriesUid = text(rf, "series_uid");
            r.modality = text(rf, "modality");
            r.description = text(rf, "description");
            r.instances = detail::integer(rf.require("instances"), rf.pathOf("instances"), 0,
                                          std::numeric_limits<int64_t>::max());
            r.volume = text(rf, "volume");
            s.series.push_back(std::move(r));
        }
        m.studies.push_back(std::move(s));
    }
    return m;
}

ServerMessage readProgress(const Fields &f, RequestId id) {
    ProgressMessage m;
    m.id = std::move(id);
    m.volume = detail::string(f.require("volume"), "volume", kAnyLength);
    const std::string stage = detail::string(f.require("stage"), "stage", kAnyLength);
    bool known = false;
    for (const auto &[s, name] : kStages)
        if (name == stage) m.stage = s, known = true;
    if (!known) detail::badField("stage", "unknown stage " + json(stage).dump());
    if (const json *task = f.find("task")) m.task = detail::string(*task, "task", kAnyLength);
    m.fraction = detail::number(f.require("fraction"), "fraction");
    if (m.fraction < 0 || m.fraction > 1) detail::badField("fraction", "must be in [0, 1]");
    if (const json *instances = f.find("instances")) {
        detail::array(*instances, "instances");
        if (instances->size() != 2) detail::badField("instances", "must be [done, total]");
        std::array<int64_t, 2> counts{};
        for (size_t i = 0; i < 2; ++i)
            counts[i] = detail::integer((*instances)[i], detail::element("instances", i), 0,
                                        std::numeric_limits<int64_t>::max());
        m.instances = counts;
    }
    if (const json *bytes = f.find("bytes")) m.bytes = detail::unsignedInteger(*bytes, "bytes");
    return m;
}

ServerMessage readState(const Fields &f, RequestId id) {
    StateMessage m;
    m.id = std::move(id);
    if (const json *volume = f.find("volume"); volume && !volume->is_null()) m.volume = readVolume(*volume, "volume");
    m.scene = detail::object(f.require("scene"), "scene");
    const Fields policy(f.require("quality_policy"), "quality_policy", {}, kIgnore);
    m.qualityPolicy = detail::readQualityPolicy(policy);
    m.interacting = detail::boolean(f.require("interacting"), "interacting");
    return m;
}

std::optional<double> optionalNumber(const Fields &f, std::string_view key) {
    const json &v = f.require(key);
    if (v.is_null()) return std::nullopt;
    return detail::number(v, f.pathOf(key));
}

std::optional<std::string> optionalText(const Fields &f, std::string_view key) {
    const json *v = f.find(key);
    if (!v || v->is_null()) return std::nullopt;
    return detail::string(*v, f.pathOf(key), kAnyLength);
}

ServerMessage readProbe(const Fields &f, RequestId id) {
    ProbeMessage m;
    m.id = std::move(id);
    m.point = numbers<3>(f.require("point"), "point");
    m.inside = detail::boolean(f.require("inside"), "inside");
    m.value = optionalNumber(f, "value");
    m.unit = optionalText(f, "unit");
    return m;
}

ServerMessage readRoiStats(const Fields &f, RequestId id) {
    RoiStatsMessage m;
    m.id = std::move(id);
    m.samples = detail::integer(f.require("samples"), "samples", 0, std::numeric_limits<int64_t>::max());
    m.areaMm2 = detail::number(f.require("area_mm2"), "area_mm2");
    m.mean = optionalNumber(f, "mean");
    m.std = optionalNumber(f, "std");
    m.min = optionalNumber(f, "min");
    m.max = optionalNumber(f, "max");
    m.unit = optionalText(f, "unit");
    return m;
}

ServerMessage readPick(const Fields &f, RequestId id) {
    PickMessage m;
    m.id = std::move(id);
    m.hit = detail::boolean(f.require("hit"), "hit");
    if (const json &p = f.require("point"); !p.is_null()) m.point = numbers<3>(p, "point");
    m.opacity = detail::number(f.require("opacity"), "opacity");
    return m;
}

ServerMessage readError(const Fields &f, RequestId id) {
    ProtocolError m;
    m.requestId = std::move(id);
    const std::string code = detail::string(f.require("code"), "code", kAnyLength);
    // A code this client does not know yet is still an error; it reads as internal.
    m.code = errorCodeFromName(code).value_or(ErrorCode::Internal);
    m.message = detail::string(f.require("message"), "message", kAnyLength);
    if (const json *type = f.find("request_type"); type && !type->is_null())
        m.requestType = detail::string(*type, "request_type", kAnyLength);
    if (const json *stacks = f.find("stacks")) {
        const json &list = detail::array(*stacks, "stacks");
        for (size_t i = 0; i < list.size(); ++i) {
            const Fields sf(list[i], detail::element("stacks", i), {}, kIgnore);
            const auto count = [&](std::string_view key) {
                return detail::integer(sf.require(key), sf.pathOf(key), 0, std::numeric_limits<int64_t>::max());
            };
            StackOffer s;
            s.volume = detail::string(sf.require("volume"), sf.pathOf("volume"), kAnyLength);
            s.slices = count("slices");
            s.rows = count("rows");
            s.columns = count("columns");
            s.orientation = detail::string(sf.require("orientation"), sf.pathOf("orientation"), kAnyLength);
            s.localizer = detail::boolean(sf.require("localizer"), sf.pathOf("localizer"));
            m.stacks.push_back(std::move(s));
        }
    }
    return m;
}

} // namespace

std::string_view progressStageName(ProgressStage stage) {
    for (const auto &[s, name] : kStages)
        if (s == stage) return name;
    return "loading";
}

std::string_view messageType(const ServerMessage &message) {
    return std::visit([](const auto &m) { return m.kType; }, message);
}

std::string toJsonText(const ServerMessage &message) {
    json j = std::visit([](const auto &m) { return fieldsOf(m); }, message);
    j["type"] = messageType(message);
    // Always present, null when the message answers no request, so clients can rely on it.
    j["id"] = idOf(message);
    // Every string in a message should be valid UTF-8 already (client text is quoted through
    // quotableText); should one not be, U+FFFD goes out instead of an exception.
    return j.dump(-1, ' ', false, json::error_handler_t::replace);
}

ServerMessage parseServerMessage(std::string_view text) {
    try {
        // No size limit or depth limit to speak of: the server is trusted to be sane, but
        // the depth bound costs nothing and keeps a broken one from exhausting the stack.
        const detail::ParsedText parsed = detail::parseText(text, 64);
        const json &root = parsed.value;
        if (!root.is_object()) detail::fail(ErrorCode::BadMessage, "a message must be a JSON object, got " + detail::kindOf(root));
        const Fields f(root, "", {}, kIgnore);
        RequestId id;
        if (const json *i = f.find("id")) id = detail::requestId(*i, "id", kAnyLength);
        const std::string type = detail::string(f.require("type"), "type", kAnyLength);
        if (type == ServerHello::kType) return readHello(f, std::move(id));
        if (type == VolumesMessage::kType) return readVolumes(f, std::move(id));
        if (type == ProgressMessage::kType) return readProgress(f, std::move(id));
        if (type == StateMessage::kType) return readState(f, std::move(id));
        if (type == StudiesMessage::kType) return readStudies(f, std::move(id));
        if (type == ProtocolError::kType) return readError(f, std::move(id));
        if (type == ProbeMessage::kType) return readProbe(f, std::move(id));
        if (type == RoiStatsMessage::kType) return readRoiStats(f, std::move(id));
        if (type == PickMessage::kType) return readPick(f, std::move(id));
        detail::fail(ErrorCode::UnknownType, "unknown message type " + json(type).dump());
    } catch (const detail::ReadError &e) {
        throw DecodeError(std::string("server message: ") + e.what());
    } catch (const detail::FieldError &e) {
        throw DecodeError("server message: " + detail::messageOf(e));
    }
}

} // namespace volcast::protocol
