#include "render/session.h"
#include "render/pixel_filter.h"

#include "techniques/adrrs.h"
#include "techniques/guiding/guiding.h"
#include "techniques/irradiance_cache.h"

#include "shaders_embedded.h"
#include "../../../shaders/shared/ggx_tables.h"

#include <algorithm>
#include <chrono>
#include <condition_variable>
#include <thread>
#include <cstdlib>
#include <cstdio>
#include <cstring>
#include <limits>
#include <stdexcept>
#include <unistd.h>

namespace px {

Session::Session(uint32_t width, uint32_t height, const std::string& device) : width_(width), height_(height) {
    if (width == 0 || height == 0 || width > 16384 || height > 16384)
        throw std::invalid_argument("image size " + std::to_string(width) + "x" + std::to_string(height) +
                                    " is out of range (1..16384)");
    ctx_ = Context::shared(device);
    // The techniques, in the order their hooks run: the one place that names them.
    auto cache = std::make_unique<IrradianceCache>(*ctx_);
    auto adrrs = std::make_unique<Adrrs>(*ctx_, *cache);  // reads the cache as its adjoint
    techniques_.push_back(std::move(cache));
    techniques_.push_back(std::move(adrrs));
    techniques_.push_back(std::make_unique<Guiding>(*ctx_));
    std::vector<uint32_t> tlas_bindings = {BINDING_TLAS};
    for (const auto& t : techniques_)
        for (uint32_t b : t->tlas_bindings()) tlas_bindings.push_back(b);
    set_ = std::make_unique<DescriptorSet>(*ctx_, BINDING_COUNT, tlas_bindings);
    const size_t pixels = size_t(width) * height;
    for (const PassInfo& p : px::passes()) listed_passes_ |= 1u << p.index;
    ray_count_ = Buffer(*ctx_, pixels * sizeof(uint32_t), kStorageUsage);
    test_io_ = Buffer(*ctx_, 16, kStorageUsage);
    set_->bind_buffer(BINDING_RAY_COUNT, ray_count_);
    set_->bind_buffer(BINDING_TEST_IO, test_io_);
    technique_params_ = Buffer(*ctx_, sizeof(TechniqueParams), kStorageUsage);
    set_->bind_buffer(BINDING_TECH_PARAMS, technique_params_);
    ggx_tables_ = Buffer::with_data(*ctx_, GGX_TABLE_WORDS, sizeof(GGX_TABLE_WORDS), kStorageUsage);
    set_->bind_buffer(BINDING_GGX_TABLES, ggx_tables_);
    pixel_filter_ = Buffer(*ctx_, PIXEL_FILTER_TABLE_SIZE * sizeof(float), kStorageUsage);
    set_->bind_buffer(BINDING_PIXEL_FILTER, pixel_filter_);
    adaptive_ = std::make_unique<AdaptiveSampling>(*ctx_, width, height);
    adaptive_->bind(*set_);
    for (const auto& t : techniques_) t->bind(*set_);
    upload_technique_params();
    reset();
}

void Session::upload_technique_params() {
    TechniqueParams t{};
    for (const auto& technique : techniques_) technique->write_params(t);
    technique_params_.upload(&t, sizeof(t));
}

// Caller holds mutex_.
void Session::reset_accumulation(bool view_only) {
    stats_ = {};
    cursor_ = {};
    fallback_frame_ = film_after_fallback_ = false;
    allocate_film();
    film_.fill_zero();
    ray_count_.fill_zero();
    adaptive_->configure(params_);  // every pixel sampled again
    const std::pair<uint32_t, float> filter{params_.pixel_filter_type, params_.filter_width};
    if (filter != pixel_filter_uploaded_) {
        const std::vector<float> table = pixel_filter_table(filter.first, filter.second);
        pixel_filter_.upload(table.data(), table.size() * sizeof(float));
        pixel_filter_uploaded_ = filter;
    }
    if (!scene_) return;
    if (view_only) {  // what the techniques hold in world space stays
        for (const auto& t : techniques_) t->view_changed();
        return;
    }
    const TechniqueSetup setup{scene_->host(), scene_version_, width_, height_, film_passes()};
    for (const auto& t : techniques_) {
        // Built where a technique that is on needs it (Technique::needs), even if off itself.
        bool needed = false;
        for (const auto& other : techniques_)
            for (const std::string& name : other->needs(params_))
                needed = needed || (name == t->name() && technique_on(params_, other->name()));
        t->configure(params_, setup, needed);
        t->bind(*set_);  // configure may have made new buffers and a new TLAS
    }
    upload_technique_params();
}

Session::~Session() = default;

uint32_t Session::film_passes() const {
    uint32_t mask = 1u << PASS_COMBINED;  // holds every pixel's sample count
    for (const PassInfo& p : px::passes())
        if (p.index < PASS_COUNT && (listed_passes_ >> p.index & 1u) &&
            (!*p.setting || read_setting(&params_, setting(p.setting))))
            mask |= 1u << p.index;
    for (const auto& t : techniques_) mask |= t->film_passes(params_);
    return mask;
}

size_t Session::film_offset(uint32_t pass) const {
    const uint32_t below = allocated_passes_ & ((1u << pass) - 1u);
    return size_t(__builtin_popcount(below)) * width_ * height_ * sizeof(vec4);  // film_slot in common.glsl
}

std::vector<vec4> Session::film_sums(uint32_t pass) const {
    std::vector<vec4> sums(allocated_passes_ >> pass & 1u ? size_t(width_) * height_ : 0);  // not held: none
    if (!sums.empty()) film_.download(sums.data(), sums.size() * sizeof(vec4), film_offset(pass));
    return sums;
}

void Session::allocate_film() {
    const uint32_t mask = film_passes();
    if (mask == allocated_passes_ && film_.size()) return;
    film_ = Buffer(*ctx_, size_t(__builtin_popcount(mask)) * width_ * height_ * sizeof(vec4), kStorageUsage);
    set_->bind_buffer(BINDING_FILM, film_);
    allocated_passes_ = mask;
}

void Session::set_passes(const std::vector<std::string>& names) {
    uint32_t mask = 1u << PASS_COMBINED;
    for (const std::string& name : names) {
        const PassInfo& p = pass(name);  // unknown: invalid_argument
        if (p.engine) throw std::invalid_argument("pass '" + name + "' is made by the engine (parallax_core.denoise), not the film");
        mask |= 1u << p.index;
    }
    std::lock_guard<std::mutex> updating(update_mutex_);
    std::lock_guard<std::mutex> lock(mutex_);
    if (mask == listed_passes_) return;
    listed_passes_ = mask;
    reset_accumulation();
}

std::vector<std::string> Session::passes() {
    std::lock_guard<std::mutex> lock(mutex_);
    std::vector<std::string> names;
    for (const PassInfo& p : px::passes())
        if (!p.engine && (listed_passes_ >> p.index & 1u)) names.push_back(p.name);
    return names;
}

std::vector<std::string> Session::update(const SceneArrays& arrays, bool spatial_order, uint32_t parts) {
    std::lock_guard<std::mutex> updating(update_mutex_);
    if (parts == 0 || (parts & ~uint32_t(PART_ALL))) throw std::invalid_argument("update: bad scene part mask");
    // The arrays after this update: the given ones, and for a partial update the kept ones
    // of the other parts (shared, not copied). Committed only if the update succeeds.
    std::map<std::string, std::shared_ptr<const OwnedArray>> next_arrays;
    if (parts != PART_ALL) {
        if (!scene_) throw std::runtime_error("no scene to update partially: call update(scene) with the whole scene first");
        for (const auto& [name, array] : arrays_)
            if (!(scene_part_of_array(name) & parts)) next_arrays.emplace(name, array);
        for (const auto& [name, view] : arrays) {
            uint32_t part = scene_part_of_array(name);
            if (part && !(part & parts))
                throw std::invalid_argument("update: array '" + name + "' belongs to scene part '" +
                                            scene_part_name(part) + "', which this update does not include");
        }
    }
    for (const auto& [name, view] : arrays) next_arrays[name] = std::make_shared<const OwnedArray>(view);
    SceneArrays views;
    for (const auto& [name, array] : next_arrays) views.emplace(name, array->view());

    // Validates before touching the GPU; the parts not updated are shared with the current
    // scene. scene_ changes only in this function, which update_mutex_ serialises.
    const bool light_tree = params_.light_tree != 0;
    SceneHost host = scene_ ? update_scene(scene_->host(), views, spatial_order, parts, light_tree)
                            : prepare_scene(views, spatial_order, light_tree);
    auto warnings = host.warnings();
    // Upload next to the old scene (sharing its buffers and BLASes where the host data is
    // the same): if this fails (out of memory, device lost), the session keeps rendering
    // what it had.
    std::unique_ptr<Scene> next;
    try {
        next = std::make_unique<Scene>(*ctx_, std::move(host), scene_.get());
    } catch (const DeviceMemoryError& e) {
        throw DeviceMemoryError(std::string("the scene does not fit (the session keeps its previous one): ") + e.what());
    }
    std::lock_guard<std::mutex> lock(mutex_);
    blas_builds_ += next->blases_built();
    scene_ = std::move(next);
    arrays_ = std::move(next_arrays);
    scene_->bind(*set_);
    if (parts != PART_CAMERA) ++scene_version_;  // (TechniqueSetup: what survives camera moves)
    // Edited scene data: the techniques start over (nothing stale). A camera move keeps what
    // they hold in world space (Technique::view_changed).
    reset_accumulation(parts == PART_CAMERA);
    return warnings;
}

void Session::set_params(const RenderParams& p) {
    validate(p);
    std::lock_guard<std::mutex> updating(update_mutex_);
    if (p == params_) return;
    // The light tree is part of the light table: remade from the kept arrays, uploaded next
    // to the current scene (which stays, with the old settings, if that fails).
    std::unique_ptr<Scene> next;
    if (scene_ && p.light_tree != params_.light_tree) {
        SceneArrays views;
        for (const auto& [name, array] : arrays_) views.emplace(name, array->view());
        next = std::make_unique<Scene>(*ctx_, relight_scene(scene_->host(), views, p.light_tree != 0), scene_.get());
    }
    std::lock_guard<std::mutex> lock(mutex_);
    if (next) {
        scene_ = std::move(next);
        scene_->bind(*set_);
    }
    params_ = p;
    reset_accumulation();  // any setting may change what a technique holds: they start over
}

void Session::reset() {
    std::lock_guard<std::mutex> lock(mutex_);
    reset_accumulation();
}

// Pipelines are compiled once per device and specialisation and shared by every session
// (their descriptor set layouts are the same object): a new F12 render or viewport session
// does not wait for a compile again. Like the device they are kept until the process ends
// (never destroyed at exit, when the driver may already be going away).
// Each is compiled once (std::call_once per key): a session needing another variant compiles
// it at the same time rather than waiting (the viewport compiles its path tracer while its
// preview program renders).
namespace {
struct PipelineSlot {
    std::once_flag once;
    std::unique_ptr<RayTracingPipeline> pipeline;
    std::atomic<bool> ready{false};
    std::atomic<bool> compiling{false};  // a background compile holds or waits for `once`
    std::string error;                   // the last background compile's failure (under pipelines_mutex)
};
std::mutex pipelines_mutex;  // guards the map and the slots' errors, not the compiles
auto& pipelines = *new std::map<std::pair<Context*, PipelineKey>, std::shared_ptr<PipelineSlot>>();

std::shared_ptr<PipelineSlot> pipeline_slot(Context* ctx, const PipelineKey& key) {
    std::lock_guard<std::mutex> lock(pipelines_mutex);
    auto& s = pipelines[{ctx, key}];
    if (!s) s = std::make_shared<PipelineSlot>();
    return s;
}

// Background compiles in flight (parallax_core waits for them at interpreter exit: a compile
// still running while the process tears down its statics and the driver crashed it).
std::mutex compiles_mutex;
std::condition_variable compiles_done;
uint32_t compiles_in_flight = 0;
}  // namespace

uint32_t background_compiles() {
    std::lock_guard<std::mutex> lock(compiles_mutex);
    return compiles_in_flight;
}

void wait_for_background_compiles() {
    std::unique_lock<std::mutex> lock(compiles_mutex);
    compiles_done.wait(lock, [] { return compiles_in_flight == 0; });
}

// PAYLOAD_RESERVE on GPUs (integrator.glsl, payload_reserve): NVIDIA's ray-tracing compiler makes
// faster or slower code by the size of a payload the raygen declares and never traces, per
// pipeline and with no order, so each size here is what measured fastest for its pipelines on an
// H100, on the 9 scenes of bench.converge's suites (geometric means against 1 vec4, which
// measured as none; bench/results/gpu_pt_reserve):
// - PT, 2 vec4s: 0.97-0.98 with unbiased light paths and a box pixel (frame_cost's pins; within
//   2% of 67a4504 on every scene, where 1 was 19% slower on one), 0.97 at Cycles' light paths
//   and filter, 0.98 with adaptive sampling too.
// - NEE with unbiased light paths and a box pixel, 16 vec4s: frames 0.97, the soup 1.10x.
//   With Cycles' light paths or filter 16 cost 1.03 (0.99 with adaptive sampling), 2 measured
//   1.01 (0.98).
// - MIS keeps 1: every size went both ways.
// PARALLAX_PAYLOAD_RESERVE (1-64) overrides it, to measure.
static uint32_t gpu_payload_reserve(const SpecConstants& c) {
    if (const char* env = std::getenv("PARALLAX_PAYLOAD_RESERVE")) {
        const long v = std::strtol(env, nullptr, 10);
        if (v >= 1 && v <= 64) return uint32_t(v);
    }
    if (c.method == METHOD_NEE) return c.light_path_limits == 0u && c.filter_from_table == 0u ? 16u : 2u;
    return c.method == METHOD_PT ? 2u : 1u;
}

// ADRRS' split dispatch: lavapipe walks the queue through the camera loop's trace_path call,
// GPUs loop over it with a call of their own (raygen.rgen). PARALLAX_SPLIT_WALK (0 or 1)
// overrides it: the tests compare the two shapes on lavapipe, and benches measure them.
static uint32_t split_walk(const Context& ctx) {
    const char* env = std::getenv("PARALLAX_SPLIT_WALK");
    const std::string value = env ? env : "";
    if (value == "0" || value == "1") return value == "1" ? 1u : 0u;
    return ctx.is_cpu() ? 1u : 0u;
}

// The scene features a pipeline is specialised for: exactly the scene's (lavapipe's frames
// took 4-10% longer with FEATURES_FOLDED added). PARALLAX_SCENE_FEATURES=folded adds them: the
// test suite's setting (tests/conftest.py), fewer variants and cold compiles, the same images
// (tests/render/test_pipeline_variants.py).
static uint32_t pipeline_features(uint32_t scene_features) {
    const char* env = std::getenv("PARALLAX_SCENE_FEATURES");
    const bool folded = env && std::string(env) == "folded";
    return scene_features | (folded ? FEATURES_FOLDED : 0u);
}

// The program and its specialisation constants (shaders/shared/specialization.h); the preview
// program uses the scene features only. A technique's bit may differ between render frames and
// host frames (Technique::spec_bit). GPUs make empty shadow calls, lavapipe does not
// (integrator.glsl, trace_pending_shadow), and they trace ADRRS' split queue in loops of
// their own (split_walk). A one-pixel box filter needs no table. On GPUs a pipeline carries
// adaptive sampling only where it is on; lavapipe's always does (a variant more is a slow
// cold compile there, for a gain not measured on it).
PipelineKey Session::pipeline_key(uint32_t program, bool render_frame) const {
    SpecConstants c;
    c.features = pipeline_features(scene_->host().features);
    c.empty_shadow_calls = ctx_->is_cpu() ? 0u : 1u;
    c.split_walk = split_walk(*ctx_);
    if (program == PROGRAM_PREVIEW) {
        c.method = c.heuristic = c.techniques = c.light_path_limits = c.filter_from_table = c.adaptive_sampling = 0u;
        return {program, c};
    }
    c.method = params_.method;
    c.heuristic = params_.mis_heuristic;
    c.light_path_limits = light_path_limits(params_);
    c.filter_from_table = params_.pixel_filter_type == FILTER_BOX && params_.filter_width == 1.0f ? 0u : 1u;
    c.adaptive_sampling = ctx_->is_cpu() || adaptive_->on() ? 1u : 0u;
    if (!ctx_->is_cpu()) c.payload_reserve = gpu_payload_reserve(c);
    c.techniques = 0u;
    for (const auto& t : techniques_) c.techniques |= t->spec_bit(render_frame);
    return {program, c};
}

RayTracingPipeline& Session::render_pipeline() {
    return pipeline(camera_program(), true);
}

bool Session::pipeline_ready() {
    std::lock_guard<std::mutex> lock(mutex_);
    if (!scene_) return false;
    std::lock_guard<std::mutex> plock(pipelines_mutex);
    auto it = pipelines.find({ctx_.get(), pipeline_key(camera_program(), true)});
    return it != pipelines.end() && it->second->ready;
}

void Session::compile() {
    std::lock_guard<std::mutex> lock(mutex_);
    if (!scene_) throw std::runtime_error("no scene: call update(scene) before compile()");
    render_pipeline();
    for (const auto& t : techniques_) t->compile(*this);
}

RayTracingPipeline& Session::pipeline(uint32_t program, bool render_frame) {
    return pipeline_for(pipeline_key(program, render_frame));
}

RayTracingPipeline& Session::pipeline_for(const PipelineKey& key) {
    std::shared_ptr<PipelineSlot> slot = pipeline_slot(ctx_.get(), key);
    // A compile that throws leaves the flag unset: the next call tries again.
    std::call_once(slot->once, [&] {
        slot->pipeline = create_pipeline(*ctx_, set_->layout(), pipeline_shaders(key));
        slot->ready = true;
    });
    return *slot->pipeline;
}

// The pipelines a frame with the current settings needs: the render frames' camera program
// and, while a technique is on, the host frames' programs (its host frames' camera program and
// those of its own, such as the cache's hemisphere rays).
std::vector<PipelineKey> Session::needed_pipelines() const {
    std::vector<PipelineKey> out = {pipeline_key(camera_program(), true)};
    bool any = false;
    for (const auto& t : techniques_) any = any || t->enabled();
    if (!any) return out;
    out.push_back(pipeline_key(PROGRAM_CAMERA, false));
    for (uint32_t program = 0; program < PROGRAM_COUNT; ++program)
        for (const auto& t : techniques_)
            if (t->enabled() && t->raygen(program)) out.push_back(pipeline_key(program, false));
    return out;
}

bool Session::technique_pipelines_ready() {
    if (!compiled_or_started(needed_pipelines())) return false;
    for (const auto& t : techniques_) t->compile(*this);  // its compute pipelines (quick) and the compiled rest
    return true;
}

void Session::warm() {
    std::lock_guard<std::mutex> lock(mutex_);
    if (!scene_) throw std::runtime_error("no scene: call update(scene) before warm()");
    auto wanted = needed_pipelines();
    wanted.push_back(fallback_key());
    compiled_or_started(wanted);
}

// The render pipeline with every technique off: what frames render while the techniques'
// pipelines compile in the background.
PipelineKey Session::fallback_key() const {
    PipelineKey key = pipeline_key(camera_program(), true);
    key.second.techniques = 0;
    return key;
}

// Whether every pipeline of `wanted` is compiled; otherwise starts the missing ones on a
// worker thread (once per pipeline, shared by every session) and returns false. A failed
// background compile is raised here, once; the next call compiles again.
bool Session::compiled_or_started(const std::vector<PipelineKey>& wanted) {
    struct Missing {
        PipelineKey key;
        PipelineRecipe recipe;  // gathered here: the worker reads no session state
        std::shared_ptr<PipelineSlot> slot;
    };
    bool ready = true;
    std::vector<Missing> missing;  // not compiled, and no background compile started yet
    for (const PipelineKey& key : wanted) {
        std::shared_ptr<PipelineSlot> slot = pipeline_slot(ctx_.get(), key);
        {
            std::lock_guard<std::mutex> lock(pipelines_mutex);
            if (!slot->error.empty()) {
                std::string error;
                std::swap(error, slot->error);
                throw std::runtime_error(error);
            }
        }
        if (slot->ready) continue;
        ready = false;
        if (!slot->compiling.exchange(true)) missing.push_back({key, pipeline_shaders(key), slot});
    }
    if (missing.empty()) return ready;
    {
        std::lock_guard<std::mutex> lock(compiles_mutex);
        ++compiles_in_flight;
    }
    std::thread([ctx = ctx_, layout = set_->layout(), missing] {
        for (const Missing& m : missing) {
            try {
                std::call_once(m.slot->once, [&] {
                    m.slot->pipeline = create_pipeline(*ctx, layout, m.recipe);
                    m.slot->ready = true;
                });
            } catch (const std::exception& e) {
                std::lock_guard<std::mutex> lock(pipelines_mutex);
                m.slot->error = std::string("compiling a pipeline in the background failed: ") + e.what();
            }
            m.slot->compiling = false;
        }
        std::lock_guard<std::mutex> lock(compiles_mutex);
        --compiles_in_flight;
        compiles_done.notify_all();
    }).detach();
    return false;
}

Session::PipelineRecipe Session::pipeline_shaders(const PipelineKey& key) const {
    const uint32_t program = key.first;
    // Stages and groups gathered from the path tracer and the techniques (those whose bit is
    // in the key's TECHNIQUES): the raygen of `program`, misses by slot (MISS_*), hit groups by slot
    // (HIT_GROUP_*). A technique's shaders are left out of pipelines that never use it (less
    // to compile).
    PipelineShaders shaders;
    const std::vector<uint32_t>* raygen = program == PROGRAM_PREVIEW ? &shader_preview()
                                          : key.second.split_walk ? &shader_raygen()
                                                                  : &shader_raygen_split_loops();
    for (const auto& t : techniques_)
        if (const std::vector<uint32_t>* own = t->raygen(program)) raygen = own;
    shaders.add(VK_SHADER_STAGE_RAYGEN_BIT_KHR, *raygen);
    const uint32_t closest_hit = shaders.add(VK_SHADER_STAGE_CLOSEST_HIT_BIT_KHR, shader_closesthit());
    shaders.misses[MISS_SCENE] = {VK_RAY_TRACING_SHADER_GROUP_TYPE_GENERAL_KHR,
                                  shaders.add(VK_SHADER_STAGE_MISS_BIT_KHR, shader_miss())};
    if (program != PROGRAM_PREVIEW)  // the preview traces no shadow rays
        shaders.misses[MISS_SHADOW] = {VK_RAY_TRACING_SHADER_GROUP_TYPE_GENERAL_KHR,
                                       shaders.add(VK_SHADER_STAGE_MISS_BIT_KHR, shader_shadow_miss())};
    shaders.hits[HIT_GROUP_TRIANGLES] = {VK_RAY_TRACING_SHADER_GROUP_TYPE_TRIANGLES_HIT_GROUP_KHR, VK_SHADER_UNUSED_KHR,
                                         closest_hit};
    for (const auto& t : techniques_) t->add_shaders(key.second.techniques, shaders);
    if (program != PROGRAM_PREVIEW && (key.second.features & FEATURE_TRANSMISSION)) {  // rays leaving a surface skip its triangle (self_skip.rahit)
        const uint32_t any_hit = shaders.add(VK_SHADER_STAGE_ANY_HIT_BIT_KHR, shader_self_skip_any_hit());
        for (auto& [slot, g] : shaders.hits)
            if (g.type == VK_RAY_TRACING_SHADER_GROUP_TYPE_TRIANGLES_HIT_GROUP_KHR) g.any_hit = any_hit;
    }
    // Raygen, misses, hits; a slot below the last that no shader fills (its technique is off)
    // takes the next filled slot's group: the shader binding table has a record for each.
    std::vector<ShaderGroup> groups = {{VK_RAY_TRACING_SHADER_GROUP_TYPE_GENERAL_KHR, 0}};
    for (const auto* slots : {&shaders.misses, &shaders.hits})
        for (uint32_t slot = 0; slot <= slots->rbegin()->first; ++slot)
            groups.push_back(slots->lower_bound(slot)->second);
    return {shaders.stages, groups, key.second, program};
}

// PARALLAX_COMPILE_LOG=FILE appends a line per pipeline created: "pipeline", the process and its
// parent, the milliseconds vkCreateRayTracingPipelinesKHR took (lavapipe finishes the compile at
// the first dispatch: there it is a part), the shader stages and the specialisation constants
// in constant_id order. It tells which variants a run compiles, and where (README, Robustness).
static void log_pipeline(const SpecConstants& constants, size_t stages, double milliseconds) {
    const char* path = std::getenv("PARALLAX_COMPILE_LOG");
    if (!path || !*path) return;
    std::string line = "pipeline " + std::to_string(getpid()) + " " + std::to_string(getppid()) + " " +
                       std::to_string(int64_t(milliseconds)) + " " + std::to_string(stages);
    for (uint v : constants.values()) line += " " + std::to_string(v);
    if (FILE* f = std::fopen(path, "a")) {  // one write per line: processes append side by side
        std::fputs((line + "\n").c_str(), f);
        std::fclose(f);
    }
}

// PARALLAX_PIPELINE_STATS=FILE appends a JSON line per pipeline created: its program, its
// specialisation constants by name and what the driver says of it (RayTracingPipeline::
// statistics_json: stack sizes, and the driver's statistics where it reports them).
// bench/pipeline_stats.py tabulates them: registers and stack of one variant against another.
static void log_pipeline_statistics(const RayTracingPipeline& pipeline, uint32_t program, const SpecConstants& constants) {
    const char* path = std::getenv("PARALLAX_PIPELINE_STATS");
    if (!path || !*path) return;
    std::string line = "{\"program\": " + std::to_string(program) + ", \"constants\": {";
    const auto values = constants.values();
    const char* names[] = {
#define PX_SPEC_NAME(id, NAME, member, value) #member,
        PX_SPEC_CONSTANTS(PX_SPEC_NAME)
#undef PX_SPEC_NAME
    };
    for (size_t i = 0; i < values.size(); ++i)
        line += std::string(i ? ", \"" : "\"") + names[i] + "\": " + std::to_string(values[i]);
    std::string driver;
    try {  // a diagnostic: a driver that fails the queries must not fail the pipeline
        driver = pipeline.statistics_json();
    } catch (const std::exception& e) {
        driver = "{\"stack\": [], \"error\": " + json_string(e.what()) + "}";
    }
    line += "}, \"driver\": " + driver + "}\n";
    if (FILE* f = std::fopen(path, "a")) {
        std::fputs(line.c_str(), f);
        std::fclose(f);
    }
}

std::unique_ptr<RayTracingPipeline> Session::create_pipeline(Context& ctx, VkDescriptorSetLayout layout,
                                                             const PipelineRecipe& recipe) {
    const auto start = std::chrono::steady_clock::now();
    auto pipeline = std::make_unique<RayTracingPipeline>(ctx, layout, uint32_t(sizeof(FrameParams)), recipe.stages,
                                                         recipe.groups, recipe.constants);
    log_pipeline(recipe.constants, recipe.stages.size(), std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count());
    log_pipeline_statistics(*pipeline, recipe.program, recipe.constants);
    return pipeline;
}

FrameParams Session::frame_params(uint32_t frame) const {
    FrameParams fp{};
    fp.width = width_;
    fp.height = height_;
    fp.frame = frame;
    fp.seed = params_.seed;
    fp.samples_per_frame = params_.samples_per_frame;
    fp.sample_count = params_.samples_per_frame;
    fp.max_depth = params_.max_depth;
    fp.depth_leeway = params_.depth_leeway;
    fp.rr_start_depth = params_.rr_start_depth;
    fp.light_samples = params_.light_samples;
    fp.diffuse_bounces = params_.diffuse_bounces;
    fp.glossy_bounces = params_.glossy_bounces;
    fp.transmission_bounces = params_.transmission_bounces;
    // Cycles' clamps: 0 is off; else 3x the setting, against the sum of |RGB| (film_clamp_light).
    auto clamp_limit = [](float v) { return v > 0.0f ? 3.0f * v : std::numeric_limits<float>::infinity(); };
    fp.clamp_direct = clamp_limit(params_.sample_clamp_direct);
    fp.clamp_indirect = clamp_limit(params_.sample_clamp_indirect);
    fp.filter_glossy = params_.blur_glossy > 0.0f ? 1.0f / params_.blur_glossy : 0.0f;  // read where LIMIT_BLUR_GLOSSY
    fp.mode = FRAME_RENDER;
    fp.film_passes = allocated_passes_;
    for (const auto& t : techniques_) t->fill_frame_params(fp);
    return fp;
}

Session::DispatchPlan Session::dispatch_plan() const {
    DispatchPlan plan{};
    // Rays of one path at most: camera ray and bounces up to the depth limits, with the
    // shadow rays of each vertex.
    // The techniques add rays to a sample's path and copies of it (Technique::extra_rays_per_sample,
    // copies_per_sample).
    plan.cost = uint64_t(params_.max_depth + params_.depth_leeway + 2) * (1 + params_.light_samples);
    for (const auto& t : techniques_) plan.cost += t->extra_rays_per_sample();
    for (const auto& t : techniques_) plan.cost *= t->copies_per_sample();
    plan.budget = ctx_->report().type == "cpu" ? (uint64_t(1) << 21) : (uint64_t(1) << 30);
    const uint64_t spp = params_.samples_per_frame;
    const uint64_t row = uint64_t(width_) * plan.cost;
    auto fit = [&](uint64_t unit, uint32_t most) { return uint32_t(std::clamp<uint64_t>(plan.budget / unit, 1, most)); };
    // Whole rows with all samples if a row fits, else one row with some samples, else
    // part of a row with one sample.
    plan.rows = row * spp <= plan.budget ? fit(row * spp, height_) : 1;
    plan.samples = row * spp <= plan.budget ? uint32_t(spp) : fit(row, uint32_t(spp));
    plan.cols = row <= plan.budget ? width_ : fit(plan.cost, width_);
    return plan;
}

uint64_t Session::record_dispatch(VkCommandBuffer cmd, RayTracingPipeline& pipe, const DispatchPlan& plan,
                                  uint32_t frame, uint32_t& rows, bool& frame_done) {
    Cursor& c = cursor_;
    const uint32_t frame_rows = adaptive_->rows();  // fixed within a frame (checks come between frames)
    const uint32_t h = std::min({plan.rows, frame_rows - c.row, rows});
    const uint32_t w = std::min(plan.cols, width_ - c.col);
    const uint32_t n = std::min(plan.samples, params_.samples_per_frame - c.sample);
    FrameParams fp = frame_params(frame);
    fp.row_offset = c.row;
    fp.col_offset = c.col;
    fp.sample_offset = c.sample;
    fp.sample_count = n;
    adaptive_->fill(fp);  // rows: of the active list's virtual image once adaptive sampling has one
    VkMemoryBarrier b{VK_STRUCTURE_TYPE_MEMORY_BARRIER};
    b.srcAccessMask = VK_ACCESS_SHADER_WRITE_BIT;
    b.dstAccessMask = VK_ACCESS_SHADER_READ_BIT | VK_ACCESS_SHADER_WRITE_BIT | VK_ACCESS_TRANSFER_READ_BIT |
                      VK_ACCESS_TRANSFER_WRITE_BIT;
    auto barrier = [&] {
        vkCmdPipelineBarrier(cmd, VK_PIPELINE_STAGE_RAY_TRACING_SHADER_BIT_KHR,
                             VK_PIPELINE_STAGE_RAY_TRACING_SHADER_BIT_KHR | VK_PIPELINE_STAGE_TRANSFER_BIT, 0, 1, &b,
                             0, nullptr, 0, nullptr);
    };
    auto trace = [&](const FrameParams& f) {
        pipe.trace(cmd, set_->set(), &f, sizeof(f), w, h);
        barrier();
    };
    if (fallback_frame_) {  // the fallback pipeline has no technique (see trace)
        trace(fp);
    } else {
        for (const auto& t : techniques_) t->record_before_trace(cmd);
        trace(fp);
        for (const auto& t : techniques_) t->record_after_trace(fp, trace);
    }
    // Columns, then samples, then rows: a band of rows is complete when all its samples are.
    frame_done = false;
    if ((c.col += w) < width_) return plan.cost * w * h * n;
    c.col = 0;
    if ((c.sample += n) < params_.samples_per_frame) return plan.cost * w * h * n;
    c.sample = 0;
    c.row += h;
    if (rows != UINT32_MAX) rows -= h;
    if (c.row == frame_rows) {
        c.row = 0;
        frame_done = true;
    }
    return plan.cost * w * h * n;
}

// A host frame (Technique::needs_host_frame; thesis 4.4-4.6): 1 spp camera paths over the
// whole image that feed the technique alone.
void Session::host_frame(Technique& technique) {
    RayTracingPipeline& camera = host_pipeline(PROGRAM_CAMERA);
    FrameParams fp = frame_params(0);
    technique.begin_host_frame(fp);  // its mode and frame index
    fp.samples_per_frame = fp.sample_count = 1;
    auto start = std::chrono::steady_clock::now();
    ctx_->submit_and_wait([&](VkCommandBuffer cmd) {
        for (const auto& t : techniques_) t->record_frame_start(cmd, &technique);
        camera.trace(cmd, set_->set(), &fp, sizeof(fp), width_, height_);
    });
    const double ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count();
    technique.end_host_frame(*this, fp, ms);
    for (const auto& t : techniques_) t->sync(*this, &technique);
}

// Frames go to the device in submissions of dispatches up to the plan's budget; cancel() is
// checked between submissions. A frame after which a technique steps (Technique::
// steps_after_frame) ends its submission and is followed by the techniques' after_frame; a
// new frame is preceded by the host frames the techniques still need: all of them for
// render(), one per call for render_rows() (so a caller can still stop between short calls).
uint32_t Session::trace(uint32_t frames, uint32_t rows) {
    if (!scene_) throw std::runtime_error("no scene: call update(scene) before render()");
    if (cancel_.exchange(false)) return 0;
    auto start = std::chrono::steady_clock::now();
    const DispatchPlan plan = dispatch_plan();
    // With background compiles, a frame that starts while the techniques' pipelines compile
    // renders with the techniques off (the fallback), and so does the rest of that frame.
    // Once they are compiled, the film starts over with the techniques' first render frame
    // (their host frames come first, the fallback's image shown meanwhile): the image holds
    // the techniques' samples alone, the fallback's are counted apart (fallback_samples).
    if (cursor_.at_frame_start()) {
        const bool was_fallback = fallback_frame_;
        fallback_frame_ = background_compile_ && pipeline_key(camera_program(), true).second.techniques != 0 &&
                          !technique_pipelines_ready();
        if (was_fallback && !fallback_frame_) film_after_fallback_ = true;
    }
    const bool fallback = fallback_frame_;
    PipelineKey key = pipeline_key(camera_program(), true);
    // A technique that leaves the pipeline between frames (guiding where it does not pay:
    // Guiding::spec_bit) waits, with background compiles, until the pipeline without it is
    // compiled: the frames keep the one they had meanwhile, never stalling on a compile.
    if (!fallback && background_compile_ && rendered_key_) {
        PipelineKey same_but_bits = *rendered_key_;
        same_but_bits.second.techniques = key.second.techniques;
        const bool left = (rendered_key_->second.techniques & ~key.second.techniques) != 0;
        if (left && same_but_bits == key && !compiled_or_started({key})) key = *rendered_key_;
    }
    if (!fallback) rendered_key_ = key;
    RayTracingPipeline& pipe = fallback ? pipeline_for(fallback_key()) : pipeline_for(key);
    uint32_t completed = 0;
    uint32_t rows_left = frames ? UINT32_MAX : rows;
    bool stop = false;
    double frame_milliseconds = 0;  // the submissions of the frame in progress (FrameEnd)
    // A frame after which a technique steps ends its submission (the fallback has none).
    auto steps_after = [&](uint64_t samples) {
        if (fallback) return false;
        for (const auto& t : techniques_)
            if (t->steps_after_frame(samples)) return true;
        return false;
    };
    while (!stop && (frames ? completed < frames : rows_left > 0)) {
        // Adaptive sampling between frames: the convergence check when due, and no frame once
        // every pixel converged.
        if (cursor_.at_frame_start() && !film_after_fallback_) {
            const uint64_t samples = stats_.samples + uint64_t(completed) * params_.samples_per_frame;
            if (adaptive_->check_due(samples)) adaptive_->check(samples, set_->layout(), set_->set());
            if (adaptive_->converged()) break;
        }
        Technique* host = nullptr;  // the first technique that needs a host frame now
        for (const auto& t : techniques_)
            if (!fallback && !host && cursor_.at_frame_start() && t->needs_host_frame()) host = t.get();
        if (host) {
            host_frame(*host);
            stop = frames == 0 || cancel_.exchange(false);
            continue;
        }
        if (film_after_fallback_) {  // the techniques' first render frame: the film starts over
            film_after_fallback_ = false;
            const SessionStats fallback_stats = stats_;
            stats_ = {};
            stats_.fallback_samples = fallback_stats.fallback_samples;
            stats_.fallback_milliseconds = fallback_stats.fallback_milliseconds;
            film_.fill_zero();
            ray_count_.fill_zero();
            adaptive_->reset();
            start = std::chrono::steady_clock::now();
        }
        bool frame_done = false, step = false;
        const auto submit_start = std::chrono::steady_clock::now();
        ctx_->submit_and_wait([&](VkCommandBuffer cmd) {
            uint64_t work = 0;
            while (work < plan.budget && (frames ? completed < frames : rows_left > 0)) {
                if (cursor_.at_frame_start() && !fallback)
                    for (const auto& t : techniques_) t->record_frame_start(cmd, nullptr);
                work += record_dispatch(cmd, pipe, plan, stats_.frames + completed, rows_left, frame_done);
                if (!frame_done) continue;
                if (steps_after(stats_.samples + uint64_t(completed + 1) * params_.samples_per_frame)) {
                    // the techniques' steps come next
                    step = true;
                    break;
                }
                ++completed;
                if (frames == 0) break;  // render_rows: at most the rest of one frame
                // Adaptive sampling's check comes between submissions (it reads the film back).
                if (adaptive_->check_due(stats_.samples + uint64_t(completed) * params_.samples_per_frame)) break;
            }
        });
        frame_milliseconds += std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - submit_start).count();
        if (step) {
            const uint64_t samples = stats_.samples + uint64_t(completed + 1) * params_.samples_per_frame;
            const uint64_t paths = uint64_t(adaptive_->active_pixels()) * params_.samples_per_frame;
            const FrameEnd end{frame_params(stats_.frames + completed), paths, samples, frame_milliseconds};
            for (const auto& t : techniques_)
                if (t->steps_after_frame(samples)) t->after_frame(*this, end);
            frame_milliseconds = 0;
            ++completed;
            for (const auto& t : techniques_) t->sync(*this, nullptr);
        }
        if (frame_done && frames == 0) break;
        stop = cancel_.exchange(false);
    }
    stats_.milliseconds += std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count();
    stats_.frames += completed;
    stats_.samples += uint64_t(completed) * params_.samples_per_frame;
    if (fallback) {
        stats_.fallback_samples += uint64_t(completed) * params_.samples_per_frame;
        stats_.fallback_milliseconds = stats_.milliseconds;
    }
    return completed;
}

