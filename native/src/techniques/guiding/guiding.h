// Path guiding, the session's side (thesis 4.6; Ruppert, Herholz & Lensch 2020;
// shaders/techniques/guiding_field.glsl): owns the GuidingField (field.h) and its GPU data —
// regions, lobes, the region tree (walked by the shaders' region lookup), the region AABBs'
// BLAS/TLAS (the Guiding Lobes pass' spheres) and the training sample buffer — and drives the training between frames:
//   the first guiding_training_spp samples per pixel of the image (at least
//   GUIDING_MIN_TRAINING_FRAMES frames) record training samples, or, with
//   guiding_training_spp = 0, every frame does ("keep training"); every frame's samples
//   reach the image (each is unbiased whatever mixture sampled it), so training costs no
//   samples, only the recording and the fit. After each recording frame fit_frame() reads the
//   samples back, adds them to the field and starts the fit (multithreaded) on a worker
//   thread, which runs while the GPU traces the next frame; the fit_frame() that follows
//   waits for it and uploads its mixtures (rebuilding the region tree and TLAS when adaptive
//   refinement changed the regions). The frames thus trace with the field one frame behind,
//   the same for every run (deterministic); the last recording frame waits for its own fit,
//   so that the rest of the image accumulates with the finished field.
//   With guiding_fit = device the fit is compute passes instead (device_fit.h): no sample
//   readback or upload; the host field then only provides the initial regions. After the
//   fit's passes 32 bytes per region come back (GuidingFitTally): the learnt probabilities'
//   sums (their global rule, as the host field's, can drop the guiding pipeline) and the counts
//   of adaptive refinement, which splits a copy of the region tree on the host (node buffer,
//   AABBs and TLAS rebuilt as for the host fit) and hands the splits to the device
//   (DeviceFit::refine).
// The field survives camera moves, probe changes and guiding being switched off and on; new
// geometry or lights, the seed or any other guiding setting start it over (configure).
#pragma once
#include "scene/scene.h"
#include "techniques/guiding/device_fit.h"
#include "techniques/guiding/field.h"
#include "techniques/technique.h"
#include "vk/accel.h"
#include "vk/pipeline.h"

#include <future>
#include <memory>

namespace px {

struct GuidingStats {
    uint32_t training_frames = 0;  // recording frames whose samples reached the field
    uint32_t regions = 0;
    uint32_t trained_regions = 0;  // regions with a mixture
    uint32_t lobes = 0;            // active lobes, all regions
    uint64_t samples_added = 0;
    uint64_t samples_dropped = 0;
    uint64_t region_fits = 0;
    uint32_t refinements = 0;      // regions split, all time
    bool device_fit = false;       // the field is fitted by compute passes (guiding_fit device/auto)
    // Training cost, summed over the recording frames: the frame (submission to completion),
    // the sample readback, the fit (on a worker thread, overlapped with the next frame), the
    // part of the fit the host waited for after that frame, the upload (with tree and TLAS
    // rebuilds).
    double frame_milliseconds = 0, readback_milliseconds = 0, fit_milliseconds = 0, fit_wait_milliseconds = 0,
           upload_milliseconds = 0;
    uint64_t bytes_per_region = 0;   // GPU: region record, lobes, AABB, BLAS share
    uint64_t sample_buffer_bytes = 0;
};

class Guiding : public Technique {
public:
    explicit Guiding(Context& ctx);
    ~Guiding() override;
    // Technique (technique.h).
    const SettingTable& table() const override { return guiding_table(); }
    // Settings, scene and image size for the next frames. The field is kept when nothing it
    // depends on changed: the guiding settings (the probe and on/off aside), the seed and the
    // scene version (bumped by every update but a camera-only one).
    void configure(const RenderParams& params, const TechniqueSetup& setup, bool needed) override;
    bool enabled() const override { return params_.enabled != 0; }
    void bind(DescriptorSet& set) const override;
    void write_params(TechniqueParams& params) const override { params.guiding = params_; }
    // Off once training is over where the field does not guide (mixture_sampled_) and no
    // guiding pass is shown: the frames then trace the plain pipeline, at its cost. (The device
    // fit's probabilities stay on the device: its tally tells, DeviceFit::mixture_sampled.)
    // The Guiding Lobes pass adds TECH_GUIDING_LOBES: its region query and hit group.
    uint32_t spec_bit(bool) const override {
        if (!enabled() || !(records_render_frames() || mixture_sampled_ || shows_passes_)) return 0u;
        return TECH_GUIDING | (shows_lobes_ ? TECH_GUIDING_LOBES : 0u);
    }
    void add_shaders(uint32_t bits, PipelineShaders& shaders) const override;
    std::vector<uint32_t> tlas_bindings() const override { return {BINDING_GUIDING_TLAS}; }
    // Frames record training samples (FrameParams.guiding_record) while it trains.
    void fill_frame_params(FrameParams& frame) const override {
        frame.guiding_record = records_render_frames() ? 1u : 0u;
    }
    // A sample's region and lobe queries (a region lookup is no ray: a tree walk).
    uint64_t extra_rays_per_sample() const override { return enabled() ? 2 : 0; }
    // Clears the sample buffer before a recording frame: its own training frame, or a render
    // frame that records (keep training).
    void record_frame_start(VkCommandBuffer cmd, const Technique* host_frame) const override;
    // Recording frames (thesis 4.6.2) step after the frame: readback, fit, upload.
    bool steps_after_frame(uint64_t) const override { return records_render_frames(); }
    void after_frame(TechniqueHost& host, const FrameEnd& frame) override;
    void stats(StatList& out) const override;

