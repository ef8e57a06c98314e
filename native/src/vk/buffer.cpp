#include "vk/buffer.h"

#include <algorithm>
#include <cstring>

namespace px {

Buffer::Buffer(Context& ctx, VkDeviceSize size, VkBufferUsageFlags usage, bool host_visible, bool readback)
    : ctx_(&ctx) {
    size_ = std::max<VkDeviceSize>(size, 16);
    host_visible = host_visible || ctx.is_cpu();
    usage |= VK_BUFFER_USAGE_SHADER_DEVICE_ADDRESS_BIT | VK_BUFFER_USAGE_TRANSFER_DST_BIT |
             VK_BUFFER_USAGE_TRANSFER_SRC_BIT;
    ctx.check_memory(size_);  // before the driver sees a size it may not be able to hold
    VkBufferCreateInfo info{VK_STRUCTURE_TYPE_BUFFER_CREATE_INFO};
    info.size = size_;
    info.usage = usage;
    VK_CHECK(vkCreateBuffer(ctx.device(), &info, nullptr, &buffer_));
    VkMemoryRequirements req;
    vkGetBufferMemoryRequirements(ctx.device(), buffer_, &req);
    VkMemoryAllocateFlagsInfo flags{VK_STRUCTURE_TYPE_MEMORY_ALLOCATE_FLAGS_INFO};
    flags.flags = VK_MEMORY_ALLOCATE_DEVICE_ADDRESS_BIT;
    VkMemoryAllocateInfo alloc{VK_STRUCTURE_TYPE_MEMORY_ALLOCATE_INFO};
    alloc.pNext = &flags;
    alloc.allocationSize = req.size;
    const VkMemoryPropertyFlags host = VK_MEMORY_PROPERTY_HOST_VISIBLE_BIT | VK_MEMORY_PROPERTY_HOST_COHERENT_BIT;
    bool typed = false;
    if (readback && !ctx.is_cpu()) {
        try {
            alloc.memoryTypeIndex = ctx.memory_type(req.memoryTypeBits, host | VK_MEMORY_PROPERTY_HOST_CACHED_BIT);
            typed = true;
        } catch (const VulkanError&) {  // no cached host memory: the coherent one below
        }
    }
    if (!typed)
        alloc.memoryTypeIndex = ctx.memory_type(req.memoryTypeBits, host_visible ? host : VK_MEMORY_PROPERTY_DEVICE_LOCAL_BIT);
    try {
        ctx.reserve_memory(req.size);  // throws DeviceMemoryError past the budget
    } catch (...) {
        vkDestroyBuffer(ctx.device(), buffer_, nullptr);
        buffer_ = VK_NULL_HANDLE;
        throw;
    }
    reserved_ = req.size;
    VkResult r = vkAllocateMemory(ctx.device(), &alloc, nullptr, &memory_);
    if (r != VK_SUCCESS) {
        release();
        const std::string what = "vkAllocateMemory (" + std::to_string(req.size >> 20) + " MiB)";
        if (r == VK_ERROR_OUT_OF_DEVICE_MEMORY || r == VK_ERROR_OUT_OF_HOST_MEMORY)
            throw DeviceMemoryError("Vulkan: " + what + " failed: the device is out of memory (lower "
                                    "parallax_core.set_memory_budget to stay below what it can hold)");
        vk_check(r, what.c_str());
    }
    VK_CHECK(vkBindBufferMemory(ctx.device(), buffer_, memory_, 0));
    if (host_visible) VK_CHECK(vkMapMemory(ctx.device(), memory_, 0, VK_WHOLE_SIZE, 0, &mapped_));
    VkBufferDeviceAddressInfo ainfo{VK_STRUCTURE_TYPE_BUFFER_DEVICE_ADDRESS_INFO};
    ainfo.buffer = buffer_;
    address_ = vkGetBufferDeviceAddress(ctx.device(), &ainfo);
}

Buffer& Buffer::operator=(Buffer&& o) noexcept {
    if (this != &o) {
        release();
        ctx_ = o.ctx_;
        buffer_ = o.buffer_;
        memory_ = o.memory_;
        size_ = o.size_;
        reserved_ = o.reserved_;
        address_ = o.address_;
        mapped_ = o.mapped_;
        o.buffer_ = VK_NULL_HANDLE;
        o.memory_ = VK_NULL_HANDLE;
        o.mapped_ = nullptr;
        o.reserved_ = 0;
    }
    return *this;
}

void Buffer::release() {
    if (!ctx_) return;
    if (!ctx_->hung()) {  // else the abandoned submission may still use it (Context::hung)
        if (buffer_) vkDestroyBuffer(ctx_->device(), buffer_, nullptr);
        if (memory_) vkFreeMemory(ctx_->device(), memory_, nullptr);
    }
    ctx_->release_memory(reserved_);
    reserved_ = 0;
    buffer_ = VK_NULL_HANDLE;
    memory_ = VK_NULL_HANDLE;
    mapped_ = nullptr;
}

Buffer Buffer::with_data(Context& ctx, const void* data, size_t bytes, VkBufferUsageFlags usage) {
    Buffer b(ctx, bytes, usage);
    if (bytes) b.upload(data, bytes);
    return b;
}

void Buffer::upload(const void* data, size_t bytes, size_t offset) {
    if (!bytes) return;
    if (mapped_) {
        std::memcpy(static_cast<char*>(mapped_) + offset, data, bytes);
        return;
    }
    Buffer staging(*ctx_, bytes, VK_BUFFER_USAGE_TRANSFER_SRC_BIT, true);
    staging.upload(data, bytes);
    ctx_->submit_and_wait([&](VkCommandBuffer cmd) {
        VkBufferCopy region{0, offset, bytes};
        vkCmdCopyBuffer(cmd, staging.buffer_, buffer_, 1, &region);
    });
}

void Buffer::download(void* data, size_t bytes, size_t offset) const {
    if (!bytes) return;
    if (mapped_) {
        std::memcpy(data, static_cast<const char*>(mapped_) + offset, bytes);
        return;
    }
    Buffer staging(*ctx_, bytes, VK_BUFFER_USAGE_TRANSFER_DST_BIT, true, true);
    ctx_->submit_and_wait([&](VkCommandBuffer cmd) {
        VkBufferCopy region{offset, 0, bytes};
        vkCmdCopyBuffer(cmd, buffer_, staging.buffer_, 1, &region);
    });
    staging.download(data, bytes);
}

void Buffer::fill_zero() {
    if (mapped_) {
        std::memset(mapped_, 0, size_);
        return;
    }
    ctx_->submit_and_wait([&](VkCommandBuffer cmd) { vkCmdFillBuffer(cmd, buffer_, 0, VK_WHOLE_SIZE, 0); });
}

void Buffer::record_fill_zero(VkCommandBuffer cmd, VkDeviceSize bytes) const {
    vkCmdFillBuffer(cmd, buffer_, 0, bytes, 0);
    VkMemoryBarrier b{VK_STRUCTURE_TYPE_MEMORY_BARRIER};
    b.srcAccessMask = VK_ACCESS_TRANSFER_WRITE_BIT;
    b.dstAccessMask = VK_ACCESS_SHADER_READ_BIT | VK_ACCESS_SHADER_WRITE_BIT;
    vkCmdPipelineBarrier(cmd, VK_PIPELINE_STAGE_TRANSFER_BIT, VK_PIPELINE_STAGE_RAY_TRACING_SHADER_BIT_KHR, 0, 1, &b, 0,
                         nullptr, 0, nullptr);
}

}  // namespace px
