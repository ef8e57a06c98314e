// Session: one device, one scene, one film. Progressive: every render() call adds
// samples_per_frame samples per pixel to the running sums; read() divides by the count.
#pragma once
#include "render/adaptive.h"
#include "render/params.h"
#include "scene/scene.h"
#include "techniques/technique.h"
#include "vk/pipeline.h"

#include <array>
#include <atomic>
#include <map>
#include <memory>
#include <optional>
#include <mutex>

namespace px {

struct SessionStats {
    uint64_t samples = 0;  // per pixel
    uint64_t rays = 0;     // all rays traced since the last reset
    // Rendered with the techniques off while their pipelines compiled (Session::set_background_compile):
    // in the film until the techniques' first frame, which starts the film and the figures above over.
    uint64_t fallback_samples = 0;
    double fallback_milliseconds = 0;
    bool fallback_film = false;  // the film still holds the fallback's samples alone
    double milliseconds = 0;  // GPU-side render time since the last reset (wall clock)
    uint32_t frames = 0;
    uint64_t blas_builds = 0;  // BLASes built by this session's updates (never reset; debugging)
    uint32_t light_tree_nodes = 0;  // nodes of the scene's light tree (0: lights picked by power)
    uint32_t contact_boxes = 0;     // boxes round transmissive instances (SceneInfo.contact_lo/hi)
    // Pixels the next frame samples (adaptive sampling stops the converged ones; all without it).
    uint64_t adaptive_active_pixels = 0;
    StatList techniques;  // each technique's own (Technique::stats)
};

// Pipelines compiling on worker threads (Session::set_background_compile, Session::warm), and a
// wait for them all: the process must not exit while one is inside the driver.
uint32_t background_compiles();
void wait_for_background_compiles();

class Session : private TechniqueHost {
public:
    Session(uint32_t width, uint32_t height, const std::string& device);
    ~Session();

    // Replaces the scene's `parts` (ScenePart bits; PART_ALL: the whole scene, as given) with
    // `arrays`, which then holds only arrays of those parts: the session keeps a copy of the
    // last arrays of every part and re-prepares and re-uploads only the changed parts and
    // what depends on them (geometry: everything). A partial update needs an earlier whole
    // one. Returns the warnings (skipped items) of the whole resulting scene. Resets
    // accumulation. On any error the session keeps its previous scene, unchanged.
    std::vector<std::string> update(const SceneArrays& arrays, bool spatial_order = true, uint32_t parts = PART_ALL);
    void set_params(const RenderParams& params);
    const RenderParams& params() const { return params_; }
    // Adds `frames` whole frames (finishing a frame that render_rows began first); returns
    // the frames completed, fewer than `frames` when cancel() stopped it.
    uint32_t render(uint32_t frames);
    // Traces the next `rows` rows of the current frame (short dispatches, so a caller can
    // react between them); returns true when that completed the frame. While a technique
    // needs host frames, a call at a frame's start may instead run one of them (false). Sample
    // counts include completed frames only, so read() is exact after a completed frame (in
    // between, traced rows hold one frame more). update, set_params and reset drop a partial
    // frame.
    bool render_rows(uint32_t rows);
    // Thread-safe, from any thread: stops the render() or render_rows() call in progress at
    // its next dispatch boundary (see dispatch_plan), or the next such call if none is in
    // progress (which then returns at once). The stopped call keeps what it traced.
    void cancel() { cancel_ = true; }
    uint32_t next_row() const { return cursor_.row; }
    // Samples per pixel accumulated (completed frames); cheap, unlike stats().
    // With adaptive sampling, those of the pixels still sampled (the most any pixel has).
    uint64_t samples() {
        std::lock_guard<std::mutex> lock(mutex_);
        return stats_.samples;
    }
    // Adaptive sampling found every pixel converged: render() and render_rows() add nothing
    // until a reset (cheap). Never while the film holds the fallback's samples: they are
    // thrown away once the techniques' pipelines are ready.
    bool converged() {
        std::lock_guard<std::mutex> lock(mutex_);
        return !fallback_frame_ && !film_after_fallback_ && adaptive_->converged();
    }
    // (height, width, channels) float32, row 0 = top; each pixel's sums divided by its own
    // sample count (exact after a partial or cancelled frame too).
    std::vector<float> read(const std::string& pass, uint32_t& channels);
    // The passes the film holds (names of the passes table; combined always). A pass whose
    // technique is off takes no film memory and reads as zeros; read() of a pass not listed
    // throws. Default: every pass. Resets accumulation when the list changes.
    void set_passes(const std::vector<std::string>& names);
    std::vector<std::string> passes();
    void reset();
    SessionStats stats();
    // The technique called `name` (its table's technique name); null if there is none.
    const Technique* technique(const std::string& name) const;