uint32_t Session::render(uint32_t frames) {
    std::lock_guard<std::mutex> lock(mutex_);
    return trace(frames, 0);
}

bool Session::render_rows(uint32_t rows) {
    if (rows == 0) throw std::invalid_argument("render_rows needs at least one row");
    std::lock_guard<std::mutex> lock(mutex_);
    return trace(0, rows) > 0;
}

std::vector<float> Session::read(const std::string& pass, uint32_t& channels) {
    const PassInfo* info = &px::pass(pass);
    if (info->engine)
        throw std::invalid_argument("pass '" + pass + "' is made by the engine (parallax_core.denoise), not the film");
    std::lock_guard<std::mutex> lock(mutex_);
    if (!(listed_passes_ >> info->index & 1u))
        throw std::invalid_argument("pass '" + pass + "' is not rendered: add it to Session.passes");
    const size_t pixels = size_t(width_) * height_;
    channels = info->channels;
    std::vector<float> out(pixels * channels, 0.0f);
    // Sample Count has no film slot of its own: it is Combined's w. A pass whose technique is
    // off is not held: zeros.
    const uint32_t slot = info->index == PASS_SAMPLE_COUNT ? PASS_COMBINED : info->index;
    const bool held = allocated_passes_ >> slot & 1u;
    std::vector<vec4> sums(held ? pixels : 0), counts(pixels);  // counts: the combined pass, w = samples
    if (held) film_.download(sums.data(), pixels * sizeof(vec4), film_offset(slot));
    film_.download(counts.data(), pixels * sizeof(vec4), film_offset(PASS_COMBINED));
    for (size_t i = 0; i < pixels && held; ++i) {
        const float inv = counts[i].w > 0 ? 1.0f / counts[i].w : 0.0f;
        float v[4] = {sums[i].x * inv, sums[i].y * inv, sums[i].z * inv, sums[i].w * inv};
        if (info->fraction) v[0] = sums[i].y > 0 ? sums[i].x / sums[i].y : 0.0f;
        if (info->index == PASS_SAMPLE_COUNT) v[0] = counts[i].w;  // no film slot: the count itself
        for (uint32_t c = 0; c < channels; ++c) out[i * channels + c] = v[c];
    }
    if (info->index == PASS_DEPTH)
        for (size_t i = 0; i < pixels; ++i)
            if (counts[i].w == 0) out[i] = 1e10f;
    if (info->index == PASS_COMBINED) {
        const auto sums = [this](uint32_t slot) { return film_sums(slot); };
        for (const auto& t : techniques_) t->resolve_combined(out, counts, width_, height_, sums);
    }
    return out;
}

