#pragma once
// The transfer function as a uniform table for the kernels: RGBA (colour not premultiplied,
// opacity per opacityUnit) linear between entries. Its size is chosen so that its own error
// against the exact piecewise-linear function stays below a bound (DESIGN.md: a table must
// be fine enough that its error stays below the quality tolerance).

#include "renderer/transfer_function.hpp"

#include <vector>

namespace volcast {

struct TfTable {
    double minValue = 0;    // data value of entry 0
    double scale = 1;       // entries per data unit
    std::vector<float> rgba; // entries × 4
    int entries() const { return int(rgba.size() / 4); }
    double maxError = 0;    // largest |table − exact| over all channels, as measured
};

// Doubles the size from 256 entries up to maxEntries until maxError ≤ bound.
TfTable buildTfTable(const TransferFunction &tf, double bound = 1e-4, int maxEntries = 1 << 16);

} // namespace volcast
