// probe, roi_stats, pick and thick slabs through a real server over loopback: the numbers
// agree with closed forms on a volume the test writes itself (a linear ramp beside air, in
// Hounsfield units) and with the renderer's own functions (renderer/model/slice.hpp,
// ReferenceRenderer::pick) on the same scene; hostile requests get their error, change nothing
// in the session's scene, and the session carries on to a final frame.

#include "client/cpp/ws_client.hpp"
#include "renderer/io/volume_io.hpp"
#include "renderer/io/volume_source.hpp"
#include "renderer/model/presets.hpp"
#include "renderer/reference/reference_renderer.hpp"
#include "renderer/model/slice.hpp"
#include "server/server.hpp"
#include "tests/server/png_decode.hpp"
#include "tests/server/server_fixture.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <unistd.h>

namespace {

namespace fs = std::filesystem;
using namespace std::chrono_literals;
using nlohmann::json;
using volcast::client::Client;
using volcast::client::Message;
using volcast::test::asError;
namespace protocol = volcast::protocol;

constexpr auto kTimeout = 20s;   // a cold PoCL cache builds programs for seconds

// Voxel (i, j, k) of the ramp volume, spacing 1 mm, origin 0, identity direction: air
// (−1000 HU) for i < 12, else the ramp 2i − 3j + k + 200 (integers, stored exactly in int16;
// trilinear reconstruction reproduces a linear function exactly between its samples). Signed,
// air at −1000 and values up to 277 are what renderer/model/presets.hpp takes for CT in HU.
double rampValue(double x, double y, double z) { return 2 * x - 3 * y + z + 200; }

volcast::Volume rampVolume() {
    volcast::Volume v;
    v.name = "ramp_ct";
    v.dims = {32, 32, 16};
    v.spacing = {1, 1, 1};
    v.origin = {0, 0, 0};
    v.direction = volcast::Mat3d::identity();
    v.voxels.resize(v.voxelCount());
    for (int64_t k = 0; k < v.dims.z; ++k)
        for (int64_t j = 0; j < v.dims.y; ++j)
            for (int64_t i = 0; i < v.dims.x; ++i)
                v.voxels[v.index(i, j, k)] = float(i < 12 ? -1000.0 : rampValue(double(i), double(j), double(k)));
    volcast::computeStatistics(v);
    return v;
}

using volcast::test::decodePng;

class MeasurementServerTest : public ::testing::Test {
  protected:
    static inline std::unique_ptr<volcast::server::Server> server;
    static inline fs::path tmp;

    static void SetUpTestSuite() {
        tmp = fs::temp_directory_path() / ("volcast_measure_test_" + std::to_string(::getpid()));
        fs::remove_all(tmp);
        fs::create_directories(tmp / "data");
        volcast::saveVolume(rampVolume(), tmp / "data" / "ramp_ct.nrrd", {volcast::VoxelType::Int16, false});
        volcast::server::ServerConfig config;
        config.port = 0;
        config.dataDirs = {tmp / "data"};
        config.idleMs = 100;
        config.ioThreads = 2;
        server = std::make_unique<volcast::server::Server>(config);
        volcast::test::startAndWaitReady(*server, kTimeout);
    }
    static void TearDownTestSuite() {
        server.reset();
        fs::remove_all(tmp);
    }

    std::unique_ptr<Client> session(const std::string &volume) {
        auto c = volcast::test::helloClient(server->port(), "gtest measurements", kTimeout);
        c->sendText(R"({"type":"viewport","id":2,"image":{"width":32,"height":32}})");
        c->sendText(json{{"type", "open_volume"}, {"id", 3}, {"name", volume}}.dump());
        const Message state = volcast::client::waitForReply(*c, 3, kTimeout);
        EXPECT_TRUE(state.decoded && std::holds_alternative<protocol::StateMessage>(*state.decoded)) << state.text;
        return c;
    }

