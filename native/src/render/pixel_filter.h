// The pixel filter (Cycles' Film > Pixel Filter): camera rays are importance-sampled from the
// filter, so every sample has weight 1 and the film stays a plain mean (Ernst et al. 2006,
// "Filter importance sampling"; Cycles' filter_table). The filter is separable: one table, the
// inverted CDF of its 1D profile, gives a pixel sample's offset from the pixel centre in x and
// in y (raygen: pixel_filter_offset).
#pragma once
#include <cstdint>
#include <vector>

namespace px {

// PIXEL_FILTER_TABLE_SIZE offsets in pixels, entry i for the CDF value i / (size - 1), of the
// filter `type` (FILTER_*) of width `width` (pixels, Cycles' Filter Width): a box of that width,
// a Gaussian over 3x it and Blackman-Harris over 2x it, as Cycles (film.cpp, filter_table).
std::vector<float> pixel_filter_table(uint32_t type, float width);

}  // namespace px
