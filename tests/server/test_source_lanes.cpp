// How the server shares its sources between sessions, against a fake PACS (fake_pacs.hpp)
// that can be made slow: a local open never waits behind retrievals from a slow PACS, a
// search of one source is answered while another source's search hangs, many sessions
// searching one source at once are all answered, and a series the loader refused leaves the
// retrieval cache, so that a second open retrieves it again.

#include "fake_pacs.hpp"
#include "registry_fixture.hpp"
#include "renderer/io/volume_io.hpp"
#include "server/dicomweb_provider.hpp"
#include "server/work_lane.hpp"
#include "server_fixture.hpp"

#include <gtest/gtest.h>

#include <atomic>
#include <chrono>
#include <filesystem>
#include <fstream>
#include <future>
#include <iostream>
#include <memory>
#include <mutex>
#include <string>
#include <vector>

namespace {

namespace fs = std::filesystem;
using json = nlohmann::json;
using namespace std::chrono_literals;
using volcast::client::Client;
using volcast::client::Message;
using volcast::protocol::ErrorCode;
using volcast::test::FakePacs;

constexpr auto kTimeout = 60s;

// A 64 x 64 x 4 int16 series written as DICOM files: the instances a fake PACS serves.
std::vector<std::string> writeSeries(const fs::path &folder) {
    volcast::Volume v;
    v.dims = {64, 64, 4};
    v.spacing = {1, 1, 2};
    v.voxels.resize(v.voxelCount());
    for (size_t i = 0; i < v.voxels.size(); ++i) v.voxels[i] = float(int(i % 500) - 100);
    volcast::saveDicomSeries(v, folder, volcast::VoxelType::Int16);
    return FakePacs::filesOf(folder);
}

// A 50 x 50 x 25 int16 NRRD (125 KB of samples): the small local file a session opens.
void writeSmallNrrd(const fs::path &path) {
    volcast::Volume v;
    v.dims = {50, 50, 25};
    v.spacing = {1, 1, 1};
    v.voxels.resize(v.voxelCount());
    for (size_t i = 0; i < v.voxels.size(); ++i) v.voxels[i] = float(i % 1000);
    volcast::SaveOptions options;
    options.type = volcast::VoxelType::Int16;
    volcast::saveVolume(v, path, options);
}

std::string seriesName(const std::string &source, const FakePacs &pacs) {
    return "dicomweb:" + source + "/" + pacs.studyUid() + "/" + pacs.seriesUid();
}

// Waits up to `timeout` for `condition`; false if it never held.
template <class Condition>
bool waitFor(Condition condition, std::chrono::milliseconds timeout) {
    const auto deadline = std::chrono::steady_clock::now() + timeout;
    while (!condition()) {
        if (std::chrono::steady_clock::now() > deadline) return false;
        std::this_thread::sleep_for(10ms);
    }
    return true;
}

double secondsSince(std::chrono::steady_clock::time_point t) {
    return std::chrono::duration<double>(std::chrono::steady_clock::now() - t).count();
}

class SourceLanes : public volcast::test::RegistryTest {
  protected:
    fs::path series;   // the DICOM files the fake PACS serve, outside the data folder
    fs::path cache;    // a DicomWebProvider's cache folder

    void SetUp() override {
        RegistryTest::SetUp();
        series = data.string() + "_series";
        cache = data.string() + "_cache";
    }
    void TearDown() override {
        fs::remove_all(series);
        fs::remove_all(cache);
        RegistryTest::TearDown();
    }