    // Runs shaders/tests/sampling_test.comp: see that file. Returns count * 8 floats.
    std::vector<float> test_sampling(uint32_t routine, const std::vector<float>& params, uint32_t count,
                                     uint32_t seed, const std::vector<float>& input);

    uint32_t width() const { return width_; }
    uint32_t height() const { return height_; }
    const DeviceReport& device() const { return ctx_->report(); }
    // Whether the pipeline the next render() needs is compiled (false: it compiles first).
    bool pipeline_ready();
    // Compiles the pipelines the next render() needs, without rendering (the viewport runs it
    // on a thread of its own while its preview program renders).
    void compile();
    // With background compiles on, a frame that needs a technique's pipelines before they are
    // compiled renders with the techniques off while a worker thread compiles them
    // (stats().fallback_samples counts those samples; the film starts over at the techniques'
    // first frame); off (the default), render() waits for the compile.
    void set_background_compile(bool on) { background_compile_ = on; }
    // Whether the film holds the fallback's samples alone (cheap, unlike stats()): a sample
    // target counts the techniques' samples only.
    bool fallback_film() {
        std::lock_guard<std::mutex> lock(mutex_);
        return fallback_frame_ || film_after_fallback_;
    }
    bool background_compile() const { return background_compile_; }
    // Starts compiling, on a worker thread, the pipelines the current settings need and their
    // fallback; returns at once (the add-on warms them when the engine is picked or a file loads).
    void warm();
    size_t triangle_count() const { return scene_ ? scene_->triangle_count() : 0; }

private:
    // How a frame is split into dispatches: tiles of `rows` x `cols` pixels tracing `samples`
    // of each pixel's samples. A dispatch's worst-case rays (every path its full depth with
    // its shadow rays) stay within `budget`, so none runs for long on lavapipe; a submission
    // holds dispatches up to the budget, and cancel() is checked between submissions.
    struct DispatchPlan {
        uint32_t rows, cols, samples;
        uint64_t cost;    // worst-case rays of one pixel-sample
        uint64_t budget;  // worst-case rays per dispatch and per submission
    };
    DispatchPlan dispatch_plan() const;
    // Where the current frame stands: the next dispatch's first row, column and sample.
    struct Cursor {
        uint32_t row = 0, col = 0, sample = 0;
        bool at_frame_start() const { return row == 0 && col == 0 && sample == 0; }
    };
    // Whole frames, or (frames == 0) rows of one; returns the frames completed.
    uint32_t trace(uint32_t frames, uint32_t rows);
    // Records the dispatch at cursor_ and advances it; `rows` counts the rows left to
    // complete (UINT32_MAX: no limit). Returns the dispatch's worst-case rays and sets
    // `frame_done` when it completed the frame.
    uint64_t record_dispatch(VkCommandBuffer cmd, RayTracingPipeline& pipe, const DispatchPlan& plan, uint32_t frame,
                             uint32_t& rows, bool& frame_done);
    // One host frame of `technique` (Technique::needs_host_frame): 1 spp over the whole image,
    // nothing reaches the film; then every technique's sync.
    void host_frame(Technique& technique);
    // Film, stats and partial frame; the techniques start over unless `view_only` (only the
    // camera moved: Technique::view_changed).
    void reset_accumulation(bool view_only = false);
    FrameParams frame_params(uint32_t frame) const;
    // The pipeline of `program` for the current settings, for render frames (`render_frame`:
    // each technique's spec_bit(true)) or host frames.
    RayTracingPipeline& pipeline(uint32_t program, bool render_frame);
    RayTracingPipeline& render_pipeline();
    PipelineKey pipeline_key(uint32_t program, bool render_frame) const;
    RayTracingPipeline& pipeline_for(const PipelineKey& key);
    // What a pipeline is made of, gathered from the session and its techniques; made into a
    // pipeline from that alone (no session state), so a worker thread can compile it.
    struct PipelineRecipe {
        std::vector<ShaderStage> stages;
        std::vector<ShaderGroup> groups;
        SpecConstants constants;
        uint32_t program;  // PROGRAM_*
    };
    PipelineRecipe pipeline_shaders(const PipelineKey& key) const;
    static std::unique_ptr<RayTracingPipeline> create_pipeline(Context& ctx, VkDescriptorSetLayout layout,
                                                               const PipelineRecipe& recipe);
    std::vector<PipelineKey> needed_pipelines() const;
    bool technique_pipelines_ready();
    bool compiled_or_started(const std::vector<PipelineKey>& wanted);
    PipelineKey fallback_key() const;
    uint32_t camera_program() const { return params_.preview ? PROGRAM_PREVIEW : PROGRAM_CAMERA; }
    // TechniqueHost
    Context& context() override { return *ctx_; }
    DescriptorSet& descriptors() override { return *set_; }
    RayTracingPipeline& host_pipeline(uint32_t program) override { return pipeline(program, false); }
    void upload_technique_params() override;
    const Buffer& film() const override { return film_; }
    std::vector<vec4> film_sums(uint32_t pass) const override;
    // The film's passes (FrameParams.film_passes): the listed ones whose technique is on.
    uint32_t film_passes() const;
    // Byte offset of `pass` in the film (it must be one of film_passes()).
    size_t film_offset(uint32_t pass) const;
    // Reallocates the film for film_passes() if they changed (caller holds mutex_).
    void allocate_film();
    std::shared_ptr<Context> ctx_;  // first member: destroyed after everything using it
    uint32_t width_, height_;
    std::unique_ptr<DescriptorSet> set_;
    // Written only by update() and set_params() (a light_tree change), under update_mutex_ and mutex_.
    std::unique_ptr<Scene> scene_;
    std::map<std::string, std::shared_ptr<const OwnedArray>> arrays_;  // the last arrays of every part
    uint64_t blas_builds_ = 0;
    uint32_t listed_passes_ = 0;     // set_passes, bit PASS_*
    uint32_t allocated_passes_ = 0;  // the passes film_ holds
    Buffer film_, ray_count_, test_io_, technique_params_, ggx_tables_;  // ggx: constant, multiscatter albedos
    std::unique_ptr<AdaptiveSampling> adaptive_;  // Cycles' adaptive sampling (render/adaptive.h)
    Buffer pixel_filter_;  // the pixel filter's inverted CDF (render/pixel_filter.h) ...
    std::pair<uint32_t, float> pixel_filter_uploaded_{~0u, 0.0f};  // ... of this type and width
    // The techniques, in the order their hooks run (built by the constructor).
    std::vector<std::unique_ptr<Technique>> techniques_;
    uint64_t scene_version_ = 0;  // bumped by every update but a camera-only one (guiding keeps its field)
    // One pipeline per (method, heuristic, scene features) combination, built on first use.
    std::unique_ptr<ComputePipeline> test_pipeline_;
    RenderParams params_;
    SessionStats stats_;
    Cursor cursor_;            // progress through the current frame
    std::atomic<bool> background_compile_{false};
    bool fallback_frame_ = false;       // the current frame renders with the techniques off
    std::optional<PipelineKey> rendered_key_;  // the last render frame's pipeline
    bool film_after_fallback_ = false;  // the film starts over before the next render dispatch
    std::atomic<bool> cancel_{false};
    std::mutex mutex_;         // the scene, film and stats against concurrent render()/read()
    // One update() or set_params() at a time: each builds on the previous one. Taken before
    // mutex_; params_ is written under both.
    std::mutex update_mutex_;
};

}  // namespace px