const Technique* Session::technique(const std::string& name) const {
    for (const auto& t : techniques_)
        if (name == t->name()) return t.get();
    return nullptr;
}

SessionStats Session::stats() {
    std::lock_guard<std::mutex> lock(mutex_);
    const size_t pixels = size_t(width_) * height_;
    std::vector<uint32_t> counts(pixels);
    ray_count_.download(counts.data(), pixels * sizeof(uint32_t));
    uint64_t total = 0;
    for (uint32_t c : counts) total += c;
    stats_.rays = total;
    SessionStats out = stats_;
    out.blas_builds = blas_builds_;
    out.fallback_film = fallback_frame_ || film_after_fallback_;
    out.light_tree_nodes = scene_ ? scene_->host().info.light_tree_nodes : 0;
    out.contact_boxes = scene_ ? scene_->host().info.contact_box_count : 0;
    out.adaptive_active_pixels = adaptive_->active_pixels();
    for (const auto& t : techniques_) t->stats(out.techniques);
    return out;
}

std::vector<float> Session::test_sampling(uint32_t routine, const std::vector<float>& params, uint32_t count,
                                          uint32_t seed, const std::vector<float>& input) {
    std::lock_guard<std::mutex> lock(mutex_);
    if (!scene_) throw std::runtime_error("no scene: call update(scene) before test_sampling()");
    if (params.size() != 5) throw std::invalid_argument("test_sampling needs 5 parameters");
    // count*8 floats (directions for eval mode), then whole vec4s of constants (a mixture's lobes)
    if (!input.empty() && (input.size() < size_t(count) * 8 || (input.size() - size_t(count) * 8) % 4 != 0))
        throw std::invalid_argument("test input must be count*8 floats followed by whole vec4s");
    if (!test_pipeline_)
        test_pipeline_ = std::make_unique<ComputePipeline>(*ctx_, set_->layout(), uint32_t(sizeof(FrameParams)),
                                                           shader_sampling_test());
    Buffer io(*ctx_, std::max(size_t(count) * 8, input.size()) * sizeof(float), kStorageUsage);
    if (!input.empty()) io.upload(input.data(), input.size() * sizeof(float));
    set_->bind_buffer(BINDING_TEST_IO, io);
    FrameParams fp{};
    fp.test_routine = routine;
    fp.test_count = count;
    fp.seed = seed;
    fp.test_params = {params[0], params[1], params[2], params[3]};
    fp.test_param0 = params[4];
    ctx_->submit_and_wait([&](VkCommandBuffer cmd) {
        test_pipeline_->dispatch(cmd, set_->set(), &fp, sizeof(fp), (count + 63) / 64);
    });
    std::vector<float> out(size_t(count) * 8);
    io.download(out.data(), out.size() * sizeof(float));
    set_->bind_buffer(BINDING_TEST_IO, test_io_);
    return out;
}

}  // namespace px
