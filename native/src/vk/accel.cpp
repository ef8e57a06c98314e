#include "vk/accel.h"

#include <algorithm>
#include <cstring>
#include <stdexcept>

namespace px {

AccelerationStructure::AccelerationStructure(Context& ctx, VkAccelerationStructureTypeKHR type, VkDeviceSize size)
    : ctx_(ctx), storage_(ctx, size, VK_BUFFER_USAGE_ACCELERATION_STRUCTURE_STORAGE_BIT_KHR) {
    VkAccelerationStructureCreateInfoKHR info{VK_STRUCTURE_TYPE_ACCELERATION_STRUCTURE_CREATE_INFO_KHR};
    info.buffer = storage_.handle();
    info.size = size;
    info.type = type;
    VK_CHECK(ctx.rt().create_as(ctx.device(), &info, nullptr, &as_));
    VkAccelerationStructureDeviceAddressInfoKHR ainfo{VK_STRUCTURE_TYPE_ACCELERATION_STRUCTURE_DEVICE_ADDRESS_INFO_KHR};
    ainfo.accelerationStructure = as_;
    address_ = ctx.rt().get_as_address(ctx.device(), &ainfo);
}

AccelerationStructure::~AccelerationStructure() {
    if (as_ && !ctx_.hung()) ctx_.rt().destroy_as(ctx_.device(), as_, nullptr);
}

static VkDeviceSize align_up(VkDeviceSize v, VkDeviceSize a) { return (v + a - 1) / a * a; }

static void barrier_after_build(VkCommandBuffer cmd) {
    VkMemoryBarrier b{VK_STRUCTURE_TYPE_MEMORY_BARRIER};
    b.srcAccessMask = VK_ACCESS_ACCELERATION_STRUCTURE_WRITE_BIT_KHR;
    b.dstAccessMask = VK_ACCESS_ACCELERATION_STRUCTURE_READ_BIT_KHR;
    vkCmdPipelineBarrier(cmd, VK_PIPELINE_STAGE_ACCELERATION_STRUCTURE_BUILD_BIT_KHR,
                         VK_PIPELINE_STAGE_ACCELERATION_STRUCTURE_BUILD_BIT_KHR |
                             VK_PIPELINE_STAGE_RAY_TRACING_SHADER_BIT_KHR,
                         0, 1, &b, 0, nullptr, 0, nullptr);
}

std::vector<std::unique_ptr<AccelerationStructure>> build_triangle_blases(
    Context& ctx, const Buffer& positions, uint32_t vertex_count, const Buffer& indices,
    const std::vector<TriangleRange>& ranges) {
    const size_t n = ranges.size();
    std::vector<VkAccelerationStructureGeometryKHR> geometries(n);
    std::vector<VkAccelerationStructureBuildGeometryInfoKHR> builds(n);
    std::vector<VkAccelerationStructureBuildRangeInfoKHR> range_infos(n);
    std::vector<std::unique_ptr<AccelerationStructure>> result;
    std::vector<VkDeviceSize> scratch_offsets(n);
    VkDeviceSize scratch_total = 0;
    const VkDeviceSize scratch_align = 256;

    for (size_t i = 0; i < n; ++i) {
        auto& g = geometries[i];
        g = {VK_STRUCTURE_TYPE_ACCELERATION_STRUCTURE_GEOMETRY_KHR};
        g.geometryType = VK_GEOMETRY_TYPE_TRIANGLES_KHR;
        g.flags = 0;  // not opaque: rays that leave a surface run self_skip.rahit (opaque-flagged rays do not)
        auto& t = g.geometry.triangles;
        t = {VK_STRUCTURE_TYPE_ACCELERATION_STRUCTURE_GEOMETRY_TRIANGLES_DATA_KHR};
        t.vertexFormat = VK_FORMAT_R32G32B32_SFLOAT;
        t.vertexData.deviceAddress = positions.address();
        t.vertexStride = 12;
        t.maxVertex = vertex_count ? vertex_count - 1 : 0;
        t.indexType = VK_INDEX_TYPE_UINT32;
        t.indexData.deviceAddress = indices.address() + VkDeviceSize(ranges[i].first_triangle) * 12;

        auto& b = builds[i];
        b = {VK_STRUCTURE_TYPE_ACCELERATION_STRUCTURE_BUILD_GEOMETRY_INFO_KHR};
        b.type = VK_ACCELERATION_STRUCTURE_TYPE_BOTTOM_LEVEL_KHR;
        b.flags = VK_BUILD_ACCELERATION_STRUCTURE_PREFER_FAST_TRACE_BIT_KHR;
        b.mode = VK_BUILD_ACCELERATION_STRUCTURE_MODE_BUILD_KHR;
        b.geometryCount = 1;
        b.pGeometries = &g;
        VkAccelerationStructureBuildSizesInfoKHR sizes{VK_STRUCTURE_TYPE_ACCELERATION_STRUCTURE_BUILD_SIZES_INFO_KHR};
        ctx.rt().get_build_sizes(ctx.device(), VK_ACCELERATION_STRUCTURE_BUILD_TYPE_DEVICE_KHR, &b,
                                 &ranges[i].triangle_count, &sizes);
        result.push_back(std::make_unique<AccelerationStructure>(
            ctx, VK_ACCELERATION_STRUCTURE_TYPE_BOTTOM_LEVEL_KHR, sizes.accelerationStructureSize));
        b.dstAccelerationStructure = result.back()->handle();
        scratch_offsets[i] = scratch_total;
        scratch_total += align_up(sizes.buildScratchSize, scratch_align);
        range_infos[i] = {ranges[i].triangle_count, 0, 0, 0};
    }
    if (n == 0) return result;
    Buffer scratch(ctx, scratch_total + scratch_align, VK_BUFFER_USAGE_STORAGE_BUFFER_BIT);
    VkDeviceAddress base = align_up(scratch.address(), scratch_align);
    std::vector<const VkAccelerationStructureBuildRangeInfoKHR*> range_ptrs(n);
    for (size_t i = 0; i < n; ++i) {
        builds[i].scratchData.deviceAddress = base + scratch_offsets[i];
        range_ptrs[i] = &range_infos[i];
    }
    ctx.submit_and_wait([&](VkCommandBuffer cmd) {
        ctx.rt().cmd_build_as(cmd, uint32_t(n), builds.data(), range_ptrs.data());
        barrier_after_build(cmd);
    });
    return result;
}

namespace {
// Sizes of a build of `info` over `count` primitives (they hold every build of fewer).
VkAccelerationStructureBuildSizesInfoKHR build_sizes(Context& ctx, const VkAccelerationStructureBuildGeometryInfoKHR& info,
                                                     uint32_t count) {
    VkAccelerationStructureBuildSizesInfoKHR out{VK_STRUCTURE_TYPE_ACCELERATION_STRUCTURE_BUILD_SIZES_INFO_KHR};
    ctx.rt().get_build_sizes(ctx.device(), VK_ACCELERATION_STRUCTURE_BUILD_TYPE_DEVICE_KHR, &info, &count, &out);
    return out;
}

// The build description of a BLAS over the boxes at `aabbs`; sizes() for a count of them.
struct AabbGeometry {
    VkAccelerationStructureGeometryKHR geometry{VK_STRUCTURE_TYPE_ACCELERATION_STRUCTURE_GEOMETRY_KHR};
    VkAccelerationStructureBuildGeometryInfoKHR info{VK_STRUCTURE_TYPE_ACCELERATION_STRUCTURE_BUILD_GEOMETRY_INFO_KHR};
    AabbGeometry(VkDeviceAddress aabbs, bool refit) {
        geometry.geometryType = VK_GEOMETRY_TYPE_AABBS_KHR;
        geometry.flags = 0;  // not opaque: the any-hit shader sees every entry
        geometry.geometry.aabbs = {VK_STRUCTURE_TYPE_ACCELERATION_STRUCTURE_GEOMETRY_AABBS_DATA_KHR};
        geometry.geometry.aabbs.data.deviceAddress = aabbs;
        geometry.geometry.aabbs.stride = sizeof(VkAabbPositionsKHR);
        info.type = VK_ACCELERATION_STRUCTURE_TYPE_BOTTOM_LEVEL_KHR;
        info.flags = VK_BUILD_ACCELERATION_STRUCTURE_PREFER_FAST_TRACE_BIT_KHR |
                     VK_BUILD_ACCELERATION_STRUCTURE_ALLOW_UPDATE_BIT_KHR;
        info.mode = refit ? VK_BUILD_ACCELERATION_STRUCTURE_MODE_UPDATE_KHR : VK_BUILD_ACCELERATION_STRUCTURE_MODE_BUILD_KHR;
        info.geometryCount = 1;
        info.pGeometries = &geometry;
    }
    VkAccelerationStructureBuildSizesInfoKHR sizes(Context& ctx, uint32_t count) const {
        return build_sizes(ctx, info, count);
    }
};

// The build description of a TLAS over the instances at `instances`.
struct InstanceGeometry {
    VkAccelerationStructureGeometryKHR geometry{VK_STRUCTURE_TYPE_ACCELERATION_STRUCTURE_GEOMETRY_KHR};
    VkAccelerationStructureBuildGeometryInfoKHR info{VK_STRUCTURE_TYPE_ACCELERATION_STRUCTURE_BUILD_GEOMETRY_INFO_KHR};
    InstanceGeometry(VkDeviceAddress instances) {
        geometry.geometryType = VK_GEOMETRY_TYPE_INSTANCES_KHR;
        geometry.geometry.instances = {VK_STRUCTURE_TYPE_ACCELERATION_STRUCTURE_GEOMETRY_INSTANCES_DATA_KHR};
        geometry.geometry.instances.data.deviceAddress = instances;
        info.type = VK_ACCELERATION_STRUCTURE_TYPE_TOP_LEVEL_KHR;
        info.flags = VK_BUILD_ACCELERATION_STRUCTURE_PREFER_FAST_TRACE_BIT_KHR;
        info.mode = VK_BUILD_ACCELERATION_STRUCTURE_MODE_BUILD_KHR;
        info.geometryCount = 1;
        info.pGeometries = &geometry;
    }
    VkAccelerationStructureBuildSizesInfoKHR sizes(Context& ctx, uint32_t count) const {
        return build_sizes(ctx, info, count);
    }
};

VkAccelerationStructureInstanceKHR vk_instance(const TlasInstance& s) {
    VkAccelerationStructureInstanceKHR d{};
    std::memcpy(d.transform.matrix, s.transform.data(), sizeof(d.transform.matrix));
    d.instanceCustomIndex = s.custom_index & 0xffffff;
    d.mask = s.mask & 0xff;
    d.instanceShaderBindingTableRecordOffset = s.sbt_offset;
    d.flags = VK_GEOMETRY_INSTANCE_TRIANGLE_FACING_CULL_DISABLE_BIT_KHR;
    d.accelerationStructureReference = s.blas;
    return d;
}
}  // namespace

AabbAccel::AabbAccel(Context& ctx, uint32_t sbt_offset) : ctx_(ctx), sbt_offset_(sbt_offset) {}

bool AabbAccel::reserve(uint32_t count, uint32_t limit) {
    count = std::max(count, 1u);
    if (count <= capacity_) return false;
    capacity_ = std::max(count, std::min(2 * capacity_, limit));
    // Sizes for capacity_ boxes hold every build of fewer (VkAccelerationStructureBuildSizesInfoKHR).
    const VkAccelerationStructureBuildSizesInfoKHR blas_sizes = AabbGeometry(0, false).sizes(ctx_, capacity_);
    blas_.reset();
    blas_ = std::make_unique<AccelerationStructure>(ctx_, VK_ACCELERATION_STRUCTURE_TYPE_BOTTOM_LEVEL_KHR,
                                                    blas_sizes.accelerationStructureSize);
    TlasInstance instance{};
    instance.transform = {1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0};
    instance.mask = 0xff;
    instance.sbt_offset = sbt_offset_;
    instance.blas = blas_->address();
    const VkAccelerationStructureInstanceKHR vk = vk_instance(instance);
    instance_ = Buffer::with_data(ctx_, &vk, sizeof(vk), VK_BUFFER_USAGE_ACCELERATION_STRUCTURE_BUILD_INPUT_READ_ONLY_BIT_KHR);
    const VkAccelerationStructureBuildSizesInfoKHR tlas_sizes = InstanceGeometry(instance_.address()).sizes(ctx_, 1);
    if (!tlas_)
        tlas_ = std::make_unique<AccelerationStructure>(ctx_, VK_ACCELERATION_STRUCTURE_TYPE_TOP_LEVEL_KHR,
                                                        tlas_sizes.accelerationStructureSize);
    const VkDeviceSize scratch = std::max({blas_sizes.buildScratchSize, blas_sizes.updateScratchSize,
                                           tlas_sizes.buildScratchSize});
    scratch_ = Buffer();
    scratch_ = Buffer(ctx_, scratch + 256, VK_BUFFER_USAGE_STORAGE_BUFFER_BIT);
    built_count_ = 0;  // a new BLAS: the next build cannot be a refit
    return true;
}

void AabbAccel::record_build(VkCommandBuffer cmd, const Buffer& aabbs, uint32_t count, bool refit) {
    count = std::max(count, 1u);
    if (count > capacity_) throw std::logic_error("AabbAccel: record_build past the reserved boxes");
    if (refit && count != built_count_) throw std::logic_error("AabbAccel: a refit needs the last build's count");
    // The boxes were written by shaders (ic_finish.comp), copied, or written by the host; so
    // may be what the shaders read beside the structure (the guiding regions' order and nodes).
    VkMemoryBarrier b{VK_STRUCTURE_TYPE_MEMORY_BARRIER};
    b.srcAccessMask = VK_ACCESS_SHADER_WRITE_BIT | VK_ACCESS_TRANSFER_WRITE_BIT | VK_ACCESS_HOST_WRITE_BIT;
    b.dstAccessMask = VK_ACCESS_ACCELERATION_STRUCTURE_READ_BIT_KHR | VK_ACCESS_SHADER_READ_BIT;
    vkCmdPipelineBarrier(cmd, VK_PIPELINE_STAGE_ALL_COMMANDS_BIT, VK_PIPELINE_STAGE_ALL_COMMANDS_BIT, 0, 1, &b, 0,
                         nullptr, 0, nullptr);
    const VkDeviceAddress scratch = align_up(scratch_.address(), 256);
    AabbGeometry blas(aabbs.address(), refit);
    blas.info.srcAccelerationStructure = refit ? blas_->handle() : VK_NULL_HANDLE;
    blas.info.dstAccelerationStructure = blas_->handle();
    blas.info.scratchData.deviceAddress = scratch;
    const VkAccelerationStructureBuildRangeInfoKHR blas_range{count, 0, 0, 0};
    const VkAccelerationStructureBuildRangeInfoKHR* blas_range_ptr = &blas_range;
    ctx_.rt().cmd_build_as(cmd, 1, &blas.info, &blas_range_ptr);
    // The TLAS build reads the BLAS and writes the scratch the BLAS build wrote.
    VkMemoryBarrier between{VK_STRUCTURE_TYPE_MEMORY_BARRIER};
    between.srcAccessMask = VK_ACCESS_ACCELERATION_STRUCTURE_WRITE_BIT_KHR;
    between.dstAccessMask = VK_ACCESS_ACCELERATION_STRUCTURE_READ_BIT_KHR | VK_ACCESS_ACCELERATION_STRUCTURE_WRITE_BIT_KHR;
    vkCmdPipelineBarrier(cmd, VK_PIPELINE_STAGE_ACCELERATION_STRUCTURE_BUILD_BIT_KHR,
                         VK_PIPELINE_STAGE_ACCELERATION_STRUCTURE_BUILD_BIT_KHR, 0, 1, &between, 0, nullptr, 0, nullptr);
    InstanceGeometry tlas(instance_.address());
    tlas.info.dstAccelerationStructure = tlas_->handle();
    tlas.info.scratchData.deviceAddress = scratch;
    const VkAccelerationStructureBuildRangeInfoKHR tlas_range{1, 0, 0, 0};
    const VkAccelerationStructureBuildRangeInfoKHR* tlas_range_ptr = &tlas_range;
    ctx_.rt().cmd_build_as(cmd, 1, &tlas.info, &tlas_range_ptr);
    barrier_after_build(cmd);
    built_count_ = count;
}

std::unique_ptr<AccelerationStructure> build_tlas(Context& ctx, const std::vector<TlasInstance>& instances) {
    std::vector<VkAccelerationStructureInstanceKHR> vk_instances(instances.size());
    for (size_t i = 0; i < instances.size(); ++i) vk_instances[i] = vk_instance(instances[i]);
    Buffer instance_buffer = Buffer::with_vector(
        ctx, vk_instances, VK_BUFFER_USAGE_ACCELERATION_STRUCTURE_BUILD_INPUT_READ_ONLY_BIT_KHR);
    const uint32_t count = uint32_t(instances.size());
    InstanceGeometry build(instance_buffer.address());
    const VkAccelerationStructureBuildSizesInfoKHR sizes = build.sizes(ctx, count);
    auto tlas = std::make_unique<AccelerationStructure>(ctx, VK_ACCELERATION_STRUCTURE_TYPE_TOP_LEVEL_KHR,
                                                        sizes.accelerationStructureSize);
    Buffer scratch(ctx, sizes.buildScratchSize + 256, VK_BUFFER_USAGE_STORAGE_BUFFER_BIT);
    build.info.dstAccelerationStructure = tlas->handle();
    build.info.scratchData.deviceAddress = align_up(scratch.address(), 256);
    VkAccelerationStructureBuildRangeInfoKHR range{count, 0, 0, 0};
    const VkAccelerationStructureBuildRangeInfoKHR* range_ptr = &range;
    ctx.submit_and_wait([&](VkCommandBuffer cmd) {
        ctx.rt().cmd_build_as(cmd, 1, &build.info, &range_ptr);
        barrier_after_build(cmd);
    });
    return tlas;
}

}  // namespace px
