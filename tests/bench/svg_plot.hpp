#pragma once
// A small SVG chart for the benchmark studies: lines and markers on linear or log axes, a
// legend, and ticks at round numbers. Enough to read a study at a glance; the numbers
// themselves are in the study's CSV and JSON.

#include <string>
#include <utility>
#include <vector>

namespace volcast::bench {

struct Series {
    Series(std::string label_ = {}, std::vector<double> x_ = {}, std::vector<double> y_ = {})
        : label(std::move(label_)), x(std::move(x_)), y(std::move(y_)) {}
    std::string label;
    std::vector<double> x, y;
    bool lines = true;     // join the points in order
    bool markers = true;
    bool dashed = false;
    // The palette's colour by index, so that series of one kind share it (e.g. a configuration
    // drawn twice, solid and dashed); −1: the series' own position.
    int colour = -1;
};

struct Plot {
    std::string title, xLabel, yLabel;
    bool logX = false, logY = false;
    int width = 760, height = 480;
    std::vector<Series> series;
};

// Non-finite points, and non-positive ones on a log axis, are left out.
std::string renderSvg(const Plot &plot);

} // namespace volcast::bench
