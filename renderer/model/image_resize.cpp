#include "renderer/model/image.hpp"

// Apart from image.cpp (files through OpenImageIO): what the renderer itself needs links
// without OpenImageIO, as the GPU machine's bundle does (tests/device/).

#include <algorithm>

namespace volcast {

Image resizeBilinear(const Image &src, int width, int height) {
    Image out(width, height);
    if (src.width < 1 || src.height < 1) return out;
    // Source coordinate of a destination pixel centre, clamped to the outer pixel centres.
    auto axis = [](int x, int dst, int srcSize, int &i0, int &i1, float &f) {
        const double s = std::clamp((x + 0.5) * srcSize / dst - 0.5, 0.0, double(srcSize - 1));
        i0 = int(s);
        i1 = std::min(i0 + 1, srcSize - 1);
        f = float(s - i0);
    };
    for (int y = 0; y < height; ++y) {
        int y0, y1;
        float fy;
        axis(y, height, src.height, y0, y1, fy);
        for (int x = 0; x < width; ++x) {
            int x0, x1;
            float fx;
            axis(x, width, src.width, x0, x1, fx);
            const float *a = src.pixel(x0, y0), *b = src.pixel(x1, y0), *c = src.pixel(x0, y1), *d = src.pixel(x1, y1);
            float *o = out.pixel(x, y);
            for (int k = 0; k < 4; ++k) {
                const float top = a[k] + fx * (b[k] - a[k]), bottom = c[k] + fx * (d[k] - c[k]);
                o[k] = top + fy * (bottom - top);
            }
        }
    }
    return out;
}

} // namespace volcast
