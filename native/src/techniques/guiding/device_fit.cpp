#include "techniques/guiding/device_fit.h"
#include "techniques/guiding/selection.h"

#include "shaders_embedded.h"

#include <algorithm>
#include <cmath>
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

DeviceFit::DeviceFit(Context& ctx, uint32_t regions, const FitOptions& o, bool parallax, uint32_t min_samples,
                     float prob, bool adaptive_prob)
    : ctx_(ctx), regions_(regions), capacity_(regions) {
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
    push_.prob = prob;
    push_.adaptive_prob = adaptive_prob ? 1u : 0u;
    set_ = std::make_unique<DescriptorSet>(ctx_, GUIDING_FIT_BINDING_COUNT, std::vector<uint32_t>{});
    states_ = Buffer(ctx_, size_t(regions) * sizeof(GuidingFitRegion), kStorageUsage);
    lobes_state_ = Buffer(ctx_, size_t(regions) * GUIDING_MAX_COMPONENTS * sizeof(GuidingFitLobe), kStorageUsage);
    states_.fill_zero();
    lobes_state_.fill_zero();
    starts_ = Buffer(ctx_, (2 * size_t(regions) + 2) * sizeof(uint32_t), kStorageUsage);
    starts_.fill_zero();
    pending_ = Buffer(ctx_, size_t(regions) * push_.pending_capacity * sizeof(GuidingSample), kStorageUsage);
    set_->bind_buffer(GUIDING_FIT_BINDING_PENDING, pending_);
    set_->bind_buffer(GUIDING_FIT_BINDING_STATE, states_);
    set_->bind_buffer(GUIDING_FIT_BINDING_STATE_LOBES, lobes_state_);
    set_->bind_buffer(GUIDING_FIT_BINDING_STARTS, starts_);
    tally_ = Buffer(ctx_, size_t(regions) * sizeof(GuidingFitTally), kStorageUsage, true, true);
    tally_.fill_zero();
    set_->bind_buffer(GUIDING_FIT_BINDING_TALLY, tally_);
    splits_ = Buffer(ctx_, sizeof(GuidingFitSplit), kStorageUsage, true);
    set_->bind_buffer(GUIDING_FIT_BINDING_SPLITS, splits_);
    ensure_capacity(1);
    fit_pipeline(ctx_, set_->layout());
}

