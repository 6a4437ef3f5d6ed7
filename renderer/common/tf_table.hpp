#pragma once
// The transfer function as a uniform table for the kernels: colour (not premultiplied) and
// the optical depth of one opacity unit, sigma = −ln(1 − a), linear between entries. Storing
// sigma rather than a saves the kernel a logarithm per sample (PoCL spends most of a sample's
// time in transcendentals); a = 1 is stored as kOpaqueSigma, finite so that interpolation
// never meets inf·0. Its size is chosen so that its own error
// against the exact piecewise-linear function stays below a bound (docs/design.md: a table must
// be fine enough that its error stays below the quality tolerance).

#include "renderer/model/transfer_function.hpp"

#include <vector>

namespace volcast {

struct TfTable {
    double minValue = 0;    // data value of entry 0
    double scale = 1;       // entries per data unit
    std::vector<float> rgba; // entries × 4: r, g, b, sigma
    int entries() const { return int(rgba.size() / 4); }
    double maxError = 0;    // largest |table − exact| over r, g, b and a, as measured
};

// Stands for a = 1: opaque over any segment longer than 1e-28 opacity units.
inline constexpr float kOpaqueSigma = 1e30f;

// Doubles the size from 256 entries up to maxEntries until maxError ≤ bound.
TfTable buildTfTable(const TransferFunction &tf, double bound = 1e-4, int maxEntries = 1 << 16);

} // namespace volcast
