#include "renderer/model/orientation_correction.hpp"

namespace volcast {

std::string signedPermutationProblem(const OrientationCorrection &c) {
    for (int i = 0; i < 9; ++i)
        if (c.m[size_t(i)] < -1 || c.m[size_t(i)] > 1)
            return "entry [" + std::to_string(i / 3) + "][" + std::to_string(i % 3) + "] is " +
                   std::to_string(c.m[size_t(i)]) + "; entries must be -1, 0 or 1";
    for (int r = 0; r < 3; ++r) {
        int rowCount = 0, columnCount = 0;
        for (int k = 0; k < 3; ++k) {
            rowCount += c(r, k) != 0;
            columnCount += c(k, r) != 0;
        }
        if (rowCount != 1)
            return "row " + std::to_string(r) + " has " + std::to_string(rowCount) +
                   " non-zero entries; a signed permutation (flips and quarter turns) has one in each row and column";
        if (columnCount != 1)
            return "column " + std::to_string(r) + " has " + std::to_string(columnCount) +
                   " non-zero entries; a signed permutation (flips and quarter turns) has one in each row and column";
    }
    return {};
}

VolumePlacement correctedPlacement(const Volume &volume, const OrientationCorrection &correction) {
    VolumePlacement p{volume.origin, volume.direction, volume.spacing};
    if (correction.identity()) return p;
    Mat3d c;
    for (int i = 0; i < 9; ++i) c.m[size_t(i)] = double(correction.m[size_t(i)]);
    const Vec3d centre = volume.center();
    p.origin = centre + c * (volume.origin - centre);
    for (int r = 0; r < 3; ++r)
        for (int k = 0; k < 3; ++k)
            p.direction(r, k) = c(r, 0) * volume.direction(0, k) + c(r, 1) * volume.direction(1, k) +
                                c(r, 2) * volume.direction(2, k);
    return p;
}

} // namespace volcast
