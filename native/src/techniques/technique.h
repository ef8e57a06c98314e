// The technique interface (shaped like Falcor's RTXDI module): what the session asks of every
// technique of the thesis (irradiance cache, ADRRS, path guiding). The session keeps a list
// of them (Session::Session is the one place that names them) and loops over it at each of
// the hooks below, in list order; a technique that is off does nothing at any of them.
//
// A frame, as the session runs it (render/session.cpp, Session::trace):
//   host frames   while a technique needs_host_frame(): one 1-spp camera frame over the whole
//                 image that reaches no film, for that technique alone (the cache's prepare
//                 frames, ADRRS' estimate frames): begin_host_frame,
//                 record_frame_start, the trace, end_host_frame, then every technique's sync.
//   render frame  record_frame_start; per dispatch record_before_trace, the camera trace,
//                 record_after_trace; after a frame that some technique steps_after_frame
//                 (a submission then ends with it) every after_frame, then every sync.
#pragma once
#include "render/params.h"
#include "scene/scene.h"
#include "techniques/settings.h"
#include "vk/pipeline.h"

#include <functional>
#include <map>
#include <string>
#include <utility>
#include <variant>
#include <vector>

namespace px {

// The stages and shader groups of one ray-tracing pipeline, gathered from the session and the
// techniques: misses and hit groups by their slot (MISS_*, HIT_GROUP_* in types.h, which the
// shaders and the instances' SBT offsets name).
struct PipelineShaders {
    std::vector<ShaderStage> stages;
    std::map<uint32_t, ShaderGroup> misses, hits;
    uint32_t add(VkShaderStageFlagBits stage, const std::vector<uint32_t>& spirv) {
        stages.push_back({stage, &spirv});
        return uint32_t(stages.size() - 1);
    }
};

// What the session offers its techniques at their host steps.
class TechniqueHost {
public:
    virtual Context& context() = 0;
    virtual DescriptorSet& descriptors() = 0;
    // The ray-tracing pipeline of `program` that host frames use: with every existing
    // technique's shaders (spec_bit(false)).
    virtual RayTracingPipeline& host_pipeline(uint32_t program) = 0;
    // After a technique's settings changed on the host (TechniqueParams, BINDING_TECH_PARAMS).
    virtual void upload_technique_params() = 0;
    virtual const Buffer& film() const = 0;
    // A pass' per-pixel sums as the film holds them now (empty if the film does not hold it).
    virtual std::vector<vec4> film_sums(uint32_t pass) const = 0;

protected:
    ~TechniqueHost() = default;
};

// What configure() gets besides the settings.
struct TechniqueSetup {
    const SceneHost& scene;
    uint64_t scene_version;  // bumped by every scene update but a camera-only one
    uint32_t width, height;
    uint32_t passes;  // the passes the film holds (bit PASS_*)
};

// A render frame that completed, for after_frame().
struct FrameEnd {
    FrameParams frame;   // its parameters (frame index and seed)
    uint64_t paths;      // camera paths traced (pixels x samples per frame)
    uint64_t samples;    // samples per pixel accumulated, this frame's included
    double milliseconds; // its submissions, submission to completion
};

// Stats, under the names Session.stats() returns (ic_entries, guiding_lobes, ...).
using StatValue = std::variant<uint64_t, double, std::string>;
using StatList = std::vector<std::pair<std::string, StatValue>>;

class Technique {
public:
    virtual ~Technique() = default;
    // Its settings (the fields of its Params struct in RenderParams) and passes; the table's
    // technique is its name.
    virtual const SettingTable& table() const = 0;
    const char* name() const { return table().technique; }
    // The techniques it needs built (by name) under `params`: they are configured as `needed`
    // while it is on.
    virtual std::vector<std::string> needs(const RenderParams& /*params*/) const { return {}; }
    // New settings, scene or image size: everything starts over. `needed`: a technique that
    // needs this one is on (the cache is built for ADRRS even with ic off).
    virtual void configure(const RenderParams& params, const TechniqueSetup& setup, bool needed) = 0;
    // Only the camera moved: what lives in world space is kept, what lives per pixel is not.
    virtual void view_changed() {}
    virtual bool enabled() const = 0;  // exists this frame (on, or needed)
    // Its bindings of the descriptor set that hold acceleration structures (the others are
    // storage buffers).
    virtual std::vector<uint32_t> tlas_bindings() const { return {}; }
    virtual void bind(DescriptorSet& set) const = 0;  // its buffers and acceleration structures
    virtual void write_params(TechniqueParams& params) const = 0;  // its part of BINDING_TECH_PARAMS

