// Vulkan instance, device selection and the few helpers every other part needs.
#pragma once
#include <vulkan/vulkan.h>

#include <atomic>
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

// Thrown when an allocation would pass the device-memory budget (or the driver is out of
// memory); Python sees parallax_core.DeviceMemoryError, a MemoryError.
struct DeviceMemoryError : VulkanError {
    using VulkanError::VulkanError;
};

void vk_check(VkResult result, const char* what);

// Khronos validation (issue 9): PARALLAX_VALIDATION=1 (read when the process's instance is
// created) enables VK_LAYER_KHRONOS_validation with synchronization validation and a
// VK_EXT_debug_utils messenger that records every warning and error.
bool validation_enabled();  // creates the process instance if needed
// The recorded messages (the first 1000 since the last clear) and how many there were.
std::vector<std::string> validation_messages(uint64_t* total = nullptr);
void clear_validation_messages();
class Context;
void validation_self_test(Context& ctx);  // makes the layer report two known mistakes
#define VK_CHECK(call) ::px::vk_check((call), #call)

struct DeviceReport {
    std::string name;
    std::string type;  // "discrete", "integrated", "cpu", "virtual", "other"
    uint32_t index = 0;
    bool ray_tracing = false;
    std::vector<std::string> missing;  // required extensions/features this device lacks
    // Whether the device's acceleration-structure builder splits primitives in their input
    // order (lavapipe halves the list at its middle), so that the core's primitive order
    // (bvh_order) shapes its trees. GPU drivers build their own trees from any order: ordering
    // for them only costs upload time (1M triangles: 0.4 s -> 1.2-1.6 s on the H200).
    bool builds_in_input_order() const { return type == "cpu"; }
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
    PFN_vkGetRayTracingShaderGroupStackSizeKHR get_group_stack_size = nullptr;
    // VK_KHR_pipeline_executable_properties, loaded where pipeline_statistics() is on
    PFN_vkGetPipelineExecutablePropertiesKHR get_executable_properties = nullptr;
    PFN_vkGetPipelineExecutableStatisticsKHR get_executable_statistics = nullptr;
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
    // PARALLAX_PIPELINE_STATS=FILE (read when the device is created), on a device with
    // VK_KHR_pipeline_executable_properties: pipelines capture the driver's statistics
    // (registers, stack, instructions: whatever it reports) for Session's log of them.
    bool pipeline_statistics() const { return pipeline_statistics_; }

    uint32_t memory_type(uint32_t type_bits, VkMemoryPropertyFlags flags) const;

    // Device memory the core holds (every Buffer: scene data, acceleration structures and
    // their scratch, film, staging) against a budget: reserve_memory() throws
    // DeviceMemoryError instead of passing it. Default budget: PARALLAX_MEMORY_BUDGET
    // (bytes, or with a K/M/G suffix), else 80% of the largest device-local heap on a GPU
    // and 50% on a CPU device (lavapipe's heap is the machine's RAM, shared with the host).
    void reserve_memory(VkDeviceSize bytes);
    void check_memory(VkDeviceSize bytes) const { check_memory(bytes, allocated_); }  // throws, reserves nothing
    void release_memory(VkDeviceSize bytes) { allocated_ -= bytes; }
    VkDeviceSize memory_allocated() const { return allocated_; }
    VkDeviceSize memory_budget() const { return budget_; }
    VkDeviceSize memory_heap() const { return heap_; }
    void set_memory_budget(VkDeviceSize bytes);  // 0: the default
    // Records with `record`, submits, and waits (device loss becomes an exception).
    // Thread-safe: submissions of all sessions on this device are serialised.
    // A submission that has not finished within submit_timeout_ns() is taken for a hung device
    // (a driver or shader fault): it throws, and so does every later submission on this
    // device, instead of waiting for ever (Blender must not hang).
    void submit_and_wait(const std::function<void(VkCommandBuffer)>& record);
    // PARALLAX_DEVICE_TIMEOUT_S (seconds) where set, else 120 s on a GPU (one submission holds
    // about 2^30 rays) and none on the CPU (lavapipe runs on the host's threads).
    uint64_t submit_timeout_ns() const;
    // Whether a submission timed out. The objects it uses may still be in use then: Buffer,
    // AccelerationStructure, DescriptorSet and pipeline destructors leave them to the process's
    // end instead of destroying them (invalid while in use: lavapipe, still running it, crashed).
    bool hung() const { return hung_flag_; }

private:
    VkInstance instance_ = VK_NULL_HANDLE;  // the process-wide instance, not owned
    VkPhysicalDevice physical_ = VK_NULL_HANDLE;
    VkDevice device_ = VK_NULL_HANDLE;
    VkQueue queue_ = VK_NULL_HANDLE;
    uint32_t queue_family_ = 0;
    VkCommandPool pool_ = VK_NULL_HANDLE;
    VkFence fence_ = VK_NULL_HANDLE;
    std::mutex submit_mutex_;  // guards pool_, fence_, queue_ and hung_
    std::string hung_;         // why the device is taken for hung ("": it is not)
    std::atomic<bool> hung_flag_{false};  // !hung_.empty(), for destructors on any thread
    RayTracingFunctions rt_{};
    bool pipeline_statistics_ = false;
    VkPhysicalDeviceRayTracingPipelinePropertiesKHR rt_props_{};
    VkPhysicalDeviceMemoryProperties memory_props_{};
    DeviceReport report_;
    void check_memory(VkDeviceSize bytes, VkDeviceSize held) const;
    std::atomic<VkDeviceSize> allocated_{0};
    VkDeviceSize heap_ = 0, budget_ = 0;
};

}  // namespace px
