#pragma once
// Helpers shared by the tests of the volume registry on its own (test_volume_registry.cpp,
// test_dicom_isolation.cpp): a data folder of the test's own, a registry over it, and an
// open that waits for its answer.

#include "server/metrics.hpp"
#include "server/volume_registry.hpp"

#include <gtest/gtest.h>

#include <chrono>
#include <filesystem>
#include <future>
#include <memory>
#include <string>
#include <unistd.h>
#include <vector>

namespace volcast::test {

constexpr uint64_t kMiB = uint64_t(1) << 20;

// A fresh data folder per test, named after the suite, the test and this process (ctest runs
// tests of one executable in parallel processes), removed after the test.
class RegistryTest : public ::testing::Test {
  protected:
    server::Metrics metrics;
    std::filesystem::path data;

    void SetUp() override {
        const auto *info = ::testing::UnitTest::GetInstance()->current_test_info();
        data = std::filesystem::temp_directory_path() / ("volcast_" + std::string(info->test_suite_name()) + "_" +
                                                         std::to_string(::getpid()) + "_" + info->name());
        std::filesystem::remove_all(data);
        std::filesystem::create_directories(data);
    }
    void TearDown() override { std::filesystem::remove_all(data); }

    // The native CPU path (no OpenCL context): what the registry does is the same for both.
    std::unique_ptr<server::VolumeRegistry> registry(uint64_t budget, double loadTimeout = 120) {
        return std::make_unique<server::VolumeRegistry>(std::vector<std::filesystem::path>{data}, budget, nullptr,
                                                        metrics, loadTimeout);
    }
};

// Opens `name` and waits for the answer (60 s at most: then the test fails).
inline server::VolumeRegistry::Result openNow(server::VolumeRegistry &r, const std::string &name,
                                              const std::shared_ptr<const server::VolumeEntry> &releasing = nullptr) {
    auto promise = std::make_shared<std::promise<server::VolumeRegistry::Result>>();
    auto future = promise->get_future();
    r.open(
        name, [](const protocol::ProgressMessage &) {},
        [promise](server::VolumeRegistry::Result result) { promise->set_value(std::move(result)); }, releasing);
    if (future.wait_for(std::chrono::seconds(60)) != std::future_status::ready) {
        ADD_FAILURE() << "open " << name << " gave no answer in 60 s";
        return protocol::ProtocolError{};
    }
    return future.get();
}

// The loaded volume, or null after failing the test with the error.
inline std::shared_ptr<server::VolumeEntry> entryOf(const server::VolumeRegistry::Result &r) {
    if (auto *e = std::get_if<protocol::ProtocolError>(&r)) {
        ADD_FAILURE() << "unexpected error: " << e->message;
        return nullptr;
    }
    return std::get<std::shared_ptr<server::VolumeEntry>>(r);
}

// The message of a failed load (code load_failed), or "" after failing the test.
inline std::string loadFailure(const server::VolumeRegistry::Result &r) {
    if (auto *e = std::get_if<protocol::ProtocolError>(&r)) {
        EXPECT_EQ(e->code, protocol::ErrorCode::LoadFailed) << e->message;
        return e->message;
    }
    ADD_FAILURE() << "the open succeeded but should have failed";
    return "";
}

} // namespace volcast::test
