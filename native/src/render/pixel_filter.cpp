#include "render/pixel_filter.h"

#include "../../../shaders/shared/types.h"

#include <algorithm>
#include <cmath>
#include <stdexcept>

namespace px {

namespace {

constexpr double kPi = 3.14159265358979323846;

// The filter's 1D profile at offset x (pixels) and the half width of its support, as Cycles
// defines them: the Gaussian exp(-2 (6x / 3w)^2), Blackman-Harris' four cosines over 2w.
double profile(uint32_t type, double width, double x) {
    if (type == FILTER_GAUSSIAN) return std::exp(-2.0 * std::pow(6.0 * x / (3.0 * width), 2.0));
    if (type == FILTER_BLACKMAN_HARRIS) {
        const double t = 2.0 * kPi * (x / (2.0 * width) + 0.5);
        return 0.35875 - 0.48829 * std::cos(t) + 0.14128 * std::cos(2.0 * t) - 0.01168 * std::cos(3.0 * t);
    }
    return 1.0;  // box
}

double half_support(uint32_t type, double width) {
    if (type == FILTER_GAUSSIAN) return 1.5 * width;
    if (type == FILTER_BLACKMAN_HARRIS) return width;
    return 0.5 * width;
}

}  // namespace

std::vector<float> pixel_filter_table(uint32_t type, float width) {
    if (type > FILTER_BLACKMAN_HARRIS) throw std::invalid_argument("unknown pixel filter type " + std::to_string(type));
    if (!(width > 0.0f)) throw std::invalid_argument("pixel filter width must be > 0");
    // The CDF on a fine grid (trapezoids), then inverted by linear interpolation.
    const int steps = 8192;
    const double half = half_support(type, width);
    std::vector<double> cdf(steps + 1, 0.0);
    double previous = profile(type, width, -half);
    for (int i = 1; i <= steps; ++i) {
        const double f = std::max(0.0, profile(type, width, -half + 2.0 * half * i / steps));
        cdf[i] = cdf[i - 1] + 0.5 * (previous + f);
        previous = f;
    }
    std::vector<float> table(PIXEL_FILTER_TABLE_SIZE);
    int k = 0;
    for (uint32_t j = 0; j < PIXEL_FILTER_TABLE_SIZE; ++j) {
        const double target = cdf[steps] * j / (PIXEL_FILTER_TABLE_SIZE - 1);
        while (k < steps - 1 && cdf[k + 1] < target) ++k;
        const double span = cdf[k + 1] - cdf[k];
        const double t = span > 0.0 ? std::clamp((target - cdf[k]) / span, 0.0, 1.0) : 0.0;
        table[j] = float(-half + 2.0 * half * (k + t) / steps);
    }
    return table;
}

}  // namespace px
