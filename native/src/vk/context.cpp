#include "vk/context.h"

#include <algorithm>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <map>
#include <thread>

namespace px {

static const char* result_name(VkResult r) {
    switch (r) {
        case VK_ERROR_OUT_OF_HOST_MEMORY: return "out of host memory";
        case VK_ERROR_OUT_OF_DEVICE_MEMORY: return "out of device memory";
        case VK_ERROR_DEVICE_LOST: return "device lost";
        case VK_ERROR_INITIALIZATION_FAILED: return "initialization failed";
        case VK_ERROR_EXTENSION_NOT_PRESENT: return "extension not present";
        case VK_ERROR_FEATURE_NOT_PRESENT: return "feature not present";
        case VK_ERROR_INCOMPATIBLE_DRIVER: return "incompatible driver (no Vulkan driver found)";
        case VK_TIMEOUT: return "timeout";
        default: return "error";
    }
}

void vk_check(VkResult result, const char* what) {
    if (result != VK_SUCCESS)
        throw VulkanError(std::string("Vulkan: ") + what + " failed: " + result_name(result) +
                          " (" + std::to_string(int(result)) + ")");
}

static const std::vector<const char*> kRequiredExtensions = {
    VK_KHR_ACCELERATION_STRUCTURE_EXTENSION_NAME,
    VK_KHR_RAY_TRACING_PIPELINE_EXTENSION_NAME,
    VK_KHR_DEFERRED_HOST_OPERATIONS_EXTENSION_NAME,
};

// Lavapipe splits a dispatch into one chunk per worker thread; with one thread per core the
// core that drew the cheap chunk (sky) idles while another traces the geometry. Four threads
// per core let the OS balance them: 1.3 -> 1.95 cores busy on 2 cores (bench/).
// Its shaders run 8 invocations per SIMD group at the default 256-bit vectors; rays diverge,
// and the group runs its slowest lane's traversal and path to the end. At 128 bits (4 lanes)
// whole renders take 5-9% less time, images bit for bit the same
// (bench/results/lavapipe_vector_width).
// Mesa's shader cache (a database in 50 parts by default) writes into one part until another
// process holds its lock, and caps each part at 1/50 of the cache's 1 GB: 21 MB, about a
// hundred of our pipelines. Past that it evicts them, and they compile cold again (after a
// whole `make test`, an ADRRS test's pipelines did: README, Robustness). One part holds the
// whole 1 GB. And a directory of our own (XDG_CACHE_HOME or ~/.cache, then parallax/): Blender's
// OpenGL, where it is Mesa's too (llvmpipe, radeonsi, iris), opens the default cache with its 50
// parts and trims the part it writes to, ours, to 21 MB (measured: a pipeline compiled again
// after a 50-part process wrote to the cache). All four are set once, before the first
// instance, unless the user chose a value (Mesa reads them once per process).
static void tune_lavapipe() {
    static std::once_flag once;
    std::call_once(once, [] {
        unsigned threads = std::min(4u * std::max(1u, std::thread::hardware_concurrency()), 32u);
        setenv("LP_NUM_THREADS", std::to_string(threads).c_str(), 0);
        setenv("LP_NATIVE_VECTOR_WIDTH", "128", 0);
        setenv("MESA_DISK_CACHE_DATABASE_NUM_PARTS", "1", 0);
        const char* chosen = std::getenv("MESA_SHADER_CACHE_DIR");
        const char* xdg = std::getenv("XDG_CACHE_HOME");
        const char* home = std::getenv("HOME");
        const std::string base = xdg && *xdg ? xdg : home && *home ? std::string(home) + "/.cache" : "";
        if (!(chosen && *chosen) && !base.empty()) {
            std::error_code ignored;  // no directory: Mesa goes without a cache, as it would anyway
            std::filesystem::create_directories(base + "/parallax", ignored);
            setenv("MESA_SHADER_CACHE_DIR", (base + "/parallax").c_str(), 1);
        }
    });
}

// ---- Validation (issue 9) --------------------------------------------------------------

static bool validation_requested() {
    const char* v = std::getenv("PARALLAX_VALIDATION");
    return v && *v && std::strcmp(v, "0") != 0;
}

namespace {
struct ValidationLog {
    std::mutex mutex;
    std::vector<std::string> messages;
    uint64_t total = 0;
    bool enabled = false;
};
ValidationLog& validation_log() {
    static auto* log = new ValidationLog();  // never destroyed: messages may arrive at exit
    return *log;
}
}  // namespace

static VKAPI_ATTR VkBool32 VKAPI_CALL on_validation_message(VkDebugUtilsMessageSeverityFlagBitsEXT severity,
                                                            VkDebugUtilsMessageTypeFlagsEXT,
                                                            const VkDebugUtilsMessengerCallbackDataEXT* data,
                                                            void*) {
    std::string text = std::string(severity & VK_DEBUG_UTILS_MESSAGE_SEVERITY_ERROR_BIT_EXT ? "error" : "warning") +
                       " [" + (data->pMessageIdName ? data->pMessageIdName : "?") + "] " +
                       (data->pMessage ? data->pMessage : "");
    std::fprintf(stderr, "parallax: Vulkan validation %s\n", text.c_str());
    auto& log = validation_log();
    std::lock_guard<std::mutex> lock(log.mutex);
    if (log.messages.size() < 1000) log.messages.push_back(std::move(text));
    ++log.total;
    return VK_FALSE;  // never abort the call
}

static VkDebugUtilsMessengerCreateInfoEXT messenger_info() {
    VkDebugUtilsMessengerCreateInfoEXT info{VK_STRUCTURE_TYPE_DEBUG_UTILS_MESSENGER_CREATE_INFO_EXT};
    info.messageSeverity = VK_DEBUG_UTILS_MESSAGE_SEVERITY_WARNING_BIT_EXT | VK_DEBUG_UTILS_MESSAGE_SEVERITY_ERROR_BIT_EXT;
    info.messageType = VK_DEBUG_UTILS_MESSAGE_TYPE_GENERAL_BIT_EXT | VK_DEBUG_UTILS_MESSAGE_TYPE_VALIDATION_BIT_EXT |
                       VK_DEBUG_UTILS_MESSAGE_TYPE_PERFORMANCE_BIT_EXT;
    info.pfnUserCallback = on_validation_message;
    return info;
}

static bool has_instance_layer(const char* name) {
    uint32_t n = 0;
    vkEnumerateInstanceLayerProperties(&n, nullptr);
    std::vector<VkLayerProperties> layers(n);
    vkEnumerateInstanceLayerProperties(&n, layers.data());
    return std::any_of(layers.begin(), layers.end(), [&](const VkLayerProperties& l) { return !strcmp(l.layerName, name); });
}

static VkInstance create_instance() {
    tune_lavapipe();
    VkApplicationInfo app{VK_STRUCTURE_TYPE_APPLICATION_INFO};
    app.pApplicationName = "Parallax";
    app.apiVersion = VK_API_VERSION_1_2;
    VkInstanceCreateInfo info{VK_STRUCTURE_TYPE_INSTANCE_CREATE_INFO};
    info.pApplicationInfo = &app;

    const bool validate = validation_requested();
    const char* layer = "VK_LAYER_KHRONOS_validation";
    const char* extensions[] = {VK_EXT_DEBUG_UTILS_EXTENSION_NAME, VK_EXT_VALIDATION_FEATURES_EXTENSION_NAME};
    // Synchronization validation on top of the layer's default (core) checks.
    VkValidationFeatureEnableEXT enables[] = {VK_VALIDATION_FEATURE_ENABLE_SYNCHRONIZATION_VALIDATION_EXT};
    VkValidationFeaturesEXT features{VK_STRUCTURE_TYPE_VALIDATION_FEATURES_EXT};
    features.enabledValidationFeatureCount = 1;
    features.pEnabledValidationFeatures = enables;
    VkDebugUtilsMessengerCreateInfoEXT messenger = messenger_info();  // also covers instance creation
    if (validate) {
        if (!has_instance_layer(layer))
            throw VulkanError("PARALLAX_VALIDATION is set but VK_LAYER_KHRONOS_validation is not installed "
                              "(Debian: apt install vulkan-validationlayers; `make setup` installs it)");
        info.enabledLayerCount = 1;
        info.ppEnabledLayerNames = &layer;
        info.enabledExtensionCount = 2;
        info.ppEnabledExtensionNames = extensions;
        features.pNext = &messenger;
        info.pNext = &features;
    }
    VkInstance instance = VK_NULL_HANDLE;
    VkResult r = vkCreateInstance(&info, nullptr, &instance);
    if (r != VK_SUCCESS)
        throw VulkanError(
            std::string("no Vulkan driver could be loaded (vkCreateInstance: ") + result_name(r) +
            "). Install Mesa's lavapipe (mesa-vulkan-drivers from bookworm-backports: run "
            "`make setup`) or an NVIDIA driver.");
    if (validate) {
        auto create = reinterpret_cast<PFN_vkCreateDebugUtilsMessengerEXT>(
            vkGetInstanceProcAddr(instance, "vkCreateDebugUtilsMessengerEXT"));
        VkDebugUtilsMessengerEXT handle = VK_NULL_HANDLE;  // lives as long as the instance
        VkDebugUtilsMessengerCreateInfoEXT minfo = messenger_info();
        if (!create || create(instance, &minfo, nullptr, &handle) != VK_SUCCESS)
            throw VulkanError("PARALLAX_VALIDATION: could not create the VK_EXT_debug_utils messenger");
        validation_log().enabled = true;
    }
    return instance;
}

struct Features {
    VkPhysicalDeviceFeatures2 base{VK_STRUCTURE_TYPE_PHYSICAL_DEVICE_FEATURES_2};
    VkPhysicalDeviceVulkan12Features v12{VK_STRUCTURE_TYPE_PHYSICAL_DEVICE_VULKAN_1_2_FEATURES};
    VkPhysicalDeviceAccelerationStructureFeaturesKHR as{
        VK_STRUCTURE_TYPE_PHYSICAL_DEVICE_ACCELERATION_STRUCTURE_FEATURES_KHR};
    VkPhysicalDeviceRayTracingPipelineFeaturesKHR rt{
        VK_STRUCTURE_TYPE_PHYSICAL_DEVICE_RAY_TRACING_PIPELINE_FEATURES_KHR};
    Features() {
        base.pNext = &v12;
        v12.pNext = &as;
        as.pNext = &rt;
    }
};

static bool has_extension(VkPhysicalDevice pd, const char* name) {
    uint32_t n = 0;
    vkEnumerateDeviceExtensionProperties(pd, nullptr, &n, nullptr);
    std::vector<VkExtensionProperties> exts(n);
    vkEnumerateDeviceExtensionProperties(pd, nullptr, &n, exts.data());
    return std::any_of(exts.begin(), exts.end(), [&](const VkExtensionProperties& e) { return !strcmp(e.extensionName, name); });
}

static DeviceReport inspect(VkPhysicalDevice pd, uint32_t index) {
    VkPhysicalDeviceProperties props;
    vkGetPhysicalDeviceProperties(pd, &props);
    DeviceReport rep;
    rep.name = props.deviceName;
    rep.index = index;
    switch (props.deviceType) {
        case VK_PHYSICAL_DEVICE_TYPE_DISCRETE_GPU: rep.type = "discrete"; break;
        case VK_PHYSICAL_DEVICE_TYPE_INTEGRATED_GPU: rep.type = "integrated"; break;
        case VK_PHYSICAL_DEVICE_TYPE_CPU: rep.type = "cpu"; break;
        case VK_PHYSICAL_DEVICE_TYPE_VIRTUAL_GPU: rep.type = "virtual"; break;
        default: rep.type = "other";
    }
    if (props.apiVersion < VK_API_VERSION_1_2) rep.missing.push_back("Vulkan 1.2");
    for (const char* req : kRequiredExtensions)
        if (!has_extension(pd, req)) rep.missing.push_back(req);
    if (rep.missing.empty()) {
        Features f;
        vkGetPhysicalDeviceFeatures2(pd, &f.base);
        if (!f.v12.bufferDeviceAddress) rep.missing.push_back("bufferDeviceAddress");
        if (!f.v12.scalarBlockLayout) rep.missing.push_back("scalarBlockLayout");
        if (!f.as.accelerationStructure) rep.missing.push_back("accelerationStructure");
        if (!f.rt.rayTracingPipeline) rep.missing.push_back("rayTracingPipeline");
    }
    rep.ray_tracing = rep.missing.empty();
    return rep;
}

// One VkInstance for the process, never destroyed: NVIDIA's driver (seen on the H200
// machines) stops creating instances after a few hundred create/destroy cycles.
static VkInstance process_instance() {
    static std::mutex mutex;
    static VkInstance instance = VK_NULL_HANDLE;
    std::lock_guard<std::mutex> lock(mutex);
    if (!instance) instance = create_instance();  // throws (and retries next time) without a driver
    return instance;
}

std::vector<DeviceReport> Context::enumerate() {
    VkInstance instance = process_instance();
    uint32_t n = 0;
    vkEnumeratePhysicalDevices(instance, &n, nullptr);
    std::vector<VkPhysicalDevice> pds(n);
    vkEnumeratePhysicalDevices(instance, &n, pds.data());
    std::vector<DeviceReport> reports;
    for (uint32_t i = 0; i < n; ++i) reports.push_back(inspect(pds[i], i));
    return reports;
}

uint32_t Context::choose(const std::vector<DeviceReport>& reports, const std::string& selector) {
    std::string why;
    for (const auto& r : reports)
        if (!r.ray_tracing) {
            why += "\n  " + r.name + " (" + r.type + "): lacks";
            for (const auto& m : r.missing) why += " " + m;
        }
    auto fail = [&](const std::string& msg) -> uint32_t {
        throw VulkanError(msg + (why.empty() ? "" : "\nDevices without ray tracing:" + why) +
                          "\nOn Debian 12, `make setup` installs lavapipe with ray tracing "
                          "(Mesa 25 from bookworm-backports); Mesa 22 has none.");
    };
    if (reports.empty()) return fail("no Vulkan device found");
    bool digits = !selector.empty() && std::all_of(selector.begin(), selector.end(), ::isdigit);
    if (digits) {
        uint32_t i = uint32_t(std::stoul(selector));
        if (i >= reports.size())
            return fail("device index " + selector + " out of range (" + std::to_string(reports.size()) + " devices)");
        if (!reports[i].ray_tracing) return fail("device " + selector + " (" + reports[i].name + ") cannot ray-trace");
        return i;
    }
    auto first = [&](auto pred) -> int {
        for (const auto& r : reports)
            if (r.ray_tracing && pred(r)) return int(r.index);
        return -1;
    };
    auto is_gpu = [](const DeviceReport& r) { return r.type != "cpu"; };
    auto is_cpu = [](const DeviceReport& r) { return r.type == "cpu"; };
    auto is_discrete = [](const DeviceReport& r) { return r.type == "discrete"; };
    int pick = -1;
    if (selector == "auto" || selector.empty()) {
        pick = first(is_discrete);
        if (pick < 0) pick = first(is_gpu);
        if (pick < 0) pick = first(is_cpu);
    } else if (selector == "gpu") {
        pick = first(is_discrete);
        if (pick < 0) pick = first(is_gpu);
    } else if (selector == "cpu") {
        pick = first(is_cpu);
    } else {
        return fail("unknown device selector '" + selector + "' (use auto, cpu, gpu or an index)");
    }
    if (pick < 0) return fail("no Vulkan device with ray tracing matches '" + selector + "'");
    return uint32_t(pick);
}

std::shared_ptr<Context> Context::shared(const std::string& selector) {
    static std::mutex mutex;
    // By device index. Devices, like the instance, live as long as the process (created on
    // first use, then reused: re-creating them per session is slow and wears drivers out);
    // the map is never destroyed, so no Vulkan call runs during static destruction at exit.
    static auto* contexts = new std::map<uint32_t, std::shared_ptr<Context>>();
    std::lock_guard<std::mutex> lock(mutex);
    auto reports = enumerate();
    uint32_t index = choose(reports, selector);
    auto& ctx = (*contexts)[index];
    if (!ctx) ctx = std::make_shared<Context>(reports[index]);
    return ctx;
}

Context::Context(const DeviceReport& report) : report_(report) {
    instance_ = process_instance();
    uint32_t n = 0;
    vkEnumeratePhysicalDevices(instance_, &n, nullptr);
    std::vector<VkPhysicalDevice> pds(n);
    vkEnumeratePhysicalDevices(instance_, &n, pds.data());
    physical_ = pds.at(report_.index);
    vkGetPhysicalDeviceMemoryProperties(physical_, &memory_props_);
    for (uint32_t i = 0; i < memory_props_.memoryHeapCount; ++i)
        if (memory_props_.memoryHeaps[i].flags & VK_MEMORY_HEAP_DEVICE_LOCAL_BIT)
            heap_ = std::max(heap_, memory_props_.memoryHeaps[i].size);
    set_memory_budget(0);  // before the device exists: a bad PARALLAX_MEMORY_BUDGET leaks nothing

    uint32_t qn = 0;
    vkGetPhysicalDeviceQueueFamilyProperties(physical_, &qn, nullptr);
    std::vector<VkQueueFamilyProperties> qprops(qn);
    vkGetPhysicalDeviceQueueFamilyProperties(physical_, &qn, qprops.data());
    queue_family_ = UINT32_MAX;
    for (uint32_t i = 0; i < qn; ++i)
        if ((qprops[i].queueFlags & VK_QUEUE_COMPUTE_BIT) && queue_family_ == UINT32_MAX) queue_family_ = i;
    if (queue_family_ == UINT32_MAX) throw VulkanError("device has no compute queue");

    float priority = 1.0f;
    VkDeviceQueueCreateInfo qinfo{VK_STRUCTURE_TYPE_DEVICE_QUEUE_CREATE_INFO};
    qinfo.queueFamilyIndex = queue_family_;
    qinfo.queueCount = 1;
    qinfo.pQueuePriorities = &priority;

    Features f;  // enable exactly what we need
    f.v12.bufferDeviceAddress = VK_TRUE;
    f.v12.scalarBlockLayout = VK_TRUE;
    f.as.accelerationStructure = VK_TRUE;
    f.rt.rayTracingPipeline = VK_TRUE;
    VkPhysicalDeviceFeatures2 supported{VK_STRUCTURE_TYPE_PHYSICAL_DEVICE_FEATURES_2};
    vkGetPhysicalDeviceFeatures2(physical_, &supported);
    f.base.features.shaderInt64 = supported.features.shaderInt64;

    std::vector<const char*> extensions = kRequiredExtensions;
    VkPhysicalDevicePipelineExecutablePropertiesFeaturesKHR executable_info{
        VK_STRUCTURE_TYPE_PHYSICAL_DEVICE_PIPELINE_EXECUTABLE_PROPERTIES_FEATURES_KHR};
    const char* stats_log = std::getenv("PARALLAX_PIPELINE_STATS");
    if (stats_log && *stats_log && has_extension(physical_, VK_KHR_PIPELINE_EXECUTABLE_PROPERTIES_EXTENSION_NAME)) {
        extensions.push_back(VK_KHR_PIPELINE_EXECUTABLE_PROPERTIES_EXTENSION_NAME);
        executable_info.pipelineExecutableInfo = VK_TRUE;
        f.rt.pNext = &executable_info;
        pipeline_statistics_ = true;
    }

    VkDeviceCreateInfo dinfo{VK_STRUCTURE_TYPE_DEVICE_CREATE_INFO};
    dinfo.pNext = &f.base;
    dinfo.queueCreateInfoCount = 1;
    dinfo.pQueueCreateInfos = &qinfo;
    dinfo.enabledExtensionCount = uint32_t(extensions.size());
    dinfo.ppEnabledExtensionNames = extensions.data();
    VK_CHECK(vkCreateDevice(physical_, &dinfo, nullptr, &device_));
    vkGetDeviceQueue(device_, queue_family_, 0, &queue_);

#define PX_LOAD(member, name) rt_.member = reinterpret_cast<PFN_##name>(vkGetDeviceProcAddr(device_, #name))
    PX_LOAD(create_as, vkCreateAccelerationStructureKHR);
    PX_LOAD(destroy_as, vkDestroyAccelerationStructureKHR);
    PX_LOAD(get_build_sizes, vkGetAccelerationStructureBuildSizesKHR);
    PX_LOAD(cmd_build_as, vkCmdBuildAccelerationStructuresKHR);
    PX_LOAD(get_as_address, vkGetAccelerationStructureDeviceAddressKHR);
    PX_LOAD(create_rt_pipelines, vkCreateRayTracingPipelinesKHR);
    PX_LOAD(get_group_handles, vkGetRayTracingShaderGroupHandlesKHR);
    PX_LOAD(cmd_trace_rays, vkCmdTraceRaysKHR);
    PX_LOAD(get_group_stack_size, vkGetRayTracingShaderGroupStackSizeKHR);
    if (pipeline_statistics_) {
        PX_LOAD(get_executable_properties, vkGetPipelineExecutablePropertiesKHR);
        PX_LOAD(get_executable_statistics, vkGetPipelineExecutableStatisticsKHR);
    }
#undef PX_LOAD

    rt_props_.sType = VK_STRUCTURE_TYPE_PHYSICAL_DEVICE_RAY_TRACING_PIPELINE_PROPERTIES_KHR;
    VkPhysicalDeviceProperties2 p2{VK_STRUCTURE_TYPE_PHYSICAL_DEVICE_PROPERTIES_2};
    p2.pNext = &rt_props_;
    vkGetPhysicalDeviceProperties2(physical_, &p2);

    VkCommandPoolCreateInfo pinfo{VK_STRUCTURE_TYPE_COMMAND_POOL_CREATE_INFO};
    pinfo.flags = VK_COMMAND_POOL_CREATE_RESET_COMMAND_BUFFER_BIT;
    pinfo.queueFamilyIndex = queue_family_;
    VK_CHECK(vkCreateCommandPool(device_, &pinfo, nullptr, &pool_));
    VkFenceCreateInfo finfo{VK_STRUCTURE_TYPE_FENCE_CREATE_INFO};
    VK_CHECK(vkCreateFence(device_, &finfo, nullptr, &fence_));
}

Context::~Context() {
    if (device_) {
        if (!hung()) vkDeviceWaitIdle(device_);
        vkDestroyFence(device_, fence_, nullptr);
        vkDestroyCommandPool(device_, pool_, nullptr);
        vkDestroyDevice(device_, nullptr);
    }
}

uint32_t Context::memory_type(uint32_t type_bits, VkMemoryPropertyFlags flags) const {
    for (uint32_t i = 0; i < memory_props_.memoryTypeCount; ++i)
        if ((type_bits & (1u << i)) && (memory_props_.memoryTypes[i].propertyFlags & flags) == flags) return i;
    throw VulkanError("no suitable memory type");
}

uint64_t Context::submit_timeout_ns() const {
    const char* text = std::getenv("PARALLAX_DEVICE_TIMEOUT_S");
    const double seconds = text && *text ? std::strtod(text, nullptr) : is_cpu() ? 0.0 : 120.0;
    return seconds > 0 ? uint64_t(seconds * 1e9) : UINT64_MAX;
}

void Context::submit_and_wait(const std::function<void(VkCommandBuffer)>& record) {
    std::lock_guard<std::mutex> lock(submit_mutex_);
    if (!hung_.empty()) throw VulkanError(hung_);
    VkCommandBufferAllocateInfo ainfo{VK_STRUCTURE_TYPE_COMMAND_BUFFER_ALLOCATE_INFO};
    ainfo.commandPool = pool_;
    ainfo.level = VK_COMMAND_BUFFER_LEVEL_PRIMARY;
    ainfo.commandBufferCount = 1;
    VkCommandBuffer cmd;
    VK_CHECK(vkAllocateCommandBuffers(device_, &ainfo, &cmd));
    struct Free {
        VkDevice d; VkCommandPool p; VkCommandBuffer c;
        ~Free() { vkFreeCommandBuffers(d, p, 1, &c); }
    } free_on_exit{device_, pool_, cmd};
    VkCommandBufferBeginInfo binfo{VK_STRUCTURE_TYPE_COMMAND_BUFFER_BEGIN_INFO};
    binfo.flags = VK_COMMAND_BUFFER_USAGE_ONE_TIME_SUBMIT_BIT;
    VK_CHECK(vkBeginCommandBuffer(cmd, &binfo));
    record(cmd);
    VK_CHECK(vkEndCommandBuffer(cmd));
    VkSubmitInfo sinfo{VK_STRUCTURE_TYPE_SUBMIT_INFO};
    sinfo.commandBufferCount = 1;
    sinfo.pCommandBuffers = &cmd;
    VK_CHECK(vkResetFences(device_, 1, &fence_));
    VK_CHECK(vkQueueSubmit(queue_, 1, &sinfo, fence_));
    const uint64_t timeout = submit_timeout_ns();
    const VkResult r = vkWaitForFences(device_, 1, &fence_, VK_TRUE, timeout);
    if (r == VK_TIMEOUT) {
        free_on_exit.c = VK_NULL_HANDLE;  // the device may still run it: never freed
        char seconds[32];
        std::snprintf(seconds, sizeof(seconds), "%g", timeout / 1e9);
        hung_ = report_.name + " did not finish a submission within " + seconds +
                " s (PARALLAX_DEVICE_TIMEOUT_S) and is taken for hung: restart the application to render on it again";
        hung_flag_ = true;
        throw VulkanError(hung_);
    }
    vk_check(r, "vkWaitForFences");
}

// ---- Device memory budget (issue 9) -----------------------------------------------------

static VkDeviceSize parse_bytes(const char* text) {
    char* end = nullptr;
    const double v = std::strtod(text, &end);
    double scale = 1;
    if (end && (*end == 'k' || *end == 'K')) scale = 1024.0;
    if (end && (*end == 'm' || *end == 'M')) scale = 1024.0 * 1024;
    if (end && (*end == 'g' || *end == 'G')) scale = 1024.0 * 1024 * 1024;
    if (end == text || !(v > 0) || v * scale > 1e18)
        throw std::invalid_argument(std::string("PARALLAX_MEMORY_BUDGET: '") + text +
                                    "' is not a size (bytes, or a number with K, M or G)");
    return VkDeviceSize(v * scale);
}

void Context::set_memory_budget(VkDeviceSize bytes) {
    if (bytes == 0) {
        const char* env = std::getenv("PARALLAX_MEMORY_BUDGET");
        bytes = env && *env ? parse_bytes(env) : VkDeviceSize(double(heap_) * (is_cpu() ? 0.5 : 0.8));
    }
    budget_ = bytes;
}

static std::string mib(VkDeviceSize bytes) {
    char buf[32];
    std::snprintf(buf, sizeof buf, "%.1f MiB", double(bytes) / (1024.0 * 1024.0));
    return buf;
}

void Context::check_memory(VkDeviceSize bytes, VkDeviceSize held) const {
    if (held + bytes > budget_)
        throw DeviceMemoryError("device memory budget exceeded: " + mib(bytes) + " more on top of the " + mib(held) +
                                " in use would pass the budget of " + mib(budget_) + " on " + report_.name +
                                " (parallax_core.set_memory_budget or PARALLAX_MEMORY_BUDGET sets it; the heap is " +
                                mib(heap_) + ")");
}

void Context::reserve_memory(VkDeviceSize bytes) {
    VkDeviceSize held = allocated_.load();
    do check_memory(bytes, held);
    while (!allocated_.compare_exchange_weak(held, held + bytes));
}

bool validation_enabled() {
    process_instance();
    return validation_log().enabled;
}

std::vector<std::string> validation_messages(uint64_t* total) {
    auto& log = validation_log();
    std::lock_guard<std::mutex> lock(log.mutex);
    if (total) *total = log.total;
    return log.messages;
}

// Two mistakes the layer must report and the driver survives: a buffer created without a
// usage bit (core validation) and two transfer writes to one buffer with no barrier between
// them (synchronization validation: WRITE_AFTER_WRITE).
void validation_self_test(Context& ctx) {
    VkBufferCreateInfo info{VK_STRUCTURE_TYPE_BUFFER_CREATE_INFO};
    info.size = 256;
    VkBuffer bad = VK_NULL_HANDLE;
    if (vkCreateBuffer(ctx.device(), &info, nullptr, &bad) == VK_SUCCESS) vkDestroyBuffer(ctx.device(), bad, nullptr);
    info.usage = VK_BUFFER_USAGE_TRANSFER_DST_BIT;
    VkBuffer buffer = VK_NULL_HANDLE;
    VK_CHECK(vkCreateBuffer(ctx.device(), &info, nullptr, &buffer));
    VkMemoryRequirements req;
    vkGetBufferMemoryRequirements(ctx.device(), buffer, &req);
    VkMemoryAllocateInfo alloc{VK_STRUCTURE_TYPE_MEMORY_ALLOCATE_INFO};
    alloc.allocationSize = req.size;
    alloc.memoryTypeIndex = ctx.memory_type(req.memoryTypeBits, 0);
    VkDeviceMemory memory = VK_NULL_HANDLE;
    VK_CHECK(vkAllocateMemory(ctx.device(), &alloc, nullptr, &memory));
    VK_CHECK(vkBindBufferMemory(ctx.device(), buffer, memory, 0));
    ctx.submit_and_wait([&](VkCommandBuffer cmd) {
        vkCmdFillBuffer(cmd, buffer, 0, 256, 1);
        vkCmdFillBuffer(cmd, buffer, 0, 256, 2);
    });
    vkDestroyBuffer(ctx.device(), buffer, nullptr);
    vkFreeMemory(ctx.device(), memory, nullptr);
}

void clear_validation_messages() {
    auto& log = validation_log();
    std::lock_guard<std::mutex> lock(log.mutex);
    log.messages.clear();
    log.total = 0;
}

}  // namespace px
