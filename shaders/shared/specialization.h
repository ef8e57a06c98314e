// The specialisation constants of the ray-tracing pipelines, declared once (polyglot like
// types.h, after which it is included). GLSL gets one `layout(constant_id = N) const uint`
// per row; C++ gets px::SpecConstants, which is both part of the pipeline cache's key and the
// data of its VkSpecializationInfo (spec_constant_entries: constant id and offset per row).
// Code for what a pipeline's constants leave out folds away when it is compiled.
#ifndef PARALLAX_SHARED_SPECIALIZATION_H
#define PARALLAX_SHARED_SPECIALIZATION_H

#include "types.h"

// X(constant_id, GLSL name, C++ member, default), one row per constant:
//   METHOD              METHOD_*: the estimator (integrator.glsl)
//   MIS_HEURISTIC       HEURISTIC_* (mis.glsl)
//   SCENE_FEATURES      FEATURE_* bits of the scene, tested by HAS()
//   TECHNIQUES          TECH_* bits of the enabled techniques (techniques.h), tested by USES
//   EMPTY_SHADOW_CALLS  1: paths without a pending shadow ray make an empty trace call
//                       (integrator.glsl, trace_pending_shadow); 0 on lavapipe
//   LIGHT_PATH_LIMITS   LIMIT_* bits of the light-path limits that can bind, tested by LIMITS()
//   FILTER_FROM_TABLE   1: camera samples are drawn from the pixel filter's table; 0: the filter
//                       is a one-pixel box, a plain jitter (camera.glsl, pixel_filter_sample)
//   ADAPTIVE_SAMPLING   0: adaptive sampling is off and its raygen state folds away (GPUs); 1:
//                       FrameParams.adaptive decides (lavapipe always: a variant more costs it
//                       a cold compile of 1-29 s, bench/results/compile_lavapipe)
//   PAYLOAD_RESERVE     vec4s of the payload the raygen declares and never traces (integrator.glsl,
//                       payload_reserve): NVIDIA's compiler makes different code by it; 1 on
//                       lavapipe and where no other size measured faster
//   SPLIT_WALK          which build of raygen.rgen the camera program runs (no GLSL reads it): 1,
//                       ADRRS' split dispatch walks its queue through main()'s one trace_path call
//                       (lavapipe); 0, PX_SPLIT_LOOPS: loops of its own with a second call (GPUs)
#define PX_SPEC_CONSTANTS(X)                              \
    X(0, METHOD, method, METHOD_MIS)                      \
    X(1, MIS_HEURISTIC, heuristic, HEURISTIC_POWER)       \
    X(2, SCENE_FEATURES, features, FEATURE_ALL)           \
    X(3, TECHNIQUES, techniques, 0u)                      \
    X(4, EMPTY_SHADOW_CALLS, empty_shadow_calls, 1u)      \
    X(5, LIGHT_PATH_LIMITS, light_path_limits, LIMIT_ALL) \
    X(6, FILTER_FROM_TABLE, filter_from_table, 1u)        \
    X(7, ADAPTIVE_SAMPLING, adaptive_sampling, 1u)        \
    X(8, PAYLOAD_RESERVE, payload_reserve, 1u)            \
    X(9, SPLIT_WALK, split_walk, 1u)

#ifdef __cplusplus
#include <array>
#include <cstddef>

namespace px {
struct SpecConstants {
#define PX_SPEC_MEMBER(id, NAME, member, value) uint member = value;
    PX_SPEC_CONSTANTS(PX_SPEC_MEMBER)
#undef PX_SPEC_MEMBER

    static constexpr uint count = 0
#define PX_SPEC_COUNT(id, NAME, member, value) +1
        PX_SPEC_CONSTANTS(PX_SPEC_COUNT)
#undef PX_SPEC_COUNT
        ;
    // The members in constant_id order: the key's order and comparison.
    std::array<uint, count> values() const {
#define PX_SPEC_VALUE(id, NAME, member, value) member,
        return {PX_SPEC_CONSTANTS(PX_SPEC_VALUE)};
#undef PX_SPEC_VALUE
    }
    bool operator==(const SpecConstants& o) const { return values() == o.values(); }
    bool operator!=(const SpecConstants& o) const { return !(*this == o); }
    bool operator<(const SpecConstants& o) const { return values() < o.values(); }
};

struct SpecConstantEntry {
    uint constant_id;
    uint offset;  // of the member in SpecConstants
};
#define PX_SPEC_ENTRY(id, NAME, member, value) SpecConstantEntry{id, uint(offsetof(SpecConstants, member))},
static constexpr SpecConstantEntry spec_constant_entries[] = {PX_SPEC_CONSTANTS(PX_SPEC_ENTRY)};
#undef PX_SPEC_ENTRY
}  // namespace px
#else
#define PX_SPEC_DECLARE(id, NAME, member, value) layout(constant_id = id) const uint NAME = value;
PX_SPEC_CONSTANTS(PX_SPEC_DECLARE)
#undef PX_SPEC_DECLARE

// Scene features and techniques as conditions; a technique's USES() guard sits inside its
// hooks (shaders/techniques/), never at the call site.
#define HAS(FEATURE) ((SCENE_FEATURES & (FEATURE)) != 0u)
#define USES(TECH) ((TECHNIQUES & (TECH)) != 0u)
#define LIMITS(LIMIT) ((LIGHT_PATH_LIMITS & (LIMIT)) != 0u)
#endif

#endif
