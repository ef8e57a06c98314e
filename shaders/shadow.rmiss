#version 460
#extension GL_EXT_ray_tracing : require
#extension GL_GOOGLE_include_directive : require
#include "lib/payload.glsl"

layout(location = 1) rayPayloadInEXT HitPayload shadow_hit;

void main() { shadow_hit.t = -1.0; }  // nothing in the way: the light is visible