    // The text answer (or error) to `id`, frames and slices skipped.
    static Message answer(Client &c, const json &request) {
        c.sendText(request.dump());
        return volcast::client::waitForReply(c, request.at("id"), kTimeout);
    }
    static json stateScene(Client &c, const std::string &id) {
        const Message m = answer(c, {{"type", "get_state"}, {"id", id}});
        const auto *s = m.decoded ? std::get_if<protocol::StateMessage>(&*m.decoded) : nullptr;
        EXPECT_TRUE(s) << m.text;
        return s ? s->scene : json();
    }
};

TEST_F(MeasurementServerTest, ProbeGivesTheRampInHounsfieldUnitsAndNullOutside) {
    auto c = session("ramp_ct.nrrd");
    const volcast::Volume loaded = volcast::loadVolume(tmp / "data" / "ramp_ct.nrrd");
    ASSERT_TRUE(volcast::chooseModality(loaded, "ramp_ct.nrrd").hounsfield)
        << "signed values with air at -1000 are CT in HU (renderer/model/presets.hpp)";
    // Between samples on every axis, inside the ramp part: exact up to double rounding.
    const Message m = answer(*c, {{"type", "probe"}, {"id", 10}, {"point", {20.25, 7.5, 3.75}}});
    const auto *p = m.decoded ? std::get_if<protocol::ProbeMessage>(&*m.decoded) : nullptr;
    ASSERT_TRUE(p) << m.text;
    EXPECT_TRUE(p->inside);
    ASSERT_TRUE(p->value);
    EXPECT_NEAR(*p->value, rampValue(20.25, 7.5, 3.75), 1e-9);
    EXPECT_EQ(p->unit, "HU");
    EXPECT_EQ(p->point, (std::array<double, 3>{20.25, 7.5, 3.75}));
    // In the air: −1000 exactly.
    const Message air = answer(*c, {{"type", "probe"}, {"id", 11}, {"point", {3, 3, 3}}});
    EXPECT_EQ(std::get<protocol::ProbeMessage>(*air.decoded).value, -1000.0);
    // Past the cell box (x = 31.5 is its face): outside, value and its JSON null.
    const Message out = answer(*c, {{"type", "probe"}, {"id", 12}, {"point", {31.6, 3, 3}}});
    const auto &o = std::get<protocol::ProbeMessage>(*out.decoded);
    EXPECT_FALSE(o.inside);
    EXPECT_FALSE(o.value);
    EXPECT_TRUE(json::parse(out.text).at("value").is_null());
}

TEST_F(MeasurementServerTest, ProbeOfAGreyValueVolumeHasNoUnit) {
    auto c = session("builtin:demo");
    const auto demo = volcast::loadSceneVolume("builtin:demo");
    const volcast::Vec3d point = demo.volume.center() + volcast::Vec3d{3.3, -2.1, 1.7};
    const Message m = answer(*c, {{"type", "probe"}, {"id", 10}, {"point", {point.x, point.y, point.z}}});
    const auto *p = m.decoded ? std::get_if<protocol::ProbeMessage>(&*m.decoded) : nullptr;
    ASSERT_TRUE(p) << m.text;
    ASSERT_FALSE(volcast::chooseModality(demo.volume, "builtin:demo").hounsfield);
    EXPECT_FALSE(p->unit) << "raw data units";
    // The same reconstruction as the slices: renderer/model/slice.hpp's probeValue on the same voxels.
    EXPECT_EQ(p->value, volcast::probeValue(demo.volume, point));
}

// ROI statistics against the closed forms of tests/renderer/test_slice.cpp's RoiStats: a
// rectangle of whole grid cells (h = min(1/2, min(a, b)/8) = 0.5 mm here) on the ramp.
TEST_F(MeasurementServerTest, RoiStatsOfARectangleOnTheRampMatchClosedForms) {
    auto c = session("ramp_ct.nrrd");
    // Axial: columns +x (gu = 2), rows +y (gv = −3); inside the ramp part (x in [12, 31]).
    const double cx = 21.25, cy = 14.75, cz = 6.5, a = 4, b = 6, h = 0.5;
    const Message m = answer(*c, {{"type", "roi_stats"}, {"id", 20}, {"axis", "axial"}, {"center", {cx, cy, cz}},
                                  {"radii", {a, b}}, {"shape", "rectangle"}});
    const auto *r = m.decoded ? std::get_if<protocol::RoiStatsMessage>(&*m.decoded) : nullptr;
    ASSERT_TRUE(r) << m.text;
    const double nu = a / h, nv = b / h;
    EXPECT_EQ(r->samples, int64_t(4 * nu * nv));
    EXPECT_NEAR(r->areaMm2, 4 * a * b, 1e-9);
    ASSERT_TRUE(r->mean && r->std && r->min && r->max);
    EXPECT_NEAR(*r->mean, rampValue(cx, cy, cz), 1e-9);
    EXPECT_NEAR(*r->std, std::sqrt((4 * (4 * nu * nu - 1) + 9 * (4 * nv * nv - 1)) * h * h / 12), 1e-9);
    const double spread = (2 * (nu - 0.5) + 3 * (nv - 0.5)) * h;
    EXPECT_NEAR(*r->min, rampValue(cx, cy, cz) - spread, 1e-9);
    EXPECT_NEAR(*r->max, rampValue(cx, cy, cz) + spread, 1e-9);
    EXPECT_EQ(r->unit, "HU");
    // An ellipse beside the volume: no samples, statistics null.
    const Message none = answer(*c, {{"type", "roi_stats"}, {"id", 21}, {"axis", "coronal"}, {"center", {100, 5, 5}},
                                     {"radii", {3, 3}}});
    const auto &n = std::get<protocol::RoiStatsMessage>(*none.decoded);
    EXPECT_EQ(n.samples, 0);
    EXPECT_EQ(n.areaMm2, 0);
    EXPECT_TRUE(json::parse(none.text).at("mean").is_null());
    EXPECT_TRUE(json::parse(none.text).at("std").is_null());
}

// A pick is the reference integrator's answer on the session's scene: the same scene rebuilt
// here from get_state gives the same point. A ray beside the volume misses.
TEST_F(MeasurementServerTest, PickIsTheReferenceOnTheSessionsScene) {
    auto c = session("builtin:demo");
    const auto demo = volcast::loadSceneVolume("builtin:demo");
    const double lo = demo.volume.range.min, hi = demo.volume.range.max;
    c->sendText(json{{"type", "camera"}, {"id", 4}, {"camera", volcast::test::cameraAt(30)}}.dump());
    c->sendText(json{{"type", "transfer_function"},
                     {"id", 5},
                     {"transfer_function", {{"points", {{lo, 1, 1, 1, 0}, {hi, 1, 0.5, 0.2, 0.6}}}}}}
                    .dump());
    c->sendText(R"({"type":"clip_planes","id":6,"clip_planes":[{"point":[0,0,60],"normal":[0,0,-1]}]})");
    const json sceneJson = stateScene(*c, "s1");
    const volcast::Scene scene = volcast::parseScene(sceneJson.dump());
    volcast::ReferenceRenderer ref(demo.volume, volcast::resolvedTransferFunction(scene, demo.volume.range),
                                   volcast::Reconstruction::Linear);
    ref.setQuality(scene.quality);
    const volcast::RayGenerator rays(scene.camera, 200, 100);
    int hits = 0, id = 100;
    for (const auto &[x, y] : std::vector<std::pair<double, double>>{{100, 50}, {90.5, 40.5}, {0.5, 0.5}, {120, 70}}) {
        const Message m = answer(*c, {{"type", "pick"}, {"id", ++id}, {"x", x}, {"y", y}, {"width", 200}, {"height", 100}});
        const auto *p = m.decoded ? std::get_if<protocol::PickMessage>(&*m.decoded) : nullptr;
        ASSERT_TRUE(p) << m.text;
        const volcast::RayPick expected = ref.pick(rays.rayThrough(x, y), scene.clipPlanes, 0.5, 1e-5);
        EXPECT_EQ(p->hit, expected.hit) << x << "," << y;
        EXPECT_NEAR(p->opacity, expected.opacity, 1e-12);
        if (expected.hit) {
            ASSERT_TRUE(p->point);
            for (int a = 0; a < 3; ++a) EXPECT_NEAR((*p->point)[size_t(a)], expected.point[a], 1e-9);
            ++hits;
        } else {
            EXPECT_FALSE(p->point);
            EXPECT_TRUE(json::parse(m.text).at("point").is_null());
        }
    }
    EXPECT_GE(hits, 2) << "the centre of the view hits the demo volume";
}

// A slab through the server is renderer/model/slice.hpp's sampleSlab, byte for byte, and its header
// echoes the slab with its number of planes.
TEST_F(MeasurementServerTest, SlabSliceIsTheRenderersSlabAndEchoesIt) {
    auto c = session("ramp_ct.nrrd");
    const volcast::Volume loaded = volcast::loadVolume(tmp / "data" / "ramp_ct.nrrd");
    c->sendText(R"({"type":"slice","id":30,"axis":"coronal","width":40,"height":20,"point":[20,10,8],
                    "window":400,"level":0,"slab":{"thickness":6,"mode":"mean"}})");
    const auto deadline = std::chrono::steady_clock::now() + kTimeout;
    std::optional<Message> slice;
    while (!slice && std::chrono::steady_clock::now() < deadline) {
        auto m = c->next(100ms);
        if (m && m->isSlice && m->sliceHeader.request == 30) slice = std::move(*m);
        else if (m && !m->isFrame && asError(*m)) FAIL() << m->text;
    }
    ASSERT_TRUE(slice) << "no slab in time";
    const protocol::SliceHeader &h = slice->sliceHeader;
    ASSERT_TRUE(h.slab);
    EXPECT_EQ(h.slab->thickness, 6);
    EXPECT_EQ(h.slab->mode, "mean");
    EXPECT_EQ(h.slabPlanes, 13) << "6 mm at 0.5 mm: 12 gaps";
    volcast::SliceRequestGeometry g;
    g.axis = volcast::SliceAxis::Coronal;
    g.point = {20, 10, 8};
    g.width = 40;
    g.height = 20;
    const volcast::SlicePlane plane = volcast::slicePlane(loaded, g);
    const auto expected = volcast::windowToGray8(
        volcast::sampleSlab(loaded, plane, {6, volcast::SlabMode::Mean}), 400, 0);
    EXPECT_EQ(std::vector<uint8_t>(slice->slicePixels.begin(), slice->slicePixels.end()), expected);
}