void DeviceFit::ensure_capacity(uint32_t sample_count) {
    sample_count = std::max(sample_count, 1u);
    // Blocks of the counting sort: a thread each in COUNT and SCATTER, which walk their block's
    // samples serially; a count per (bin, block), at most ~4M of them. Small blocks: more
    // threads, fewer serial steps (128 at 1M samples and 256 regions: 8k threads, 2.1M counts,
    // which the parallel scan and the fill handle at the memory's bandwidth).
    const uint64_t bins = 2 * uint64_t(regions_) + 1;  // lit and unlit per region, dropped
    uint32_t block = 128;
    while (bins * ((uint64_t(sample_count) + block - 1) / block) > (1ull << 22)) block *= 2;
    const uint32_t blocks = (sample_count + block - 1) / block;
    const size_t count_bytes = size_t(bins) * blocks * sizeof(uint32_t);
    if (!counts_.valid() || counts_.size() < count_bytes) {
        counts_ = Buffer(ctx_, count_bytes, kStorageUsage);
        set_->bind_buffer(GUIDING_FIT_BINDING_COUNTS, counts_);
    }
    // The scan's tiles: a partial sum each (SCAN_REDUCE), then a prefix (SCAN_PARTIALS).
    const uint32_t tiles = uint32_t((bins * blocks + GUIDING_FIT_SCAN_TILE - 1) / GUIDING_FIT_SCAN_TILE);
    if (!scan_partials_.valid() || scan_partials_.size() < size_t(tiles) * sizeof(uint32_t)) {
        scan_partials_ = Buffer(ctx_, size_t(tiles) * sizeof(uint32_t), kStorageUsage);
        set_->bind_buffer(GUIDING_FIT_BINDING_SCAN_PARTIALS, scan_partials_);
    }
    // POSITIONS' parts per region: about 1024 workgroups in all, each part of at least ~4096
    // samples on average (a workgroup's fixed cost), at most 64 parts.
    const uint64_t per_region = sample_count / regions_;
    const uint32_t parts = uint32_t(std::clamp<uint64_t>(std::min<uint64_t>(1024 / regions_, per_region / 4096), 1, 64));
    if (!position_parts_.valid() || position_parts_.size() < size_t(regions_) * parts * 4 * sizeof(float)) {
        position_parts_ = Buffer(ctx_, size_t(regions_) * parts * 4 * sizeof(float), kStorageUsage);
        set_->bind_buffer(GUIDING_FIT_BINDING_POSITION_PARTS, position_parts_);
    }
    position_parts_count_ = parts;
    if (sample_count > sorted_capacity_) {
        sorted_ = Buffer(ctx_, size_t(sample_count) * sizeof(uint32_t), kStorageUsage);
        set_->bind_buffer(GUIDING_FIT_BINDING_SORTED, sorted_);
        sorted_capacity_ = sample_count;
    }
    block_size_ = block;
    block_count_ = blocks;
    scan_tiles_ = tiles;
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
    // COUNT adds to zeroed counts (a fill runs at the memory's bandwidth).
    vkCmdFillBuffer(cmd, counts_.handle(), 0, VkDeviceSize(block_count_) * (2 * regions_ + 1) * sizeof(uint32_t), 0);
    barrier(cmd);
    pc.pass = GUIDING_FIT_PASS_COUNT;
    p.dispatch(cmd, set_->set(), &pc, sizeof(pc), block_groups);
    barrier(cmd);
    pc.pass = GUIDING_FIT_PASS_SCAN_REDUCE;
    p.dispatch(cmd, set_->set(), &pc, sizeof(pc), scan_tiles_);
    barrier(cmd);
    pc.pass = GUIDING_FIT_PASS_SCAN_PARTIALS;
    p.dispatch(cmd, set_->set(), &pc, sizeof(pc), 1);
    barrier(cmd);
    pc.pass = GUIDING_FIT_PASS_SCAN_APPLY;
    p.dispatch(cmd, set_->set(), &pc, sizeof(pc), scan_tiles_);
    barrier(cmd);
    pc.pass = GUIDING_FIT_PASS_SCATTER;
    p.dispatch(cmd, set_->set(), &pc, sizeof(pc), block_groups);
    barrier(cmd);
    pc.pass = GUIDING_FIT_PASS_POSITIONS;
    pc.position_parts = position_parts_count_;
    p.dispatch(cmd, set_->set(), &pc, sizeof(pc), regions_ * position_parts_count_);
    barrier(cmd);
    pc.pass = GUIDING_FIT_PASS_EM;
    p.dispatch(cmd, set_->set(), &pc, sizeof(pc), regions_);
    barrier(cmd);
    // The tally reaches the host (refine() reads it after the fence).
    VkMemoryBarrier h{VK_STRUCTURE_TYPE_MEMORY_BARRIER};
    h.srcAccessMask = VK_ACCESS_SHADER_WRITE_BIT;
    h.dstAccessMask = VK_ACCESS_HOST_READ_BIT;
    vkCmdPipelineBarrier(cmd, VK_PIPELINE_STAGE_COMPUTE_SHADER_BIT, VK_PIPELINE_STAGE_HOST_BIT, 0, 1, &h, 0, nullptr, 0,
                         nullptr);
}

