#version 460
#extension GL_EXT_ray_tracing : require

// No region: the caller's payload keeps NO_INDEX.
void main() {}