// Hostile and early requests: each gets its own error naming what was wrong, the scene the
// session holds is unchanged, and the session still renders a final frame.
TEST_F(MeasurementServerTest, HostileRequestsAreRefusedAndChangeNothing) {
    {
        auto early = volcast::test::helloClient(server->port(), "gtest early", kTimeout);
        for (const char *request : {R"({"type":"probe","id":"e1","point":[0,0,0]})",
                                    R"({"type":"roi_stats","id":"e2","axis":"axial","center":[0,0,0],"radii":[1,1]})",
                                    R"({"type":"pick","id":"e3","x":1,"y":1,"width":8,"height":8})"}) {
            early->sendText(request);
            const Message m = volcast::client::waitForReply(*early, json::parse(request).at("id"), kTimeout);
            ASSERT_TRUE(asError(m)) << m.text;
            EXPECT_EQ(asError(m)->code, protocol::ErrorCode::BadState) << m.text;
        }
    }
    auto c = session("ramp_ct.nrrd");
    const json before = stateScene(*c, "before");
    struct Case {
        std::string request;
        protocol::ErrorCode code;
        std::string mention;
        bool idRead;   // false: the text fails to parse before its id is read
    };
    const std::vector<Case> cases = {
        {R"({"type":"probe","id":1,"point":[NaN,0,0]})", protocol::ErrorCode::MalformedJson, "", false},
        {R"({"type":"probe","id":2,"point":[1e999,0,0]})", protocol::ErrorCode::BadField, "point[0]", false},
        {R"({"type":"probe","id":3,"point":"centre"})", protocol::ErrorCode::BadField, "point", true},
        {R"({"type":"probe","id":4,"point":[1,2]})", protocol::ErrorCode::BadField, "point", true},
        {R"({"type":"roi_stats","id":5,"axis":"axial","center":[20,10,5],"radii":[1e-9,1000]})",
         protocol::ErrorCode::TooLarge, "radii", true},
        {R"({"type":"roi_stats","id":6,"axis":"axial","center":[20,10,5],"radii":[0,1]})", protocol::ErrorCode::BadField,
         "radii[0]", true},
        {R"({"type":"roi_stats","id":7,"axis":"axial","center":[20,10,5],"radii":[1,1],"shape":"star"})",
         protocol::ErrorCode::BadField, "shape", true},
        {R"({"type":"roi_stats","id":8,"axis":42,"center":[20,10,5],"radii":[1,1]})", protocol::ErrorCode::BadField,
         "axis", true},
        {R"({"type":"pick","id":9,"x":9,"y":1,"width":8,"height":8})", protocol::ErrorCode::BadField, "x", true},
        {R"({"type":"pick","id":10,"x":1,"y":1,"width":8,"height":1e300})", protocol::ErrorCode::BadField, "height", true},
        {R"({"type":"pick","id":11,"x":true,"y":1,"width":8,"height":8})", protocol::ErrorCode::BadField, "x", true},
        {R"({"type":"slice","id":12,"axis":"axial","width":8,"height":8,"slab":{"thickness":1e6}})",
         protocol::ErrorCode::TooLarge, "1024", true},
        {R"({"type":"slice","id":13,"axis":"axial","width":8,"height":8,"slab":{"thickness":-2}})",
         protocol::ErrorCode::BadField, "slab.thickness", true},
        {R"({"type":"slice","id":14,"axis":"axial","width":8,"height":8,"slab":{"thickness":2,"mode":"max"}})",
         protocol::ErrorCode::BadField, "slab.mode", true},
        {R"({"type":"quality_policy","id":15,"mode":"automatic","quality":{"compositing":"mip",
             "projection_window":{"window":0,"level":40}}})",
         protocol::ErrorCode::BadField, "quality.projection_window.window", true},
        {R"({"type":"quality_policy","id":16,"mode":"automatic","quality":{"compositing":"mip",
             "projection_window":{"window":"wide","level":40}}})",
         protocol::ErrorCode::BadField, "quality.projection_window.window", true},
    };
    for (const Case &k : cases) {
        SCOPED_TRACE(k.request);
        c->sendText(k.request);
        Message m;
        if (!k.idRead) {
            // No id could be read from it: the next error is its answer.
            const auto deadline = std::chrono::steady_clock::now() + kTimeout;
            while (std::chrono::steady_clock::now() < deadline) {
                auto next = c->next(100ms);
                if (next && !next->isFrame && !next->isSlice && asError(*next)) {
                    m = std::move(*next);
                    break;
                }
            }
        } else {
            const auto deadline = std::chrono::steady_clock::now() + kTimeout;
            const json id = json::parse(k.request).at("id");
            while (std::chrono::steady_clock::now() < deadline) {
                auto next = c->next(100ms);
                if (next && !next->isFrame && !next->isSlice && asError(*next) && asError(*next)->requestId == id) {
                    m = std::move(*next);
                    break;
                }
            }
        }
        const protocol::ProtocolError *e = asError(m);
        ASSERT_TRUE(e) << "not refused";
        EXPECT_EQ(e->code, k.code) << e->message;
        EXPECT_NE(e->message.find(k.mention), std::string::npos) << e->message;
    }
    EXPECT_EQ(stateScene(*c, "after"), before) << "a refused request changed the scene";
    c->sendText(R"({"type":"still","id":"after"})");
    const auto deadline = std::chrono::steady_clock::now() + kTimeout;
    bool final = false;
    while (!final && std::chrono::steady_clock::now() < deadline) {
        auto m = c->next(100ms);
        final = m && m->isFrame && m->frame.header.final && m->frame.header.request == "after";
    }
    EXPECT_TRUE(final) << "no final frame after the refused requests";
}

