// A VkBuffer with its own memory. Device-local on GPUs (filled through a staging copy),
// host-visible on CPU devices where the two are the same memory anyway.
#pragma once
#include "vk/context.h"

#include <vector>

namespace px {

class Buffer {
public:
    Buffer() = default;
    // `readback`: host-visible memory the CPU reads fast (HOST_CACHED where the device has it:
    // reads of uncached, write-combined memory run at about 1 GB/s).
    Buffer(Context& ctx, VkDeviceSize size, VkBufferUsageFlags usage, bool host_visible = false, bool readback = false);
    ~Buffer() { release(); }
    Buffer(Buffer&& o) noexcept { *this = std::move(o); }
    Buffer& operator=(Buffer&& o) noexcept;
    Buffer(const Buffer&) = delete;
    Buffer& operator=(const Buffer&) = delete;

    // Creates a buffer holding `bytes` (a 16-byte buffer when empty: Vulkan forbids size 0).
    static Buffer with_data(Context& ctx, const void* data, size_t bytes, VkBufferUsageFlags usage);
    template <class T>
    static Buffer with_vector(Context& ctx, const std::vector<T>& v, VkBufferUsageFlags usage) {
        return with_data(ctx, v.data(), v.size() * sizeof(T), usage);
    }

    void upload(const void* data, size_t bytes, size_t offset = 0);
    void download(void* data, size_t bytes, size_t offset = 0) const;
    void fill_zero();
    // Records zeroing the first `bytes` (VK_WHOLE_SIZE: all) into `cmd`, made visible to the
    // ray-tracing shaders recorded after it (queue counters cleared at a frame's start).
    void record_fill_zero(VkCommandBuffer cmd, VkDeviceSize bytes) const;

    VkBuffer handle() const { return buffer_; }
    VkDeviceSize size() const { return size_; }
    VkDeviceAddress address() const { return address_; }
    bool valid() const { return buffer_ != VK_NULL_HANDLE; }

private:
    void release();
    Context* ctx_ = nullptr;
    VkBuffer buffer_ = VK_NULL_HANDLE;
    VkDeviceMemory memory_ = VK_NULL_HANDLE;
    VkDeviceSize size_ = 0;
    VkDeviceSize reserved_ = 0;  // counted against the context's memory budget
    VkDeviceAddress address_ = 0;
    void* mapped_ = nullptr;  // host-visible buffers stay mapped
};

// Usage of every storage buffer the shaders read.
constexpr VkBufferUsageFlags kStorageUsage = VK_BUFFER_USAGE_STORAGE_BUFFER_BIT |
                                             VK_BUFFER_USAGE_TRANSFER_DST_BIT |
                                             VK_BUFFER_USAGE_TRANSFER_SRC_BIT |
                                             VK_BUFFER_USAGE_SHADER_DEVICE_ADDRESS_BIT;

}  // namespace px
