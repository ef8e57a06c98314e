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

// The guiding regions' structures: a TLAS of one untransformed
// instance (hit group `sbt_offset`) of a BLAS over boxes (VkAabbPositionsKHR), procedural and
// not opaque (any-hit shaders run). Storage, scratch and the instance are kept across builds
// and grow (doubling) only when more boxes come; builds and refits are recorded into the
// caller's command buffer. A rebuild then costs no allocation and no submit of its own (each
// was ~1 ms on the H200, and the guiding regions' refinement rebuilt every few frames).
class AabbAccel {
public:
    AabbAccel(Context& ctx, uint32_t sbt_offset);
    // Room for `count` boxes (at most `limit` when growing by doubling); true where the
    // structures were replaced (the TLAS descriptor must be bound again).
    bool reserve(uint32_t count, uint32_t limit = ~0u);
    // Builds the BLAS over the first `count` boxes of `aabbs` (or refits it: the same count as
    // its last build, the boxes moved or grown), then the TLAS over it. Needs reserve(count).
    void record_build(VkCommandBuffer cmd, const Buffer& aabbs, uint32_t count, bool refit = false);
    VkAccelerationStructureKHR tlas() const { return tlas_->handle(); }
    VkDeviceSize blas_bytes() const { return blas_ ? blas_->size() : 0; }

private:
    Context& ctx_;
    uint32_t sbt_offset_;
    uint32_t capacity_ = 0, built_count_ = 0;
    std::unique_ptr<AccelerationStructure> blas_, tlas_;
    Buffer instance_, scratch_;
};

// A TLAS over `instances` (in the given order: order them spatially first on lavapipe).
std::unique_ptr<AccelerationStructure> build_tlas(Context& ctx, const std::vector<TlasInstance>& instances);

}  // namespace px
