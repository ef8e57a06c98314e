#include "vk/pipeline.h"

#include <algorithm>
#include <cstring>
#include <map>
#include <mutex>
#include <tuple>

namespace px {

static constexpr VkShaderStageFlags kAllStages =
    VK_SHADER_STAGE_RAYGEN_BIT_KHR | VK_SHADER_STAGE_CLOSEST_HIT_BIT_KHR | VK_SHADER_STAGE_MISS_BIT_KHR |
    VK_SHADER_STAGE_ANY_HIT_BIT_KHR | VK_SHADER_STAGE_INTERSECTION_BIT_KHR | VK_SHADER_STAGE_COMPUTE_BIT;

namespace {
bool contains(const std::vector<uint32_t>& v, uint32_t x) { return std::find(v.begin(), v.end(), x) != v.end(); }

VkDescriptorSetLayout shared_layout(Context& ctx, uint32_t binding_count, const std::vector<uint32_t>& tlas_bindings) {
    static std::mutex mutex;
    static std::map<std::tuple<VkDevice, uint32_t, std::vector<uint32_t>>, VkDescriptorSetLayout> layouts;
    std::lock_guard<std::mutex> lock(mutex);
    VkDescriptorSetLayout& layout = layouts[{ctx.device(), binding_count, tlas_bindings}];
    if (layout != VK_NULL_HANDLE) return layout;
    std::vector<VkDescriptorSetLayoutBinding> bindings(binding_count);
    for (uint32_t i = 0; i < binding_count; ++i) {
        bindings[i].binding = i;
        bindings[i].descriptorType = contains(tlas_bindings, i) ? VK_DESCRIPTOR_TYPE_ACCELERATION_STRUCTURE_KHR
                                                                : VK_DESCRIPTOR_TYPE_STORAGE_BUFFER;
        bindings[i].descriptorCount = 1;
        bindings[i].stageFlags = kAllStages;
    }
    VkDescriptorSetLayoutCreateInfo linfo{VK_STRUCTURE_TYPE_DESCRIPTOR_SET_LAYOUT_CREATE_INFO};
    linfo.bindingCount = binding_count;
    linfo.pBindings = bindings.data();
    VK_CHECK(vkCreateDescriptorSetLayout(ctx.device(), &linfo, nullptr, &layout));
    return layout;
}
}  // namespace

DescriptorSet::DescriptorSet(Context& ctx, uint32_t binding_count, const std::vector<uint32_t>& tlas_bindings)
    : ctx_(ctx), layout_(shared_layout(ctx, binding_count, tlas_bindings)) {
    const uint32_t tlas_count = uint32_t(tlas_bindings.size());
    VkDescriptorPoolSize sizes[2] = {{VK_DESCRIPTOR_TYPE_ACCELERATION_STRUCTURE_KHR, tlas_count},
                                     {VK_DESCRIPTOR_TYPE_STORAGE_BUFFER, binding_count - tlas_count}};
    VkDescriptorPoolCreateInfo pinfo{VK_STRUCTURE_TYPE_DESCRIPTOR_POOL_CREATE_INFO};
    pinfo.maxSets = 1;
    pinfo.poolSizeCount = tlas_count ? 2 : 1;  // no size of 0 descriptors (a set without TLASes)
    pinfo.pPoolSizes = tlas_count ? sizes : sizes + 1;
    VK_CHECK(vkCreateDescriptorPool(ctx.device(), &pinfo, nullptr, &pool_));
    VkDescriptorSetAllocateInfo ainfo{VK_STRUCTURE_TYPE_DESCRIPTOR_SET_ALLOCATE_INFO};
    ainfo.descriptorPool = pool_;
    ainfo.descriptorSetCount = 1;
    ainfo.pSetLayouts = &layout_;
    VK_CHECK(vkAllocateDescriptorSets(ctx.device(), &ainfo, &set_));
}

DescriptorSet::~DescriptorSet() {
    if (!ctx_.hung()) vkDestroyDescriptorPool(ctx_.device(), pool_, nullptr);
}

void DescriptorSet::bind_buffer(uint32_t binding, const Buffer& buffer) {
    VkDescriptorBufferInfo info{buffer.handle(), 0, VK_WHOLE_SIZE};
    VkWriteDescriptorSet w{VK_STRUCTURE_TYPE_WRITE_DESCRIPTOR_SET};
    w.dstSet = set_;
    w.dstBinding = binding;
    w.descriptorCount = 1;
    w.descriptorType = VK_DESCRIPTOR_TYPE_STORAGE_BUFFER;
    w.pBufferInfo = &info;
    vkUpdateDescriptorSets(ctx_.device(), 1, &w, 0, nullptr);
}

void DescriptorSet::bind_tlas(uint32_t binding, VkAccelerationStructureKHR tlas) {
    VkWriteDescriptorSetAccelerationStructureKHR as{VK_STRUCTURE_TYPE_WRITE_DESCRIPTOR_SET_ACCELERATION_STRUCTURE_KHR};
    as.accelerationStructureCount = 1;
    as.pAccelerationStructures = &tlas;
    VkWriteDescriptorSet w{VK_STRUCTURE_TYPE_WRITE_DESCRIPTOR_SET};
    w.pNext = &as;
    w.dstSet = set_;
    w.dstBinding = binding;
    w.descriptorCount = 1;
    w.descriptorType = VK_DESCRIPTOR_TYPE_ACCELERATION_STRUCTURE_KHR;
    vkUpdateDescriptorSets(ctx_.device(), 1, &w, 0, nullptr);
}

static VkPipelineLayout make_layout(Context& ctx, VkDescriptorSetLayout set_layout, uint32_t push_size) {
    VkPushConstantRange range{kAllStages, 0, push_size};
    VkPipelineLayoutCreateInfo info{VK_STRUCTURE_TYPE_PIPELINE_LAYOUT_CREATE_INFO};
    info.setLayoutCount = 1;
    info.pSetLayouts = &set_layout;
    info.pushConstantRangeCount = push_size ? 1 : 0;
    info.pPushConstantRanges = &range;
    VkPipelineLayout layout;
    VK_CHECK(vkCreatePipelineLayout(ctx.device(), &info, nullptr, &layout));
    return layout;
}

static VkShaderModule make_module(Context& ctx, const std::vector<uint32_t>& spirv) {
    VkShaderModuleCreateInfo info{VK_STRUCTURE_TYPE_SHADER_MODULE_CREATE_INFO};
    info.codeSize = spirv.size() * 4;
    info.pCode = spirv.data();
    VkShaderModule m;
    VK_CHECK(vkCreateShaderModule(ctx.device(), &info, nullptr, &m));
    return m;
}

// Every stage gets all the constants (shaders/shared/specialization.h); a stage ignores those it
// does not declare.
struct Specialization {
    std::vector<VkSpecializationMapEntry> entries;
    VkSpecializationInfo info{};
    explicit Specialization(const SpecConstants& constants) {
        for (const SpecConstantEntry& e : spec_constant_entries) entries.push_back({e.constant_id, e.offset, sizeof(uint)});
        info.mapEntryCount = uint32_t(entries.size());
        info.pMapEntries = entries.data();
        info.dataSize = sizeof(SpecConstants);
        info.pData = &constants;
    }
};

static VkDeviceSize align_up(VkDeviceSize v, VkDeviceSize a) { return (v + a - 1) / a * a; }

RayTracingPipeline::RayTracingPipeline(Context& ctx, VkDescriptorSetLayout set_layout, uint32_t push_size,
                                       const std::vector<ShaderStage>& stages,
                                       const std::vector<ShaderGroup>& groups,
                                       const SpecConstants& constants)
    : ctx_(ctx), groups_(groups) {
    layout_ = make_layout(ctx, set_layout, push_size);
    Specialization spec(constants);
    std::vector<VkPipelineShaderStageCreateInfo> stage_infos;
    std::vector<VkShaderModule> modules;
    for (const auto& s : stages) {
        modules.push_back(make_module(ctx, *s.spirv));
        VkPipelineShaderStageCreateInfo si{VK_STRUCTURE_TYPE_PIPELINE_SHADER_STAGE_CREATE_INFO};
        si.stage = s.stage;
        si.module = modules.back();
        si.pName = "main";
        si.pSpecializationInfo = &spec.info;
        stage_infos.push_back(si);
    }
    std::vector<VkRayTracingShaderGroupCreateInfoKHR> group_infos;
    uint32_t miss_count = 0, hit_count = 0;
    for (const auto& g : groups) {
        VkRayTracingShaderGroupCreateInfoKHR gi{VK_STRUCTURE_TYPE_RAY_TRACING_SHADER_GROUP_CREATE_INFO_KHR};
        gi.type = g.type;
        gi.generalShader = g.general;
        gi.closestHitShader = g.closest_hit;
        gi.anyHitShader = g.any_hit;
        gi.intersectionShader = g.intersection;
        group_infos.push_back(gi);
        if (g.type == VK_RAY_TRACING_SHADER_GROUP_TYPE_GENERAL_KHR) {
            if (&g != &groups[0]) ++miss_count;
        } else {
            ++hit_count;
        }
    }
    VkRayTracingPipelineCreateInfoKHR info{VK_STRUCTURE_TYPE_RAY_TRACING_PIPELINE_CREATE_INFO_KHR};
    info.stageCount = uint32_t(stage_infos.size());
    info.pStages = stage_infos.data();
    info.groupCount = uint32_t(group_infos.size());
    info.pGroups = group_infos.data();
    info.maxPipelineRayRecursionDepth = 1;
    info.layout = layout_;
    if (ctx.pipeline_statistics()) info.flags |= VK_PIPELINE_CREATE_CAPTURE_STATISTICS_BIT_KHR;
    VkResult r = ctx.rt().create_rt_pipelines(ctx.device(), VK_NULL_HANDLE, VK_NULL_HANDLE, 1, &info, nullptr,
                                              &pipeline_);
    for (auto m : modules) vkDestroyShaderModule(ctx.device(), m, nullptr);
    vk_check(r, "vkCreateRayTracingPipelinesKHR");

    // Shader binding table: raygen | miss... | hit...
    const auto& p = ctx.rt_properties();
    const uint32_t handle_size = p.shaderGroupHandleSize;
    const VkDeviceSize stride = align_up(handle_size, p.shaderGroupHandleAlignment);
    const VkDeviceSize base_align = p.shaderGroupBaseAlignment;
    std::vector<uint8_t> handles(size_t(handle_size) * groups.size());
    VK_CHECK(ctx.rt().get_group_handles(ctx.device(), pipeline_, 0, uint32_t(groups.size()), handles.size(),
                                        handles.data()));
    VkDeviceSize raygen_size = align_up(stride, base_align);
    VkDeviceSize miss_size = align_up(stride * miss_count, base_align);
    VkDeviceSize hit_size = align_up(stride * std::max(hit_count, 1u), base_align);
    std::vector<uint8_t> table(raygen_size + miss_size + hit_size, 0);
    auto put = [&](VkDeviceSize offset, uint32_t group) {
        std::memcpy(table.data() + offset, handles.data() + size_t(group) * handle_size, handle_size);
    };
    put(0, 0);
    for (uint32_t i = 0; i < miss_count; ++i) put(raygen_size + i * stride, 1 + i);
    for (uint32_t i = 0; i < hit_count; ++i) put(raygen_size + miss_size + i * stride, 1 + miss_count + i);
    sbt_ = Buffer(ctx, table.size() + base_align, VK_BUFFER_USAGE_SHADER_BINDING_TABLE_BIT_KHR);
    VkDeviceAddress base = align_up(sbt_.address(), base_align);
    sbt_.upload(table.data(), table.size(), base - sbt_.address());
    raygen_ = {base, raygen_size, raygen_size};
    miss_ = {base + raygen_size, stride, stride * miss_count};
    hit_ = {base + raygen_size + miss_size, stride, stride * hit_count};
}

std::string json_string(const char* text) {
    std::string out = "\"";
    for (const char* c = text; *c; ++c) {
        if (*c == '"' || *c == '\\') out += '\\';
        out += (unsigned char)(*c) < 0x20 ? ' ' : *c;
    }
    return out + "\"";
}

std::string RayTracingPipeline::statistics_json() const {
    const VkDevice device = ctx_.device();
    std::string stack = "[";
    for (uint32_t g = 0; g < groups_.size(); ++g) {
        const ShaderGroup& group = groups_[g];
        const std::pair<uint32_t, VkShaderGroupShaderKHR> shaders[] = {
            {group.general, VK_SHADER_GROUP_SHADER_GENERAL_KHR},
            {group.closest_hit, VK_SHADER_GROUP_SHADER_CLOSEST_HIT_KHR},
            {group.any_hit, VK_SHADER_GROUP_SHADER_ANY_HIT_KHR},
            {group.intersection, VK_SHADER_GROUP_SHADER_INTERSECTION_KHR}};
        const char* names[] = {"general", "closest_hit", "any_hit", "intersection"};
        stack += g ? ", {" : "{";
        bool first = true;
        for (int k = 0; k < 4; ++k) {
            if (shaders[k].first == VK_SHADER_UNUSED_KHR) continue;
            VkDeviceSize bytes = ctx_.rt().get_group_stack_size(device, pipeline_, g, shaders[k].second);
            stack += (first ? "\"" : ", \"") + std::string(names[k]) + "\": " + std::to_string(bytes);
            first = false;
        }
        stack += "}";
    }
    std::string out = "{\"stack\": " + stack + "]";
    if (!ctx_.pipeline_statistics()) return out + "}";
    VkPipelineInfoKHR pinfo{VK_STRUCTURE_TYPE_PIPELINE_INFO_KHR};
    pinfo.pipeline = pipeline_;
    uint32_t count = 0;
    VK_CHECK(ctx_.rt().get_executable_properties(device, &pinfo, &count, nullptr));
    std::vector<VkPipelineExecutablePropertiesKHR> executables(count, {VK_STRUCTURE_TYPE_PIPELINE_EXECUTABLE_PROPERTIES_KHR});
    VK_CHECK(ctx_.rt().get_executable_properties(device, &pinfo, &count, executables.data()));
    out += ", \"executables\": [";
    for (uint32_t e = 0; e < count; ++e) {
        VkPipelineExecutableInfoKHR einfo{VK_STRUCTURE_TYPE_PIPELINE_EXECUTABLE_INFO_KHR};
        einfo.pipeline = pipeline_;
        einfo.executableIndex = e;
        uint32_t n = 0;
        VK_CHECK(ctx_.rt().get_executable_statistics(device, &einfo, &n, nullptr));
        std::vector<VkPipelineExecutableStatisticKHR> stats(n, {VK_STRUCTURE_TYPE_PIPELINE_EXECUTABLE_STATISTIC_KHR});
        VK_CHECK(ctx_.rt().get_executable_statistics(device, &einfo, &n, stats.data()));
        out += std::string(e ? ", " : "") + "{\"name\": " + json_string(executables[e].name) +
               ", \"stages\": " + std::to_string(executables[e].stages) +
               ", \"subgroup_size\": " + std::to_string(executables[e].subgroupSize) + ", \"statistics\": {";
        for (uint32_t i = 0; i < n; ++i) {
            const VkPipelineExecutableStatisticKHR& st = stats[i];
            std::string value;
            switch (st.format) {
                case VK_PIPELINE_EXECUTABLE_STATISTIC_FORMAT_BOOL32_KHR: value = st.value.b32 ? "true" : "false"; break;
                case VK_PIPELINE_EXECUTABLE_STATISTIC_FORMAT_INT64_KHR: value = std::to_string(st.value.i64); break;
                case VK_PIPELINE_EXECUTABLE_STATISTIC_FORMAT_UINT64_KHR: value = std::to_string(st.value.u64); break;
                default: value = std::to_string(st.value.f64);
            }
            out += std::string(i ? ", " : "") + json_string(st.name) + ": " + value;
        }
        out += "}}";
    }
    return out + "]}";
}

RayTracingPipeline::~RayTracingPipeline() {
    if (ctx_.hung()) return;
    vkDestroyPipeline(ctx_.device(), pipeline_, nullptr);
    vkDestroyPipelineLayout(ctx_.device(), layout_, nullptr);
}

void RayTracingPipeline::trace(VkCommandBuffer cmd, VkDescriptorSet set, const void* push, uint32_t push_size,
                               uint32_t width, uint32_t height) const {
    vkCmdBindPipeline(cmd, VK_PIPELINE_BIND_POINT_RAY_TRACING_KHR, pipeline_);
    vkCmdBindDescriptorSets(cmd, VK_PIPELINE_BIND_POINT_RAY_TRACING_KHR, layout_, 0, 1, &set, 0, nullptr);
    vkCmdPushConstants(cmd, layout_, kAllStages, 0, push_size, push);
    ctx_.rt().cmd_trace_rays(cmd, &raygen_, &miss_, &hit_, &callable_, width, height, 1);
}

ComputePipeline::ComputePipeline(Context& ctx, VkDescriptorSetLayout set_layout, uint32_t push_size,
                                 const std::vector<uint32_t>& spirv)
    : ctx_(ctx) {
    layout_ = make_layout(ctx, set_layout, push_size);
    VkShaderModule module = make_module(ctx, spirv);
    VkComputePipelineCreateInfo info{VK_STRUCTURE_TYPE_COMPUTE_PIPELINE_CREATE_INFO};
    info.stage = {VK_STRUCTURE_TYPE_PIPELINE_SHADER_STAGE_CREATE_INFO};
    info.stage.stage = VK_SHADER_STAGE_COMPUTE_BIT;
    info.stage.module = module;
    info.stage.pName = "main";
    info.layout = layout_;
    VkResult r = vkCreateComputePipelines(ctx.device(), VK_NULL_HANDLE, 1, &info, nullptr, &pipeline_);
    vkDestroyShaderModule(ctx.device(), module, nullptr);
    vk_check(r, "vkCreateComputePipelines");
}

ComputePipeline::~ComputePipeline() {
    if (ctx_.hung()) return;
    vkDestroyPipeline(ctx_.device(), pipeline_, nullptr);
    vkDestroyPipelineLayout(ctx_.device(), layout_, nullptr);
}

void ComputePipeline::dispatch(VkCommandBuffer cmd, VkDescriptorSet set, const void* push, uint32_t push_size,
                               uint32_t groups_x) const {
    vkCmdBindPipeline(cmd, VK_PIPELINE_BIND_POINT_COMPUTE, pipeline_);
    vkCmdBindDescriptorSets(cmd, VK_PIPELINE_BIND_POINT_COMPUTE, layout_, 0, 1, &set, 0, nullptr);
    vkCmdPushConstants(cmd, layout_, kAllStages, 0, push_size, push);
    vkCmdDispatch(cmd, groups_x, 1, 1);
}

}  // namespace px
