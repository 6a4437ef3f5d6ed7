#include "renderer/reference/reconstruction.hpp"

#include "renderer/common/bspline_prefilter.hpp"

#include <algorithm>
#include <cmath>

namespace volcast {

namespace {
// Clamp-to-edge: the cell of the lower sample and the fraction within it.
inline void locate(double p, int64_t n, int64_t &i0, double &f) {
    p = std::clamp(p, 0.0, double(n - 1));
    i0 = std::min(int64_t(std::floor(p)), std::max<int64_t>(n - 2, 0));
    f = p - double(i0);
}
} // namespace

double TrilinearField::operator()(const Vec3d &q) const {
    const Vec3i n = v_.dims;
    int64_t i, j, k;
    double fx, fy, fz;
    locate(q.x, n.x, i, fx);
    locate(q.y, n.y, j, fy);
    locate(q.z, n.z, k, fz);
    const int64_t i1 = std::min(i + 1, n.x - 1), j1 = std::min(j + 1, n.y - 1), k1 = std::min(k + 1, n.z - 1);
    auto lerp = [](double a, double b, double t) { return a + t * (b - a); };
    const double c00 = lerp(v_.at(i, j, k), v_.at(i1, j, k), fx);
    const double c10 = lerp(v_.at(i, j1, k), v_.at(i1, j1, k), fx);
    const double c01 = lerp(v_.at(i, j, k1), v_.at(i1, j, k1), fx);
    const double c11 = lerp(v_.at(i, j1, k1), v_.at(i1, j1, k1), fx);
    return lerp(lerp(c00, c10, fy), lerp(c01, c11, fy), fz);
}

CubicBSplineField::CubicBSplineField(const Volume &v)
    : dims_(v.dims), coeffs_(v.voxelCount()) {
    const SampleGrid samples = v.samples();
    for (size_t i = 0; i < coeffs_.size(); ++i) coeffs_[i] = samples[i];
    bsplinePrefilterSimple(coeffs_.data(), dims_);
}

double CubicBSplineField::operator()(const Vec3d &q) const {
    int64_t base[3];
    double w[3][4];
    for (int a = 0; a < 3; ++a) {
        const int64_t n = dims_[a];
        const double p = std::clamp(q[a], 0.0, double(n - 1));
        base[a] = int64_t(std::floor(p));
        cubicBSplineWeights(p - double(base[a]), w[a]);
    }
    int64_t ix[4], iy[4], iz[4];
    for (int t = 0; t < 4; ++t) {
        ix[t] = mirrorIndex(base[0] - 1 + t, dims_.x);
        iy[t] = mirrorIndex(base[1] - 1 + t, dims_.y);
        iz[t] = mirrorIndex(base[2] - 1 + t, dims_.z);
    }
    double sum = 0;
    for (int c = 0; c < 4; ++c) {
        double sy = 0;
        for (int b = 0; b < 4; ++b) {
            const double *row = &coeffs_[size_t((iz[c] * dims_.y + iy[b]) * dims_.x)];
            const double sx = w[0][0] * row[ix[0]] + w[0][1] * row[ix[1]] + w[0][2] * row[ix[2]] +
                              w[0][3] * row[ix[3]];
            sy += w[1][b] * sx;
        }
        sum += w[2][c] * sy;
    }
    return sum;
}

} // namespace volcast