    const GuidingParams& params() const { return params_; }  // record_stride, record_samples filled in
    // The field the host fits, its fit in flight finished; null without guiding or with the
    // device fit (whose mixtures live on the GPU only).
    const guiding::GuidingField* host_field() const;

private:
    // This frame records training samples: while training (guiding_training_spp), or always.
    bool records_render_frames() const {
        return enabled() && (params_.training_spp == GUIDING_KEEP_TRAINING || training_left());
    }
    bool training_left() const {
        return trained_spp_ < params_.training_spp ||
               training_frames_ < std::min(params_.training_spp, GUIDING_MIN_TRAINING_FRAMES);
    }
    void setup(const GuidingParams& params, const SceneHost& scene, uint64_t scene_version, uint32_t seed,
               uint32_t width, uint32_t height, uint32_t samples_per_frame);
    // After a recording frame: readback, fit, upload; rebinds the TLAS into `set` when the
    // regions changed. `frame_milliseconds`: the frame's GPU time, for the stats.
    void fit_frame(DescriptorSet& set, double frame_milliseconds);
    GuidingStats current_stats() const;
    // The field, its fit in flight finished (its mixtures reach the GPU at the next fit_frame).
    const guiding::GuidingField* field() const;
    void finish_fit() const;  // waits for the fit in flight and adds its figures to stats_
    void upload(DescriptorSet* set);  // regions and lobes; AABBs, order and TLAS if the layout changed
    void upload_layout(const guiding::RegionTree& tree);  // AABBs, order, nodes, BLAS/TLAS
    void build_placeholder();
    Context& ctx_;
    GuidingParams params_{};
    GuidingParams field_key_{};  // the settings the field was made for
    uint64_t scene_version_ = ~0ull;
    uint32_t seed_ = 0;
    uint32_t record_paths_ = 0;  // path slots of the sample buffer
    std::unique_ptr<guiding::GuidingField> field_;
    std::unique_ptr<guiding::DeviceFit> device_fit_;  // guiding_fit = device
    guiding::RegionTree device_tree_;                 // its regions (refined on the host)
    Buffer regions_, lobes_, samples_;
    Buffer order_, aabbs_, nodes_, layout_staging_;  // the layout, kept and grown (upload_layout)
    AabbAccel accel_;
    uint64_t built_layout_ = ~0ull;
    uint32_t training_frames_ = 0;
    uint64_t trained_spp_ = 0;  // samples per pixel of the recording frames
    // The field guides: some region samples its mixture (prob > 0; the host field's or the device
    // fit's) or thins NEE where most vertices are (GuidingField::guides).
    bool mixture_sampled_ = false;
    bool shows_passes_ = false;    // a guiding pass is in the film
    bool shows_lobes_ = false;     // ... the Guiding Lobes pass
    mutable std::future<void> fit_;      // the fit in flight (worker thread), if any
    mutable bool fitted_ = false;        // a finished fit whose mixtures are not uploaded yet
    mutable GuidingStats stats_;
};

}  // namespace px
