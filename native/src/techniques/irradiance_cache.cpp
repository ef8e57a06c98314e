#include "techniques/irradiance_cache.h"

#include "shaders_embedded.h"


#include <algorithm>
#include <cassert>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <map>
#include <memory>
#include <mutex>
#include <random>
#include <stdexcept>
#include <string>
#include <tuple>
#include <unordered_map>
#include <utility>

namespace px {

namespace {

constexpr uint32_t IC_COMBINE_WINDOW = 9;  // pixels per side of the window of one James-Stein factor
// Samples a pixel needs before the paths' variance is trusted; until then the image is the
// cache's. Paths' noise is heavy-tailed: from two samples most windows' variance came out too
// low, and the image took the paths' noise (sun_room, 320 px on lavapipe: relMSE 0.015 with one
// sample, 0.036 with two).
constexpr double IC_COMBINE_MIN_SAMPLES = 4;
// Samples each part of a snapshot pair needs before its difference is trusted over the
// samples' variance (the same heavy tails), and the first snapshot's count (a power of two).
constexpr double IC_COMBINE_MIN_HALF = 4;
constexpr uint64_t kFirstSnapshot = 4;
// A pixel whose residual carries less than this share of its paths' variance is handed back to
// the paths: a query cost lavapipe 20-50% of a path on the direct-lit scenes, so a cache that
// removes less than 20-25% of the variance cannot win at equal time there.
constexpr double IC_HANDOVER_SHARE = 0.25;

// Jobs per hemisphere dispatch (theta x phi paths each); a frame's jobs go in several.
constexpr uint32_t kJobsPerDispatch = 2048;
constexpr uint32_t kMaxRefreshes = 4096;       // per frame
constexpr uint32_t kMaxQueue = 1u << 20;       // requests the queue may hold
// Consistent mode: most render frames per host step. A step ends the frames' submission,
// reads the queue back and dispatches the jobs in a submission of its own; once the cache
// covers the view, steps mostly refresh entries, which can wait.
constexpr uint32_t kMaxStepFrames = 16;
// Prepare frames: uncovered points ask for entries with at least the probability that makes
// about this many requests per frame. The entries a view needs do not grow with its pixels, so
// small images would otherwise take many more prepare frames (320 x 180 px at the default
// 0.01: 44 frames, 1.8 s on lavapipe; at this floor 13 frames, 0.8 s).
constexpr double kPrepareRequests = 2048;

// Room for the creation requests between host steps: the binomial count of `paths` trials
// with the creation probability, plus six standard deviations, so the queue practically never
// overflows (which requests an overflow keeps depends on the threads' order, and the cache
// would lose its determinism). Requests past it are left for a later step and counted as
// deferred.
uint32_t queue_capacity(double create_prob, uint64_t paths) {
    const double mean = create_prob * double(paths);
    return uint32_t(std::min<double>(kMaxQueue, std::max(1024.0, std::ceil(mean + 6.0 * std::sqrt(mean) + 64.0))));
}

double ms_since(std::chrono::steady_clock::time_point start) {
    return std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count();
}

}  // namespace

// The cache's settings (thesis 4.4; Ward et al. 1988; Ward & Heckbert 1992) and passes.
const SettingTable& ic_table() {
    static const SettingTable table{"ic",
        {
            bool_setting("ic", PX_FIELD(IcParams, enabled), false, "Irradiance Cache",
                         "Reuse indirect diffuse irradiance from sparse cache entries, each the mean of a hemisphere "
                         "of paths, interpolated between nearby entries (Ward, Rubinstein & Clear 1988; thesis, sec. "
                         "4.4)", "ic"),
            enum_setting("ic_mode", PX_FIELD(IcParams, mode), IC_MODE_CONSISTENT,
                         {{"consistent", "Consistent",
                           "Paths go on past the cache; the image leans on the cache's smooth estimate where the "
                           "paths are still noisy and converges to the paths' unbiased result (James-Stein "
                           "shrinkage)", IC_MODE_CONSISTENT},
                          {"thesis", "Thesis",
                           "Paths end at cached points, shaded from the cache (thesis, sec. 4.4): smooth and fast, "
                           "but biased, and the bias stays", IC_MODE_THESIS}},
                         "Mode", "How the image uses the cache", "ic"),
            float_setting("ic_accuracy", PX_FIELD(IcParams, accuracy), 0.2, 0.001, 2.0, "Accuracy",
                          "Ward's accuracy a: an entry is used where its error estimate is below a, i.e. within a "
                          "times its radius and for normals close to its own. Smaller is more accurate and needs "
                          "more entries (Ward et al. 1988)", "ic").in_group("Accuracy"),
            float_setting("ic_min_radius", PX_FIELD(IcParams, min_radius), 0.1, 0.0001, 1e6, "Min Radius",
                          "Lower limit of an entry's radius, the harmonic mean distance of its hemisphere paths, in "
                          "scene units: keeps corners and contact regions from needing unbounded numbers of entries",
                          "ic").in_group("Accuracy").with_unit("length"),
            float_setting("ic_create_prob", PX_FIELD(IcParams, create_prob), 0.01, 0.0, 1.0, "Creation Probability",
                          "Probability that a path vertex without a valid cache entry queues the creation of one "
                          "(thesis, sec. 4.4); prepare frames ask with at least the probability that makes about 2048 "
                          "requests per frame", "ic").in_group("Creation"),
            float_setting("ic_update_prob", PX_FIELD(IcParams, update_prob), 0.003, 0.0, 1.0, "Update Probability",
                          "Probability per pixel and frame of refreshing a cache entry with new hemisphere paths, so "
                          "early noisy entries improve over time (consistent mode refines its cheap entries so; the "
                          "thesis used 1e-5)", "ic").in_group("Creation"),
            int_setting("ic_nee_samples", PX_FIELD(IcParams, nee_samples), 1, 1, 64, "Entry Light Samples",
                        "Light samples per vertex of the hemisphere paths that compute a cache entry", "ic")
                .in_group("Creation"),
            bool_setting("ic_gradients", PX_FIELD(IcParams, gradients), false, "Gradients",
                         "Extrapolate each entry with its rotational and translational irradiance gradients (Ward & "
                         "Heckbert 1992) for smoother interpolation", "ic").in_group("Gradients"),
            float_setting("ic_gradient_max", PX_FIELD(IcParams, gradient_max), 5.0, 0.0, 1e6, "Max Gradient Length",
                          "Clamp of the gradients' length relative to the entry's irradiance, against extrapolating "
                          "noisy gradients", "ic").in_group("Gradients"),
            bool_setting("ic_visibility_check", PX_FIELD(IcParams, visibility_check), true, "Visibility Check",
                         "Skip entries that lie in front of the shaded point (Ward et al. 1988's 'in front' test), "
                         "so light does not leak across creases", "ic").in_group("Accuracy"),
            int_setting("ic_prepare_frames", PX_FIELD(IcParams, prepare_frames), 50, 0, 10000, "Prepare Frames",
                        "Frames that only fill the cache before the image starts to accumulate", "ic")
                            .in_group("Creation"),
            int_setting("ic_capacity", PX_FIELD(IcParams, capacity), 65536, 1, 4000000, "Capacity",
                        "Maximum number of cache entries; creations beyond it are dropped (and counted in the "
                        "render stats)", "ic").in_group("Creation"),
            bool_setting("ic_highlight", PX_FIELD(IcParams, highlight), false, "Colour Highlight",
                         "The IC Irradiance pass shows only the colour (the thesis' colour-highlight mode, fig. "
                         "4.13)", "ic").in_group("Visualisation"),
        },
        {
            {"ic_irradiance", "IC Irradiance", 3, "RGB",
             "Irradiance cache: the cached indirect irradiance at the first diffuse hit, without the surface colour",
             PASS_IC_IRRADIANCE, "ic"},
            {"ic_gradients", "IC Gradients", 3, "RGB",
             "Irradiance cache: R = length of the translational gradient, G = of the rotational gradient",
             PASS_IC_GRADIENTS, "ic"},
            {"ic_radius", "IC Radius", 1, "X",
             "Irradiance cache: the validity radius of the nearest entry the query read at the first diffuse hit "
             "(0: none; consistent mode reads at most 4)",
             PASS_IC_RADIUS, "ic"},
            {"ic_residual", "IC Residual", 4, "RGBA",
             "Irradiance cache, consistent mode: RGB = the cache's estimate less the path's, A = its squared norm "
             "(means per sample): where the cache is wrong or the paths are noisy", PASS_IC_RESIDUAL, "ic"},
        }};
    return table;
}

// Sums of per-pixel values over the IC_COMBINE_WINDOW-wide window around each pixel (clipped
// at the image's edges), from a summed-area table.
class WindowSums {
public:
    WindowSums(const std::vector<double>& values, uint32_t width, uint32_t height)
        : width_(width), height_(height), table_((size_t(height) + 1) * (width + 1), 0.0) {
        const size_t stride = size_t(width) + 1;
        for (uint32_t y = 0; y < height; ++y)
            for (uint32_t x = 0; x < width; ++x) {
                const size_t at = (y + 1) * stride + x + 1;
                table_[at] = values[size_t(y) * width + x] + table_[at - 1] + table_[at - stride] - table_[at - stride - 1];
            }
    }
    double operator()(uint32_t x, uint32_t y) const {
        constexpr int kHalf = IC_COMBINE_WINDOW / 2;
        const size_t stride = size_t(width_) + 1;
        const size_t x0 = size_t(std::max(0, int(x) - kHalf)), x1 = size_t(std::min(int(width_), int(x) + kHalf + 1));
        const size_t y0 = size_t(std::max(0, int(y) - kHalf)), y1 = size_t(std::min(int(height_), int(y) + kHalf + 1));
        return table_[y1 * stride + x1] - table_[y0 * stride + x1] - table_[y1 * stride + x0] + table_[y0 * stride + x0];
    }

private:
    uint32_t width_, height_;
    std::vector<double> table_;
};

// James & Stein 1961, positive part (Baranchik 1964): for d coordinates of B with noise of
// total variance V around unknown means, A + (1 - (d - 2)/d V / |B - A|^2)+ (B - A) has a lower
// expected squared error than B itself, whatever A is. Here A is the cache's estimate, so the
// factor is near 0 where the paths are still noisier than the cache is wrong, and tends to 1
// (B, unbiased) as their variance falls: the image is consistent. Each pixel's factor comes from
// the window around it (its pixels' three channels are the coordinates), so it varies smoothly.
// The norm is relative, as the error that matters (relMSE): each pixel's terms are divided by
// A's brightness squared (+ 1e-3, as relMSE), so a bright lamp in the window does not decide
// for the dark corner beside it.
// V is the variance of the mean of the pixel's n samples. Var/n, as for independent samples,
// overestimates it for our Owen-scrambled Sobol samples, whose means converge faster: on the
// thesis' irradiance-cache scene 5x at 16 samples and 10x at 64, so the image leaned on the
// cache long after the paths were better. Where the sequence's own convergence has been
// measured (ic_sequence_variance: the first half of the samples up to a power of two against
// the second), carried to n as 1/n, each window takes the smaller of the two.
void ic_combine(std::vector<float>& rgba, const std::vector<float>& samples, const std::vector<vec4>& residual,
                uint32_t width, uint32_t height, const std::vector<float>& sequence_variance,
                const std::vector<uint32_t>& paths_only) {
    const size_t pixels = size_t(width) * height;
    if (residual.size() != pixels || samples.size() != pixels || rgba.size() != pixels * 4 ||
        (!sequence_variance.empty() && sequence_variance.size() != pixels) ||
        (!paths_only.empty() && paths_only.size() != pixels))
        throw std::invalid_argument("ic_combine: the image, sample counts and residual sums differ in size");
    // Window sums of |mean(A - B)|^2, of its variance estimate and of the coordinates (channels
    // of pixels with enough samples), each term weighted by the pixel's 1/|A|^2.
    std::vector<double> sq(pixels, 0.0), var(pixels, 0.0), sequence_var(pixels, 0.0), dims(pixels, 0.0);
    for (size_t i = 0; i < pixels; ++i) {
        const double n = samples[i];
        if (!(n >= IC_COMBINE_MIN_SAMPLES) || (!paths_only.empty() && paths_only[i])) continue;
        const vec4& r = residual[i];
        const double mx = r.x / n, my = r.y / n, mz = r.z / n;
        const double a = (rgba[i * 4] + mx + rgba[i * 4 + 1] + my + rgba[i * 4 + 2] + mz) / 3.0;
        const double w = 1.0 / (a * a + 1e-3);
        sq[i] = w * (mx * mx + my * my + mz * mz);
        // Of the mean: the samples' variance / n, and the sequence's where it was measured.
        var[i] = w * std::max(0.0, r.w / n - (mx * mx + my * my + mz * mz)) / (n - 1);
        const double measured = sequence_variance.empty() ? -1.0 : sequence_variance[i];
        sequence_var[i] = measured >= 0 ? w * measured / n : var[i];
        dims[i] = 3;
    }
    const WindowSums sq_sums(sq, width, height), var_sums(var, width, height), dims_sums(dims, width, height);
    const WindowSums sequence_var_sums(sequence_var, width, height);
    for (uint32_t y = 0; y < height; ++y)
        for (uint32_t x = 0; x < width; ++x) {
            const size_t i = size_t(y) * width + x;
            const float n = samples[i];
            if (!(n > 0) || (!paths_only.empty() && paths_only[i])) continue;  // B
            // The smaller of the window's two variance estimates: the samples' overestimates a
            // faster-converging sequence's; the halves' alone came out too large on a glass
            // floor under adaptive sampling (the image leaned on the cache, and the per-block
            // Z-test against MIS failed: tests/render/test_adaptive_sampling.py).
            const double s = sq_sums(x, y), v = std::min(var_sums(x, y), sequence_var_sums(x, y));
            const double d = dims_sums(x, y);
            // Weight of B: 0 (the cache's A) until this pixel has enough samples.
            double keep = 0;
            if (n >= IC_COMBINE_MIN_SAMPLES && d > 2) keep = s > 0 ? std::clamp(1.0 - (d - 2) / d * v / s, 0.0, 1.0) : 1.0;
            const float toward_cache = float(1.0 - keep);
            rgba[i * 4 + 0] += toward_cache * residual[i].x / n;
            rgba[i * 4 + 1] += toward_cache * residual[i].y / n;
            rgba[i * 4 + 2] += toward_cache * residual[i].z / n;
        }
}

// For parts of n1 and n2 samples with means m1 and m2 and independent errors of variance
// s^2/n1 and s^2/n2: E|m1 - m2|^2 = s^2 (1/n1 + 1/n2), so n_b Var(mean of n_b) = s^2 =
// |m1 - m2|^2 n1 n2 / n_b. Our parts are each a run of a power of two of Sobol points, as
// the whole is, so their difference sees how fast the sequence converges on this pixel.
std::vector<float> ic_sequence_variance(const std::vector<vec4>& first, const std::vector<vec4>& both) {
    if (first.size() != both.size()) throw std::invalid_argument("ic_sequence_variance: the snapshots differ in size");
    std::vector<float> out(both.size(), -1.0f);
    for (size_t i = 0; i < both.size(); ++i) {
        const double n1 = first[i].w, n2 = both[i].w - first[i].w;
        if (!(n1 >= IC_COMBINE_MIN_HALF && n2 >= IC_COMBINE_MIN_HALF)) continue;
        const double dx = first[i].x / n1 - (both[i].x - first[i].x) / n2;
        const double dy = first[i].y / n1 - (both[i].y - first[i].y) / n2;
        const double dz = first[i].z / n1 - (both[i].z - first[i].z) / n2;
        out[i] = float((dx * dx + dy * dy + dz * dz) * n1 * n2 / (n1 + n2));
    }
    return out;
}

void ic_hand_over(std::vector<uint32_t>& paths_only, const std::vector<float>& residual_variance,
                  const std::vector<float>& path_variance, const std::vector<float>& means, uint32_t width,
                  uint32_t height) {
    const size_t pixels = size_t(width) * height;
    if (paths_only.size() != pixels || residual_variance.size() != pixels || path_variance.size() != pixels ||
        means.size() != pixels)
        throw std::invalid_argument("ic_hand_over: the per-pixel arrays differ in size");
    std::vector<double> residual(pixels, 0.0), paths(pixels, 0.0);
    for (size_t i = 0; i < pixels; ++i) {
        if (paths_only[i] || !(residual_variance[i] >= 0) || !(path_variance[i] >= 0)) continue;
        const double w = 1.0 / (double(means[i]) * means[i] + 1e-3);
        residual[i] = w * residual_variance[i];
        paths[i] = w * path_variance[i];
    }
    const WindowSums residual_sums(residual, width, height), path_sums(paths, width, height);
    for (uint32_t y = 0; y < height; ++y)
        for (uint32_t x = 0; x < width; ++x) {
            const size_t i = size_t(y) * width + x;
            const double p = path_sums(x, y);
            if (!(residual_variance[i] >= 0) || !(p > 0)) continue;  // unknown: not yet
            if (residual_sums(x, y) < IC_HANDOVER_SHARE * p) paths_only[i] = 1;
        }
}

IrradianceCache::IrradianceCache(Context& ctx)
    : ctx_(ctx), paths_only_buffer_(ctx, 16, kStorageUsage), reuse_buffer_(ctx, 16, kStorageUsage) {
    setup(IcParams{}, SceneInfo{}, 0);
}

void IrradianceCache::configure(const RenderParams& params, const TechniqueSetup& config, bool needed) {
    IcParams cache = params.ic;
    cache.enabled = params.ic.enabled || needed;
    cache.shade = params.ic.enabled;
    needed_ = needed;
    width_ = config.width;
    pixels_ = uint64_t(config.width) * config.height;
    // Consistent mode's handover flags, per pixel (a placeholder while the cache is off).
    paths_only_.assign(cache.enabled ? pixels_ : 0, 0u);
    const size_t flag_bytes = std::max<size_t>(16, paths_only_.size() * sizeof(uint32_t));
    if (paths_only_buffer_.size() != flag_bytes) {
        paths_only_buffer_ = Buffer();
        paths_only_buffer_ = Buffer(ctx_, flag_bytes, kStorageUsage);
    }
    // The pixels' reuse records (48 B each), where paths combine with the cache.
    const bool combine = params.ic.enabled && params.ic.mode == IC_MODE_CONSISTENT;
    const size_t reuse_bytes = combine ? size_t(pixels_) * sizeof(IcReuseRecord) : 16;
    if (reuse_buffer_.size() != reuse_bytes) {
        reuse_buffer_ = Buffer();
        reuse_buffer_ = Buffer(ctx_, reuse_bytes, kStorageUsage);
        reuse_buffer_.fill_zero();  // stamp 0: no record (reuse_stamp_ starts at 1)
    }
    samples_per_frame_ = std::max(1u, params.samples_per_frame);
    const bool batched = cache.shade && cache.mode == IC_MODE_CONSISTENT;
    setup(cache, config.scene.info, pixels_ * samples_per_frame_ * (batched ? kMaxStepFrames : 1));
}

const std::vector<uint32_t>* IrradianceCache::raygen(uint32_t program) const {
    return program == PROGRAM_IC_HEMISPHERE ? &shader_ic_hemisphere() : nullptr;
}

// ic_finish.comp's pipeline: one per device, shared by every session, kept for the process
// (like the ray-tracing pipelines, session.cpp).
static ComputePipeline& finish_pipeline(TechniqueHost& host) {
    static std::mutex mutex;
    static auto& pipelines = *new std::map<Context*, std::unique_ptr<ComputePipeline>>();
    std::lock_guard<std::mutex> lock(mutex);
    auto& p = pipelines[&host.context()];
    if (!p)
        p = std::make_unique<ComputePipeline>(host.context(), host.descriptors().layout(), uint32_t(sizeof(FrameParams)),
                                              shader_ic_finish());
    return *p;
}

void IrradianceCache::compile(TechniqueHost& host) {
    if (!enabled()) return;
    host.host_pipeline(PROGRAM_CAMERA);
    host.host_pipeline(PROGRAM_IC_HEMISPHERE);
    finish_pipeline(host);
}

// Prepare frames are numbered from 2^31 (FrameParams.frame): their random streams are apart
// from the render frames'.
void IrradianceCache::begin_host_frame(FrameParams& frame) const {
    frame.frame = 0x80000000u + prepared_frames_;
    frame.mode = FRAME_IC_PREPARE;
}

void IrradianceCache::end_host_frame(TechniqueHost& host, const FrameParams& frame, double) {
    make_entries(host, frame, pixels_, 1, true);
}

bool IrradianceCache::steps_after_frame(uint64_t samples) const {
    // Built for ADRRS alone (no shade), the cache is done once prepared: render frames queue
    // no requests (their pipelines lack TECH_IC), and ADRRS' adjoint grid is remade only when
    // the entries grow (Adrrs::update_adjoint), which refreshes do not. Stepping after every
    // frame refreshed entries nothing read: up to kMaxRefreshes hemisphere jobs per frame.
    if (!enabled() || left_ || !params_.shade) return false;
    if (params_.mode != IC_MODE_CONSISTENT) return true;
    return samples >= next_snapshot_ || samples >= stepped_samples_ + uint64_t(step_frames_) * samples_per_frame_;
}

void IrradianceCache::after_frame(TechniqueHost& host, const FrameEnd& frame) {
    const uint64_t since = frame.samples > stepped_samples_ ? frame.samples - stepped_samples_ : 0;
    const uint32_t frames = uint32_t(std::max<uint64_t>(1, since / samples_per_frame_));
    make_entries(host, frame.frame, frame.paths, frames, false);
    stepped_samples_ = frame.samples;
    ++stats_.host_steps;
    if (!params_.shade || params_.mode != IC_MODE_CONSISTENT) return;
    // Each step doubles the wait for the next: the prepare frames left the cache covering
    // the view, and a new view starts over from one frame (clear_snapshots).
    step_frames_ = std::min(kMaxStepFrames, 2 * step_frames_);
    if (frame.samples >= next_snapshot_) take_snapshot(host, frame.samples);
}

void IrradianceCache::take_snapshot(TechniqueHost& host, uint64_t samples) {
    std::vector<vec4> sums = host.film_sums(PASS_IC_RESIDUAL);
    std::vector<vec4> paths = host.film_sums(PASS_COMBINED);  // w: the pixels' sample counts
    if (sums.empty() || paths.size() != sums.size() || paths_only_.size() != sums.size()) return;
    for (size_t i = 0; i < sums.size(); ++i) sums[i].w = paths[i].w;
    if (snapshot_.size() == sums.size()) {
        sequence_variance_ = ic_sequence_variance(snapshot_, sums);
        std::vector<float> means(paths.size());
        for (size_t i = 0; i < paths.size(); ++i)
            means[i] = paths[i].w > 0 ? (paths[i].x + paths[i].y + paths[i].z) / (3.0f * paths[i].w) : 0.0f;
        const size_t before = std::count(paths_only_.begin(), paths_only_.end(), 1u);
        ic_hand_over(paths_only_, sequence_variance_, ic_sequence_variance(snapshot_paths_, paths), means,
                     width_, uint32_t(paths.size() / width_));
        stats_.paths_only = std::count(paths_only_.begin(), paths_only_.end(), 1u);
        if (stats_.paths_only != before)
            paths_only_buffer_.upload(paths_only_.data(), paths_only_.size() * sizeof(uint32_t));
        left_ = !needed_ && 4 * stats_.paths_only >= 3 * paths_only_.size();
        stats_.left = left_;
    }
    snapshot_ = std::move(sums);
    snapshot_paths_ = std::move(paths);
    while (next_snapshot_ <= samples) next_snapshot_ *= 2;
}

void IrradianceCache::clear_snapshots() {
    ++reuse_stamp_;  // a new view (or none of the old entries): the pixels query afresh
    snapshot_.clear();
    snapshot_paths_.clear();
    sequence_variance_.clear();
    next_snapshot_ = kFirstSnapshot;
    stepped_samples_ = 0;  // the film starts over: so do the host steps' waits
    step_frames_ = 1;
    left_ = false;
    stats_.left = 0;
    std::fill(paths_only_.begin(), paths_only_.end(), 0u);
    stats_.paths_only = 0;
    if (paths_only_buffer_.valid()) paths_only_buffer_.fill_zero();
}

uint32_t IrradianceCache::film_passes(const RenderParams& params) const {
    return params.ic.enabled && params.ic.mode == IC_MODE_CONSISTENT ? 1u << PASS_IC_RESIDUAL : 0u;
}

void IrradianceCache::resolve_combined(std::vector<float>& rgba, const std::vector<vec4>& combined, uint32_t width,
                                       uint32_t height,
                                       const std::function<std::vector<vec4>(uint32_t)>& sums) const {
    if (!enabled() || !params_.shade || params_.mode != IC_MODE_CONSISTENT) return;
    const std::vector<vec4> residual = sums(PASS_IC_RESIDUAL);
    if (residual.empty()) return;
    std::vector<float> samples(combined.size());
    for (size_t i = 0; i < combined.size(); ++i) samples[i] = combined[i].w;
    ic_combine(rgba, samples, residual, width, height,
               sequence_variance_.size() == samples.size() ? sequence_variance_ : std::vector<float>{},
               paths_only_.size() == samples.size() ? paths_only_ : std::vector<uint32_t>{});
}

void IrradianceCache::stats(StatList& out) const {
    out.insert(out.end(), {{"ic_entries", uint64_t(stats_.entries)},
                           {"ic_capacity", uint64_t(stats_.capacity)},
                           {"ic_dropped", stats_.dropped},
                           {"ic_deferred", stats_.deferred},
                           {"ic_merged", stats_.merged},
                           {"ic_paths_only", stats_.paths_only},
                           {"ic_host_steps", stats_.host_steps},
                           {"ic_left", stats_.left},
                           {"ic_jobs", stats_.jobs},
                           {"ic_job_rays", stats_.job_rays},
                           {"ic_job_milliseconds", stats_.job_milliseconds},
                           {"ic_build_milliseconds", stats_.build_milliseconds}});
}

void IrradianceCache::setup(const IcParams& params, const SceneInfo& scene, uint64_t paths_per_step) {
    params_ = params;
    params_.prepare_create_prob =
        float(std::min(1.0, std::max<double>(params.create_prob, kPrepareRequests / double(std::max<uint64_t>(pixels_, 1)))));
    // Consistent mode's entries start cheap and refreshes refine them (IC_THETA_CONSISTENT);
    // the thesis' mode, and the cache ADRRS builds alone for its adjoint, keep the thesis' strata.
    const bool refined = params.mode == IC_MODE_CONSISTENT && params.shade;
    params_.theta = refined ? IC_THETA_CONSISTENT : IC_THETA;
    params_.phi = refined ? IC_PHI_CONSISTENT : IC_PHI;
    params_.queue_capacity = enabled() ? std::max(queue_capacity(params.create_prob, paths_per_step),
                                                  queue_capacity(params_.prepare_create_prob, pixels_))
                                       : 1;
    if (queue_.size() < 16 + size_t(params_.queue_capacity) * sizeof(IcRequest))
        queue_ = Buffer(ctx_, 16 + size_t(params_.queue_capacity) * sizeof(IcRequest), kStorageUsage);
    scene_ = scene;
    // Disabled: one empty slot keeps every binding valid (the shaders never query it).
    const uint32_t slots = enabled() ? params_.capacity : 1;
    if (slots != allocated_) {
        allocated_ = slots;
        allocate();
    }
    // The creation jobs' buffers (6 MiB) only while the cache is on; off, 16-byte
    // placeholders keep the bindings valid (bind() follows configure()).
    const size_t jobs = enabled() ? kJobsPerDispatch : 0;
    if (!jobs_.valid() || jobs_.size() != std::max<size_t>(jobs * sizeof(IcJob), 16)) {
        jobs_ = Buffer();
        samples_ = Buffer();
        jobs_ = Buffer(ctx_, jobs * sizeof(IcJob), kStorageUsage);
        samples_ = Buffer(ctx_, jobs * IC_STRATA * sizeof(IcSample), kStorageUsage);
    }
    reset();
}

void IrradianceCache::allocate() {
    entries_ = Buffer();  // released first: at a large capacity old and new need not fit side by side
    entries_ = Buffer(ctx_, size_t(allocated_) * sizeof(IcEntry), kStorageUsage);
}

void IrradianceCache::record_frame_start(VkCommandBuffer cmd, const Technique* host_frame) const {
    if (!enabled() || (host_frame && host_frame != this) || (!host_frame && !queue_read_)) return;
    queue_.record_fill_zero(cmd, 16);
    queue_read_ = false;
}

void IrradianceCache::reset() {
    clear_snapshots();
    count_ = update_cursor_ = prepared_frames_ = 0;
    frame_counter_ = 0;
    queue_read_ = true;
    stats_ = {};
    stats_.capacity = enabled() ? params_.capacity : 0;
    if (!enabled() && grid_starts_.valid()) return;  // off: the empty placeholders never change
    entries_.fill_zero();
    queue_.fill_zero();
    build_grid(nullptr, nullptr);  // empty (configure binds it)
}

// Every level's cells of side grid_cell 2^l; an entry goes to the finest level whose side holds
// its sphere's diameter, so it overlaps at most 2 cells along each axis. An entry's cells that
// hash to one bucket list it once (a query would count it twice). Each level's table: a power
// of two of buckets, at least twice its listings, so most lists hold one cell's entries.
IcGrid ic_grid(const std::vector<IcEntry>& entries, float accuracy, float min_radius) {
    IcGrid grid;
    grid.cell = 2.0f * accuracy * min_radius;
    struct Listing {
        uint32_t level = 0;
        int lo[3] = {0, 0, 0}, hi[3] = {-1, -1, -1};  // inclusive cell ranges (empty: none)
    };
    std::vector<Listing> listings(entries.size());
    size_t listed[IC_GRID_LEVELS] = {};
    for (size_t i = 0; i < entries.size(); ++i) {
        const IcEntry& e = entries[i];
        const float r = accuracy * e.radius * 1.0001f;  // a hair wider: rounding never hides an entry
        if (!(r > 0) || !(grid.cell > 0)) continue;
        Listing& l = listings[i];
        while (l.level + 1 < IC_GRID_LEVELS && grid.cell * float(1u << l.level) < 2.0f * r) ++l.level;
        const float side = grid.cell * float(1u << l.level);  // as ic_lookup computes it
        const float p[3] = {e.position.x, e.position.y, e.position.z};
        size_t cells = 1;
        for (int c = 0; c < 3; ++c) {
            l.lo[c] = int(std::floor((p[c] - r) / side));
            l.hi[c] = int(std::floor((p[c] + r) / side));
            cells *= size_t(l.hi[c] - l.lo[c] + 1);
        }
        listed[l.level] += cells;
        grid.levels |= 1u << l.level;
    }
    // The header: each level's first bucket and bucket count - 1.
    grid.starts.assign(IC_GRID_HEADER, 0);
    uint32_t buckets = 0;
    for (uint32_t level = 0; level < IC_GRID_LEVELS; ++level) {
        uint32_t size = 0;
        if (listed[level]) for (size = 16; size < 2 * listed[level]; size *= 2) {}
        grid.starts[2 * level] = buckets;
        grid.starts[2 * level + 1] = size ? size - 1 : 0;
        buckets += size;
    }
    // Each entry's distinct buckets as (bucket, slot) pairs in slot order, then a counting sort
    // by bucket.
    std::vector<std::pair<uint32_t, uint32_t>> listed_in;
    std::vector<uint32_t> own;
    for (size_t i = 0; i < listings.size(); ++i) {
        const Listing& l = listings[i];
        own.clear();
        const uint32_t base = grid.starts[2 * l.level], mask = grid.starts[2 * l.level + 1];
        for (int z = l.lo[2]; z <= l.hi[2]; ++z)
            for (int y = l.lo[1]; y <= l.hi[1]; ++y)
                for (int x = l.lo[0]; x <= l.hi[0]; ++x) own.push_back(base + ic_grid_bucket(x, y, z, mask));
        std::sort(own.begin(), own.end());
        own.erase(std::unique(own.begin(), own.end()), own.end());
        for (uint32_t bucket : own) listed_in.push_back({bucket, uint32_t(i)});
    }
    std::vector<uint32_t> count(size_t(buckets) + 1, 0);
    for (const auto& [bucket, slot] : listed_in) ++count[bucket + 1];
    for (uint32_t bucket = 0; bucket < buckets; ++bucket) count[bucket + 1] += count[bucket];
    grid.starts.insert(grid.starts.end(), count.begin(), count.end());
    grid.candidates.resize(listed_in.size());
    for (const auto& [bucket, slot] : listed_in) {
        const IcEntry& e = entries[slot];
        grid.candidates[count[bucket]++] = {e.position, accuracy * e.radius, slot};  // reach as ic_lookup tests it
    }
    return grid;
}

void IrradianceCache::build_grid(TechniqueHost* host, DescriptorSet* set) {
    auto start = std::chrono::steady_clock::now();
    const IcGrid grid = ic_grid(download_entries(), params_.accuracy, params_.min_radius);
    params_.grid_cell = grid.cell;
    params_.grid_levels = grid.levels;
    // Buffers grow (by doubling) and are kept; a new one is bound again.
    const auto store = [&](Buffer& buffer, const auto& data, uint32_t binding) {
        const size_t bytes = std::max<size_t>(16, data.size() * sizeof(data[0]));
        if (!buffer.valid() || buffer.size() < bytes) {
            const size_t size = buffer.valid() ? std::max(bytes, 2 * buffer.size()) : bytes;
            buffer = Buffer();
            buffer = Buffer(ctx_, size, kStorageUsage);
            if (set) set->bind_buffer(binding, buffer);
        }
        if (!data.empty()) buffer.upload(data.data(), bytes);
    };
    store(grid_starts_, grid.starts, BINDING_IC_GRID);
    store(grid_candidates_, grid.candidates, BINDING_IC_GRID_ENTRIES);
    if (host) host->upload_technique_params();
    grid_count_ = count_;
    stats_.build_milliseconds += ms_since(start);
}

void IrradianceCache::bind(DescriptorSet& set) const {
    set.bind_buffer(BINDING_IC_GRID, grid_starts_);
    set.bind_buffer(BINDING_IC_ENTRIES, entries_);
    set.bind_buffer(BINDING_IC_GRID_ENTRIES, grid_candidates_);
    set.bind_buffer(BINDING_IC_QUEUE, queue_);
    set.bind_buffer(BINDING_IC_JOBS, jobs_);
    set.bind_buffer(BINDING_IC_SAMPLES, samples_);
    set.bind_buffer(BINDING_IC_PATHS_ONLY, paths_only_buffer_);
    set.bind_buffer(BINDING_IC_REUSE, reuse_buffer_);
}

std::vector<IcEntry> IrradianceCache::download_entries() const {
    std::vector<IcEntry> entries(count_);
    if (count_) entries_.download(entries.data(), entries.size() * sizeof(IcEntry));
    return entries;
}

void IrradianceCache::make_entries(TechniqueHost& host, FrameParams frame, uint64_t paths, uint32_t frames,
                                   bool prepare) {
    assert(enabled());
    const RayTracingPipeline& hemisphere = host.host_pipeline(PROGRAM_IC_HEMISPHERE);
    const ComputePipeline& finish = finish_pipeline(host);
    DescriptorSet& set = host.descriptors();
    ++frame_counter_;
    ++reuse_stamp_;  // the entries change: no pixel reuses a query of the old ones
    if (prepare) ++prepared_frames_;

    // The frame's creation requests, in a fixed order (the queue's is the threads'). The
    // queue is cleared on the device when the next frame starts (record_frame_start).
    uint32_t header[4] = {};
    queue_.download(header, sizeof(header));
    const uint32_t queued = header[0], uncovered = header[1];
    const uint32_t n = std::min(queued, params_.queue_capacity);
    stats_.deferred += queued - n;
    std::vector<IcRequest> requests(n);
    if (n) queue_.download(requests.data(), n * sizeof(IcRequest), 16);
    queue_read_ = true;
    // Covered enough: the thesis mode's paths end at entries, so it waits for 98% of them; the
    // consistent mode's image is right without entries and its render frames keep asking, so
    // it starts at 90%.
    const uint64_t paths_per_uncovered = params_.mode == IC_MODE_CONSISTENT && params_.shade ? 10 : 50;
    if (prepare && uint64_t(uncovered) * paths_per_uncovered < paths) prepared_frames_ = params_.prepare_frames;
    std::sort(requests.begin(), requests.end(), [](const IcRequest& a, const IcRequest& b) {
        return std::tie(a.pixel, a.sample_index, a.position.x, a.position.y, a.position.z) <
               std::tie(b.pixel, b.sample_index, b.position.x, b.position.y, b.position.z);
    });

    std::vector<IcJob> jobs;
    const uint32_t existing = count_;
    // Requests of one frame cluster where the cache has a hole. One whose point lies within
    // 4 a R_min of an accepted one facing the same way would be covered by that entry (R >=
    // R_min): it is merged into it rather than computed again.
    const float merge_distance = 4.0f * params_.accuracy * params_.min_radius;
    std::unordered_map<uint64_t, std::vector<uint32_t>> grid;
    auto cell = [&](vec3 p, int dx, int dy, int dz) {
        auto c = [&](float v, int d) { return uint64_t(int64_t(std::floor(v / merge_distance)) + d) & 0x1fffff; };
        return c(p.x, dx) | c(p.y, dy) << 21 | c(p.z, dz) << 42;
    };
    for (const IcRequest& r : requests) {
        bool covered = false;
        for (int d = 0; d < 27 && !covered; ++d) {
            auto it = grid.find(cell(r.position, d % 3 - 1, d / 3 % 3 - 1, d / 9 - 1));
            if (it == grid.end()) continue;
            for (uint32_t j : it->second) {
                const IcJob& a = jobs[j];
                vec3 v{r.position.x - a.position.x, r.position.y - a.position.y, r.position.z - a.position.z};
                float n = r.normal.x * a.normal.x + r.normal.y * a.normal.y + r.normal.z * a.normal.z;
                if (v.x * v.x + v.y * v.y + v.z * v.z < merge_distance * merge_distance && n > 0.9f) covered = true;
            }
        }
        if (covered) {
            ++stats_.merged;
            continue;
        }
        if (count_ >= params_.capacity) {  // full: no write past the end
            ++stats_.dropped;
            continue;
        }
        grid[cell(r.position, 0, 0, 0)].push_back(uint32_t(jobs.size()));
        jobs.push_back({r.position, count_++, r.normal, IC_JOB_CREATE});
    }
    // Refreshes (thesis 4.4): each path refreshes an entry with probability update_prob; the
    // entries take turns. Binomially many, from a generator seeded by the seed and frame.
    if (!prepare && existing && params_.update_prob > 0) {
        std::mt19937_64 rng((uint64_t(frame.seed) << 32) ^ (frame_counter_ * 0x9e3779b97f4a7c15ull));
        std::binomial_distribution<uint64_t> refreshes(paths * frames, params_.update_prob);
        const uint64_t k = std::min<uint64_t>(refreshes(rng), uint64_t(kMaxRefreshes) * frames);
        for (uint64_t i = 0; i < k; ++i)
            jobs.push_back({vec3{0, 0, 0}, update_cursor_++ % existing, vec3{0, 0, 1}, IC_JOB_UPDATE});
    }

    auto start = std::chrono::steady_clock::now();
    for (size_t first = 0; first < jobs.size(); first += kJobsPerDispatch) {
        frame.ic_job_count = uint32_t(std::min<size_t>(kJobsPerDispatch, jobs.size() - first));
        jobs_.upload(jobs.data() + first, frame.ic_job_count * sizeof(IcJob));
        ctx_.submit_and_wait([&](VkCommandBuffer cmd) {
            VkMemoryBarrier b{VK_STRUCTURE_TYPE_MEMORY_BARRIER};
            b.srcAccessMask = VK_ACCESS_SHADER_WRITE_BIT | VK_ACCESS_HOST_WRITE_BIT | VK_ACCESS_TRANSFER_WRITE_BIT;
            b.dstAccessMask = VK_ACCESS_SHADER_READ_BIT | VK_ACCESS_SHADER_WRITE_BIT;
            vkCmdPipelineBarrier(cmd, VK_PIPELINE_STAGE_ALL_COMMANDS_BIT, VK_PIPELINE_STAGE_ALL_COMMANDS_BIT, 0, 1, &b,
                                 0, nullptr, 0, nullptr);
            hemisphere.trace(cmd, set.set(), &frame, sizeof(frame), params_.theta * params_.phi, frame.ic_job_count);
            vkCmdPipelineBarrier(cmd, VK_PIPELINE_STAGE_ALL_COMMANDS_BIT, VK_PIPELINE_STAGE_ALL_COMMANDS_BIT, 0, 1, &b,
                                 0, nullptr, 0, nullptr);
            finish.dispatch(cmd, set.set(), &frame, sizeof(frame), (frame.ic_job_count + 63) / 64);
            vkCmdPipelineBarrier(cmd, VK_PIPELINE_STAGE_ALL_COMMANDS_BIT, VK_PIPELINE_STAGE_ALL_COMMANDS_BIT, 0, 1, &b,
                                 0, nullptr, 0, nullptr);
        });
    }
    if (!jobs.empty()) {
        stats_.job_milliseconds += ms_since(start);
        stats_.jobs += jobs.size();
        stats_.job_rays += jobs.size() * params_.theta * params_.phi;
    }
    stats_.entries = count_;

    if (count_ != grid_count_) build_grid(&host, &set);  // new entries reach the lookup grid
}

}  // namespace px
