// Descriptor set layout shared by every pipeline, ray-tracing pipelines built from a list
// of shader groups (so techniques can add hit groups of their own), their shader binding
// table, and compute pipelines.
#pragma once
#include "vk/buffer.h"
#include "../../../shaders/shared/specialization.h"

#include <memory>
#include <string>
#include <utility>
#include <vector>

namespace px {

struct ShaderStage {
    VkShaderStageFlagBits stage;
    const std::vector<uint32_t>* spirv;
};

// A shader group: `general` for raygen/miss, or closest-hit/any-hit/intersection for a hit
// group. Indices point into the stage list; VK_SHADER_UNUSED_KHR where unused.
struct ShaderGroup {
    VkRayTracingShaderGroupTypeKHR type;
    uint32_t general = VK_SHADER_UNUSED_KHR;
    uint32_t closest_hit = VK_SHADER_UNUSED_KHR;
    uint32_t any_hit = VK_SHADER_UNUSED_KHR;
    uint32_t intersection = VK_SHADER_UNUSED_KHR;
};

class DescriptorSet {
public:
    // Every set of one device with the same bindings shares one layout, kept for the process
    // (like the device), so a pipeline compiled for one set works with all of them. Bindings
    // in `tlas_bindings` are acceleration structures, the others storage buffers.
    DescriptorSet(Context& ctx, uint32_t binding_count, const std::vector<uint32_t>& tlas_bindings);
    ~DescriptorSet();
    void bind_buffer(uint32_t binding, const Buffer& buffer);
    void bind_tlas(uint32_t binding, VkAccelerationStructureKHR tlas);
    VkDescriptorSetLayout layout() const { return layout_; }
    VkDescriptorSet set() const { return set_; }

private:
    Context& ctx_;
    VkDescriptorSetLayout layout_ = VK_NULL_HANDLE;
    VkDescriptorPool pool_ = VK_NULL_HANDLE;
    VkDescriptorSet set_ = VK_NULL_HANDLE;
};

// What tells one ray-tracing pipeline from another: its program (PROGRAM_*, the raygen shader)
// and its specialisation constants.
using PipelineKey = std::pair<uint32_t, SpecConstants>;

// `text` as a JSON string literal (quotes and backslashes escaped, control characters as spaces).
std::string json_string(const char* text);

class RayTracingPipeline {
public:
    // Groups must be ordered: one raygen, then the miss groups, then the hit groups.
    RayTracingPipeline(Context& ctx, VkDescriptorSetLayout set_layout, uint32_t push_constant_size,
                       const std::vector<ShaderStage>& stages, const std::vector<ShaderGroup>& groups,
                       const SpecConstants& constants);
    ~RayTracingPipeline();
    void trace(VkCommandBuffer cmd, VkDescriptorSet set, const void* push, uint32_t push_size,
               uint32_t width, uint32_t height) const;
    // What the driver says of the compiled pipeline, as a JSON object: "stack", the stack size in
    // bytes it reports for each group's shaders (vkGetRayTracingShaderGroupStackSizeKHR), and,
    // where Context::pipeline_statistics() is on, "executables": each one's name and the
    // driver's statistics (registers, ...). Throws VulkanError where a query fails.
    std::string statistics_json() const;

private:
    Context& ctx_;
    VkPipelineLayout layout_ = VK_NULL_HANDLE;
    VkPipeline pipeline_ = VK_NULL_HANDLE;
    std::vector<ShaderGroup> groups_;
    Buffer sbt_;
    VkStridedDeviceAddressRegionKHR raygen_{}, miss_{}, hit_{}, callable_{};
};

class ComputePipeline {
public:
    ComputePipeline(Context& ctx, VkDescriptorSetLayout set_layout, uint32_t push_constant_size,
                    const std::vector<uint32_t>& spirv);
    ~ComputePipeline();
    void dispatch(VkCommandBuffer cmd, VkDescriptorSet set, const void* push, uint32_t push_size,
                  uint32_t groups_x) const;

private:
    Context& ctx_;
    VkPipelineLayout layout_ = VK_NULL_HANDLE;
    VkPipeline pipeline_ = VK_NULL_HANDLE;
};

}  // namespace px
