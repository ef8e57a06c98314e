#version 460
#extension GL_EXT_ray_tracing : require
#extension GL_GOOGLE_include_directive : require
#include "lib/payload.glsl"

layout(location = 0) rayPayloadInEXT HitPayload hit;
hitAttributeEXT vec2 barycentrics;

void main() {
    hit.t = gl_HitTEXT;
    hit.instance = gl_InstanceCustomIndexEXT;
    hit.primitive = gl_PrimitiveID;
    hit.barycentrics = barycentrics;
}
