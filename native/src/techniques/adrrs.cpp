#include "techniques/adrrs.h"


#include <algorithm>
#include <chrono>
#include <cmath>
#include <vector>

namespace px {

namespace {

constexpr uint64_t kMaxQueuedSplits = 1u << 21;  // split entries of the whole image (176 MiB)
constexpr int kBlurRadius = 3;                   // image estimate: two box passes of 7 pixels
constexpr uint32_t kGridCells = 48;              // adjoint grid cells along its longest axis
constexpr int kMaxSplatCells = 3;                // an entry reaches at most 3 cells each way

// One box-filter pass along rows (dx = 1) or columns of an rgb image; the edges average
// the pixels inside the image only.
void box_pass(std::vector<vec3>& image, uint32_t width, uint32_t height, bool along_rows) {
    std::vector<vec3> out(image.size());
    const uint32_t lines = along_rows ? height : width, length = along_rows ? width : height;
    for (uint32_t line = 0; line < lines; ++line) {
        auto at = [&](uint32_t i) -> vec3& { return image[along_rows ? size_t(line) * width + i : size_t(i) * width + line]; };
        for (uint32_t i = 0; i < length; ++i) {
            const uint32_t lo = i >= uint32_t(kBlurRadius) ? i - kBlurRadius : 0, hi = std::min(length - 1, i + kBlurRadius);
            vec3 sum{0, 0, 0};
            for (uint32_t j = lo; j <= hi; ++j) {
                sum.x += at(j).x;
                sum.y += at(j).y;
                sum.z += at(j).z;
            }
            const float inv = 1.0f / float(hi - lo + 1);
            out[along_rows ? size_t(line) * width + i : size_t(i) * width + line] = {sum.x * inv, sum.y * inv, sum.z * inv};
        }
    }
    image.swap(out);
}

}  // namespace

// ADRRS' settings (thesis 4.5; Vorba & Krivanek 2016) and passes.
const SettingTable& adrrs_table() {
    static const SettingTable table{"adrrs",
        {
            enum_setting("rrs", PX_FIELD(AdrrsParams, mode), RRS_OFF,
                         {{"off", "Off", "Russian roulette on the path throughput alone", RRS_OFF},
                          {"adrrs", "ADRRS",
                           "Adjoint-driven Russian roulette and splitting: end paths whose continuation matters "
                           "little and split those that matter much, judged by the irradiance cache and a pixel "
                           "estimate (Vorba & Krivanek 2016; thesis, sec. 4.5). Builds the irradiance cache for its "
                           "estimates even with the cache off", RRS_ADRRS},
                          {"ears", "EARS",
                           "Efficiency-aware Russian roulette and splitting: the factor that minimises variance x "
                           "cost, from the second moment and cost of paths learnt per region and the image's "
                           "variance (Rath et al. 2022)", RRS_EARS}},
                         "Russian Roulette & Splitting",
                         "How paths are ended or split at their vertices. Every choice is unbiased", "adrrs"),
            bool_setting("adrrs_splitting", PX_FIELD(AdrrsParams, splitting), true, "Splitting",
                         "Split paths whose weight lies above the window (else only roulette below it)", "adrrs"),
            float_setting("adrrs_window", PX_FIELD(AdrrsParams, window), 5.0, 1.0, 1e6, "Window Width",
                          "s: the weight window spans 2C/(1+s) to 2sC/(1+s) around the ideal weight C (Vorba & "
                          "Krivanek recommend 5)", "adrrs"),
            float_setting("adrrs_rr_min", PX_FIELD(AdrrsParams, rr_min), 0.1, 0.001, 1.0, "Min Survival",
                          "Lowest survival probability of Russian roulette below the window (against fireflies)",
                          "adrrs"),
            int_setting("adrrs_max_splits", PX_FIELD(AdrrsParams, max_splits), 10, 0, 64, "Max Splits",
                        "Most extra paths split off per pixel sample", "adrrs"),
            int_setting("adrrs_estimate_spp", PX_FIELD(AdrrsParams, estimate_spp), 4, 1, 65536, "Estimate Samples",
                        "Irradiance Cache: estimate frames (1 sample per pixel each); Image: samples before the "
                        "first estimate", "adrrs"),
            enum_setting("adrrs_estimate", PX_FIELD(AdrrsParams, estimate), ADRRS_ESTIMATE_IC,
                         {{"ic", "Irradiance Cache",
                           "Estimate frames after the cache's prepare frames: paths to the first non-specular hit, "
                           "lit by NEE and the cache (thesis 4.5)", ADRRS_ESTIMATE_IC},
                          {"image", "Image",
                           "The image rendered so far, blurred; refreshed each time the samples double (the "
                           "alternative the thesis names in 4.5)", ADRRS_ESTIMATE_IMAGE}},
                         "Estimate", "Where the pixel estimate comes from", "adrrs"),
            int_setting("rrs_grid", PX_FIELD(AdrrsParams, grid), 32, 2, 256, "Grid",
                        "EARS: cells of its statistics along the scene's longest axis (each also split by the "
                        "normal's direction); finer cells adapt better but need more paths to settle", "adrrs"),
            int_setting("rrs_min_records", PX_FIELD(AdrrsParams, min_records), 256, 1, 1 << 24, "Min Records",
                        "EARS: paths a cell must have recorded in a training iteration before its factors are "
                        "used (noisy factors cost more than they save)", "adrrs"),
            bool_setting("adrrs_ic_glossy", PX_FIELD(AdrrsParams, ic_glossy), true, "Cache on Glossy",
                         "The Irradiance Cache estimate reads the cache at glossy surfaces too (thesis, sec. 4.4)",
                         "adrrs"),
        },
        {
            {"adrrs_estimate", "ADRRS Estimate", 3, "RGB", "ADRRS: the pixel estimate its weight window is centred on",
             PASS_ADRRS_ESTIMATE, "rrs"},
            {"adrrs_splits", "ADRRS Splits", 1, "X", "ADRRS and EARS: extra paths split off per pixel sample",
             PASS_ADRRS_SPLITS, "rrs"},
            {"rrs_factor", "RRS Factor", 1, "X",
             "EARS: the mean roulette/splitting factor of the pixel's decisions (< 1 roulette, > 1 split)",
             PASS_RRS_FACTOR, "rrs", "", true},
            {"rrs_cost", "RRS Cost", 1, "X",
             "EARS: the learnt cost of a continuation at the pixel's first decision, relative to the image's "
             "cost per sample", PASS_RRS_COST, "rrs", "", true},
        }};
    return table;
}

Adrrs::Adrrs(Context& ctx, const IrradianceCache& cache) : ctx_(ctx), cache_(cache), ears_(ctx) {
    setup(AdrrsParams{}, SceneHost{}, 1, 1, 1);
}

void Adrrs::configure(const RenderParams& params, const TechniqueSetup& config, bool) {
    setup(params.adrrs, config.scene, config.width, config.height, params.samples_per_frame);
}

void Adrrs::write_params(TechniqueParams& params) const {
    params.adrrs = params_;
    ears_.write_params(params.adrrs);
}

void Adrrs::record_after_trace(const FrameParams& frame,
                               const std::function<void(const FrameParams&)>& retrace) const {
    if (!splits()) return;
    FrameParams splits = frame;
    splits.mode = FRAME_ADRRS_SPLITS;
    retrace(splits);
    splits.mode = FRAME_ADRRS_SPLIT_SUMS;
    retrace(splits);
}

// Estimate frames are numbered from 2^30 (FrameParams.frame): their random streams are apart
// from the render frames' and the cache's prepare frames'.
void Adrrs::begin_host_frame(FrameParams& frame) const {
    frame.frame = 0x40000000u + estimate_frames_;
    frame.mode = FRAME_ADRRS_ESTIMATE;
}

void Adrrs::sync(TechniqueHost& host, const Technique* stepped) {
    if (params_.mode != RRS_ADRRS || (stepped && stepped != &cache_) || !update_adjoint()) return;
    bind(host.descriptors());
    host.upload_technique_params();
}

void Adrrs::stats(StatList& out) const {
    out.insert(out.end(), {{"adrrs_estimate_frames", uint64_t(estimate_frames_)},
                           {"adrrs_image_refreshes", uint64_t(image_refreshes_)},
                           {"adrrs_adjoint_builds", uint64_t(adjoint_builds_)},
                           {"adrrs_adjoint_milliseconds", adjoint_milliseconds_}});
    ears_.stats(out);
}

void Adrrs::setup(const AdrrsParams& params, const SceneHost& scene, uint32_t width, uint32_t height,
                  uint32_t samples_per_frame) {
    params_ = params;
    if (ears()) params_.estimate = ADRRS_ESTIMATE_IMAGE;  // EARS' pixel estimate is the image's
    ears_.configure(ears(), scene, width, height, params_.grid, params_.min_records);
    width_ = width;
    height_ = height;
    // Off: one-element buffers keep every binding valid (the shaders never touch them).
    const uint64_t pixels = enabled() ? uint64_t(width) * height : 1;
    // Entries per pixel and dispatch: a frame's budget of copies (each entry holds one or
    // more), at most what kMaxQueuedSplits leaves per pixel (at least 2). Splits past a full
    // queue are not made: the decision comes before the split, so the estimator stays unbiased.
    const uint64_t wanted = uint64_t(params_.max_splits) * samples_per_frame;
    params_.slots = uint32_t(std::min<uint64_t>(wanted, std::max<uint64_t>(2, kMaxQueuedSplits / pixels)));
    const size_t estimate_bytes = size_t(pixels) * sizeof(vec4);
    const size_t queue_bytes = 16 + size_t(pixels) * 2 * sizeof(uint32_t);
    const size_t split_bytes = std::max<size_t>(1, size_t(pixels) * params_.slots) * sizeof(AdrrsSplit);
    if (estimate_.size() != estimate_bytes) estimate_ = Buffer(ctx_, estimate_bytes, kStorageUsage);
    if (queue_.size() != queue_bytes) queue_ = Buffer(ctx_, queue_bytes, kStorageUsage);
    if (splits_.size() != split_bytes) splits_ = Buffer(ctx_, split_bytes, kStorageUsage);
    if (!adjoint_.valid()) adjoint_ = Buffer(ctx_, sizeof(vec4), kStorageUsage);
    reset();
}

void Adrrs::reset() {
    estimate_.fill_zero();
    queue_.fill_zero();
    estimate_frames_ = 0;
    image_refreshes_ = 0;
    adjoint_entries_ = adjoint_builds_ = 0;
    adjoint_milliseconds_ = 0;
    params_.grid_cell = 0.0f;  // no adjoint until the cache has entries
    next_refresh_ = params_.estimate_spp;
    ears_.reset();
}

void Adrrs::bind(DescriptorSet& set) const {
    set.bind_buffer(BINDING_ADRRS_ESTIMATE, estimate_);
    set.bind_buffer(BINDING_ADRRS_QUEUE, queue_);
    set.bind_buffer(BINDING_ADRRS_SPLITS, splits_);
    set.bind_buffer(BINDING_ADRRS_ADJOINT, adjoint_);
    ears_.bind(set);
}

// The cache's entries averaged over a grid around them, per cell and per normal direction
// (the dominant signed axis): each entry reaches the cells within its harmonic-mean distance
// R (at least half a cell, at most kMaxSplatCells), weighted 1 / (1 + d/R) like Ward's weight.
bool Adrrs::update_adjoint() {
    // Remade when the cache has grown by an eighth since (a new entry changes little).
    if (!enabled() || cache_.count() == 0 || uint64_t(cache_.count()) * 8 < uint64_t(adjoint_entries_) * 9) return false;
    const auto start = std::chrono::steady_clock::now();
    const std::vector<IcEntry> entries = cache_.download_entries();
    adjoint_entries_ = uint32_t(entries.size());
    float lo[3] = {1e30f, 1e30f, 1e30f}, hi[3] = {-1e30f, -1e30f, -1e30f};
    for (const IcEntry& e : entries) {
        const float p[3] = {e.position.x, e.position.y, e.position.z};
        for (int a = 0; a < 3; ++a) lo[a] = std::min(lo[a], p[a] - e.radius), hi[a] = std::max(hi[a], p[a] + e.radius);
    }
    const float extent = std::max({hi[0] - lo[0], hi[1] - lo[1], hi[2] - lo[2], 1e-6f});
    const float cell = extent / float(kGridCells);
    uint32_t dims[3];
    for (int a = 0; a < 3; ++a) dims[a] = std::clamp(uint32_t(std::ceil((hi[a] - lo[a]) / cell)), 1u, kGridCells);
    std::vector<vec4> sums(size_t(dims[0]) * dims[1] * dims[2] * 6, vec4{0, 0, 0, 0});
    for (const IcEntry& e : entries) {
        const float p[3] = {e.position.x, e.position.y, e.position.z}, n[3] = {e.normal.x, e.normal.y, e.normal.z};
        const int axis = std::abs(n[0]) >= std::abs(n[1]) && std::abs(n[0]) >= std::abs(n[2]) ? 0 : std::abs(n[1]) >= std::abs(n[2]) ? 1 : 2;
        const uint32_t dir = 2 * axis + (n[axis] < 0 ? 1 : 0);
        const float reach = std::clamp(e.radius, 0.5f * cell, kMaxSplatCells * cell);
        int c0[3], c1[3];
        for (int a = 0; a < 3; ++a) {
            c0[a] = std::max(0, int(std::floor((p[a] - reach - lo[a]) / cell)));
            c1[a] = std::min(int(dims[a]) - 1, int(std::floor((p[a] + reach - lo[a]) / cell)));
        }
        for (int z = c0[2]; z <= c1[2]; ++z)
            for (int y = c0[1]; y <= c1[1]; ++y)
                for (int x = c0[0]; x <= c1[0]; ++x) {
                    const float d[3] = {lo[0] + (x + 0.5f) * cell - p[0], lo[1] + (y + 0.5f) * cell - p[1],
                                        lo[2] + (z + 0.5f) * cell - p[2]};
                    const float dist = std::sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2]);
                    if (dist > reach + 0.87f * cell) continue;  // the cell lies outside the entry's reach
                    const float w = 1.0f / (1.0f + dist / std::max(e.radius, 1e-6f));
                    vec4& s = sums[((size_t(z) * dims[1] + y) * dims[0] + x) * 6 + dir];
                    s.x += w * e.irradiance.x, s.y += w * e.irradiance.y, s.z += w * e.irradiance.z, s.w += w;
                }
    }
    for (vec4& s : sums)
        if (s.w > 0) s = {s.x / s.w, s.y / s.w, s.z / s.w, s.w};
    if (adjoint_.size() != sums.size() * sizeof(vec4)) adjoint_ = Buffer(ctx_, sums.size() * sizeof(vec4), kStorageUsage);
    adjoint_.upload(sums.data(), sums.size() * sizeof(vec4));
    params_.grid_min = {lo[0], lo[1], lo[2]};
    params_.grid_cell = entries.empty() ? 0.0f : cell;
    params_.grid_nx = dims[0], params_.grid_ny = dims[1], params_.grid_nz = dims[2];
    ++adjoint_builds_;
    adjoint_milliseconds_ += std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count();
    return true;
}

