#include "techniques/ears.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstring>
#include <vector>

namespace px {

namespace {

constexpr uint32_t kEarsSlots = 1u << 17;  // hash slots: 4 MiB of sums, 2 MiB of factors

double fixed_sum(uint32_t lo, uint32_t hi) {
    return (double(hi) * 4294967296.0 + double(lo)) / double(EARS_FIXED_SCALE);
}

}  // namespace

EarsStatistics::EarsStatistics(Context& ctx) : ctx_(ctx) {
    cells_ = Buffer(ctx_, sizeof(EarsCell), kStorageUsage);
    factors_ = Buffer(ctx_, sizeof(EarsFactor), kStorageUsage);
    pixels_ = Buffer(ctx_, sizeof(EarsPixel), kStorageUsage);
    records_ = Buffer(ctx_, sizeof(EarsRecord), kStorageUsage);
    reset();
}

void EarsStatistics::configure(bool enabled, const SceneHost& scene, uint32_t width, uint32_t height, uint32_t grid,
                               uint32_t min_records) {
    enabled_ = enabled;
    min_records_ = std::max(min_records, 1u);
    slots_ = enabled ? kEarsSlots : 1;
    const size_t cell_bytes = size_t(slots_) * sizeof(EarsCell);
    if (cells_.size() != cell_bytes) cells_ = Buffer(ctx_, cell_bytes, kStorageUsage);
    if (factors_.size() != size_t(slots_) * sizeof(EarsFactor))
        factors_ = Buffer(ctx_, size_t(slots_) * sizeof(EarsFactor), kStorageUsage);
    const size_t pixel_bytes = (enabled ? size_t(width) * height : 1) * sizeof(EarsPixel);
    if (pixels_.size() != pixel_bytes) pixels_ = Buffer(ctx_, pixel_bytes, kStorageUsage);
    // A dispatch has at most one invocation per pixel.
    threads_ = enabled ? width * height : 0;
    const size_t record_bytes = std::max<size_t>(1, size_t(threads_) * EARS_PATH_VERTICES) * sizeof(EarsRecord);
    if (records_.size() != record_bytes) records_ = Buffer(ctx_, record_bytes, kStorageUsage);
    float lo[3], hi[3];
    scene_bounds(scene, lo, hi);
    const float extent = std::max({hi[0] - lo[0], hi[1] - lo[1], hi[2] - lo[2], 1e-6f});
    // Half a cell of margin each way, so that points on the box's faces fall inside.
    cell_ = extent / float(std::max(grid, 2u) - 1);
    for (int a = 0; a < 3; ++a) grid_min_[a] = lo[a] - 0.5f * cell_;
    reset();
}

void EarsStatistics::reset() {
    cells_.fill_zero();
    factors_.fill_zero();
    pixels_.fill_zero();
    factors_host_.assign(enabled_ ? slots_ : 0, EarsFactor{});
    learning_ = active_ = false;
    scale_ = 1.0f;
    image_factor_ = 0.0f;
    iterations_ = cells_with_factors_ = full_slots_ = 0;
    image_cost_ = image_variance_ = fit_milliseconds_ = 0;
}

void EarsStatistics::bind(DescriptorSet& set) const {
    set.bind_buffer(BINDING_EARS_CELLS, cells_);
    set.bind_buffer(BINDING_EARS_FACTORS, factors_);
    set.bind_buffer(BINDING_EARS_PIXELS, pixels_);
    set.bind_buffer(BINDING_EARS_RECORDS, records_);
}

void EarsStatistics::write_params(AdrrsParams& params) const {
    params.ears_min = {grid_min_[0], grid_min_[1], grid_min_[2]};
    params.ears_cell = enabled_ ? cell_ : 0.0f;
    params.ears_slots = slots_;
    params.ears_learn = enabled_ && learning_ ? 1u : 0u;
    params.ears_active = enabled_ && active_ ? 1u : 0u;
    params.ears_scale = scale_;
    params.ears_image_factor = image_factor_;
    params.ears_threads = threads_;
}

// Rath et al. 2022, per cell: the factors are E[Lr^2] / C and Var[Lr] / C in absolute
// units (the records are in units of the scale the iteration ran with), and the image's
// sqrt(C / V): C the rays per camera sample, V the mean over pixels of one sample's variance
// (from the pixel's two halves) relative to the estimate squared, each pixel's at most
// EARS_MAX_VARIANCE (Rath et al. reject the worst outliers of the image's statistics).
void EarsStatistics::end_iteration(const std::vector<float>& estimate) {
    if (!enabled_) return;
    const auto start = std::chrono::steady_clock::now();
    double luminance_sum = 0;
    for (float l : estimate) luminance_sum += l;
    const float scale = estimate.empty() ? 0.0f : float(luminance_sum / double(estimate.size()));
    if (learning_) {
        std::vector<EarsPixel> pixels(pixels_.size() / sizeof(EarsPixel));
        pixels_.download(pixels.data(), pixels_.size());
        double variance_sum = 0, rays = 0, samples = 0;
        uint64_t variance_pixels = 0;
        for (size_t i = 0; i < pixels.size() && i < estimate.size(); ++i) {
            const EarsPixel& p = pixels[i];
            rays += p.rays;
            samples += double(p.odd_samples) + p.even_samples;
            if (p.odd_samples == 0 || p.even_samples == 0) continue;
            const double a = p.odd_samples, b = p.even_samples, d = p.odd_sum / a - p.even_sum / b;
            const double relative = d * d / (1.0 / a + 1.0 / b) /
                                    (double(estimate[i]) * estimate[i] + double(EARS_EPSILON) * EARS_EPSILON);
            if (!std::isfinite(relative)) continue;
            variance_sum += std::min(relative, double(EARS_MAX_VARIANCE));
            ++variance_pixels;
        }
        pixels_.fill_zero();
        if (samples > 0 && variance_pixels > 0) {
            image_cost_ = rays / samples;
            image_variance_ = variance_sum / double(variance_pixels);
            if (image_variance_ > 0 && image_cost_ > 0) image_factor_ = float(std::sqrt(image_cost_ / image_variance_));
        }
        std::vector<EarsCell> cells(slots_);
        cells_.download(cells.data(), cells.size() * sizeof(EarsCell));
        const double unit = double(scale_) * double(scale_);
        cells_with_factors_ = full_slots_ = 0;
        for (uint32_t s = 0; s < slots_; ++s) {
            EarsCell& c = cells[s];
            if (c.key == 0) continue;
            ++full_slots_;
            if (c.count >= min_records_) {
                const double n = c.count, m1 = fixed_sum(c.lr_lo, c.lr_hi) / n, m2 = fixed_sum(c.lr2_lo, c.lr2_hi) / n;
                const double cost = fixed_sum(c.cost_lo, c.cost_hi) / n;
                EarsFactor& f = factors_host_[s];
                if (cost > 0) {
                    f.second_moment = float(m2 * unit / cost);
                    f.variance = float(std::max(m2 - m1 * m1, 0.0) * unit / cost);
                    f.cost = image_cost_ > 0 ? float(cost / image_cost_) : 0.0f;
                }
            }
            if (factors_host_[s].second_moment > 0) ++cells_with_factors_;
            const uint32_t key = c.key;
            c = EarsCell{};
            c.key = key;  // the slot stays the cell's: paths find it again
        }
        cells_.upload(cells.data(), cells.size() * sizeof(EarsCell));
        factors_.upload(factors_host_.data(), factors_host_.size() * sizeof(EarsFactor));
        active_ = cells_with_factors_ > 0 && image_factor_ > 0;
        ++iterations_;
    }
    if (std::isfinite(scale) && scale > 0) scale_ = scale;
    learning_ = true;
    fit_milliseconds_ += std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count();
}

void EarsStatistics::stats(StatList& out) const {
    if (!enabled_) return;
    out.insert(out.end(), {{"ears_iterations", uint64_t(iterations_)},
                           {"ears_cells", uint64_t(full_slots_)},
                           {"ears_cell_size", double(cell_)},
                           {"ears_scale", double(scale_)},
                           {"ears_cells_with_factors", uint64_t(cells_with_factors_)},
                           {"ears_image_factor", double(image_factor_)},
                           {"ears_image_cost", image_cost_},
                           {"ears_image_variance", image_variance_},
                           {"ears_fit_milliseconds", fit_milliseconds_}});
}

}  // namespace px
