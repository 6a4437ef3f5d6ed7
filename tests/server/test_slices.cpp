// `slice` requests through a real server over loopback (server/slice_service.hpp): the three
// orthogonal slices of a volume come back with the requested size and exactly the bytes the
// renderer's slice functions (renderer/model/slice.hpp) give for the same volume; bad requests get
// their error and the session, its 3D frames included, carries on.

#include "client/cpp/ws_client.hpp"
#include "renderer/io/volume_source.hpp"
#include "renderer/model/slice.hpp"
#include "server/server.hpp"
#include "tests/server/server_fixture.hpp"

#include <gtest/gtest.h>

#include <filesystem>
#include <thread>
#include <unistd.h>

namespace {

namespace fs = std::filesystem;
using namespace std::chrono_literals;
using nlohmann::json;
using volcast::client::Client;
using volcast::client::Message;
namespace protocol = volcast::protocol;

constexpr auto kTimeout = 20s;   // a cold PoCL cache builds programs for seconds

class SliceServerTest : public ::testing::Test {
  protected:
    static inline std::unique_ptr<volcast::server::Server> server;
    static inline fs::path tmp;

    static void SetUpTestSuite() {
        tmp = fs::temp_directory_path() / ("volcast_slice_test_" + std::to_string(::getpid()));
        fs::remove_all(tmp);
        fs::create_directories(tmp / "data");
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

    std::unique_ptr<Client> helloSession() {
        auto c = volcast::test::helloClient(server->port(), "gtest slices", kTimeout);
        c->sendText(R"({"type":"viewport","id":2,"image":{"width":32,"height":32}})");
        return c;
    }
    void openVolume(Client &c, const std::string &name) {
        c.sendText(json{{"type", "open_volume"}, {"id", 3}, {"name", name}}.dump());
        const Message state = volcast::client::waitForReply(c, 3, kTimeout);
        ASSERT_TRUE(state.decoded && std::holds_alternative<protocol::StateMessage>(*state.decoded)) << state.text;
    }
};

// The slice message answering `id`, or the error answering it; frames and other texts are
// skipped. Fails the test on timeout.
Message sliceAnswer(Client &c, const json &id) {
    const auto deadline = std::chrono::steady_clock::now() + kTimeout;
    while (std::chrono::steady_clock::now() < deadline) {
        auto m = c.next(100ms);
        if (!m) continue;
        if (m->isSlice) {
            EXPECT_TRUE(m->decodeError.empty()) << m->decodeError;
            if (m->sliceHeader.request == id) return std::move(*m);
        } else if (!m->isFrame && m->decoded) {
            if (auto *e = std::get_if<protocol::ProtocolError>(&*m->decoded); e && e->requestId == id)
                return std::move(*m);
        }
    }
    ADD_FAILURE() << "no answer to slice " << id.dump() << " in time";
    return {};
}

using volcast::test::asError;

TEST_F(SliceServerTest, ThreeSlicesHaveTheRequestedSizeAndTheRendererSliceBytes) {
    auto c = helloSession();
    openVolume(*c, "builtin:demo");
    const auto loaded = volcast::loadSceneVolume("builtin:demo");
    const volcast::Volume &volume = loaded.volume;

    struct Case {
        const char *axis;
        volcast::SliceAxis expectedAxis;
        json fields;
    };
    // A crosshair off the centre, an explicit window on two, the defaults on the third.
    const json point = {40.25, 70.5, 30.75};
    const std::vector<Case> cases = {
        {"axial", volcast::SliceAxis::Axial, {{"point", point}, {"window", 120}, {"level", 90}}},
        {"coronal", volcast::SliceAxis::Coronal, {{"point", point}, {"window", 60}, {"level", 40}, {"pixel_spacing", 1.5}}},
        {"sagittal", volcast::SliceAxis::Sagittal, json::object()},
    };
    int id = 10;
    for (const Case &k : cases) {
        SCOPED_TRACE(k.axis);
        json request = {{"type", "slice"}, {"id", ++id}, {"axis", k.axis}, {"width", 96}, {"height", 80}};
        request.update(k.fields);
        c->sendText(request.dump());
        const Message m = sliceAnswer(*c, id);
        ASSERT_TRUE(m.isSlice) << m.text;
        const protocol::SliceHeader &h = m.sliceHeader;
        EXPECT_EQ(h.axis, k.axis);
        ASSERT_EQ(h.width, 96);
        ASSERT_EQ(h.height, 80);
        ASSERT_EQ(m.slicePixels.size(), size_t(96 * 80));

        // The same request straight through the renderer's functions.
        volcast::SliceRequestGeometry g;
        g.axis = k.expectedAxis;
        g.point = k.fields.contains("point") ? volcast::Vec3d{40.25, 70.5, 30.75} : volume.center();
        g.width = 96;
        g.height = 80;
        if (k.fields.contains("pixel_spacing")) g.pixelSpacing = k.fields["pixel_spacing"].get<double>();
        const volcast::SlicePlane plane = volcast::slicePlane(volume, g);
        const volcast::WindowLevel defaults = volcast::defaultWindowLevel(volume);
        const double window = k.fields.value("window", defaults.window);
        const double level = k.fields.value("level", defaults.level);
        EXPECT_EQ(h.window, window);
        EXPECT_EQ(h.level, level);
        EXPECT_DOUBLE_EQ(h.pixelSpacing, plane.pixelSpacing);
        for (int a = 0; a < 3; ++a) {
            EXPECT_DOUBLE_EQ(h.origin[size_t(a)], plane.origin[a]);
            EXPECT_DOUBLE_EQ(h.point[size_t(a)], g.point[a]);
        }
        const std::vector<uint8_t> expected =
            volcast::windowToGray8(volcast::sampleSlice(volume, plane), window, level);
        // The same code on the same voxels: the bytes agree exactly.
        size_t differing = 0;
        for (size_t i = 0; i < expected.size(); ++i) differing += expected[i] != m.slicePixels[i];
        EXPECT_EQ(differing, 0u) << "pixels differing from renderer/model/slice.hpp's answer";
        // Not a blank image: the demo volume has structure on every one of these planes.
        size_t lit = 0;
        for (uint8_t v : m.slicePixels) lit += v > 0;
        EXPECT_GT(lit, size_t(96 * 80 / 10)) << "the slice is nearly empty";
    }
}

TEST_F(SliceServerTest, BadSlicesGetTheirErrorAndTheSessionCarriesOn) {
    auto c = helloSession();
    c->sendText(R"({"type":"slice","id":"early","axis":"axial","width":8,"height":8})");
    const Message early = sliceAnswer(*c, "early");
    ASSERT_TRUE(asError(early)) << early.text;
    EXPECT_EQ(asError(early)->code, protocol::ErrorCode::BadState);

    openVolume(*c, "builtin:demo");
    const std::vector<std::tuple<std::string, protocol::ErrorCode, std::string>> cases = {
        {R"("axis":"oblique","width":8,"height":8)", protocol::ErrorCode::BadField, "axis:"},
        {R"("axis":"axial","width":0,"height":8)", protocol::ErrorCode::BadField, "width:"},
        {R"("axis":"axial","width":8,"height":8,"pixel_spacing":1e308)", protocol::ErrorCode::BadField,
         "pixel_spacing:"},
        {R"("axis":"axial","width":16384,"height":16384)", protocol::ErrorCode::TooLarge, "--max-still-pixels"},
    };
    int id = 100;
    for (const auto &[fields, code, mention] : cases) {
        c->sendText(R"({"type":"slice","id":)" + std::to_string(++id) + "," + fields + "}");
        const Message m = sliceAnswer(*c, id);
        const protocol::ProtocolError *e = asError(m);
        ASSERT_TRUE(e) << fields << " was not refused";
        EXPECT_EQ(e->code, code) << e->message;
        EXPECT_EQ(e->requestType, "slice");
        EXPECT_NE(e->message.find(mention), std::string::npos) << e->message;
    }
    // A plane far outside the volume: a valid, all-background image.
    c->sendText(R"({"type":"slice","id":"far","axis":"axial","width":8,"height":8,"point":[0,0,1e9]})");
    const Message far = sliceAnswer(*c, "far");
    ASSERT_TRUE(far.isSlice) << far.text;
    for (uint8_t v : far.slicePixels) ASSERT_EQ(v, 0);
    // The 3D view still renders to a final frame after all that.
    c->sendText(R"({"type":"still","id":"after"})");
    const auto deadline = std::chrono::steady_clock::now() + kTimeout;
    bool final = false;
    while (!final && std::chrono::steady_clock::now() < deadline) {
        auto m = c->next(100ms);
        final = m && m->isFrame && m->frame.header.final && m->frame.header.request == "after";
    }
    EXPECT_TRUE(final) << "no final frame after the refused slices";
}

} // namespace
