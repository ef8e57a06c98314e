// Irradiance cache, host side (thesis 3.2.3, 4.4; shaders/techniques/irradiance_cache.glsl).
//
// Owns the entries, their AABBs (the geometry of the cache's own BLAS/TLAS, queried by
// zero-length rays), the creation queue and the job and sample buffers. After each frame
// (after_frame, end_host_frame): the queued creation requests (sorted, so a seed gives the same
// cache every run) and this frame's random refreshes become jobs for the hemisphere dispatch
// (ic_hemisphere.rgen, IC_STRATA rays per job) and the finish dispatch (ic_finish.comp), which
// write the entries; then the lookup grid that queries read (ic_grid) is built again.
#pragma once
#include "scene/scene.h"
#include "techniques/technique.h"
#include "vk/pipeline.h"

#include <vector>

namespace px {

// The cache's settings (the fields of IcParams) and passes.
const SettingTable& ic_table();

// Consistent mode's image (ic_mode consistent): B, the paths' mean (`rgba`, RGBA per pixel),
// shrunk toward the cache's estimate A = B + mean(A - B) by a positive-part James-Stein factor
// fitted on the IC_COMBINE_WINDOW-wide window around each pixel in a relative norm; A alone
// until a pixel has IC_COMBINE_MIN_SAMPLES. `residual` holds the sums of A - B (rgb) and
// |A - B|^2 (w) over `samples` samples per pixel. `sequence_variance` (per pixel, or empty):
// n times the variance of the mean of n samples of A - B (summed over rgb) as the sample
// sequence converges (ic_sequence_variance); negative or absent: the samples' variance.
// Pixels flagged in `paths_only` (or none, empty) show B and stay out of their neighbours' factors.
void ic_combine(std::vector<float>& rgba, const std::vector<float>& samples, const std::vector<vec4>& residual,
                uint32_t width, uint32_t height, const std::vector<float>& sequence_variance = {},
                const std::vector<uint32_t>& paths_only = {});

// The variance of the mean of A - B from two snapshots of the IC Residual pass' sums (rgb; w:
// the pixel's sample count) taken at n_a and n_b > n_a samples: the squared difference of the
// means of samples [0, n_a) and [n_a, n_b), as n_b times that variance at n_b (summed over rgb).
// Negative where a part has fewer than IC_COMBINE_MIN_HALF samples. See ic_combine.
std::vector<float> ic_sequence_variance(const std::vector<vec4>& first, const std::vector<vec4>& both);

// Consistent mode's pixel handover: which pixels to hand back to the paths for good (1). With
// a perfect cache the image's variance would be the paths' less the residual's, so where, over
// the window around a pixel, the residual's variance is below IC_HANDOVER_SHARE of the paths'
// (both per sample from ic_sequence_variance, negative: unknown; each pixel's weighted by
// 1/(its mean^2 + 1e-3) as relMSE) the cache cannot buy back its queries' cost there.
// Pixels set in `paths_only` stay set.
void ic_hand_over(std::vector<uint32_t>& paths_only, const std::vector<float>& residual_variance,
                  const std::vector<float>& path_variance, const std::vector<float>& means, uint32_t width,
                  uint32_t height);

// The cache's lookup grid over `entries` (IC_GRID_LEVELS, techniques.h): each entry listed in
// the cells its influence sphere (radius accuracy * R) overlaps at its level. `starts`: the
// levels' header (IC_GRID_HEADER), then each bucket's first place in `slots` and one past the
// last bucket's.
struct IcGrid {
    float cell = 0;        // the finest level's cell side, 2 accuracy min_radius
    uint32_t levels = 0;   // bit l: level l lists entries
    std::vector<uint32_t> starts;
    std::vector<IcCandidate> candidates;  // per bucket place
};
IcGrid ic_grid(const std::vector<IcEntry>& entries, float accuracy, float min_radius);

struct IcStats {
    uint32_t entries = 0;   // used slots
    uint32_t capacity = 0;
    uint64_t dropped = 0;   // creations refused because the cache was full
    uint64_t deferred = 0;  // requests past the queue (uncovered points ask again)
    uint64_t merged = 0;    // requests next to another of the same frame (one entry for both)
    uint64_t paths_only = 0;  // consistent mode: pixels handed back to the paths (ic_hand_over)
    uint64_t host_steps = 0;  // after render frames (consistent mode: several frames each)
    uint64_t left = 0;        // 1: the render frames left the cache's pipeline (consistent mode)
    uint64_t jobs = 0;      // hemisphere estimates computed (creations + refreshes)
    uint64_t job_rays = 0;  // their hemisphere rays (theta x phi each)
    double job_milliseconds = 0;    // hemisphere + finish dispatches
    double build_milliseconds = 0;  // lookup grid builds (entries' download, build, upload)
};

class IrradianceCache : public Technique {
public:
    explicit IrradianceCache(Context& ctx);
    // Technique (technique.h). Built when ic is on or a technique needs it (ADRRS' adjoint);
    // paths are shaded from it only with ic on.
    const SettingTable& table() const override { return ic_table(); }
    void configure(const RenderParams& params, const TechniqueSetup& setup, bool needed) override;
    bool enabled() const override { return params_.enabled != 0; }
    void bind(DescriptorSet& set) const override;
    void write_params(TechniqueParams& params) const override {
        params.ic = params_;
        params.ic.reuse_stamp = reuse_stamp_;
    }
    // Render frames query the cache only where it shades (ic on) and has not left their
    // pipeline (consistent mode, `left_`); host frames wherever it exists. On lavapipe the
    // render frames of a cache built for ADRRS alone keep the bit: its hooks do nothing there
    // (ic_camera_options), and their pipeline is then the host frames' (a cold compile of
    // 5-20 s less when ADRRS is switched on).
    uint32_t spec_bit(bool render_frame) const override {
        return enabled() && (!render_frame || (params_.shade ? !left_ : ctx_.is_cpu())) ? TECH_IC : 0u;
    }
    const std::vector<uint32_t>* raygen(uint32_t program) const override;
    void compile(TechniqueHost& host) override;
    // Clears the request queue at the start of its own prepare frame, and of the first render
    // frame after the host read it (make_entries): between host steps the queue gathers the
    // requests of several frames.
    void record_frame_start(VkCommandBuffer cmd, const Technique* host_frame) const override;
    // Prepare frames (thesis 4.4): camera paths to their first diffuse vertex only queue
    // entries, made after the frame; until prepare_frames ran or 98% of paths found an entry
    // (consistent mode: 90%).
    bool needs_host_frame() const override { return enabled() && prepared_frames_ < params_.prepare_frames; }
    void begin_host_frame(FrameParams& frame) const override;
    void end_host_frame(TechniqueHost& host, const FrameParams& frame, double milliseconds) override;
    // After every frame in thesis mode; never where it is built for ADRRS alone. In consistent mode
    // the host step (creation, refreshes, the grid) waits twice as many frames each time, up
    // to kMaxStepFrames, from one frame after preparation and after each camera move; the
    // snapshots (take_snapshot) come at their powers of two. None once `left_`.
    bool steps_after_frame(uint64_t samples) const override;
    // Consistent mode: the residual pass, and Combined shrunk toward the cache (ic_combine).
    uint32_t film_passes(const RenderParams& params) const override;
    void resolve_combined(std::vector<float>& rgba, const std::vector<vec4>& combined, uint32_t width,
                          uint32_t height, const std::function<std::vector<vec4>(uint32_t)>& sums) const override;
    void after_frame(TechniqueHost& host, const FrameEnd& frame) override;
    void view_changed() override { clear_snapshots(); }  // per pixel: the film starts over
    void stats(StatList& out) const override;

