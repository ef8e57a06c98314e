// Adjoint-driven Russian roulette and splitting, host side (thesis 3.2.4, 4.5; Vorba &
// Krivanek 2016; shaders/techniques/adrrs.glsl).
//
// Owns the pixel estimate I~ and the split queue. The estimate comes from estimate frames
// (after the irradiance cache's prepare frames: paths to the first non-delta vertex, shaded
// with NEE and the cache) or, with ADRRS_ESTIMATE_IMAGE, from the accumulated image itself,
// blurred, refreshed each time the samples double. The queue holds, per pixel of one dispatch,
// adrrs.slots split entries (max_splits per sample of a frame, fewer where the image is so large
// that the queue would pass kMaxQueuedSplits); the session follows each camera dispatch with a
// split dispatch over the same pixels (record_dispatch).
#pragma once
#include "scene/scene.h"
#include "techniques/irradiance_cache.h"
#include "vk/pipeline.h"

namespace px {

// ADRRS' settings (the fields of AdrrsParams) and passes.
const SettingTable& adrrs_table();

class Adrrs {
public:
    explicit Adrrs(Context& ctx);
    // New settings or image size: the estimate is dropped and made again.
    void configure(const AdrrsParams& params, uint32_t width, uint32_t height, uint32_t samples_per_frame);
    void reset();  // the estimate is made again (the scene changed)
    void bind(DescriptorSet& set) const;
    const AdrrsParams& params() const { return params_; }  // with slots filled in
    bool enabled() const { return params_.enabled != 0; }
    // Estimate frames still to run (ADRRS_ESTIMATE_IC), after the cache's prepare frames.
    bool needs_estimate_frame() const { return enabled() && params_.estimate == ADRRS_ESTIMATE_IC && estimate_frames_ < params_.estimate_spp; }
    uint32_t estimate_frames() const { return estimate_frames_; }
    void estimate_frame_done() { ++estimate_frames_; }
    // Before a camera dispatch: its queue starts empty.
    void record_queue_clear(VkCommandBuffer cmd) const;
    // ADRRS_ESTIMATE_IMAGE: after a frame, with `samples` per pixel in `film`, the estimate
    // becomes the blurred image once the samples reach estimate_spp, and again each time they
    // double.
    void after_frame(const Buffer& film, uint64_t samples);
    uint32_t image_refreshes() const { return image_refreshes_; }
    uint32_t adjoint_builds() const { return adjoint_builds_; }
    double adjoint_milliseconds() const { return adjoint_milliseconds_; }
    // Remakes the adjoint grid from the cache's entries when they grew; returns
    // true when it did (the settings, which hold the grid's shape, must be uploaded again and
    // the buffer bound again).
    bool update_adjoint(const IrradianceCache& cache);

private:
    Context& ctx_;
    AdrrsParams params_{};
    uint32_t width_ = 0, height_ = 0;
    Buffer estimate_, queue_, splits_, adjoint_;
    uint32_t adjoint_entries_ = 0;  // cache entries the grid was made from
    uint32_t adjoint_builds_ = 0;
    double adjoint_milliseconds_ = 0;
    uint32_t estimate_frames_ = 0;
    uint64_t next_refresh_ = 0;  // samples at which the image estimate is refreshed next
    uint32_t image_refreshes_ = 0;
};

}  // namespace px
