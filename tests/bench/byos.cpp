// volcast-bench byos: bringing your own scan, timed beside what it is compared with.
//
// DICOMweb: a 512×512×300 int16 series in a real Orthanc (started here, the series uploaded
// over its REST API first). Each round times Orthanc serving the whole series (one WADO-RS
// GET, body discarded) and a fresh in-process server's open_volume of it up to the first
// frame (its DICOMweb cache is new, so cold), split into parts by the progress messages.
// Upload: a 512×512×400 int16 .nii.gz (noise makes it compress like a scan, to ~100 MiB).
// Each round times loadVolume of it here (plain, and parsed in the checker process first, as
// the server does), and POST /api/volumes of it to a fresh server up to the first frame of
// the name it answers. The measurements take turns within each round, and the order flips
// every round, so that a slow spell of the machine falls on both sides of a ratio.

#include "tests/bench/byos.hpp"

#include "client/cpp/ws_client.hpp"
#include "renderer/io/volume_io.hpp"
#include "server/server.hpp"
#include "tests/bench/bench.hpp"
#include "tests/dicomweb/orthanc_fixture.hpp"

#include <boost/asio/ip/tcp.hpp>
#include <boost/asio/write.hpp>
#include <boost/beast/core.hpp>
#include <boost/beast/http.hpp>
#include <nlohmann/json.hpp>
#include <spdlog/spdlog.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <fstream>
#include <iostream>
#include <limits>
#include <map>
#include <optional>
#include <sstream>
#include <stdexcept>
#include <string>
#include <thread>
#include <variant>
#include <vector>

