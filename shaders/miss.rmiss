#version 460
#extension GL_EXT_ray_tracing : require
#extension GL_GOOGLE_include_directive : require
#include "lib/payload.glsl"

layout(location = 0) rayPayloadInEXT HitPayload hit;

void main() { hit.t = -1.0; }
