#include "renderer/reference/error_metrics.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <stdexcept>

namespace volcast {
namespace {

TEST(ErrorMetrics, IdenticalImagesHaveNoError) {
    Image a(3, 2);
    for (float &x : a.rgba) x = 0.25f;
    const ImageError e = compareImages(a, a);
    EXPECT_EQ(e.rmse, 0);
    EXPECT_EQ(e.maxAbs, 0);
    EXPECT_TRUE(std::isinf(e.psnr));
}

TEST(ErrorMetrics, RmseAndPsnrOverAllFourChannels) {
    Image a(4, 4), b(4, 4);
    for (size_t i = 0; i < a.rgba.size(); i += 4) a.rgba[i] = 0.1f; // red off by 0.1 everywhere
    const ImageError e = compareImages(a, b);
    // RMSE = sqrt(0.1² / 4) = 0.05 (one channel of four); PSNR = 20·log10(20) ≈ 26.02 dB.
    EXPECT_NEAR(e.rmse, 0.05, 1e-8); // 0.1f carries 1.5e-9 of float rounding
    EXPECT_NEAR(e.psnr, 20 * std::log10(20.0), 1e-6);
    EXPECT_NEAR(e.maxAbs, 0.1, 1e-8);
    const Image err = errorImage(a, b, 10);
    EXPECT_NEAR(err.pixel(2, 3)[0], 1.0f, 1e-6);
}

TEST(ErrorMetrics, SizeMismatchIsAnError) {
    EXPECT_THROW(compareImages(Image(2, 2), Image(2, 3)), std::invalid_argument);
}

} // namespace
} // namespace volcast