void Adrrs::record_before_trace(VkCommandBuffer cmd) const {
    if (enabled()) queue_.record_fill_zero(cmd, 16);
}

void Adrrs::after_frame(TechniqueHost& host, const FrameEnd& frame) {
    const Buffer& film = host.film();
    const uint64_t samples = frame.samples;
    if (!steps_after_frame(samples)) return;
    while (next_refresh_ <= samples) next_refresh_ *= 2;
    const size_t pixels = size_t(width_) * height_;
    std::vector<vec4> sums(pixels);
    film.download(sums.data(), pixels * sizeof(vec4), size_t(PASS_COMBINED) * pixels * sizeof(vec4));
    std::vector<vec3> image(pixels);
    for (size_t i = 0; i < pixels; ++i) {
        const float inv = sums[i].w > 0 ? 1.0f / sums[i].w : 0.0f;
        image[i] = {sums[i].x * inv, sums[i].y * inv, sums[i].z * inv};
    }
    // Two box passes each way: close to a Gaussian of sigma ~2.8 pixels.
    for (int pass = 0; pass < 2; ++pass) {
        box_pass(image, width_, height_, true);
        box_pass(image, width_, height_, false);
    }
    std::vector<vec4> estimate(pixels);
    std::vector<float> luminance(ears() ? pixels : 0);
    for (size_t i = 0; i < pixels; ++i) {
        estimate[i] = {image[i].x, image[i].y, image[i].z, 1.0f};
        if (ears()) luminance[i] = 0.2126f * image[i].x + 0.7152f * image[i].y + 0.0722f * image[i].z;
    }
    estimate_.upload(estimate.data(), pixels * sizeof(vec4));
    ++image_refreshes_;
    if (ears()) {
        ears_.end_iteration(luminance);
        host.upload_technique_params();
    }
}

}  // namespace px