    const IcParams& params() const { return params_; }  // with queue_capacity filled in
    uint32_t count() const { return count_; }  // used slots
    std::vector<IcEntry> download_entries() const;

private:
    // New settings or scene (bounds): every entry is dropped; buffers follow the capacity and
    // the request queue the camera paths between host steps.
    void setup(const IcParams& params, const SceneInfo& scene, uint64_t paths_per_step);
    // Drops every entry; prepare frames run again.
    void reset();
    // After `frames` frames of `paths` camera paths each (a prepare frame when `prepare`):
    // turns the queue and the frames' refreshes into entries, then builds the lookup grid
    // again if entries were added. Preparation ends after prepare_frames, or earlier once
    // fewer than 2% of a prepare frame's paths found no entry (consistent mode: 10%).
    void make_entries(TechniqueHost& host, FrameParams frame, uint64_t paths, uint32_t frames, bool prepare);
    void allocate();
    // Consistent mode: at each power of two of samples, the IC Residual pass' sums are kept
    // and compared with those of the previous power (ic_sequence_variance).
    void take_snapshot(TechniqueHost& host, uint64_t samples);
    void clear_snapshots();
    // The lookup grid over the used slots (ic_grid), uploaded and bound into `set`.
    void build_grid(TechniqueHost* host, DescriptorSet* set);
    Context& ctx_;
    IcParams params_{};
    SceneInfo scene_{};
    Buffer entries_, grid_starts_, grid_candidates_, queue_, jobs_, samples_;
    uint32_t count_ = 0;           // used slots
    uint32_t allocated_ = 0;       // capacity the buffers were made for
    uint32_t update_cursor_ = 0;   // round-robin refresh position
    uint32_t prepared_frames_ = 0;
    uint32_t grid_count_ = 0;      // used slots the lookup grid lists
    uint64_t frame_counter_ = 0;   // frames processed since the last reset (refresh RNG)
    IcStats stats_;
    uint64_t pixels_ = 0;          // of the image (a prepare frame's paths)
    uint32_t width_ = 0;           // of the image
    std::vector<vec4> snapshot_;           // IC Residual's sums at the last power of two (w: samples)
    std::vector<vec4> snapshot_paths_;     // Combined's, the same frame
    std::vector<float> sequence_variance_; // from the last two snapshots (ic_combine)
    std::vector<uint32_t> paths_only_;     // per pixel: handed back to the paths (ic_hand_over)
    Buffer paths_only_buffer_;             // its copy for the shaders (BINDING_IC_PATHS_ONLY)
    // Consistent mode: each pixel's last query (IcReuseRecord, BINDING_IC_REUSE), valid while
    // its stamp is reuse_stamp_, which every change of the entries or the view moves on.
    Buffer reuse_buffer_;
    uint32_t reuse_stamp_ = 1;
    uint64_t next_snapshot_ = 0;           // samples per pixel of the next snapshot
    uint32_t samples_per_frame_ = 1;
    uint32_t step_frames_ = 1;             // consistent mode: render frames per host step now
    uint64_t stepped_samples_ = 0;         // samples per pixel at the last host step
    mutable bool queue_read_ = true;       // the host took the queue's requests: clear it
    bool needed_ = false;                  // another technique reads the cache (ADRRS' adjoint)
    // Consistent mode: three quarters of the pixels went back to the paths, so the render
    // frames trace without the cache (its pipeline costs every pixel, not only those that ask);
    // the other pixels' residual then fades as 1/n. Until the view or the settings change.
    bool left_ = false;
};

}  // namespace px
