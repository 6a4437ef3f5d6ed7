#include "tests/bench/svg_plot.hpp"

#include <algorithm>
#include <cmath>
#include <sstream>

namespace volcast::bench {

namespace {

// Colour-blind-safe palette (Okabe and Ito).
const char *kColours[] = {"#0072B2", "#D55E00", "#009E73", "#CC79A7", "#E69F00", "#56B4E9", "#000000", "#F0E442"};

std::string escape(const std::string &s) {
    std::string out;
    for (char c : s) {
        if (c == '<') out += "&lt;";
        else if (c == '>') out += "&gt;";
        else if (c == '&') out += "&amp;";
        else out += c;
    }
    return out;
}

std::string number(double v) {
    std::ostringstream s;
    s << v;
    return s.str();
}

struct Axis {
    bool log = false;
    double lo = 0, hi = 1;
    double map(double v) const { return log ? std::log10(v) : v; }
    // Fraction along the axis.
    double at(double v) const { return (map(v) - map(lo)) / (map(hi) - map(lo)); }

    void fit(std::vector<double> values) {
        if (values.empty()) values = {1, 10};
        const auto [mn, mx] = std::minmax_element(values.begin(), values.end());
        lo = *mn;
        hi = *mx;
        if (log) {
            // A little room beyond the extreme points, then out to a quarter decade.
            lo = std::pow(10, std::floor(std::log10(lo / 1.1) * 4) / 4);
            hi = std::pow(10, std::ceil(std::log10(hi * 1.1) * 4) / 4);
            if (hi <= lo) hi = lo * 10;
        } else {
            const double pad = (hi - lo) * 0.05;
            lo = lo >= 0 && lo - pad < 0 ? 0 : lo - pad;
            hi = hi + pad;
            if (hi <= lo) hi = lo + 1;
        }
    }

    std::vector<double> ticks() const {
        std::vector<double> t;
        if (log) {
            for (double d = std::pow(10, std::floor(std::log10(lo))); d <= hi * 1.0001; d *= 10)
                for (double m : {1.0, 2.0, 5.0})
                    if (d * m >= lo * 0.9999 && d * m <= hi * 1.0001) t.push_back(d * m);
        } else {
            const double raw = (hi - lo) / 6;
            const double mag = std::pow(10, std::floor(std::log10(raw)));
            const double step = raw / mag < 2 ? 2 * mag : raw / mag < 5 ? 5 * mag : 10 * mag;
            for (double v = std::ceil(lo / step) * step; v <= hi + 1e-9 * step; v += step) t.push_back(v);
        }
        return t;
    }
};

bool usable(double v, bool log) { return std::isfinite(v) && (!log || v > 0); }

} // namespace

std::string renderSvg(const Plot &plot) {
    const double left = 80, right = 220, top = 40, bottom = 60;
    const double w = plot.width - left - right, h = plot.height - top - bottom;
    Axis ax{plot.logX}, ay{plot.logY};
    std::vector<double> xs, ys;
    for (const Series &s : plot.series)
        for (size_t i = 0; i < s.x.size() && i < s.y.size(); ++i)
            if (usable(s.x[i], plot.logX) && usable(s.y[i], plot.logY)) {
                xs.push_back(s.x[i]);
                ys.push_back(s.y[i]);
            }
    ax.fit(xs);
    ay.fit(ys);
    const auto px = [&](double v) { return left + ax.at(v) * w; };
    const auto py = [&](double v) { return top + (1 - ay.at(v)) * h; };

    std::ostringstream o;
    o << "<svg xmlns=\"http://www.w3.org/2000/svg\" width=\"" << plot.width << "\" height=\"" << plot.height
      << "\" font-family=\"sans-serif\" font-size=\"12\">\n"
      << "<rect width=\"100%\" height=\"100%\" fill=\"white\"/>\n"
      << "<text x=\"" << left + w / 2 << "\" y=\"22\" text-anchor=\"middle\" font-size=\"15\">" << escape(plot.title)
      << "</text>\n";
    for (double t : ax.ticks()) {
        o << "<line x1=\"" << px(t) << "\" x2=\"" << px(t) << "\" y1=\"" << top << "\" y2=\"" << top + h
          << "\" stroke=\"#ddd\"/>\n"
          << "<text x=\"" << px(t) << "\" y=\"" << top + h + 16 << "\" text-anchor=\"middle\">" << number(t)
          << "</text>\n";
    }
    for (double t : ay.ticks()) {
        o << "<line x1=\"" << left << "\" x2=\"" << left + w << "\" y1=\"" << py(t) << "\" y2=\"" << py(t)
          << "\" stroke=\"#ddd\"/>\n"
          << "<text x=\"" << left - 6 << "\" y=\"" << py(t) + 4 << "\" text-anchor=\"end\">" << number(t)
          << "</text>\n";
    }
    o << "<rect x=\"" << left << "\" y=\"" << top << "\" width=\"" << w << "\" height=\"" << h
      << "\" fill=\"none\" stroke=\"#333\"/>\n"
      << "<text x=\"" << left + w / 2 << "\" y=\"" << plot.height - 18 << "\" text-anchor=\"middle\">"
      << escape(plot.xLabel) << "</text>\n"
      << "<text transform=\"translate(18," << top + h / 2 << ") rotate(-90)\" text-anchor=\"middle\">"
      << escape(plot.yLabel) << "</text>\n";

    for (size_t si = 0; si < plot.series.size(); ++si) {
        const Series &s = plot.series[si];
        const char *colour = kColours[size_t(s.colour >= 0 ? size_t(s.colour) : si) % std::size(kColours)];
        std::ostringstream path;
        for (size_t i = 0; i < s.x.size() && i < s.y.size(); ++i)
            if (usable(s.x[i], plot.logX) && usable(s.y[i], plot.logY)) path << px(s.x[i]) << "," << py(s.y[i]) << " ";
        if (s.lines)
            o << "<polyline fill=\"none\" stroke=\"" << colour << "\" stroke-width=\"2\""
              << (s.dashed ? " stroke-dasharray=\"6,4\"" : "") << " points=\"" << path.str() << "\"/>\n";
        if (s.markers)
            for (size_t i = 0; i < s.x.size() && i < s.y.size(); ++i)
                if (usable(s.x[i], plot.logX) && usable(s.y[i], plot.logY))
                    o << "<circle cx=\"" << px(s.x[i]) << "\" cy=\"" << py(s.y[i]) << "\" r=\"3.5\" fill=\"" << colour
                      << "\"/>\n";
        const double ly = top + 8 + 18 * double(si);
        o << "<line x1=\"" << left + w + 12 << "\" x2=\"" << left + w + 36 << "\" y1=\"" << ly << "\" y2=\"" << ly
          << "\" stroke=\"" << colour << "\" stroke-width=\"2\"" << (s.dashed ? " stroke-dasharray=\"6,4\"" : "")
          << "/>\n<text x=\"" << left + w + 42 << "\" y=\"" << ly + 4 << "\">" << escape(s.label) << "</text>\n";
    }
    o << "</svg>\n";
    return o.str();
}

} // namespace volcast::bench
