#include "renderer/model/transfer_function.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <stdexcept>

namespace volcast {
namespace {

TEST(TransferFunction, PiecewiseLinearAndClampedOutside) {
    TransferFunction tf;
    tf.points = {{10, 0, 0, 0, 0}, {20, 1, 0.5, 0, 0.8}};
    const Rgba mid = tf.evaluate(15);
    EXPECT_DOUBLE_EQ(mid.r, 0.5);
    EXPECT_DOUBLE_EQ(mid.g, 0.25);
    EXPECT_DOUBLE_EQ(mid.a, 0.4);
    EXPECT_DOUBLE_EQ(tf.evaluate(-100).a, 0);
    EXPECT_DOUBLE_EQ(tf.evaluate(1e9).a, 0.8);
    EXPECT_DOUBLE_EQ(tf.evaluate(NAN).a, 0); // NaN data is transparent, not propagated
}

TEST(TransferFunction, OpacityCorrectionIsEquation3) {
    // α = 1 − (1 − a)^(d/u): at d = u it is a, and segments compose multiplicatively.
    EXPECT_DOUBLE_EQ(correctedOpacity(0.3, 1.0), 0.3);
    const double half = correctedOpacity(0.3, 0.5);
    EXPECT_NEAR(1 - (1 - half) * (1 - half), 0.3, 1e-15);
    EXPECT_EQ(correctedOpacity(1.0, 1e-9), 1.0);
    EXPECT_EQ(correctedOpacity(0.5, 0.0), 0.0);
    // Tiny d and tiny a: α ≈ (d/u)·(−ln(1 − a)) to full relative precision, where the naive
    // 1 − pow(1 − a, d) would return 0 or noise.
    EXPECT_NEAR(correctedOpacity(1e-9, 1e-6) / (1e-6 * -std::log1p(-1e-9)), 1.0, 1e-12);
    EXPECT_NEAR(correctedOpacity(0.5, 1e-12) / (1e-12 * std::log(2.0)), 1.0, 1e-12);
}

TEST(TransferFunction, ExtinctionMatchesOpacityPerUnit) {
    // exp(−τ·u) = 1 − a by definition of τ.
    EXPECT_NEAR(std::exp(-extinction(0.4, 2.0) * 2.0), 0.6, 1e-15);
    EXPECT_TRUE(std::isinf(extinction(1.0, 1.0)));
}

TEST(TransferFunction, ValidateNamesTheBadPoint) {
    TransferFunction tf;
    tf.points = {{0, 0, 0, 0, 0}, {0, 1, 1, 1, 1}};
    try {
        tf.validate();
        FAIL();
    } catch (const std::invalid_argument &e) {
        EXPECT_NE(std::string(e.what()).find("points[1]"), std::string::npos);
    }
    tf.points = {{0, 0, 0, 0, 1.5}};
    EXPECT_THROW(tf.validate(), std::invalid_argument);
}

TEST(TransferFunction, EveryPresetIsValid) {
    for (const auto &name : transferFunctionPresetNames())
        EXPECT_NO_THROW(presetTransferFunction(name, {0, 255}).validate()) << name;
    EXPECT_THROW(presetTransferFunction("nonsense", {0, 1}), std::invalid_argument);
}

} // namespace
} // namespace volcast
