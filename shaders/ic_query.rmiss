#version 460
#extension GL_EXT_ray_tracing : require
#extension GL_GOOGLE_include_directive : require
#include "lib/payload.glsl"

layout(location = 2) rayPayloadInEXT IcQuery ic_query;

// The cache query needs no miss work: its any-hit shader has summed every entry found.
void main() {}
