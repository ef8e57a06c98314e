// Range checks for the techniques' settings: std::invalid_argument naming the setting.
#pragma once
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <stdexcept>
#include <string>

namespace px {

inline std::string setting_number(double v) {
    char text[32];
    std::snprintf(text, sizeof(text), "%g", v);
    return text;
}

inline void check_range(const char* name, double value, double lo, double hi, bool lo_open = false) {
    if (!std::isfinite(value) || value > hi || (lo_open ? value <= lo : value < lo))
        throw std::invalid_argument(std::string(name) + " must be in " + (lo_open ? "(" : "[") + setting_number(lo) +
                                    ", " + setting_number(hi) + "], got " + setting_number(value));
}

inline void check_flag(const char* name, uint32_t value) {
    if (value > 1) throw std::invalid_argument(std::string(name) + " must be 0 or 1");
}

}  // namespace px
