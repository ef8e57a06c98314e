// Russian roulette and splitting (the setting rrs), host side: adjoint-driven (ADRRS, thesis
// 3.2.4, 4.5; Vorba & Krivanek 2016; shaders/techniques/adrrs.glsl) or efficiency-aware (EARS,
// Rath et al. 2022: the factors from learnt statistics, techniques/ears.h and
// shaders/techniques/ears.glsl, with this pixel estimate and split queue).
//
// Owns the pixel estimate I~ and the split queue. The estimate comes from estimate frames
// (after the irradiance cache's prepare frames: paths to the first non-delta vertex, shaded
// with NEE and the cache) or, with ADRRS_ESTIMATE_IMAGE, from the accumulated image itself,
// blurred, refreshed each time the samples double. The queue holds, per pixel of one dispatch,
// adrrs.slots split entries (max_splits per sample of a frame, fewer where the image is so large
// that the queue would pass kMaxQueuedSplits); each camera dispatch is followed by a split
// dispatch, which spreads the entries over its invocations, and a sums dispatch, which adds
// them to their pixels in queue order (record_after_trace).
#pragma once
#include "scene/scene.h"
#include "techniques/ears.h"
#include "techniques/irradiance_cache.h"
#include "vk/pipeline.h"

namespace px {

// ADRRS' settings (the fields of AdrrsParams) and passes.
const SettingTable& adrrs_table();

class Adrrs : public Technique {
public:
    // `cache`: its adjoint (the cache's entries, averaged over a grid).
    Adrrs(Context& ctx, const IrradianceCache& cache);
    // Technique (technique.h).
    const SettingTable& table() const override { return adrrs_table(); }
    // ADRRS' adjoint is the cache; EARS learns its own statistics.
    std::vector<std::string> needs(const RenderParams& params) const override {
        return params.adrrs.mode == RRS_ADRRS ? std::vector<std::string>{"ic"} : std::vector<std::string>{};
    }
    void configure(const RenderParams& params, const TechniqueSetup& setup, bool needed) override;
    void view_changed() override { reset(); }  // the pixel estimate is made again
    bool enabled() const override { return params_.mode != RRS_OFF; }
    bool ears() const { return params_.mode == RRS_EARS; }
    void bind(DescriptorSet& set) const override;
    void write_params(TechniqueParams& params) const override;
    uint32_t spec_bit(bool) const override { return enabled() ? TECH_ADRRS | (ears() ? TECH_EARS : 0u) : 0u; }
    // A pixel sample's paths for sizing dispatches: itself and, while splitting, one copy. Not
    // the worst case 1 + max_splits: that shrank every camera dispatch 11-fold (a 320-px,
    // 64-spp frame became two dispatches, each about as long as the whole frame's one on the
    // H200: 1.5x a MIS frame with no split, bench/results/gpu_rrs). The copies stay within
    // the split budget (max_splits per sample); on the bench scenes a sample makes 0.01-0.3
    // of them on average, 1.1-1.4 through glass (bench/results/cpu_rrs).
    uint64_t copies_per_sample() const override { return splits() ? 2 : 1; }
    // Whether paths may split (else the split queue stays empty and its dispatches are skipped).
    bool splits() const { return enabled() && params_.splitting && params_.max_splits > 0; }
    // Each camera dispatch starts with an empty split queue and, where paths may split, is
    // followed by the split dispatch (FRAME_ADRRS_SPLITS), which traces the copies, and the sums
    // dispatch (FRAME_ADRRS_SPLIT_SUMS), which adds them to the film; both over the same launch size.
    void record_before_trace(VkCommandBuffer cmd) const override;
    void record_after_trace(const FrameParams& frame,
                            const std::function<void(const FrameParams&)>& retrace) const override;
    // Estimate frames (ADRRS_ESTIMATE_IC; thesis 4.5): 1 spp to the first non-delta vertex,
    // shaded with NEE and the cache, into the pixel estimate; after the cache's prepare frames.
    bool needs_host_frame() const override {
        return enabled() && params_.estimate == ADRRS_ESTIMATE_IC && estimate_frames_ < params_.estimate_spp;
    }
    void begin_host_frame(FrameParams& frame) const override;
    void end_host_frame(TechniqueHost&, const FrameParams&, double) override { ++estimate_frames_; }
    // ADRRS_ESTIMATE_IMAGE (always with EARS): after a frame the estimate becomes the blurred
    // image once the samples reach estimate_spp, and again each time they double; each time
    // also ends one of EARS' training iterations. Other frames need no host step.
    bool steps_after_frame(uint64_t samples) const override {
        return enabled() && params_.estimate == ADRRS_ESTIMATE_IMAGE && samples >= next_refresh_;
    }
    void after_frame(TechniqueHost& host, const FrameEnd& frame) override;
    // The adjoint grid follows the cache's entries (after its prepare frames and render frames).
    void sync(TechniqueHost& host, const Technique* stepped) override;
    void stats(StatList& out) const override;

    const AdrrsParams& params() const { return params_; }  // with slots filled in

private:
    // New settings or image size: the estimate is dropped and made again.
    void setup(const AdrrsParams& params, const SceneHost& scene, uint32_t width, uint32_t height,
               uint32_t samples_per_frame);
    void reset();  // the estimate is made again (the scene changed)
    // Remakes the adjoint grid from the cache's entries when they grew; returns true when it
    // did (the settings, which hold the grid's shape, must be uploaded again and the buffer
    // bound again).
    bool update_adjoint();
    Context& ctx_;
    const IrradianceCache& cache_;
    AdrrsParams params_{};
    uint32_t width_ = 0, height_ = 0;
    Buffer estimate_, queue_, splits_, adjoint_;
    EarsStatistics ears_;
    uint32_t adjoint_entries_ = 0;  // cache entries the grid was made from
    uint32_t adjoint_builds_ = 0;
    double adjoint_milliseconds_ = 0;
    uint32_t estimate_frames_ = 0;
    uint64_t next_refresh_ = 0;  // samples at which the image estimate is refreshed next
    uint32_t image_refreshes_ = 0;
};

}  // namespace px
