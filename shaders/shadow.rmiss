#version 460
#extension GL_EXT_ray_tracing : require

layout(location = 1) rayPayloadInEXT uint shadow_visible;

void main() { shadow_visible = 1u; }
