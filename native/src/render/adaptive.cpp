#include "render/adaptive.h"

#include "shaders_embedded.h"

#include <algorithm>
#include <cmath>

namespace px {

AdaptiveSampling::AdaptiveSampling(Context& ctx, uint32_t width, uint32_t height)
    : ctx_(ctx), width_(width), height_(height) {
    const size_t pixels = size_t(width) * height;
    aux_ = Buffer(ctx, pixels * sizeof(vec4), kStorageUsage);
    pixels_ = Buffer(ctx, pixels * 2 * sizeof(uint32_t), kStorageUsage);
    reset();
}

void AdaptiveSampling::bind(DescriptorSet& set) const {
    set.bind_buffer(BINDING_ADAPTIVE_AUX, aux_);
    set.bind_buffer(BINDING_ADAPTIVE_PIXELS, pixels_);
}

uint32_t AdaptiveSampling::min_samples(const RenderParams& p) {
    if (p.adaptive_min_samples > 0) return std::max(4u, p.adaptive_min_samples);
    const float t = p.adaptive_threshold > 0 ? p.adaptive_threshold : 0.001f;
    return std::max(4u, uint32_t(std::ceil(16.0f / std::pow(t, 0.3f))));
}

float AdaptiveSampling::threshold(const RenderParams& p) {
    return (p.adaptive_threshold > 0 ? p.adaptive_threshold : 0.001f) * 5.0f;
}

void AdaptiveSampling::configure(const RenderParams& p) {
    on_ = p.use_adaptive_sampling != 0 && !p.preview;  // preview frames are one first-hit frame
    threshold_ = threshold(p);
    min_samples_ = min_samples(p);
    reset();
}

void AdaptiveSampling::reset() {
    listed_ = false;
    active_ = width_ * height_;
    checked_ = 0;
    // The half buffer empty, every pixel in the mask (the first check looks at every pixel).
    const VkDeviceSize list_bytes = VkDeviceSize(width_) * height_ * sizeof(uint32_t);
    ctx_.submit_and_wait([&](VkCommandBuffer cmd) {
        vkCmdFillBuffer(cmd, aux_.handle(), 0, VK_WHOLE_SIZE, 0u);
        vkCmdFillBuffer(cmd, pixels_.handle(), list_bytes, list_bytes, 1u);
    });
}

// Cycles filters after sample s (0-based) where s > min_samples and s % 16 == 15; frames of
// several samples check at the first frame end past such a sample.
bool AdaptiveSampling::check_due(uint64_t samples) const {
    if (!on_ || samples == 0 || active_ == 0) return false;
    return samples > uint64_t(min_samples_) + 1 && samples / kStep > checked_ / kStep;
}

void AdaptiveSampling::check(uint64_t samples, VkDescriptorSetLayout layout, VkDescriptorSet set) {
    if (!pipeline_) pipeline_ = std::make_unique<ComputePipeline>(ctx_, layout, uint32_t(sizeof(FrameParams)), shader_adaptive());
    const size_t pixels = size_t(width_) * height_;
    FrameParams fp{};
    fp.width = width_;
    fp.height = height_;
    fp.adaptive_threshold = threshold_;
    const uint32_t groups = uint32_t(std::min<size_t>((pixels + 63) / 64, 65535));
    ctx_.submit_and_wait([&](VkCommandBuffer cmd) {
        VkMemoryBarrier b{VK_STRUCTURE_TYPE_MEMORY_BARRIER};
        b.srcAccessMask = VK_ACCESS_SHADER_WRITE_BIT | VK_ACCESS_TRANSFER_WRITE_BIT;
        b.dstAccessMask = VK_ACCESS_SHADER_READ_BIT | VK_ACCESS_SHADER_WRITE_BIT;
        vkCmdPipelineBarrier(cmd, VK_PIPELINE_STAGE_RAY_TRACING_SHADER_BIT_KHR | VK_PIPELINE_STAGE_TRANSFER_BIT,
                             VK_PIPELINE_STAGE_COMPUTE_SHADER_BIT, 0, 1, &b, 0, nullptr, 0, nullptr);
        fp.mode = ADAPTIVE_CHECK;
        pipeline_->dispatch(cmd, set, &fp, sizeof(fp), groups);
        b.srcAccessMask = VK_ACCESS_SHADER_WRITE_BIT;
        vkCmdPipelineBarrier(cmd, VK_PIPELINE_STAGE_COMPUTE_SHADER_BIT, VK_PIPELINE_STAGE_COMPUTE_SHADER_BIT, 0, 1, &b,
                             0, nullptr, 0, nullptr);
        fp.mode = ADAPTIVE_FILTER;
        pipeline_->dispatch(cmd, set, &fp, sizeof(fp), groups);
    });
    // The list in image order: rows stay together, so neighbouring lanes trace neighbouring pixels.
    std::vector<uint32_t> mask(pixels), list;
    pixels_.download(mask.data(), pixels * sizeof(uint32_t), pixels * sizeof(uint32_t));
    list.reserve(pixels);
    for (uint32_t i = 0; i < pixels; ++i)
        if (mask[i]) list.push_back(i);
    if (!list.empty()) pixels_.upload(list.data(), list.size() * sizeof(uint32_t));
    active_ = uint32_t(list.size());
    listed_ = true;
    checked_ = samples;
}

void AdaptiveSampling::fill(FrameParams& frame) const {
    frame.adaptive = !on_ ? ADAPTIVE_OFF : listed_ ? ADAPTIVE_LIST : ADAPTIVE_IMAGE;
    frame.active_pixels = active_;
    frame.adaptive_threshold = threshold_;
}

}  // namespace px
