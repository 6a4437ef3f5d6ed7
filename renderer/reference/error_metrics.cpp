#include "renderer/reference/error_metrics.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <stdexcept>
#include <string>

namespace volcast {

namespace {
void requireSameSize(const Image &a, const Image &b) {
    if (a.width != b.width || a.height != b.height)
        throw std::invalid_argument("images differ in size: " + std::to_string(a.width) + "x" +
                                    std::to_string(a.height) + " against " + std::to_string(b.width) + "x" +
                                    std::to_string(b.height));
}
} // namespace

ImageError compareImages(const Image &image, const Image &reference) {
    requireSameSize(image, reference);
    ImageError e;
    double sum = 0;
    for (size_t i = 0; i < image.rgba.size(); ++i) {
        const double d = double(image.rgba[i]) - double(reference.rgba[i]);
        sum += d * d;
        e.maxAbs = std::max(e.maxAbs, std::fabs(d));
    }
    e.rmse = image.rgba.empty() ? 0 : std::sqrt(sum / double(image.rgba.size()));
    e.psnr = e.rmse > 0 ? 20 * std::log10(1 / e.rmse) : std::numeric_limits<double>::infinity();
    return e;
}

Image errorImage(const Image &image, const Image &reference, double scale) {
    requireSameSize(image, reference);
    Image out(image.width, image.height);
    for (size_t p = 0; p < size_t(image.width) * size_t(image.height); ++p) {
        double worst = 0;
        for (size_t c = 0; c < 4; ++c)
            worst = std::max(worst, std::fabs(double(image.rgba[p * 4 + c]) - double(reference.rgba[p * 4 + c])));
        const float g = float(std::min(worst * scale, 1.0));
        out.rgba[p * 4 + 0] = out.rgba[p * 4 + 1] = out.rgba[p * 4 + 2] = g;
        out.rgba[p * 4 + 3] = 1;
    }
    return out;
}

} // namespace volcast