namespace volcast::bench {
namespace {

namespace fs = std::filesystem;
using json = nlohmann::json;
using Clock = std::chrono::steady_clock;
using namespace std::chrono_literals;

constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();
// Longer than any step can take on a 2-core machine (the server's own load limit is 120 s).
constexpr auto kStepTimeout = 300s;

double msBetween(Clock::time_point a, Clock::time_point b) {
    return std::chrono::duration<double, std::milli>(b - a).count();
}
double mib(uint64_t bytes) { return double(bytes) / double(uint64_t(1) << 20); }
json number(double v) { return std::isfinite(v) ? json(v) : json(nullptr); }

// A sphere phantom in HU: air (−1000) around a water-like sphere (0 to 40 HU, rising along z)
// in a 1200 HU shell of bone, edges smoothed over ~2 voxels. noiseHu > 0 adds noise of that
// standard deviation (the sum of four uniforms), as a CT scan has: without it a .nii.gz of
// this size would compress to a few MiB, where a scan's stays near half its raw size.
Volume sphereCt(Vec3i dims, double noiseHu) {
    Volume v;
    v.dims = dims;
    v.spacing = {0.7, 0.7, 1.0};
    v.voxels.resize(v.voxelCount());
    const double nx = double(dims.x), ny = double(dims.y), nz = double(dims.z);
    const double cx = 0.5 * (nx - 1), cy = 0.5 * (ny - 1), cz = 0.5 * (nz - 1);
    const double rx = 0.45 * nx, ry = 0.45 * ny, rz = 0.45 * nz;
    const double shellVoxels = std::max(2.0, 0.015 * nx);
    const double noiseScale = noiseHu * std::sqrt(3.0);   // four uniforms in [0, 1): variance 1/3
    size_t index = 0;
    for (int64_t k = 0; k < dims.z; ++k) {
        const double water = 40.0 * double(k) / std::max(1.0, nz - 1);
        for (int64_t j = 0; j < dims.y; ++j)
            for (int64_t i = 0; i < dims.x; ++i, ++index) {
                const double r = std::sqrt(std::pow((double(i) - cx) / rx, 2) + std::pow((double(j) - cy) / ry, 2) +
                                           std::pow((double(k) - cz) / rz, 2));
                const double inside = (1 - r) * rx;   // voxels (along x) inside the surface
                const double bone = std::clamp(inside / 2 + 0.5, 0.0, 1.0);
                const double core = std::clamp((inside - shellVoxels) / 2 + 0.5, 0.0, 1.0);
                double hu = -1000 + bone * 2200 + core * (water - 1200);
                if (noiseHu > 0) {
                    // splitmix64 of the index: four 16-bit uniforms.
                    uint64_t z = (uint64_t(index) + 1) * 0x9e3779b97f4a7c15ull;
                    z = (z ^ (z >> 30)) * 0xbf58476d1ce4e5b9ull;
                    z = (z ^ (z >> 27)) * 0x94d049bb133111ebull;
                    z ^= z >> 31;
                    double sum = 0;
                    for (int q = 0; q < 4; ++q) sum += double((z >> (16 * q)) & 0xffff) / 65536.0;
                    hu += (sum - 2) * noiseScale;
                }
                v.voxels[index] = float(std::round(hu));
            }
    }
    return v;
}

struct Event {
    std::string stage, task;
    double firstMs = kNaN, lastMs = kNaN;
};

// What one open_volume took, from sending it to its first frame, cut at the progress
// messages (their arrival times here: the server stamps none).
struct OpenTiming {
    double totalMs = kNaN;
    std::map<std::string, double> parts;   // see splitOpen
    std::vector<Event> events;             // each (stage, task) in order of first arrival
    uint64_t retrievedBytes = 0;
    json volume;                           // the state's volume
    json firstFrame;                       // the first frame's level, size and render and encode times
};

// The parts an open_volume's time goes to. The boundaries are the first arrival of a
// progress step; a step the load never reached leaves its parts null.
//   metadata:       sending → the first "retrieving instances" (the series' size asked by QIDO-RS)
//   retrieve:       → the last retrieving message (the WADO-RS transfer, written to the cache)
//   parse_in_child: the first "… in a separate process" → the next step of the load
//   load:           → the first "uploading" (this process's parse, statistics, narrow samples);
//                   for an upload, whose parse was kept when it arrived, from the first loading
//                   step (reading the kept parse back, checked, statistics)
//   renderer:       → the state (the renderer's bricks and tables)
//   first_frame:    → the first frame (its own header says its render and encode times)
std::map<std::string, double> splitOpen(const std::vector<Event> &events, double stateMs, double frameMs) {
    double retrieveStart = kNaN, retrieveEnd = kNaN, checkStart = kNaN, checkEnd = kNaN, uploading = kNaN;
    double loadStart = kNaN;
    for (size_t i = 0; i < events.size(); ++i) {
        const Event &e = events[i];
        if (e.stage == "loading" && std::isnan(loadStart)) loadStart = e.firstMs;
        if (e.stage == "retrieving" && e.task == "retrieving instances") {
            retrieveStart = e.firstMs;
            retrieveEnd = e.lastMs;
        }
        if (e.task.find("separate process") != std::string::npos && std::isnan(checkStart)) {
            checkStart = e.firstMs;
            if (i + 1 < events.size()) checkEnd = events[i + 1].firstMs;
        }
        if (e.stage == "uploading" && std::isnan(uploading)) uploading = e.firstMs;
    }
    std::map<std::string, double> parts;
    if (!std::isnan(retrieveStart)) {
        parts["metadata"] = retrieveStart;
        parts["retrieve"] = retrieveEnd - retrieveStart;
    }
    parts["parse_in_child"] = checkEnd - checkStart;
    parts["load"] = uploading - (std::isnan(checkStart) ? loadStart : checkEnd);
    parts["renderer"] = stateMs - uploading;
    parts["first_frame"] = frameMs - stateMs;
    return parts;
}

// A client that said hello and set a square viewport; nothing timed yet.
std::unique_ptr<client::Client> readyClient(uint16_t port, int viewport) {
    auto c = std::make_unique<client::Client>("127.0.0.1", port);
    c->sendText(json{{"type", "hello"}, {"id", 1}, {"protocol", 1}, {"client", "volcast-bench byos"}}.dump());
    const client::Message hello = client::waitForReply(*c, 1, kStepTimeout);
    if (!hello.decoded || !std::holds_alternative<protocol::ServerHello>(*hello.decoded))
        throw std::runtime_error("the server did not answer hello: " + hello.text);
    c->sendText(json{{"type", "viewport"}, {"id", 2}, {"image", {{"width", viewport}, {"height", viewport}}}}.dump());
    return c;
}

// Sends open_volume of `name` and waits for its first frame; times are from `start`.
OpenTiming openToFirstFrame(client::Client &c, const std::string &name, Clock::time_point start, Vec3i expected) {
    const Clock::time_point sent = Clock::now();
    c.sendText(json{{"type", "open_volume"}, {"id", "open"}, {"name", name}}.dump());
    OpenTiming t;
    double stateMs = kNaN;
    const auto deadline = sent + kStepTimeout;
    while (Clock::now() < deadline) {
        const auto m = c.next(100ms);
        if (!m) {
            if (c.closed()) throw std::runtime_error("the server closed the session while opening " + name);
            continue;
        }
        const double at = msBetween(start, m->received);
        if (m->isFrame) {
            if (std::isnan(stateMs)) continue;   // a frame of an earlier view: none here, but not ours
            t.totalMs = at;
            t.parts = splitOpen(t.events, stateMs, at);
            const protocol::FrameHeader &h = m->frame.header;
            t.firstFrame = {{"level", h.level}, {"width", h.width}, {"height", h.height}, {"final", h.final},
                            {"render_ms", h.renderMs}, {"encode_ms", h.encodeMs}};
            return t;
        }
        if (!m->decoded) continue;
        if (std::holds_alternative<protocol::ProtocolError>(*m->decoded))
            throw std::runtime_error("opening " + name + ": " + m->text);
        if (const auto *p = std::get_if<protocol::ProgressMessage>(&*m->decoded)) {
            const std::string stage(protocol::progressStageName(p->stage));
            if (t.events.empty() || t.events.back().stage != stage || t.events.back().task != p->task)
                t.events.push_back({stage, p->task, at, at});
            t.events.back().lastMs = at;
            if (p->bytes) t.retrievedBytes = *p->bytes;
        }
        if (std::holds_alternative<protocol::StateMessage>(*m->decoded)) {
            stateMs = at;
            t.volume = json::parse(m->text).at("volume");
            if (t.volume.at("dims") != json::array({expected.x, expected.y, expected.z}))
                throw std::runtime_error("opened " + name + " with dims " + t.volume.at("dims").dump() +
                                         ", not the volume written");
        }
    }
    throw std::runtime_error("no first frame of " + name + " within " + std::to_string(kStepTimeout.count()) + " s");
}

// The in-process server each round opens on: cold (a new DICOMweb cache, no upload, nothing
// in memory), with the Orthanc as its source "orthanc", otherwise the server's defaults.
std::unique_ptr<server::Server> freshServer(const test::OrthancProcess &orthanc, const fs::path &webRoot) {
    server::ServerConfig config;
    config.port = 0;
    config.defaultVolume = "";
    config.webRoot = webRoot;
    config.dicomWebSources = {{"orthanc", orthanc.dicomWebUrl(), test::OrthancProcess::authorization()}};
    auto s = std::make_unique<server::Server>(config);
    s->start();
    const auto deadline = Clock::now() + kStepTimeout;
    while (!s->state().notReadyReason().empty()) {
        if (Clock::now() > deadline) throw std::runtime_error("the server is not ready: " + s->state().notReadyReason());
        std::this_thread::sleep_for(20ms);
    }
    return s;
}

// Orthanc's own serving time: the whole series by WADO-RS, the body read and dropped.
json orthancServes(const test::OrthancProcess &orthanc, const std::string &study, const std::string &series) {
    dicomweb::HttpOptions o;
    o.sourceName = "bench Orthanc";
    o.authorization = test::OrthancProcess::authorization();
    o.requestTimeoutSeconds = 0;   // the low-speed limit still ends a stalled transfer
    dicomweb::HttpClient http(o);
    uint64_t seen = 0;
    const Clock::time_point start = Clock::now();
    const uint64_t bytes = http.getStreaming(
        orthanc.dicomWebUrl() + "/studies/" + study + "/series/" + series, "multipart/related; type=\"application/dicom\"",
        [](const dicomweb::ResponseHead &) {}, [&](std::string_view chunk) { seen += chunk.size(); }, [] { return false; });
    const double ms = msBetween(start, Clock::now());
    if (bytes != seen) throw std::runtime_error("WADO-RS: the byte counts disagree");
    return {{"ms", ms}, {"bytes", bytes}};
}

json openTimingJson(const OpenTiming &t) {
    json parts = json::object();
    for (const auto &[k, v] : t.parts) parts[k] = number(v);
    json events = json::array();
    for (const auto &e : t.events)
        events.push_back({{"stage", e.stage}, {"task", e.task}, {"first_ms", e.firstMs}, {"last_ms", e.lastMs}});
    return {{"ms", t.totalMs}, {"parts_ms", parts}, {"progress", events}, {"retrieved_bytes", t.retrievedBytes},
            {"first_frame", t.firstFrame}};
}

// volcast's first frame of the series over DICOMweb, on a server started for it.
json volcastOpensSeries(const test::OrthancProcess &orthanc, const fs::path &webRoot, const std::string &name,
                        Vec3i dims, int viewport) {
    auto s = freshServer(orthanc, webRoot);
    auto c = readyClient(s->port(), viewport);
    const OpenTiming t = openToFirstFrame(*c, name, Clock::now(), dims);
    c->close();
    json j = openTimingJson(t);
    j["back_end"] = s->state().backEnd();
    return j;
}

json parseHere(const fs::path &file, bool inChild, Vec3i dims) {
    LoadOptions options;
    options.parseInChild = inChild;
    const Clock::time_point start = Clock::now();
    const Volume v = loadVolume(file, options);
    const double ms = msBetween(start, Clock::now());
    if (v.dims != dims) throw std::runtime_error("loadVolume(" + file.string() + ") gave other dims than written");
    return {{"ms", ms}};
}

// POST /api/volumes with the file streamed as the body, then open_volume of the name the
// server answers, to the first frame; all from the moment the connection is opened.
json volcastOpensUpload(const test::OrthancProcess &orthanc, const fs::path &webRoot, const fs::path &file,
                        Vec3i dims, int viewport) {
    namespace http = boost::beast::http;
    auto s = freshServer(orthanc, webRoot);
    auto c = readyClient(s->port(), viewport);
    const uint64_t size = fs::file_size(file);
    std::ifstream in(file, std::ios::binary);
    std::vector<char> chunk(size_t(1) << 20);

    const Clock::time_point start = Clock::now();
    boost::asio::io_context ioc;
    boost::beast::tcp_stream stream(ioc);
    stream.expires_after(kStepTimeout);
    stream.connect(boost::asio::ip::tcp::endpoint(boost::asio::ip::make_address("127.0.0.1"), s->port()));
    const std::string head = "POST /api/volumes HTTP/1.1\r\nHost: 127.0.0.1\r\nX-Volcast-Filename: " +
                             file.filename().string() +
                             "\r\nContent-Type: application/octet-stream\r\nContent-Length: " + std::to_string(size) +
                             "\r\n\r\n";
    boost::asio::write(stream, boost::asio::buffer(head));
    uint64_t sent = 0;
    while (in.read(chunk.data(), std::streamsize(chunk.size())) || in.gcount() > 0) {
        boost::asio::write(stream, boost::asio::buffer(chunk.data(), size_t(in.gcount())));
        sent += uint64_t(in.gcount());
    }
    if (sent != size) throw std::runtime_error("read " + std::to_string(sent) + " of " + file.string());
    const double bodySentMs = msBetween(start, Clock::now());
    boost::beast::flat_buffer buffer;
    http::response_parser<http::string_body> parser;
    parser.body_limit(1 << 20);
    http::read(stream, buffer, parser);
    const double answeredMs = msBetween(start, Clock::now());
    const auto response = parser.release();
    if (response.result_int() != 201)
        throw std::runtime_error("POST /api/volumes answered " + std::to_string(response.result_int()) + ": " +
                                 response.body());
    const std::string name = json::parse(response.body()).at("volume").get<std::string>();
    boost::beast::error_code ignored;
    stream.socket().shutdown(boost::asio::ip::tcp::socket::shutdown_both, ignored);

    OpenTiming t = openToFirstFrame(*c, name, start, dims);
    c->close();
    // The open's parts come from its own progress, on the same clock as the upload's.
    json j = openTimingJson(t);
    j["back_end"] = s->state().backEnd();
    j["parts_ms"]["send_body"] = bodySentMs;
    j["parts_ms"]["verify"] = answeredMs - bodySentMs;
    j["answered_ms"] = answeredMs;
    return j;
}

// The 1-minute load average: above ~1 while a measurement runs alone (it uses one core and a
// bit), so more says that other processes shared the 2 cores.
double loadAverage() {
    double one = kNaN;
    std::ifstream("/proc/loadavg") >> one;
    return one;
}

struct Summary {
    double median = kNaN, min = kNaN, max = kNaN;
};
Summary summarise(std::vector<double> v) {
    std::erase_if(v, [](double x) { return !std::isfinite(x); });
    if (v.empty()) return {};
    const Timing t = summarize(v);
    return {t.median, t.min, t.max};
}
json summaryJson(const Summary &s) { return {{"median", number(s.median)}, {"min", number(s.min)}, {"max", number(s.max)}}; }
std::string cell(const Summary &s) {
    return std::isfinite(s.median) ? fmt(s.median, 0) + " (" + fmt(s.min, 0) + "–" + fmt(s.max, 0) + ")" : "n/a";
}

// The values at `path` (a JSON pointer) in each round's measurement `key`.
std::vector<double> column(const json &rounds, const std::string &key, const std::string &path) {
    std::vector<double> v;
    for (const auto &r : rounds) {
        const json &x = r.at(key).at(json::json_pointer(path));
        v.push_back(x.is_number() ? x.get<double>() : kNaN);
    }
    return v;
}
std::vector<double> ratios(const std::vector<double> &num, const std::vector<double> &den) {
    std::vector<double> r;
    for (size_t i = 0; i < num.size(); ++i) r.push_back(num[i] / den[i]);
    return r;
}

} // namespace

void byosStudy(const ByosOptions &options) {
    if (const std::string missing = test::orthancMissing(); !missing.empty()) throw std::runtime_error(missing);
    const int rounds = options.quick ? 1 : options.rounds;
    const Vec3i seriesDims = options.quick ? Vec3i{32, 32, 12} : Vec3i{512, 512, 300};
    const Vec3i uploadDims = options.quick ? Vec3i{32, 32, 16} : Vec3i{512, 512, 400};
    const int viewport = options.quick ? 64 : 512;
    // Typical CT noise; it brings the 200 MiB of int16 samples to ~100 MiB in gzip.
    constexpr double kNoiseHu = 12;

    std::string pattern = (fs::temp_directory_path() / "volcast-byos-XXXXXX").string();
    if (!::mkdtemp(pattern.data())) throw std::runtime_error("mkdtemp failed for " + pattern);
    const fs::path work = pattern;
    struct Remove {
        fs::path folder;
        ~Remove() {
            std::error_code ec;
            fs::remove_all(folder, ec);
        }
    } remove{work};
    fs::create_directories(work / "web");

    std::cerr << "byos: writing the series and the .nii.gz in " << work << "\n";
    const fs::path seriesFolder = work / "series";
    saveDicomSeries(sphereCt(seriesDims, 0), seriesFolder, VoxelType::Int16);
    const fs::path niftiFile = work / "scan.nii.gz";
    saveVolume(sphereCt(uploadDims, kNoiseHu), niftiFile, {VoxelType::Int16, true});
    const uint64_t niftiBytes = fs::file_size(niftiFile);
    uint64_t seriesBytes = 0;
    int instances = 0;
    for (const auto &e : fs::directory_iterator(seriesFolder)) {
        seriesBytes += e.file_size();
        ++instances;
    }

    std::cerr << "byos: starting Orthanc and storing " << instances << " instances over its REST API\n";
    test::OrthancProcess orthanc;
    std::string lastId;
    for (const auto &e : fs::directory_iterator(seriesFolder)) lastId = orthanc.upload(e.path());
    const json tags = orthanc.rest("GET", "/instances/" + lastId + "/simplified-tags");
    const std::string study = tags.at("StudyInstanceUID"), series = tags.at("SeriesInstanceUID");
    const std::string seriesName = "dicomweb:orthanc/" + study + "/" + series;
    const json stored = orthanc.rest("GET", "/statistics");

    json roundsJson = json::array();
    for (int r = 0; r < rounds; ++r) {
        // Flipped every round: neither side always runs first.
        const bool referenceFirst = r % 2 == 0;
        std::cerr << "byos: round " << r + 1 << " of " << rounds << "\n";
        json round = {{"round", r + 1}, {"reference_first", referenceFirst}, {"load_average_1min_before", number(loadAverage())}};
        const auto dicomweb = [&](bool reference) {
            if (reference) round["orthanc_serves"] = orthancServes(orthanc, study, series);
            else round["volcast_dicomweb"] = volcastOpensSeries(orthanc, work / "web", seriesName, seriesDims, viewport);
        };
        const auto upload = [&](bool reference) {
            if (reference) {
                round["parse"] = parseHere(niftiFile, false, uploadDims);
                round["parse_in_child"] = parseHere(niftiFile, true, uploadDims);
            } else {
                round["volcast_upload"] = volcastOpensUpload(orthanc, work / "web", niftiFile, uploadDims, viewport);
            }
        };
        dicomweb(referenceFirst);
        dicomweb(!referenceFirst);
        upload(referenceFirst);
        upload(!referenceFirst);
        round["load_average_1min_after"] = number(loadAverage());
        roundsJson.push_back(round);
    }

    const auto orthancMs = column(roundsJson, "orthanc_serves", "/ms");
    const auto seriesMs = column(roundsJson, "volcast_dicomweb", "/ms");
    const auto parseMs = column(roundsJson, "parse", "/ms");
    const auto parseChildMs = column(roundsJson, "parse_in_child", "/ms");
    const auto uploadMs = column(roundsJson, "volcast_upload", "/ms");
    const auto seriesRatio = ratios(seriesMs, orthancMs);
    const auto uploadRatio = ratios(uploadMs, parseMs);

    const std::vector<std::string> seriesParts = {"metadata", "retrieve", "parse_in_child", "load", "renderer", "first_frame"};
    const std::vector<std::string> uploadParts = {"send_body", "verify", "parse_in_child", "load", "renderer", "first_frame"};
    json summary = {
        {"dicomweb",
         {{"orthanc_serves_ms", summaryJson(summarise(orthancMs))},
          {"volcast_first_frame_ms", summaryJson(summarise(seriesMs))},
          {"ratio", summaryJson(summarise(seriesRatio))},
          {"ratio_of_medians", number(summarise(seriesMs).median / summarise(orthancMs).median)},
          {"target", 2}}},
        {"upload",
         {{"parse_ms", summaryJson(summarise(parseMs))},
          {"parse_in_child_ms", summaryJson(summarise(parseChildMs))},
          {"volcast_first_frame_ms", summaryJson(summarise(uploadMs))},
          {"ratio", summaryJson(summarise(uploadRatio))},
          {"ratio_of_medians", number(summarise(uploadMs).median / summarise(parseMs).median)},
          {"ratio_to_parse_in_child", summaryJson(summarise(ratios(uploadMs, parseChildMs)))},
          {"target", 2}}},
    };
    for (const auto &p : seriesParts)
        summary["dicomweb"]["parts_ms"][p] = summaryJson(summarise(column(roundsJson, "volcast_dicomweb", "/parts_ms/" + p)));
    for (const auto &p : uploadParts)
        summary["upload"]["parts_ms"][p] = summaryJson(summarise(column(roundsJson, "volcast_upload", "/parts_ms/" + p)));

    const json result = {
        {"study", "byos"},
        {"command", std::string("volcast-bench byos --rounds ") + std::to_string(rounds) + (options.quick ? " --quick" : "")},
        {"machine", machineInfo(nullptr)},
        {"quick", options.quick},
        {"rounds", rounds},
        {"viewport", {viewport, viewport}},
        {"dicomweb_series",
         {{"dims", {seriesDims.x, seriesDims.y, seriesDims.z}},
          {"voxel_type", "int16"},
          {"instances", instances},
          {"file_bytes", seriesBytes},
          {"orthanc_statistics", stored}}},
        {"upload_file",
         {{"dims", {uploadDims.x, uploadDims.y, uploadDims.z}},
          {"voxel_type", "int16"},
          {"format", ".nii.gz"},
          {"noise_hu", kNoiseHu},
          {"bytes", niftiBytes}}},
        {"summary", summary},
        {"runs", roundsJson},
    };

    std::ostringstream md;
    md << "DICOMweb: " << seriesDims.x << "×" << seriesDims.y << "×" << seriesDims.z << " int16, " << instances
       << " instances, " << fmt(mib(seriesBytes), 1) << " MiB of files; upload: " << uploadDims.x << "×" << uploadDims.y
       << "×" << uploadDims.z << " int16 .nii.gz, " << fmt(mib(niftiBytes), 1) << " MiB. " << rounds
       << " rounds, median (min–max) ms, first frame " << viewport << "×" << viewport << ".\n\n"
       << "| measurement | ms |\n|---|---|\n"
       << "| Orthanc serves the series (one WADO-RS GET) | " << cell(summarise(orthancMs)) << " |\n"
       << "| volcast: open_volume → first frame | " << cell(summarise(seriesMs)) << " |\n";
    for (const auto &p : seriesParts)
        md << "| … " << p << " | " << cell(summarise(column(roundsJson, "volcast_dicomweb", "/parts_ms/" + p))) << " |\n";
    md << "| **ratio** (target ≤ 2) | " << fmt(summarise(seriesRatio).median, 2) << " (" << fmt(summarise(seriesRatio).min, 2)
       << "–" << fmt(summarise(seriesRatio).max, 2) << ") |\n"
       << "| loadVolume of the .nii.gz here | " << cell(summarise(parseMs)) << " |\n"
       << "| loadVolume, parsed in the child first | " << cell(summarise(parseChildMs)) << " |\n"
       << "| volcast: POST /api/volumes → first frame | " << cell(summarise(uploadMs)) << " |\n";
    for (const auto &p : uploadParts)
        md << "| … " << p << " | " << cell(summarise(column(roundsJson, "volcast_upload", "/parts_ms/" + p))) << " |\n";
    md << "| **ratio** (target ≤ 2) | " << fmt(summarise(uploadRatio).median, 2) << " (" << fmt(summarise(uploadRatio).min, 2)
       << "–" << fmt(summarise(uploadRatio).max, 2) << ") |\n";

    StudyOutput out(options.out, "byos");
    out.writeJson(result);
    out.writeMarkdown(md.str());
    std::cout << md.str() << std::flush;
}

} // namespace volcast::bench
