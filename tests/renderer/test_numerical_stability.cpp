// Numerical stability on stiff and extreme cases. The cases live in
// tests/stability/stability_cases.cpp, shared with volcast-stability, which prints the same
// rows as docs/accuracy.md's "Numerical stability" table; here each case is one test, and
// every row must stay within its bound with no NaN or Inf in any output.

#include "tests/stability/stability_cases.hpp"
#include "opencl_test_context.hpp"
#include "test_scenes.hpp"

#include <gtest/gtest.h>

namespace volcast {
namespace {

class NumericalStability : public ::testing::TestWithParam<size_t> {};

TEST_P(NumericalStability, StaysWithinItsBoundsWithoutNaNOrInf) {
    const stability::Case &c = stability::cases()[GetParam()];
    const std::vector<stability::Row> rows = c.run(test::sharedOpenClContext());
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

INSTANTIATE_TEST_SUITE_P(StiffAndExtremeCases, NumericalStability, ::testing::Range(size_t(0), stability::cases().size()),
                         [](const ::testing::TestParamInfo<size_t> &param) { return stability::cases()[param.param].id; });

} // namespace
} // namespace volcast