    // A server over the test's data folder with these DICOMweb sources.
    std::unique_ptr<volcast::server::Server> serverWith(std::vector<std::pair<std::string, const FakePacs *>> sources,
                                                        int maxSessions = 16) {
        volcast::server::ServerConfig config;
        config.port = 0;
        config.defaultVolume = "";
        config.webRoot = data;
        config.dataDirs = {data};
        config.errorCalibration = false;
        config.maxSessions = maxSessions;
        // A hanging search ends at this limit; a trickle of 10 s keeps above the low-speed limit.
        config.dicomWebTimeoutS = 30;
        for (const auto &[name, pacs] : sources) config.dicomWebSources.push_back({name, pacs->url(), ""});
        auto server = std::make_unique<volcast::server::Server>(config);
        volcast::test::startAndWaitReady(*server, kTimeout);
        return server;
    }
};

// Two sessions retrieving series that trickle in over 10 s each must not hold up a third
// session's open of a small local file: a local open never waits behind a retrieval.
TEST_F(SourceLanes, ALocalOpenIsAnsweredWhileTwoRetrievalsTrickle) {
    writeSmallNrrd(data / "small.nrrd");
    const auto files = writeSeries(series);
    FakePacs slowA(files, {.retrievalTakes = 10s}), slowB(files, {.retrievalTakes = 10s});
    auto server = serverWith({{"a", &slowA}, {"b", &slowB}});
    auto retrieving1 = volcast::test::helloClient(server->port(), "retrieving-1", kTimeout);
    auto retrieving2 = volcast::test::helloClient(server->port(), "retrieving-2", kTimeout);
    auto local = volcast::test::helloClient(server->port(), "local", kTimeout);
    retrieving1->sendText(json{{"type", "open_volume"}, {"id", 2}, {"name", seriesName("a", slowA)}}.dump());
    retrieving2->sendText(json{{"type", "open_volume"}, {"id", 2}, {"name", seriesName("b", slowB)}}.dump());
    ASSERT_TRUE(waitFor([&] { return slowA.retrievalsBegun() == 1 && slowB.retrievalsBegun() == 1; }, kTimeout))
        << "both retrievals should have begun";

    const auto started = std::chrono::steady_clock::now();
    local->sendText(json{{"type", "open_volume"}, {"id", 2}, {"name", "small.nrrd"}}.dump());
    const Message state = volcast::client::waitForReply(*local, 2, kTimeout);
    const double took = secondsSince(started);
    std::cout << "local open of small.nrrd during two trickling retrievals: " << took << " s\n";
    EXPECT_TRUE(state.decoded && std::holds_alternative<volcast::protocol::StateMessage>(*state.decoded)) << state.text;
    // Ordering, not a time bound: the local volume arrived while both series still trickled.
    EXPECT_EQ(slowA.retrievalsSent() + slowB.retrievalsSent(), 0)
        << "the local open was answered only after " << took
        << " s, once a retrieval it has nothing to do with had ended (each trickles for 10 s)";
}

// A search of one source waited on the one search thread behind another source's search
// until that one's request time limit (30 s here).
TEST_F(SourceLanes, ASearchOfOneSourceIsAnsweredWhileAnotherSourcesSearchHangs) {
    const auto files = writeSeries(series);
    auto stalled = std::make_unique<FakePacs>(files, FakePacs::Behaviour{.searchesHang = true});
    FakePacs quick(files, {});
    auto server = serverWith({{"stalled", stalled.get()}, {"quick", &quick}});
    auto first = volcast::test::helloClient(server->port(), "stalled-search", kTimeout);
    auto second = volcast::test::helloClient(server->port(), "quick-search", kTimeout);
    first->sendText(json{{"type", "find_studies"}, {"id", 2}, {"source", "stalled"}}.dump());
    ASSERT_TRUE(waitFor([&] { return stalled->searchesBegun() == 1; }, kTimeout)) << "the stalled search should have begun";

    const auto started = std::chrono::steady_clock::now();
    second->sendText(json{{"type", "find_studies"}, {"id", 2}, {"source", "quick"}}.dump());
    const Message reply = volcast::client::waitForReply(*second, 2, kTimeout);
    const double took = secondsSince(started);
    EXPECT_TRUE(reply.decoded && std::holds_alternative<volcast::protocol::StudiesMessage>(*reply.decoded)) << reply.text;
    // The stalled search holds its source until its 30 s limit; 10 s leaves the quick one
    // (a loopback answer) room for a loaded machine and still tells the two cases apart.
    EXPECT_LT(took, 10.0) << "the search of \"quick\" waited behind the hanging search of \"stalled\"";
    EXPECT_EQ(stalled->searchesAnswered(), 0);
    stalled.reset();   // its hanging search ends now, not at its time limit, and the server stops at once
}

// 40 sessions searching one source at once: each gets its studies, none is refused busy
// (one search per session; a source runs --dicomweb-searches and lets
// DicomWebProvider::kMaxWaitingSearches wait). Each search takes 300 ms at the PACS, so that
// they pile up: on one search thread with 32 waiting, 7 of the 40 were refused.
TEST_F(SourceLanes, ManySessionsSearchingOneSourceAtOnceAreAllAnswered) {
    constexpr int kSessions = 40;
    static_assert(kSessions < volcast::server::DicomWebProvider::kMaxWaitingSearches);
    const auto files = writeSeries(series);
    FakePacs pacs(files, {.searchDelay = 300ms});
    auto server = serverWith({{"pacs", &pacs}}, kSessions + 1);
    std::vector<std::unique_ptr<Client>> clients;
    for (int i = 0; i < kSessions; ++i)
        clients.push_back(volcast::test::helloClient(server->port(), "search-" + std::to_string(i), kTimeout));
    for (auto &c : clients) c->sendText(json{{"type", "find_studies"}, {"id", 2}, {"source", "pacs"}}.dump());
    int answered = 0, busy = 0;
    for (auto &c : clients) {
        const Message reply = volcast::client::waitForReply(*c, 2, kTimeout);
        if (reply.decoded && std::holds_alternative<volcast::protocol::StudiesMessage>(*reply.decoded)) ++answered;
        else if (const auto *e = volcast::test::asError(reply); e && e->code == ErrorCode::Busy) ++busy;
        else ADD_FAILURE() << "neither studies nor busy: " << reply.text;
    }
    EXPECT_EQ(busy, 0) << busy << " of " << kSessions << " searches were refused busy";
    EXPECT_EQ(answered, kSessions);
    EXPECT_EQ(pacs.searchesAnswered(), kSessions);
}

// A series with a damaged instance: the loader refuses it; the cache must not keep the
// refused files, so a second open retrieves the series again (and is refused again while the
// PACS still serves it damaged) instead of loading the same files from the cache.
TEST_F(SourceLanes, ASeriesTheLoaderRefusedIsRetrievedAgainNotServedFromTheCache) {
    auto files = writeSeries(series);
    files.back().resize(files.back().size() / 2);   // the last instance cut off in its pixel data
    FakePacs pacs(files, {});
    auto registry = this->registry(256 * volcast::test::kMiB);
    std::vector<volcast::dicomweb::SourceConfig> sources(1);
    sources[0].name = "pacs";
    sources[0].baseUrl = pacs.url();
    registry->addProvider(std::make_shared<volcast::server::DicomWebProvider>(sources, cache, 64 * volcast::test::kMiB));
    const auto cachedFiles = [&] {
        size_t n = 0;
        for (const auto &entry : fs::recursive_directory_iterator(cache))
            if (entry.is_regular_file()) ++n;
        return n;
    };

    const std::string first = volcast::test::loadFailure(volcast::test::openNow(*registry, seriesName("pacs", pacs)));
    EXPECT_EQ(pacs.retrievalsBegun(), 1);
    EXPECT_EQ(cachedFiles(), 0u) << "the refused series stayed in the retrieval cache (" << first << ")";
    const std::string second = volcast::test::loadFailure(volcast::test::openNow(*registry, seriesName("pacs", pacs)));
    EXPECT_EQ(pacs.retrievalsBegun(), 2) << "the second open loaded the refused files from the cache: " << second;
    EXPECT_EQ(first, second) << "the same damaged series is refused with the same words";
}

// One owner's many waiting jobs do not hold the lane while another owner waits: owners take
// turns, each owner's jobs in order.
TEST(WorkLane, OwnersTakeTurnsAndEachOwnersJobsRunInOrder) {
    volcast::server::WorkLane lane("test", 1, 16);
    std::promise<void> release;
    std::shared_future<void> released = release.get_future().share();
    std::mutex mutex;
    std::string order;
    const auto job = [&](uint64_t owner, char name) {
        return volcast::server::WorkLane::Job{owner, [&, name] {
                                                  std::lock_guard lock(mutex);
                                                  order += name;
                                              },
                                              {}};
    };
    std::promise<void> blocking;
    ASSERT_TRUE(lane.post({9, [&] {
                               blocking.set_value();
                               released.wait();
                           },
                           {}}));
    blocking.get_future().wait();   // the one worker is busy: what follows waits
    for (char name : std::string("abc")) ASSERT_TRUE(lane.post(job(1, name)));
    ASSERT_TRUE(lane.post(job(2, 'x')));
    ASSERT_TRUE(lane.post(job(3, 'y')));
    release.set_value();
    const bool allRan = waitFor(
        [&] {
            std::lock_guard lock(mutex);
            return order.size() == 5;
        },
        kTimeout);
    std::lock_guard lock(mutex);
    EXPECT_TRUE(allRan) << "ran only: " << order;
    EXPECT_EQ(order, "axybc");
}

TEST(WorkLane, RefusesBeyondItsWaitingBoundAndAnswersWaitingJobsWhenStopped) {
    volcast::server::WorkLane lane("test", 1, 2);
    std::promise<void> release, blocking;
    std::shared_future<void> released = release.get_future().share();
    ASSERT_TRUE(lane.post({1, [&] {
                               blocking.set_value();
                               released.wait();
                           },
                           {}}));
    blocking.get_future().wait();
    std::atomic<int> ran = 0, dropped = 0;
    const volcast::server::WorkLane::Job counted{2, [&] { ++ran; }, [&] { ++dropped; }};
    EXPECT_TRUE(lane.post(counted));
    EXPECT_TRUE(lane.post(counted));
    EXPECT_FALSE(lane.post(counted)) << "a third waiting job is over the bound of 2";
    std::thread stopper([&] { lane.stop(); });   // drops the waiting jobs, then waits for the running one
    while (dropped < 2) std::this_thread::sleep_for(1ms);
    release.set_value();
    stopper.join();
    EXPECT_EQ(ran.load(), 0);
    EXPECT_EQ(dropped.load(), 2);
    EXPECT_FALSE(lane.post(counted)) << "a stopped lane takes nothing";
}

} // namespace
