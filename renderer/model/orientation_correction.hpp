#pragma once
// A user's correction of where a volume lies in patient space, for files that name no
// patient axes (or name them wrongly): flips and quarter turns of the world (patient, LPS)
// axes, nothing else. It is a signed permutation matrix C (entries −1, 0, 1, one non-zero in
// each row and column, det ±1), applied about the volume's centre c: the voxel the file puts
// at world x is drawn at c + C·(x − c). So the volume's centre, the camera's target, stays
// where it is and the camera need not move; a flip (det −1) mirrors the image, which no
// camera move can do. The orientation marker, the standard views, clip planes and slices
// stay in world space: after the correction they are about the corrected volume.
//
// It belongs to the frame, not to the volume (which all sessions share): it travels in the
// scene's quality (quality.orientation_correction, like the crop box) and every back end
// maps world to index space through correctedPlacement().

#include "renderer/model/math.hpp"
#include "renderer/model/volume.hpp"

#include <array>
#include <string>

namespace volcast {

struct OrientationCorrection {
    std::array<int, 9> m{1, 0, 0, 0, 1, 0, 0, 0, 1};   // row-major, world axes x, y, z
    int operator()(int r, int c) const { return m[size_t(r * 3 + c)]; }
    bool identity() const { return *this == OrientationCorrection{}; }
    bool operator==(const OrientationCorrection &) const = default;
};

// What makes m not a signed permutation ("row 1 has 2 non-zero entries"); empty if it is one.
std::string signedPermutationProblem(const OrientationCorrection &c);

// Where a frame puts the volume: its origin and direction after the correction (spacing and
// dims are the volume's). The maps of Volume, with the corrected origin and direction.
struct VolumePlacement {
    Vec3d origin;
    Mat3d direction;
    Vec3d spacing;
    Vec3d indexFromWorld(const Vec3d &p) const { return div(direction.transposed() * (p - origin), spacing); }
    Vec3d indexFromWorldDir(const Vec3d &d) const { return div(direction.transposed() * d, spacing); }
    Vec3d worldFromIndex(const Vec3d &q) const { return origin + direction * mul(q, spacing); }
};

// origin' = c + C·(origin − c), direction' = C·direction, c = volume.center(). The identity
// correction gives the volume's own placement exactly.
VolumePlacement correctedPlacement(const Volume &volume, const OrientationCorrection &correction);

} // namespace volcast
