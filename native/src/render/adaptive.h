// Adaptive sampling (Cycles' way): every second sample of a pixel also goes to a half buffer;
// every ADAPTIVE_STEP samples after the minimum, adaptive.comp compares each pixel's full and
// half means and marks it converged below the threshold, a pixel stays sampled while a
// neighbour has not converged, and the pixels still sampled are listed in image order. Render
// frames then trace only those: the list is a virtual image of `width` columns and
// ceil(active / width) rows (FrameParams.adaptive = ADAPTIVE_LIST), so the session's dispatch
// plan, row bands and cursor work on it unchanged.
#pragma once
#include "render/params.h"
#include "vk/buffer.h"
#include "vk/pipeline.h"

#include <memory>

namespace px {

class AdaptiveSampling {
public:
    // Cycles checks every 16 samples (Integrator::get_adaptive_sampling, adaptive_step).
    static constexpr uint32_t kStep = 16;

    AdaptiveSampling(Context& ctx, uint32_t width, uint32_t height);
    void bind(DescriptorSet& set) const;
    // New settings; the state starts over (reset()).
    void configure(const RenderParams& params);
    // The film started over: every pixel is sampled, the half buffer is empty.
    void reset();
    bool on() const { return on_; }
    // Whether a check is due now that every sampled pixel has `samples` samples.
    bool check_due(uint64_t samples) const;
    // The check, the filter and the new active list (waits for the device).
    void check(uint64_t samples, VkDescriptorSetLayout layout, VkDescriptorSet set);
    // Its part of a render frame's parameters.
    void fill(FrameParams& frame) const;
    // Rows of the next frame: the image's, or the active list's virtual image's.
    uint32_t rows() const { return listed_ ? (active_ + width_ - 1) / width_ : height_; }
    // Pixels the next frame samples.
    uint32_t active_pixels() const { return active_; }
    // Every pixel converged: nothing is left to sample.
    bool converged() const { return on_ && listed_ && active_ == 0; }

    // Cycles' automatic minimum (min_samples 0): max(4, ceil(16 / threshold^0.3)), else max(4, min_samples).
    static uint32_t min_samples(const RenderParams& params);
    // The threshold the check compares with: Cycles' (0: automatic, 0.001 without a sample
    // target) times 5, as Cycles scales it.
    static float threshold(const RenderParams& params);

private:
    Context& ctx_;
    uint32_t width_, height_;
    Buffer aux_, pixels_;
    std::unique_ptr<ComputePipeline> pipeline_;
    bool on_ = false;
    float threshold_ = 0;
    uint32_t min_samples_ = 0;
    bool listed_ = false;      // the active list is in use (after the first check)
    uint32_t active_ = 0;      // pixels still sampled
    uint64_t checked_ = 0;     // the samples at the last check
};

}  // namespace px
