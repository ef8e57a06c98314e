#include "techniques/guiding/guiding.h"

#include "shaders_embedded.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstring>

namespace px {

namespace {

double ms_since(std::chrono::steady_clock::time_point start) {
    return std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count();
}

GuidingParams field_key(GuidingParams p) {
    p.enabled = 1;
    p.probe_x = p.probe_y = -1;  // visualisation only
    p.lobes_phase = -1.0f;
    p.record_stride = p.record_samples = 0;  // derived from the frame's size: the field does not depend on them
    return p;
}

}  // namespace

// Path guiding's settings (thesis 4.6; Ruppert, Herholz & Lensch 2020) and passes.
const SettingTable& guiding_table() {
    static const SettingTable table{"guiding",
        {
            bool_setting("guiding", PX_FIELD(GuidingParams, enabled), false, "Path Guiding",
                         "Sample directions from a von Mises-Fisher mixture of the incident light, learnt per region "
                         "of the scene from the paths traced so far, mixed with BSDF sampling (Ruppert, Herholz & "
                         "Lensch 2020; thesis, sec. 4.6). Unbiased", "guiding"),
            float_setting("guiding_prob", PX_FIELD(GuidingParams, prob), 0.5, 0.0, 1.0, "Guiding Probability",
                          "Probability of sampling the mixture rather than the BSDF at a guided vertex (one-sample "
                          "MIS of the two); with Adaptive Probability, where a region has not learnt its own yet",
                          "guiding"),
            bool_setting("guiding_adaptive_prob", PX_FIELD(GuidingParams, adaptive_prob), true, "Adaptive Probability",
                         "Each region learns its guiding probability from the training samples: the mix of mixture "
                         "and BSDF that best fits the light it receives, 0 (BSDF sampling alone, no mixture "
                         "evaluated) where guiding does not pay for itself", "guiding"),
            bool_setting("guiding_adaptive_nee", PX_FIELD(GuidingParams, adaptive_nee), true, "Adaptive NEE",
                         "With MIS, each region learns how often to take next event estimation: less where NEE "
                         "brings little of the light (a lamp behind glass), at least 1 in 10; MIS weights account "
                         "for it (CPU fit)", "guiding"),
            bool_setting("guiding_parallax", PX_FIELD(GuidingParams, parallax), true, "Parallax",
                         "Each lobe aims at the point its light came from, so one region's mixture points the right "
                         "way from anywhere in it (Ruppert et al. 2020)", "guiding"),
            int_setting("guiding_training_spp", PX_FIELD(GuidingParams, training_spp), 32, 0, 65536,
                        "Training Samples",
                        "The first samples per pixel (and at least 8 frames) train the mixtures; they count in the "
                        "image too. 0 = keep training for the whole render", "guiding"),
            int_setting("guiding_min_samples", PX_FIELD(GuidingParams, min_samples), 64, 1, 1 << 24, "Min Samples",
                        "A region fits its mixture once it has accumulated this many lit samples (across frames, so "
                        "rarely lit regions train too)", "guiding").in_group("Fitting"),
            int_setting("guiding_max_components", PX_FIELD(GuidingParams, max_components), 16, 1,
                        GUIDING_MAX_COMPONENTS, "Max Components", "Most lobes per region's mixture", "guiding")
                            .in_group("Fitting"),
            bool_setting("guiding_split_merge", PX_FIELD(GuidingParams, split_merge), true, "Split and Merge",
                         "Split lobes that fit their samples badly and merge lobes that say the same (Ruppert et al. "
                         "2020)", "guiding").in_group("Fitting"),
            int_setting("guiding_region_splits", PX_FIELD(GuidingParams, region_splits), 3, 0, 20, "Region Splits",
                        "The scene box is halved this many times along its longest axis: 2^n regions to start "
                        "with, split further as they gather light", "guiding").in_group("Regions"),
            int_setting("guiding_region_threshold", PX_FIELD(GuidingParams, region_threshold), 10000, 0, INT32_MAX,
                        "Region Threshold",
                        "A region that received this many lit samples (paths that found light) splits in two, both "
                        "halves keeping its mixture (0 = never)", "guiding").in_group("Regions"),
            int_setting("guiding_max_regions", PX_FIELD(GuidingParams, max_regions), 4096, 1, 1 << 22, "Max Regions",
                        "Adaptive refinement stops at this many regions (at least 2^Region Splits)", "guiding")
                            .in_group("Regions"),
            int_setting("guiding_probe_x", PX_FIELD(GuidingParams, probe_x), -1, -1, 16383, "Probe X",
                        "Pixel column whose first hit's mixture the Guiding Lobes pass plots (-1 = the image "
                        "centre)", "guiding").in_group("Visualisation"),
            int_setting("guiding_probe_y", PX_FIELD(GuidingParams, probe_y), -1, -1, 16383, "Probe Y",
                        "Pixel row (from the top) whose first hit's mixture the Guiding Lobes pass plots (-1 = the "
                        "image centre)", "guiding").in_group("Visualisation"),
            // The add-on's Animate Lobes derives it from the timeline: not a panel setting.
            float_setting("guiding_lobes_phase", PX_FIELD(GuidingParams, lobes_phase), -1.0, -1.0, 1.0,
                          "Lobes Phase",
                          "Guiding Lobes pass: the spheres sit at their regions' centres (-1) or, in [0, 1), move "
                          "through them (thesis fig. 4.20)", ""),
            enum_setting("guiding_fit", PX_FIELD(GuidingParams, fit), GUIDING_FIT_AUTO,
                         {{"auto", "Automatic", "Device on a GPU, CPU on lavapipe: where each was measured faster",
                           GUIDING_FIT_AUTO},
                          {"cpu", "CPU",
                           "Fit the mixtures on the CPU: the samples are read back after each training frame, kept "
                           "per region until there are enough, and regions refine", GUIDING_FIT_CPU},
                          {"device", "Device",
                           "Fit the mixtures in compute shaders where the samples are: no sample readback; regions "
                           "refine as with the CPU fit (a few bytes per region read back)", GUIDING_FIT_DEVICE}},
                         "Fit On", "Where the guiding mixtures are fitted", "guiding").in_group("Fitting"),
        },
        {
            {"guiding_regions", "Guiding Regions", 3, "RGB",
             "Path guiding: a colour per guiding region at the first hit", PASS_GUIDING_REGIONS, "guiding"},
            {"guiding_components", "Guiding Components", 1, "X",
             "Path guiding: active lobes of the first hit's region / Max Components", PASS_GUIDING_COMPONENTS,
             "guiding"},
            {"guiding_lobes", "Guiding Lobes", 3, "RGB",
             "Path guiding: a lat-long plot of the probe pixel's mixture (inset, bottom left) and a sphere per "
             "trained region coloured by its mixture's density", PASS_GUIDING_LOBES, "guiding"},
        }};
    return table;
}

Guiding::Guiding(Context& ctx) : ctx_(ctx), accel_(ctx, HIT_GROUP_GUIDING) {
    samples_ = Buffer(ctx_, sizeof(GuidingSample), kStorageUsage);
    build_placeholder();
}

Guiding::~Guiding() {
    if (fit_.valid()) fit_.wait();
}

// Guiding never switched on: one empty region keeps every binding valid (the shaders are
// specialised without guiding and never read it).
void Guiding::build_placeholder() {
    const GuidingRegion region{};
    regions_ = Buffer::with_data(ctx_, &region, sizeof(region), kStorageUsage);
    const GuidingLobe lobe{};
    lobes_ = Buffer::with_data(ctx_, &lobe, sizeof(lobe), kStorageUsage);
    upload_layout(guiding::RegionTree());
}

void Guiding::configure(const RenderParams& params, const TechniqueSetup& config, bool) {
    shows_passes_ = false;
    for (const PassInfo& p : guiding_table().passes) shows_passes_ = shows_passes_ || (config.passes >> p.index & 1u);
    shows_lobes_ = config.passes >> PASS_GUIDING_LOBES & 1u;
    setup(params.guiding, config.scene, config.scene_version, params.seed, config.width, config.height,
          params.samples_per_frame);
}

// The region query of the Guiding Lobes pass' spheres: a miss shader and a procedural hit
// group (intersection + closest-hit), in the pipelines that show that pass only.
void Guiding::add_shaders(uint32_t bits, PipelineShaders& s) const {
    if (!(bits & TECH_GUIDING_LOBES)) return;
    const uint32_t miss = s.add(VK_SHADER_STAGE_MISS_BIT_KHR, shader_guiding_query_miss());
    const uint32_t intersection = s.add(VK_SHADER_STAGE_INTERSECTION_BIT_KHR, shader_guiding_query_intersection());
    const uint32_t closest_hit = s.add(VK_SHADER_STAGE_CLOSEST_HIT_BIT_KHR, shader_guiding_query_closest_hit());
    s.misses[MISS_GUIDING_QUERY] = {VK_RAY_TRACING_SHADER_GROUP_TYPE_GENERAL_KHR, miss};
    s.hits[HIT_GROUP_GUIDING] = {VK_RAY_TRACING_SHADER_GROUP_TYPE_PROCEDURAL_HIT_GROUP_KHR, VK_SHADER_UNUSED_KHR,
                                 closest_hit, VK_SHADER_UNUSED_KHR, intersection};
}

void Guiding::after_frame(TechniqueHost& host, const FrameEnd& frame) {
    trained_spp_ += frame.frame.samples_per_frame;
    fit_frame(host.descriptors(), frame.milliseconds);
}

const guiding::GuidingField* Guiding::host_field() const {
    return enabled() && !device_fit_ ? field() : nullptr;
}

void Guiding::stats(StatList& out) const {
    const GuidingStats g = current_stats();
    out.insert(out.end(), {{"guiding_training_frames", uint64_t(g.training_frames)},
                           {"guiding_regions", uint64_t(g.regions)},
                           {"guiding_trained_regions", uint64_t(g.trained_regions)},
                           {"guiding_lobes", uint64_t(g.lobes)},
                           {"guiding_samples", g.samples_added},
                           {"guiding_samples_dropped", g.samples_dropped},
                           {"guiding_region_fits", g.region_fits},
                           {"guiding_refinements", uint64_t(g.refinements)},
                           {"guiding_fit_on", std::string(g.device_fit ? "device" : "cpu")},
                           {"guiding_pipeline", uint64_t(spec_bit(true) ? 1 : 0)},
                           {"guiding_frame_milliseconds", g.frame_milliseconds},
                           {"guiding_readback_milliseconds", g.readback_milliseconds},
                           {"guiding_fit_milliseconds", g.fit_milliseconds},
                           {"guiding_fit_wait_milliseconds", g.fit_wait_milliseconds},
                           {"guiding_upload_milliseconds", g.upload_milliseconds},
                           {"guiding_bytes_per_region", g.bytes_per_region},
                           {"guiding_sample_buffer_bytes", g.sample_buffer_bytes}});
}

void Guiding::setup(const GuidingParams& params, const SceneHost& scene, uint64_t scene_version, uint32_t seed,
                    uint32_t width, uint32_t height, uint32_t samples_per_frame) {
    params_ = params;
    const uint64_t pixels = uint64_t(width) * height;
    // Every path of a frame records while GUIDING_MAX_RECORD_PATHS allows (a GPU's frames
    // hold many samples per pixel: recording only the first starved the training); beyond
    // it the first sample of every stride-th pixel.
    params_.record_stride = uint32_t((pixels + GUIDING_MAX_RECORD_PATHS - 1) / GUIDING_MAX_RECORD_PATHS);
    params_.record_samples = params_.record_stride == 1
        ? uint32_t(std::clamp<uint64_t>(GUIDING_MAX_RECORD_PATHS / std::max<uint64_t>(pixels, 1), 1, std::max(samples_per_frame, 1u)))
        : 1u;
    if (!enabled()) return;  // a trained field stays (switching guiding back on reuses it)
    record_paths_ = params_.record_stride == 1 ? uint32_t(pixels * params_.record_samples)
                                               : uint32_t((pixels + params_.record_stride - 1) / params_.record_stride);
    const size_t sample_bytes = size_t(record_paths_) * GUIDING_PATH_VERTICES * sizeof(GuidingSample);
    if (samples_.size() != sample_bytes) {
        samples_ = Buffer(ctx_, sample_bytes, kStorageUsage);
        if (device_fit_) device_fit_->bind(samples_, regions_, lobes_);
    }
    const GuidingParams key = field_key(params_);
    finish_fit();  // the field may be replaced
    if (field_ && std::memcmp(&key, &field_key_, sizeof(key)) == 0 && scene_version == scene_version_ && seed == seed_)
        return;
    float lo[3], hi[3];
    scene_bounds(scene, lo, hi);
    field_ = std::make_unique<guiding::GuidingField>(params_, lo, hi, seed);
    device_fit_.reset();
    field_key_ = key;
    scene_version_ = scene_version;
    seed_ = seed;
    training_frames_ = 0;
    trained_spp_ = 0;
    stats_ = GuidingStats{};
    fitted_ = false;
    built_layout_ = ~0ull;
    upload(nullptr);
    // auto: the device fit on a GPU (no readback: 1.2-8.6 ms against 10-15 ms per training
    // frame on the H200), the host fit on lavapipe, where compute passes run slower than the
    // host's threads (bench/guiding_fit_cost.py).
    if (params_.fit == GUIDING_FIT_DEVICE || (params_.fit == GUIDING_FIT_AUTO && !ctx_.is_cpu())) {
        device_fit_ = std::make_unique<guiding::DeviceFit>(ctx_, uint32_t(field_->region_count()), field_->fit_options(),
                                                           params_.parallax != 0, params_.min_samples, params_.prob,
                                                           params_.adaptive_prob != 0);
        device_tree_ = field_->tree();
        device_fit_->bind(samples_, regions_, lobes_);
    }
}

void Guiding::bind(DescriptorSet& set) const {
    set.bind_tlas(BINDING_GUIDING_TLAS, accel_.tlas());
    set.bind_buffer(BINDING_GUIDING_REGIONS, regions_);
    set.bind_buffer(BINDING_GUIDING_LOBES, lobes_);
    set.bind_buffer(BINDING_GUIDING_ORDER, order_);
    set.bind_buffer(BINDING_GUIDING_NODES, nodes_);
    set.bind_buffer(BINDING_GUIDING_SAMPLES, samples_);
}

void Guiding::upload(DescriptorSet* set) {
    std::vector<GuidingRegion> regions;
    std::vector<GuidingLobe> lobes;
    field_->write_regions(regions);
    field_->write_lobes(lobes);
    const size_t n = regions.size();
    if (regions_.size() != n * sizeof(GuidingRegion)) {
        regions_ = Buffer(ctx_, n * sizeof(GuidingRegion), kStorageUsage);
        lobes_ = Buffer(ctx_, n * GUIDING_MAX_COMPONENTS * sizeof(GuidingLobe), kStorageUsage);
    }
    regions_.upload(regions.data(), n * sizeof(GuidingRegion));
    mixture_sampled_ = field_->guides();
    lobes_.upload(lobes.data(), lobes.size() * sizeof(GuidingLobe));
    if (field_->layout_version() != built_layout_) {
        upload_layout(field_->tree());
        built_layout_ = field_->layout_version();
    }
    if (set) bind(*set);
}

// The regions' boxes in the tree's depth-first order (lavapipe's BVH builder splits in input
// order; primitive i is region order[i]), the order and the tree's nodes: copied from one
// staging buffer and built into the kept BLAS/TLAS in one submit. The buffers grow by doubling.
void Guiding::upload_layout(const guiding::RegionTree& tree) {
    std::vector<float> boxes;
    std::vector<uint32_t> order;
    std::vector<GuidingNode> nodes;
    if (tree.size() == 0) {  // the placeholder: one region, a tiny box at the origin
        boxes = {0, 0, 0, 1e-3f, 1e-3f, 1e-3f};
        order = {0};
        nodes = {GuidingNode{0.0f, GUIDING_NODE_LEAF}};  // region 0
    } else {
        std::vector<float> unsorted;
        tree.write_aabbs(unsorted);
        order = tree.spatial_order();
        boxes.resize(order.size() * 6);
        for (size_t i = 0; i < order.size(); ++i) std::copy_n(&unsorted[size_t(order[i]) * 6], 6, &boxes[i * 6]);
        tree.write_nodes(nodes);
    }
    const size_t box_bytes = boxes.size() * sizeof(float), order_bytes = order.size() * sizeof(uint32_t),
                 node_bytes = nodes.size() * sizeof(GuidingNode);
    const auto grow = [&](Buffer& b, size_t bytes, VkBufferUsageFlags usage, bool host_visible = false) {
        if (b.valid() && b.size() >= bytes) return;
        b = Buffer();
        b = Buffer(ctx_, 2 * bytes, usage, host_visible);
    };
    grow(aabbs_, box_bytes, kStorageUsage | VK_BUFFER_USAGE_ACCELERATION_STRUCTURE_BUILD_INPUT_READ_ONLY_BIT_KHR);
    grow(order_, order_bytes, kStorageUsage);
    grow(nodes_, node_bytes, kStorageUsage);
    grow(layout_staging_, box_bytes + order_bytes + node_bytes, VK_BUFFER_USAGE_TRANSFER_SRC_BIT, true);
    layout_staging_.upload(boxes.data(), box_bytes);
    layout_staging_.upload(order.data(), order_bytes, box_bytes);
    layout_staging_.upload(nodes.data(), node_bytes, box_bytes + order_bytes);
    const uint32_t count = uint32_t(order.size());
    accel_.reserve(count);
    ctx_.submit_and_wait([&](VkCommandBuffer cmd) {
        const VkBufferCopy copies[3] = {{0, 0, box_bytes}, {box_bytes, 0, order_bytes},
                                        {box_bytes + order_bytes, 0, node_bytes}};
        vkCmdCopyBuffer(cmd, layout_staging_.handle(), aabbs_.handle(), 1, &copies[0]);
        vkCmdCopyBuffer(cmd, layout_staging_.handle(), order_.handle(), 1, &copies[1]);
        vkCmdCopyBuffer(cmd, layout_staging_.handle(), nodes_.handle(), 1, &copies[2]);
        accel_.record_build(cmd, aabbs_, count);  // its barrier orders the copies before the build
    });
}

void Guiding::record_frame_start(VkCommandBuffer cmd, const Technique* host_frame) const {
    if (!host_frame && records_render_frames()) samples_.record_fill_zero(cmd, VK_WHOLE_SIZE);
}

void Guiding::fit_frame(DescriptorSet& set, double frame_milliseconds) {
    if (!enabled() || !field_) return;
    auto start = std::chrono::steady_clock::now();
    if (device_fit_) {  // compute passes where the samples are; the frame loop waits for them
        const uint32_t slots = record_paths_ * GUIDING_PATH_VERTICES;
        ctx_.submit_and_wait([&](VkCommandBuffer cmd) { device_fit_->record(cmd, slots); });
        stats_.fit_milliseconds += ms_since(start);
        // Adaptive refinement, as the host fit's (after the fit): the regions split before the
        // next frame traces, which then looks samples up in the refined tree.
        const auto refine_start = std::chrono::steady_clock::now();
        const uint32_t split =
            device_fit_->refine(device_tree_, params_.region_threshold, params_.max_regions, regions_, lobes_);
        // refine() read the tally: the learnt probabilities' global rule (GuidingField::guiding_pays).
        mixture_sampled_ = device_fit_->mixture_sampled();
        if (split) {
            stats_.refinements += split;
            upload_layout(device_tree_);
            bind(set);
        }
        stats_.upload_milliseconds += ms_since(refine_start);
        stats_.frame_milliseconds += frame_milliseconds;
        ++training_frames_;
        return;
    }
    std::vector<GuidingSample> samples(size_t(record_paths_) * GUIDING_PATH_VERTICES);
    samples_.download(samples.data(), samples.size() * sizeof(GuidingSample));
    // Unfilled slots (pdf 0: paths with fewer guided vertices) are no samples.
    samples.erase(std::remove_if(samples.begin(), samples.end(), [](const GuidingSample& s) { return s.pdf == 0.0f; }),
                  samples.end());
    stats_.readback_milliseconds += ms_since(start);
    stats_.frame_milliseconds += frame_milliseconds;
    ++training_frames_;
    // The previous frame's fit (it ran while the GPU traced this frame) reaches the GPU; this
    // frame's samples go to a fit on a worker thread, overlapped with the next frame.
    const auto upload_fitted = [&] {
        finish_fit();
        if (!fitted_) return;
        const auto upload_start = std::chrono::steady_clock::now();
        upload(&set);
        stats_.upload_milliseconds += ms_since(upload_start);
        fitted_ = false;
    };
    upload_fitted();
    guiding::GuidingField* field = field_.get();
    fit_ = std::async(std::launch::async, [field, samples = std::move(samples)] {
        field->add_samples(samples.data(), samples.size());
        field->fit();
    });
    // The last recording frame: the rest of the image accumulates with the finished field.
    if (!records_render_frames()) upload_fitted();
}

void Guiding::finish_fit() const {
    if (!fit_.valid()) return;
    const auto start = std::chrono::steady_clock::now();
    fit_.get();  // rethrows the fit's exception
    stats_.fit_wait_milliseconds += ms_since(start);
    const guiding::FieldStats& fit = field_->stats();  // the last fit()'s figures
    stats_.fit_milliseconds += fit.fit_milliseconds;
    stats_.refinements += fit.refinements;
    fitted_ = fitted_ || fit.regions_fitted || fit.refinements;
}

const guiding::GuidingField* Guiding::field() const {
    finish_fit();
    return field_.get();
}

GuidingStats Guiding::current_stats() const {
    finish_fit();
    GuidingStats s = stats_;
    s.training_frames = training_frames_;
    if (!field_) return s;
    const guiding::FieldStats& f = field_->stats();
    s.regions = uint32_t(device_fit_ ? device_fit_->region_count() : field_->region_count());
    s.device_fit = bool(device_fit_);
    s.samples_added = f.samples_added;
    s.samples_dropped = f.samples_dropped;
    s.region_fits = f.region_fits;
    if (device_fit_) {  // a readback of the fit state, outside the frame loop
        s.samples_added = s.region_fits = 0;
        for (const GuidingFitRegion& r : device_fit_->read_states()) {
            s.trained_regions += r.count > 0;
            s.lobes += r.count;
            s.samples_added += r.samples;
            s.region_fits += r.fits;
        }
        s.samples_added -= device_fit_->inherited_samples();  // counted in both halves of a split
        s.region_fits -= device_fit_->inherited_fits();
    } else {
        for (uint32_t r = 0; r < s.regions; ++r) {
            const uint32_t k = field_->mixture(r).count;
            s.trained_regions += k > 0;
            s.lobes += k;
        }
    }
    s.bytes_per_region = guiding::GuidingField::gpu_bytes_per_region() + sizeof(uint32_t) +
                         accel_.blas_bytes() / std::max<size_t>(1, s.regions);
    s.sample_buffer_bytes = samples_.size();
    return s;
}

}  // namespace px
