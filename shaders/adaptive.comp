#version 460
#extension GL_GOOGLE_include_directive : require
#define PX_NO_TRACE
#include "lib/common.glsl"

// Adaptive sampling's convergence check over the image (Cycles' film_adaptive_sampling_*),
// one invocation per pixel, in two dispatches (FrameParams.mode):
//   ADAPTIVE_CHECK   the pixel's error from its half buffer A (adaptive_aux.rgb, the odd
//                    samples' sums times 2) and its full sums I (Combined): with n samples,
//                      e = (|I - A|_1 / n) / (1e-4 + s),  s = sqrt(i) if i < 1 else i,  i = (I.r+I.g+I.b) / n
//                    (Dammertz et al. 2010, sec. 2.1, as Cycles normalises it); converged if
//                    e < threshold, kept in adaptive_aux.w. A pixel that converged and was no
//                    longer sampled stays converged.
//   ADAPTIVE_FILTER  a pixel stays sampled while any pixel of its 3x3 neighbourhood has not
//                    converged (Cycles' filters in x then y): the mask after the active list.
layout(local_size_x = 64) in;

void pixel_step(uint i, uint npix) {
    if (params.mode == ADAPTIVE_CHECK) {
        vec4 a = adaptive_aux[i];
        if (a.w != 0.0 && adaptive_pixels[npix + i] == 0u) return;
        vec4 I = film[PASS_COMBINED * npix + i];
        bool converged = false;
        if (I.w > 0.0) {
            float inv = 1.0 / I.w;
            float difference = (abs(I.x - a.x) + abs(I.y - a.y) + abs(I.z - a.z)) * inv;
            float intensity = (I.x + I.y + I.z) * inv;
            // Bright pixels (r+g+b > 1) need less: they are near or past the display's range.
            float scale = intensity < 1.0 ? sqrt(max(intensity, 0.0)) : intensity;
            converged = difference / (1e-4 + scale) < params.adaptive_threshold;
        }
        adaptive_aux[i].w = converged ? 1.0 : 0.0;
        return;
    }
    int x = int(i % params.width), y = int(i / params.width);
    bool sampled = false;
    for (int dy = -1; dy <= 1; ++dy)
        for (int dx = -1; dx <= 1; ++dx) {
            int nx = x + dx, ny = y + dy;
            if (nx < 0 || ny < 0 || nx >= int(params.width) || ny >= int(params.height)) continue;
            sampled = sampled || adaptive_aux[uint(ny) * params.width + uint(nx)].w == 0.0;
        }
    adaptive_pixels[npix + i] = sampled ? 1u : 0u;
}

// The host dispatches at most 65535 groups (the count Vulkan guarantees): invocations stride
// over larger images.
void main() {
    uint npix = params.width * params.height;
    for (uint i = gl_GlobalInvocationID.x; i < npix; i += gl_NumWorkGroups.x * gl_WorkGroupSize.x) pixel_step(i, npix);
}