uint32_t DeviceFit::refine(RegionTree& tree, uint32_t threshold, uint32_t max_regions, Buffer& regions,
                           Buffer& lobes) {
    if (tree.size() != regions_) throw std::invalid_argument("device fit: the region tree has other regions");
    const std::vector<GuidingFitTally>& tally = read_tally();
    if (threshold == 0 || regions_ >= max_regions) return 0;
    const double min_extent = 1e-6 * length(tree.root().extent());
    std::vector<GuidingFitSplit> splits;
    for (uint32_t r = 0; r < regions_ && regions_ + splits.size() < max_regions; ++r) {
        if (tally[r].received <= threshold) continue;  // 0: no mixture (its children would inherit none)
        const Aabb& b = tree.bounds(r);
        const int axis = b.longest_axis();
        if (b.extent()[axis] <= min_extent) continue;
        const uint32_t child = tree.split(r);
        splits.push_back({r, child, uint32_t(axis), float(tree.bounds(child).lo[axis])});
        inherited_samples_ += tally[r].samples;
        inherited_fits_ += tally[r].fits;
    }
    if (splits.empty()) return 0;
    const uint32_t count = regions_ + uint32_t(splits.size());
    const size_t split_bytes = splits.size() * sizeof(GuidingFitSplit);
    if (splits_.size() < split_bytes) {
        splits_ = Buffer(ctx_, split_bytes, kStorageUsage, true);
        set_->bind_buffer(GUIDING_FIT_BINDING_SPLITS, splits_);
    }
    splits_.upload(splits.data(), split_bytes);
    std::vector<Buffer> old;  // kept until the copies completed
    ctx_.submit_and_wait([&](VkCommandBuffer cmd) {
        // Grown with a copy: the fit's buffers to twice the regions (amortised), the records to fit.
        const auto grow = [&](Buffer& b, size_t bytes, bool host_visible = false) {
            if (b.size() >= bytes) return false;
            Buffer n(ctx_, bytes, kStorageUsage, host_visible, host_visible);
            const VkBufferCopy c{0, 0, b.size()};
            vkCmdCopyBuffer(cmd, b.handle(), n.handle(), 1, &c);
            old.push_back(std::move(b));
            b = std::move(n);
            return true;
        };
        if (count > capacity_) {
            capacity_ = std::max(count, std::min(2 * capacity_, max_regions));
            grow(states_, size_t(capacity_) * sizeof(GuidingFitRegion));
            grow(lobes_state_, size_t(capacity_) * GUIDING_MAX_COMPONENTS * sizeof(GuidingFitLobe));
            grow(pending_, size_t(capacity_) * push_.pending_capacity * sizeof(GuidingSample));
            grow(starts_, (2 * size_t(capacity_) + 2) * sizeof(uint32_t));
            grow(tally_, size_t(capacity_) * sizeof(GuidingFitTally), true);
            set_->bind_buffer(GUIDING_FIT_BINDING_STATE, states_);
            set_->bind_buffer(GUIDING_FIT_BINDING_STATE_LOBES, lobes_state_);
            set_->bind_buffer(GUIDING_FIT_BINDING_PENDING, pending_);
            set_->bind_buffer(GUIDING_FIT_BINDING_STARTS, starts_);
            set_->bind_buffer(GUIDING_FIT_BINDING_TALLY, tally_);
        }
        grow(regions, size_t(capacity_) * sizeof(GuidingRegion));
        grow(lobes, size_t(capacity_) * GUIDING_MAX_COMPONENTS * sizeof(GuidingLobe));
        set_->bind_buffer(GUIDING_FIT_BINDING_REGIONS, regions);
        set_->bind_buffer(GUIDING_FIT_BINDING_LOBES, lobes);
        VkMemoryBarrier b{VK_STRUCTURE_TYPE_MEMORY_BARRIER};
        b.srcAccessMask = VK_ACCESS_TRANSFER_WRITE_BIT | VK_ACCESS_SHADER_WRITE_BIT | VK_ACCESS_HOST_WRITE_BIT;
        b.dstAccessMask = VK_ACCESS_SHADER_READ_BIT | VK_ACCESS_SHADER_WRITE_BIT;
        vkCmdPipelineBarrier(cmd, VK_PIPELINE_STAGE_ALL_COMMANDS_BIT, VK_PIPELINE_STAGE_COMPUTE_SHADER_BIT, 0, 1, &b,
                             0, nullptr, 0, nullptr);
        GuidingFitPush pc = push_;
        pc.pass = GUIDING_FIT_PASS_REFINE;
        pc.region_count = count;
        pc.split_count = uint32_t(splits.size());
        fit_pipeline(ctx_, set_->layout()).dispatch(cmd, set_->set(), &pc, sizeof(pc), pc.split_count);
        barrier(cmd);
    });
    regions_ = count;
    push_.region_count = count;
    return uint32_t(splits.size());
}

const std::vector<GuidingFitTally>& DeviceFit::read_tally() {
    tally_read_.resize(regions_);
    tally_.download(tally_read_.data(), tally_read_.size() * sizeof(GuidingFitTally));
    double gain = 0.0, weight = 0.0;  // in region order, in double (as the host field's sums)
    bool sampled = false;             // fitted: a mixture (a child inherits its parent's fits)
    for (const GuidingFitTally& t : tally_read_) {
        gain += double(t.score_chosen) - double(t.score_bsdf);
        weight += t.weight;
        sampled = sampled || (t.fits > 0 && t.prob > 0.0f);
    }
    pays_ = !push_.adaptive_prob || selection_pays(gain, weight, GUIDING_SELECTION_MARGIN);
    mixture_sampled_ = pays_ && sampled;
    return tally_read_;
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
    std::vector<uint32_t> out(2 * size_t(regions_) + 2);
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
