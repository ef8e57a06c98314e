// Vulkan instance, device selection and the few helpers every other part needs.
#pragma once
#include <vulkan/vulkan.h>

#include <functional>
#include <memory>
#include <mutex>
#include <stdexcept>
#include <string>
#include <vector>

namespace px {

// Thrown for every Vulkan failure; nanobind turns it into a Python RuntimeError.
struct VulkanError : std::runtime_error {
    using std::runtime_error::runtime_error;
};

void vk_check(VkResult result, const char* what);
#define VK_CHECK(call) ::px::vk_check((call), #call)

struct DeviceReport {
    std::string name;
    std::string type;  // "discrete", "integrated", "cpu", "virtual", "other"
    uint32_t index = 0;
    bool ray_tracing = false;
    std::vector<std::string> missing;  // required extensions/features this device lacks
};

// Extension functions that the loader does not export directly.
struct RayTracingFunctions {
    PFN_vkCreateAccelerationStructureKHR create_as = nullptr;
    PFN_vkDestroyAccelerationStructureKHR destroy_as = nullptr;
    PFN_vkGetAccelerationStructureBuildSizesKHR get_build_sizes = nullptr;
    PFN_vkCmdBuildAccelerationStructuresKHR cmd_build_as = nullptr;
    PFN_vkGetAccelerationStructureDeviceAddressKHR get_as_address = nullptr;
    PFN_vkCreateRayTracingPipelinesKHR create_rt_pipelines = nullptr;
    PFN_vkGetRayTracingShaderGroupHandlesKHR get_group_handles = nullptr;
    PFN_vkCmdTraceRaysKHR cmd_trace_rays = nullptr;
};

class Context {
public:
    // The device `report` describes (an index from enumerate()); use shared() instead.
    explicit Context(const DeviceReport& report);
    ~Context();
    Context(const Context&) = delete;
    Context& operator=(const Context&) = delete;

    // The process-wide context of the device `selector` picks ("auto": discrete GPU first,
    // else any GPU, else lavapipe; "cpu", "gpu" or an index): sessions on one device share
    // its VkDevice, which lives as long as the process (a device per session exhausts
    // drivers; Blender has several sessions).
    static std::shared_ptr<Context> shared(const std::string& selector);

    static std::vector<DeviceReport> enumerate();
    // Index that `selector` picks among `reports`; throws with the reason if none fits.
    static uint32_t choose(const std::vector<DeviceReport>& reports, const std::string& selector);

    VkDevice device() const { return device_; }
    VkPhysicalDevice physical() const { return physical_; }
    VkQueue queue() const { return queue_; }
    const RayTracingFunctions& rt() const { return rt_; }
    const VkPhysicalDeviceRayTracingPipelinePropertiesKHR& rt_properties() const { return rt_props_; }
    const DeviceReport& report() const { return report_; }
    bool is_cpu() const { return report_.type == "cpu"; }

    uint32_t memory_type(uint32_t type_bits, VkMemoryPropertyFlags flags) const;
    // Records with `record`, submits, and waits (device loss becomes an exception).
    // Thread-safe: submissions of all sessions on this device are serialised.
    void submit_and_wait(const std::function<void(VkCommandBuffer)>& record);

private:
    VkInstance instance_ = VK_NULL_HANDLE;  // the process-wide instance, not owned
    VkPhysicalDevice physical_ = VK_NULL_HANDLE;
    VkDevice device_ = VK_NULL_HANDLE;
    VkQueue queue_ = VK_NULL_HANDLE;
    uint32_t queue_family_ = 0;
    VkCommandPool pool_ = VK_NULL_HANDLE;
    VkFence fence_ = VK_NULL_HANDLE;
    std::mutex submit_mutex_;  // guards pool_, fence_ and queue_
    RayTracingFunctions rt_{};
    VkPhysicalDeviceRayTracingPipelinePropertiesKHR rt_props_{};
    VkPhysicalDeviceMemoryProperties memory_props_{};
    DeviceReport report_;
};

}  // namespace px
