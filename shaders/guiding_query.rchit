#version 460
#extension GL_EXT_ray_tracing : require
#extension GL_GOOGLE_include_directive : require
#define PX_NO_TRACE
#include "lib/common.glsl"
#include "lib/sampling.glsl"
#include "lib/payload.glsl"
#include "techniques/guiding_field.glsl"

layout(location = 3) rayPayloadInEXT GuidingQuery guiding_query;

// The region (and distance) the intersection shader accepted.
void main() {
    guiding_query.region = guiding_order[gl_PrimitiveID];
    guiding_query.t = gl_HitTEXT;
}