// A windowed MIP travels in the quality policy, comes back in get_state, and its final frame
// is grey and opaque over the volume (R = G = B, alpha 255 at the centre).
TEST_F(MeasurementServerTest, WindowedMipTravelsInThePolicyAndDrawsGrey) {
    auto c = session("ramp_ct.nrrd");
    c->sendText(R"({"type":"quality_policy","id":40,"mode":"automatic","quality":{"compositing":"mip",
                    "projection_window":{"window":200,"level":100}}})");
    const json scene = stateScene(*c, "s");
    EXPECT_EQ(scene.at("quality").at("compositing"), "mip");
    EXPECT_EQ(scene.at("quality").at("projection_window"), (json{{"window", 200}, {"level", 100}}));
    c->sendText(R"({"type":"still","id":"mip"})");
    const auto deadline = std::chrono::steady_clock::now() + kTimeout;
    std::optional<Message> frame;
    while (!frame && std::chrono::steady_clock::now() < deadline) {
        auto m = c->next(100ms);
        if (m && m->isFrame && m->frame.header.final && m->frame.header.request == "mip") frame = std::move(*m);
    }
    ASSERT_TRUE(frame) << "no final MIP frame";
    const auto &f = frame->frame;
    ASSERT_EQ(f.header.codec, protocol::Codec::Png);
    int w = 0, h = 0, channels = 0;
    const std::vector<uint8_t> rgba = decodePng(f.image, w, h, channels);
    ASSERT_EQ(w, 32);
    ASSERT_EQ(channels, 4);
    const size_t centre = (size_t(16) * 32 + 16) * 4;
    EXPECT_EQ(rgba[centre + 3], 255);
    EXPECT_EQ(rgba[centre], rgba[centre + 1]);
    EXPECT_EQ(rgba[centre], rgba[centre + 2]);
}

} // namespace
