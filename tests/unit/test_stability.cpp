// Issue 4: numerical stability on stiff and extreme cases. The cases live in
// tests/stability/stability_cases.cpp, shared with volcast-stability, which prints the same
// rows as the README's "Numerical stability" table; here each case is one test, and every
// row must stay within its bound with no NaN or Inf in any output, on both back ends
// (Issue4/Stability.<case>/OpenCl and …/Cpu).

#include "tests/stability/stability_cases.hpp"
#include "test_scenes.hpp"

#include <gtest/gtest.h>

#include <tuple>

namespace volcast {
namespace {

enum class Backend { OpenCl, Cpu };

class Stability : public ::testing::TestWithParam<std::tuple<size_t, Backend>> {};

TEST_P(Stability, StaysWithinItsBoundsWithoutNaNOrInf) {
    const auto [index, backend] = GetParam();
    const stability::Case &c = stability::cases()[index];
    const stability::Backend be =
        backend == Backend::Cpu ? stability::cpuBackend() : stability::openClBackend(test::sharedOpenClContext());
    const std::vector<stability::Row> rows = c.run(be);
    ASSERT_FALSE(rows.empty());
    for (const stability::Row &row : rows) {
        SCOPED_TRACE(row.caseName + " [" + row.path + "]");
        EXPECT_EQ(row.nonFinite, 0u) << "of " << row.values << " output values";
        EXPECT_LE(row.worst, row.bound) << "against " << row.comparedWith;
        // Every row looked at something: outputs, or the clear error it expects.
        EXPECT_TRUE(row.values > 0 || !row.outcome.empty());
        for (const std::string &failure : row.failures) ADD_FAILURE() << failure;
    }
}

INSTANTIATE_TEST_SUITE_P(Issue4, Stability,
                         ::testing::Combine(::testing::Range(size_t(0), stability::cases().size()),
                                            ::testing::Values(Backend::OpenCl, Backend::Cpu)),
                         [](const ::testing::TestParamInfo<std::tuple<size_t, Backend>> &param) {
                             return stability::cases()[std::get<0>(param.param)].id +
                                    (std::get<1>(param.param) == Backend::Cpu ? "_Cpu" : "_OpenCl");
                         });

} // namespace
} // namespace volcast
