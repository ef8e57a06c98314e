// Path guiding in the trace loop (thesis 4.6; Ruppert, Herholz & Lensch 2020): the region
// buffers, the region query, one-sample MIS of the regions' VMM with the BSDF, training
// sample records and the visualisation passes. The maths (vMF, VMM, packing) is in
// guiding.glsl; the host side in native/src/techniques/guiding/guiding.cpp.
//
// A point's region is found by walking the region tree (BINDING_GUIDING_NODES). The regions
// are also AABBs in their own TLAS (BINDING_GUIDING_TLAS, primitive i = region
// guiding_order[i]): the lobes pass sends camera rays through it, and the intersection shader
// reports the sphere drawn at each trained region's centre.
//
// Entry points that cannot trace rays (intersection, closest-hit) define PX_NO_TRACE and get
// only the buffers.

layout(set = 0, binding = BINDING_GUIDING_REGIONS, scalar) readonly buffer GuidingRegionBuffer { GuidingRegion guiding_regions[]; };
layout(set = 0, binding = BINDING_GUIDING_LOBES, scalar) readonly buffer GuidingLobeBuffer { GuidingLobe guiding_lobes[]; };
layout(set = 0, binding = BINDING_GUIDING_ORDER, scalar) readonly buffer GuidingOrderBuffer { uint guiding_order[]; };
layout(set = 0, binding = BINDING_GUIDING_NODES, scalar) readonly buffer GuidingNodeBuffer { GuidingNode guiding_nodes[]; };
#define GUIDING_FETCH_LOBE(i) guiding_lobes[i]
#include "guiding.glsl"

// The sphere of the lobes pass: a quarter of the region's shortest side, at its centre, or with
// guiding_lobes_phase = phase in [0, 1) on a closed curve through the region (thesis fig. 4.20:
// the mixture is shown where the sphere is, so parallax-aware lobes turn to keep aiming at their
// targets as it moves). The curve keeps the sphere inside the box (0.2 + 0.25 < 0.5 of a side).
float guiding_sphere_radius(GuidingRegion g) {
    vec3 e = g.aabb_max - g.aabb_min;
    return 0.25 * min(e.x, min(e.y, e.z));
}

vec3 guiding_sphere_centre(GuidingRegion g, float phase) {
    vec3 c = 0.5 * (g.aabb_min + g.aabb_max);
    if (phase < 0.0) return c;
    float a = 2.0 * PI * phase;
    return c + 0.2 * (g.aabb_max - g.aabb_min) * vec3(sin(a), sin(2.0 * a), cos(a));
}

#ifndef PX_NO_TRACE
layout(set = 0, binding = BINDING_GUIDING_TLAS) uniform accelerationStructureEXT guiding_tlas;
layout(set = 0, binding = BINDING_GUIDING_SAMPLES, scalar) writeonly buffer GuidingSampleBuffer { GuidingSample guiding_samples[]; };
layout(location = 3) rayPayloadEXT GuidingQuery guiding_query;

// The region holding p (thesis 4.6.1): a walk down the region tree (GuidingNode); points
// outside the scene box land in the nearest region, non-finite ones in none (NO_INDEX). The
// thesis queries the region TLAS with a zero-length ray instead; on lavapipe that ray costs
// about as much as a path segment, the walk a few loads (the TLAS stays for the lobes pass).
uint guiding_region_at(vec3 p) {
    if (any(isnan(p)) || any(isinf(p))) return NO_INDEX;
    GuidingNode node = guiding_nodes[0];
    for (uint depth = 0u; depth < 256u && (node.link & 3u) != GUIDING_NODE_LEAF; ++depth)
        node = guiding_nodes[(node.link >> 2) + (p[node.link & 3u] >= node.split ? 1u : 0u)];
    return (node.link & 3u) == GUIDING_NODE_LEAF ? node.link >> 2 : NO_INDEX;
}

// Vertices that are guided and record training samples: diffuse, or rough enough that the
// incident light matters more than the BSDF lobe (the reference skips roughness <= 0.3).
// A Principled BSDF is guided when rough or when it has a diffuse base.
bool guiding_surface(Surface s, float roughness) {
    return s.type == MATERIAL_DIFFUSE ||
           ((s.type == MATERIAL_CONDUCTOR || s.type == MATERIAL_DIELECTRIC) && roughness > GUIDING_MIN_ROUGHNESS) ||
           (HAS(FEATURE_PRINCIPLED) && s.type == MATERIAL_PRINCIPLED &&
            (roughness > GUIDING_MIN_ROUGHNESS || max3(s.pr.w[5]) > 0.0));
}

// Heat colour for a direction density, on a log scale relative to the uniform sphere:
// black (0) .. red .. yellow .. white (1000x uniform).
vec3 guiding_heat(float pdf) {
    float t = clamp(log(1.0 + 4.0 * PI * max(pdf, 0.0)) / log(1001.0), 0.0, 1.0);
    return clamp(vec3(3.0 * t, 3.0 * t - 1.0, 3.0 * t - 2.0), 0.0, 1.0);
}

// A colour per region (Guiding Regions pass): a hash of its index.
vec3 guiding_region_colour(uint r) {
    if (r == NO_INDEX) return vec3(0.0);
    uint h = r * 0x9e3779b1u;
    h ^= h >> 15;
    h *= 0x85ebca77u;
    h ^= h >> 13;
    return vec3(float(h & 0xffu), float((h >> 8) & 0xffu), float((h >> 16) & 0xffu)) / 255.0 * 0.8 + 0.2;
}

// Guiding Lobes pass, outside the inset: the sphere of a trained region (guiding_sphere_centre)
// that the camera ray (o, d) meets before t_max, coloured by that region's VMM pdf, queried at the
// sphere's centre, of the direction of its normal (thesis figs. 4.19, 4.20). Black where there is none.
vec3 guiding_sphere_colour(vec3 o, vec3 d, float t_max, float phase) {
    guiding_query.region = NO_INDEX;
    traceRayEXT(guiding_tlas, gl_RayFlagsOpaqueEXT, 0xff, 0, 0, MISS_GUIDING_QUERY, o, 0.0, d, t_max, 3);
    uint r = guiding_query.region;
    if (r == NO_INDEX) return vec3(0.0);
    GuidingRegion g = guiding_regions[r];
    vec3 c = guiding_sphere_centre(g, phase);
    vec3 n = normalize(o + guiding_query.t * d - c);
    return guiding_heat(guiding_vmm_pdf(r * GUIDING_MAX_COMPONENTS, g.lobe_count, c, n));
}

// Guiding Lobes pass inset: the lat-long plot (+z up, row 0 = zenith) of the VMM at point x
// (the probe pixel's first hit), at inset coordinates uv in [0,1)^2.
vec3 guiding_inset_colour(vec3 x, bool found, vec2 uv) {
    if (!found) return vec3(0.05);
    uint r = guiding_region_at(x);
    if (r == NO_INDEX || guiding_regions[r].lobe_count == 0u) return vec3(0.1);
    float phi = 2.0 * PI * uv.x, theta = PI * uv.y;
    vec3 w = vec3(sin(theta) * cos(phi), sin(theta) * sin(phi), cos(theta));
    return guiding_heat(guiding_vmm_pdf(r * GUIDING_MAX_COMPONENTS, guiding_regions[r].lobe_count, x, w));
}
#endif
