#pragma once
// Gradient Phong shading (quality.shading, the paper's Fig. 5 C) with a headlight, shared by
// the reference integrator; the kernel (raycast.cl, phong()) uses the same constants. The
// gradient is taken by central differences one voxel apart on the reconstruction, so both
// renderers light the same field; a zero gradient leaves the colour unlit.

#include "renderer/model/phong_constants.h"

#include <algorithm>
#include <cmath>

namespace volcast {

// Diffuse factor and specular term for |n·l| = ndl (two-sided: the normal's sign in a
// scalar field is a matter of convention).
template <typename Real>
void phongLight(Real ndl, Real &diffuse, Real &specular) {
    diffuse = Real(VC_PHONG_AMBIENT) + Real(VC_PHONG_DIFFUSE) * ndl;
    specular = Real(VC_PHONG_SPECULAR) * std::pow(ndl, Real(VC_PHONG_SHININESS));
}

// Lit colour (not premultiplied) of colour c.
template <typename Real>
Real phongShade(Real c, Real diffuse, Real specular) {
    return std::min(c * diffuse + specular, Real(1));
}

} // namespace volcast