    // ---- pipelines ------------------------------------------------------------------------
    // Its bit of the TECHNIQUES specialisation constant in pipelines of render frames
    // (`render_frame`) or of host frames (0: none).
    virtual uint32_t spec_bit(bool render_frame) const = 0;
    // The ray-generation shader of `program` if that program is its own (nullptr: not its).
    virtual const std::vector<uint32_t>* raygen(uint32_t /*program*/) const { return nullptr; }
    // Adds its stages and groups to a pipeline whose TECHNIQUES constant is `bits`.
    virtual void add_shaders(uint32_t /*bits*/, PipelineShaders& /*shaders*/) const {}
    // Compiles the pipelines its host steps need (Session::compile).
    virtual void compile(TechniqueHost& /*host*/) {}

    // ---- frames ---------------------------------------------------------------------------
    virtual void fill_frame_params(FrameParams& /*frame*/) const {}  // every frame's, render and host
    // A pixel sample's rays for the dispatch plan: (base + extra) x copies, the path's
    // worst-case rays times the paths a sample makes.
    virtual uint64_t extra_rays_per_sample() const { return 0; }
    virtual uint64_t copies_per_sample() const { return 1; }
    // At the start of each frame, in the submission that records it; `host_frame`: the
    // technique whose host frame it is (nullptr: a render frame).
    virtual void record_frame_start(VkCommandBuffer /*cmd*/, const Technique* /*host_frame*/) const {}
    // Around each camera dispatch of a render frame; `retrace` traces the same pixels again
    // with other frame parameters (and a barrier after).
    virtual void record_before_trace(VkCommandBuffer /*cmd*/) const {}
    virtual void record_after_trace(const FrameParams& /*frame*/,
                                    const std::function<void(const FrameParams&)>& /*retrace*/) const {}

    // ---- host steps -----------------------------------------------------------------------
    virtual bool needs_host_frame() const { return false; }
    // Its host frame's parameters: mode, frame index (in a space of its own) and the like.
    virtual void begin_host_frame(FrameParams& /*frame*/) const {}
    virtual void end_host_frame(TechniqueHost& /*host*/, const FrameParams& /*frame*/, double /*milliseconds*/) {}
    // Whether it needs after_frame() after the render frame that brings the image to `samples`
    // per pixel (that frame then ends its submission: the host waits for it).
    virtual bool steps_after_frame(uint64_t /*samples*/) const { return false; }
    virtual void after_frame(TechniqueHost& /*host*/, const FrameEnd& /*frame*/) {}
    // After a host step: follows what the techniques it needs changed. `stepped`: the
    // technique whose host frame ran (nullptr: the steps after a render frame).
    virtual void sync(TechniqueHost& /*host*/, const Technique* /*stepped*/) {}

    // ---- the film ---------------------------------------------------------------------------
    // Passes (bit PASS_*) the film must hold under `params`, listed or not: what its
    // resolve_combined reads.
    virtual uint32_t film_passes(const RenderParams& /*params*/) const { return 0; }
    // Combined as read (RGBA means per pixel, width x height) from its sums (`combined`, whose w
    // is the pixel's sample count): the technique may change it. `sums(pass)` downloads a
    // pass' per-pixel sums (empty if the film does not hold it).
    virtual void resolve_combined(std::vector<float>& /*rgba*/, const std::vector<vec4>& /*combined*/,
                                  uint32_t /*width*/, uint32_t /*height*/,
                                  const std::function<std::vector<vec4>(uint32_t)>& /*sums*/) const {}

    virtual void stats(StatList& /*out*/) const {}
};

}  // namespace px
