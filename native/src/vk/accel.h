// Bottom- and top-level acceleration structures.
#pragma once
#include "vk/buffer.h"

#include <array>
#include <memory>

namespace px {

class AccelerationStructure {
public:
    AccelerationStructure(Context& ctx, VkAccelerationStructureTypeKHR type, VkDeviceSize size);
    ~AccelerationStructure();
    AccelerationStructure(const AccelerationStructure&) = delete;
    AccelerationStructure& operator=(const AccelerationStructure&) = delete;
    VkAccelerationStructureKHR handle() const { return as_; }
    VkDeviceAddress address() const { return address_; }
    VkDeviceSize size() const { return storage_.size(); }

private:
    Context& ctx_;
    Buffer storage_;
    VkAccelerationStructureKHR as_ = VK_NULL_HANDLE;
    VkDeviceAddress address_ = 0;
};

struct TriangleRange {
    uint32_t first_triangle;
    uint32_t triangle_count;
};

// One BLAS per range, all built in one submission. Indices are global into `positions`.
std::vector<std::unique_ptr<AccelerationStructure>> build_triangle_blases(
    Context& ctx, const Buffer& positions, uint32_t vertex_count, const Buffer& indices,
    const std::vector<TriangleRange>& ranges);

struct TlasInstance {
    std::array<float, 12> transform;  // rows of a 3x4 matrix
    uint32_t custom_index;            // gl_InstanceCustomIndexEXT (24 bits)
    uint32_t mask;
    uint32_t sbt_offset;
    VkDeviceAddress blas;
};

// A BLAS over `count` AABBs (VkAabbPositionsKHR: 6 floats each) at the start of `aabbs`:
// procedural, not opaque (any-hit shaders run), built to allow in-place refits.
std::unique_ptr<AccelerationStructure> build_aabb_blas(Context& ctx, const Buffer& aabbs, uint32_t count);
// Refits `blas` (built by build_aabb_blas with the same count) to the AABBs' new bounds.
void refit_aabb_blas(Context& ctx, AccelerationStructure& blas, const Buffer& aabbs, uint32_t count);

// A TLAS over `instances` (in the given order: order them spatially first on lavapipe).
std::unique_ptr<AccelerationStructure> build_tlas(Context& ctx, const std::vector<TlasInstance>& instances);
// A TLAS of one untransformed instance of `blas` with hit group `sbt_offset` (the irradiance
// cache's and the guiding regions' own structures).
std::unique_ptr<AccelerationStructure> build_tlas_over(Context& ctx, const AccelerationStructure& blas,
                                                       uint32_t sbt_offset);

}  // namespace px
