#include "techniques/guiding/device_fit.h"

#include "shaders_embedded.h"

#include <algorithm>
#include <map>
#include <mutex>

namespace px::guiding {

namespace {

// One pipeline per device, kept for the process like the shared descriptor set layout.
ComputePipeline& fit_pipeline(Context& ctx, VkDescriptorSetLayout layout) {
    static std::mutex mutex;
    static auto& pipelines = *new std::map<Context*, std::unique_ptr<ComputePipeline>>();
    std::lock_guard<std::mutex> lock(mutex);
    auto& p = pipelines[&ctx];
    if (!p) p = std::make_unique<ComputePipeline>(ctx, layout, uint32_t(sizeof(GuidingFitPush)), shader_guiding_fit());
    return *p;
}

void barrier(VkCommandBuffer cmd) {
    VkMemoryBarrier b{VK_STRUCTURE_TYPE_MEMORY_BARRIER};
    b.srcAccessMask = VK_ACCESS_SHADER_WRITE_BIT | VK_ACCESS_HOST_WRITE_BIT | VK_ACCESS_TRANSFER_WRITE_BIT;
    b.dstAccessMask = VK_ACCESS_SHADER_READ_BIT | VK_ACCESS_SHADER_WRITE_BIT;
    vkCmdPipelineBarrier(cmd, VK_PIPELINE_STAGE_ALL_COMMANDS_BIT, VK_PIPELINE_STAGE_ALL_COMMANDS_BIT, 0, 1, &b, 0,
                         nullptr, 0, nullptr);
}

}  // namespace

DeviceFit::DeviceFit(Context& ctx, uint32_t regions, const FitOptions& o, bool parallax, uint32_t min_samples)
    : ctx_(ctx), regions_(regions) {
    validate_fit_options(o);
    if (regions < 1 || regions > (1u << 22)) throw std::invalid_argument("device fit: regions must be in [1, 2^22]");
    if (min_samples < 1 || min_samples > (1u << 24)) throw std::invalid_argument("device fit: min_samples must be in [1, 2^24]");
    push_.min_samples = min_samples;
    push_.pending_capacity = std::max(min_samples, 2 * o.max_components + 1);
    push_.region_count = regions;
    push_.max_components = o.max_components;
    push_.initial_components = std::min(o.initial_components, o.max_components);
    push_.max_iterations = o.max_iterations;
    push_.kappa0 = float(o.kappa0);
    push_.kappa_max = float(o.kappa_max);
    push_.tolerance = float(o.tolerance);
    push_.weight_prior = float(o.weight_prior);
    push_.mean_cosine_prior = float(o.mean_cosine_prior);
    push_.mean_cosine_prior_strength = float(o.mean_cosine_prior_strength);
    push_.decay = float(o.decay);
    push_.split_merge = o.split_merge ? 1u : 0u;
    push_.split_threshold = float(o.split_threshold);
    push_.split_min_samples = float(o.split_min_samples);
    push_.merge_threshold = float(o.merge_threshold);
    push_.merge_min_samples = float(o.merge_min_samples);
    push_.parallax = parallax ? 1u : 0u;
    set_ = std::make_unique<DescriptorSet>(ctx_, GUIDING_FIT_BINDING_COUNT, std::vector<uint32_t>{});
    states_ = Buffer(ctx_, size_t(regions) * sizeof(GuidingFitRegion), kStorageUsage);
    lobes_state_ = Buffer(ctx_, size_t(regions) * GUIDING_MAX_COMPONENTS * sizeof(GuidingFitLobe), kStorageUsage);
    states_.fill_zero();
    lobes_state_.fill_zero();
    starts_ = Buffer(ctx_, (size_t(regions) + 2) * sizeof(uint32_t), kStorageUsage);
    starts_.fill_zero();
    pending_ = Buffer(ctx_, size_t(regions) * push_.pending_capacity * sizeof(GuidingSample), kStorageUsage);
    set_->bind_buffer(GUIDING_FIT_BINDING_PENDING, pending_);
    set_->bind_buffer(GUIDING_FIT_BINDING_STATE, states_);
    set_->bind_buffer(GUIDING_FIT_BINDING_STATE_LOBES, lobes_state_);
    set_->bind_buffer(GUIDING_FIT_BINDING_STARTS, starts_);
    ensure_capacity(1);
    fit_pipeline(ctx_, set_->layout());
}

void DeviceFit::ensure_capacity(uint32_t sample_count) {
    sample_count = std::max(sample_count, 1u);
    // Blocks of the counting sort: a count per (bin, block), at most ~4M of them.
    const uint64_t bins = uint64_t(regions_) + 1;
    uint32_t block = 256;
    while (bins * ((uint64_t(sample_count) + block - 1) / block) > (1ull << 22)) block *= 2;
    const uint32_t blocks = (sample_count + block - 1) / block;
    const size_t count_bytes = size_t(bins) * blocks * sizeof(uint32_t);
    if (!counts_.valid() || counts_.size() < count_bytes) {
        counts_ = Buffer(ctx_, count_bytes, kStorageUsage);
        set_->bind_buffer(GUIDING_FIT_BINDING_COUNTS, counts_);
    }
    if (sample_count > sorted_capacity_) {
        sorted_ = Buffer(ctx_, size_t(sample_count) * sizeof(uint32_t), kStorageUsage);
        set_->bind_buffer(GUIDING_FIT_BINDING_SORTED, sorted_);
        sorted_capacity_ = sample_count;
    }
    block_size_ = block;
    block_count_ = blocks;
}

void DeviceFit::bind(const Buffer& samples, const Buffer& regions, const Buffer& lobes) {
    if (regions.size() < size_t(regions_) * sizeof(GuidingRegion) ||
        lobes.size() < size_t(regions_) * GUIDING_MAX_COMPONENTS * sizeof(GuidingLobe))
        throw std::invalid_argument("device fit: the region or lobe buffer is smaller than the regions");
    set_->bind_buffer(GUIDING_FIT_BINDING_SAMPLES, samples);
    set_->bind_buffer(GUIDING_FIT_BINDING_REGIONS, regions);
    set_->bind_buffer(GUIDING_FIT_BINDING_LOBES, lobes);
    samples_bytes_ = samples.size();
}

void DeviceFit::record(VkCommandBuffer cmd, uint32_t sample_count) {
    if (size_t(sample_count) * sizeof(GuidingSample) > samples_bytes_)
        throw std::invalid_argument("device fit: more samples than the sample buffer holds");
    ensure_capacity(sample_count);
    ComputePipeline& p = fit_pipeline(ctx_, set_->layout());
    GuidingFitPush pc = push_;
    pc.sample_count = sample_count;
    pc.block_size = block_size_;
    pc.block_count = block_count_;
    const uint32_t block_groups = (block_count_ + GUIDING_FIT_GROUP - 1) / GUIDING_FIT_GROUP;
    barrier(cmd);
    pc.pass = GUIDING_FIT_PASS_COUNT;
    p.dispatch(cmd, set_->set(), &pc, sizeof(pc), block_groups);
    barrier(cmd);
    pc.pass = GUIDING_FIT_PASS_SCAN;
    p.dispatch(cmd, set_->set(), &pc, sizeof(pc), 1);
    barrier(cmd);
    pc.pass = GUIDING_FIT_PASS_SCATTER;
    p.dispatch(cmd, set_->set(), &pc, sizeof(pc), block_groups);
    barrier(cmd);
    pc.pass = GUIDING_FIT_PASS_EM;
    p.dispatch(cmd, set_->set(), &pc, sizeof(pc), regions_);
    barrier(cmd);
}

std::vector<GuidingFitRegion> DeviceFit::read_states() const {
    std::vector<GuidingFitRegion> out(regions_);
    states_.download(out.data(), out.size() * sizeof(GuidingFitRegion));
    return out;
}

std::vector<GuidingFitLobe> DeviceFit::read_lobes() const {
    std::vector<GuidingFitLobe> out(size_t(regions_) * GUIDING_MAX_COMPONENTS);
    lobes_state_.download(out.data(), out.size() * sizeof(GuidingFitLobe));
    return out;
}

std::vector<uint32_t> DeviceFit::read_starts() const {
    std::vector<uint32_t> out(size_t(regions_) + 2);
    starts_.download(out.data(), out.size() * sizeof(uint32_t));
    return out;
}

std::vector<uint32_t> DeviceFit::read_sorted(uint32_t sample_count) const {
    if (sample_count > sorted_capacity_) throw std::invalid_argument("device fit: more slots than were sorted");
    std::vector<uint32_t> out(sample_count);
    if (sample_count) sorted_.download(out.data(), out.size() * sizeof(uint32_t));
    return out;
}

Vmm DeviceFit::mixture(uint32_t r) const {
    if (r >= regions_) throw std::invalid_argument("device fit: no such region");
    GuidingFitRegion st;
    states_.download(&st, sizeof(st), size_t(r) * sizeof(GuidingFitRegion));
    GuidingFitLobe l[GUIDING_MAX_COMPONENTS];
    lobes_state_.download(l, sizeof(l), size_t(r) * GUIDING_MAX_COMPONENTS * sizeof(GuidingFitLobe));
    Vmm m;
    m.count = st.count;
    m.pivot = Vec3(st.position_mean.x, st.position_mean.y, st.position_mean.z);
    for (uint32_t k = 0; k < m.count; ++k) {
        m.mu[k] = Vec3(l[k].mu.x, l[k].mu.y, l[k].mu.z);
        m.kappa[k] = l[k].kappa;
        m.weight[k] = l[k].weight;
        m.distance[k] = l[k].distance > 0.0f ? double(l[k].distance) : kInfinity;
    }
    return m;
}

}  // namespace px::guiding
