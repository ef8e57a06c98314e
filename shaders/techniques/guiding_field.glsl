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

#ifdef PX_TRACE_LOOP
// ---- hooks of the trace loop (lib/integrator.glsl, techniques.glsl) ----------------------

// A path's use of guiding.
struct GuidingOptions {
    bool on;            // guided sampling where the region has a mixture
    bool record_pixel;  // the pixel's turn (record_stride) to record training samples this frame
    bool record;        // record training samples at the path's first guided vertices ...
    uint slot;          // ... into guiding_samples[slot * GUIDING_PATH_VERTICES + k]
};

GuidingOptions guiding_no_options() { return GuidingOptions(false, false, false, 0u); }

GuidingOptions guiding_camera_options(uint pixel_index, bool estimate_frame) {
    GuidingOptions o = guiding_no_options();
    o.on = USES(TECH_GUIDING) && !estimate_frame;
    // This pixel's first record_samples paths of the frame record training samples, if the
    // pixel's turn (record_stride) has come.
    uint stride = max(tech.guiding.record_stride, 1u);
    o.record_pixel = USES(TECH_GUIDING) && params.guiding_record != 0u && !estimate_frame &&
                     pixel_index % stride == params.frame % stride;
    return o;
}

// ADRRS' split copies are guided; they record nothing.
GuidingOptions guiding_split_options() { return GuidingOptions(USES(TECH_GUIDING), false, false, 0u); }

// Sample s of this dispatch's share of the frame.
void guiding_sample_options(inout GuidingOptions o, uint s, uint pixel_index, uint npix) {
    if (!USES(TECH_GUIDING)) return;
    uint stride = max(tech.guiding.record_stride, 1u);
    uint g_sample = params.sample_offset + s;  // of the frame (a dispatch may hold a share)
    o.record = o.record_pixel && g_sample < tech.guiding.record_samples;
    o.slot = g_sample * npix + pixel_index / stride;
}

// Guiding training records (thesis 4.6.2) of this path's first guided vertices: the
// direction sampled there, its pdf, and what the rest of the path brings in along it,
// luminance(radiance at the end - radiance when it was sampled) / luminance(throughput
// after its sampling weight), the incident luminance weighted by the path's colour. With
// NEE that is the MIS-weighted emission the next segment finds plus the light (NEE and
// beyond) of the later vertices: the next vertex's NEE is credited, the emission NEE
// already sampled here counts only with its BSDF-side MIS weight. A record goes to the
// sample buffer at its vertex and gets its distance and weight there later: only two
// floats per record stay in registers (whole records kept across the trace calls made a
// GPU's ray-tracing stack, and every path, much larger).
struct GuidingPath {
    vec4 base;        // luminance of the radiance when each record was sampled
    vec4 norm;        // luminance of the throughput after its sampling weight * pdf
    vec4 nee;         // what each record's vertex's shadow ray brought, as with NEE always taken (-1: none)
    uint count;
    uint open;        // the record whose next non-specular vertex is not reached yet
    float travelled;  // path length from that record's vertex to this segment's origin
    uint slot;
    uint shadow_record;  // the record sampled at the pending shadow ray's vertex (NO_INDEX: none)
    float shadow_nee_prob;   // that vertex's probability of NEE
    float previous_nee_prob; // the probability of NEE at the vertex the path last left by sampling
};

GuidingPath guiding_path(GuidingOptions o) {
    return GuidingPath(vec4(0.0), vec4(0.0), vec4(-1.0), 0u, NO_INDEX, 0.0, o.slot * GUIDING_PATH_VERTICES, NO_INDEX,
                       1.0, 1.0);
}

// The pending shadow ray was traced or not (traced: one was pending; lit: it reached its light,
// adding `light`). The record sampled at its vertex (base: the radiance when it was sampled)
// counts that light as already there: a vertex's own NEE is not light arriving along its sampled
// direction. The record also keeps the light as NEE taken every time would have brought it
// (the learnt NEE probability's statistics).
void guiding_shadow_traced(inout GuidingPath g, bool traced, bool lit, vec3 light) {
    if (!USES(TECH_GUIDING)) return;
    if (g.shadow_record != NO_INDEX) {
        if (lit) g.base[g.shadow_record] += luminance(light);
        if (traced) g.nee[g.shadow_record] = lit ? luminance(light) * g.shadow_nee_prob : 0.0;
    }
    g.shadow_record = NO_INDEX;
}

// The probability of NEE at the vertex the path last left (emission MIS weights).
float guiding_previous_nee_prob(GuidingPath g) { return USES(TECH_GUIDING) ? g.previous_nee_prob : 1.0; }

// The segment escaped: its record keeps the infinite distance.
void guiding_escaped(GuidingPath g) {
    if (USES(TECH_GUIDING) && g.open != NO_INDEX) guiding_samples[g.slot + g.open].distance = GUIDING_DISTANCE_INFINITE;
}

// The segment hit a surface at distance t: the open record's distance, final unless this
// vertex turns out delta (guiding_vertex).
void guiding_hit(GuidingPath g, float t) {
    if (USES(TECH_GUIDING) && g.open != NO_INDEX) guiding_samples[g.slot + g.open].distance = g.travelled + t;
}

// The guiding region's mixture at a vertex (none: BSDF sampling alone).
struct GuidingVertex {
    bool guided;  // a guided vertex (it records a training sample)
    uint region;
    uint lobes;
    float prob;   // of sampling the mixture (0: none here; learnt per region, GuidingRegion.prob)
    uint first;   // the region's first lobe
    float nee_prob;  // of taking NEE here (learnt per region, GuidingRegion.nee_prob; MIS only)
};

GuidingVertex guiding_vertex(inout GuidingPath g, GuidingOptions o, Surface surf, float roughness, bool delta,
                             float t, vec3 p) {
    if (USES(TECH_GUIDING) && g.open != NO_INDEX) {
        if (delta) g.travelled += t;  // through specular chains to the next real vertex
        else g.open = NO_INDEX;
    }
    GuidingVertex v;
    v.guided = USES(TECH_GUIDING) && o.on && !delta && guiding_surface(surf, roughness);
    v.region = NO_INDEX;
    v.lobes = 0u;
    v.prob = 0.0;
    v.nee_prob = 1.0;
    if (v.guided) {
        v.region = guiding_region_at(p);
        if (v.region != NO_INDEX) {
            v.lobes = guiding_regions[v.region].lobe_count;
            v.prob = v.lobes > 0u ? guiding_regions[v.region].prob : 0.0;
            if (METHOD == METHOD_MIS) v.nee_prob = guiding_regions[v.region].nee_prob;
        }
    }
    v.first = v.region * GUIDING_MAX_COMPONENTS;
    return v;
}

// The probability of NEE at a vertex: the region's where the path goes on (a last vertex has
// NEE alone, no BSDF sample to share the light with).
float guiding_nee_prob(GuidingVertex v, bool last_vertex) {
    return USES(TECH_GUIDING) && !last_vertex ? v.nee_prob : 1.0;
}

// The path left vertex v by sampling: the emission its next segment finds is weighted against
// v's NEE, taken with v's probability.
void guiding_continued(inout GuidingPath g, GuidingVertex v) {
    if (USES(TECH_GUIDING)) g.previous_nee_prob = v.nee_prob;
}

// Guided vertex: the continuation's density is the one-sample MIS mixture.
float guiding_continuation_pdf(GuidingVertex v, float bsdf_pdf, vec3 p, vec3 wi) {
    if (USES(TECH_GUIDING) && v.prob > 0.0) return mix(bsdf_pdf, guiding_vmm_pdf(v.first, v.lobes, p, wi), v.prob);
    return bsdf_pdf;
}

// With probability prob a direction from the region's VMM (one-sample MIS, Veach 1997 sec.
// 9.2.4: the direction's weight is f cos / (p p_vmm + (1 - p) p_bsdf) whichever technique drew
// it; guiding_sampled_pdf makes it so). False: the BSDF samples. `ok` false: the path ends.
bool guiding_sample(GuidingVertex v, Surface surf, vec3 wo_local, vec3 p, vec3 tangent, vec3 bitangent, vec3 ns,
                    inout Rng rng, out BsdfSample bs, out bool ok) {
    ok = true;
    if (!(USES(TECH_GUIDING) && v.prob > 0.0 && rnd(rng) < v.prob)) return false;
    vec3 wi = guiding_vmm_sample(v.first, v.lobes, p, rnd3(rng).zxy);
    bs.wi = vec3(dot(wi, tangent), dot(wi, bitangent), dot(wi, ns));
    vec3 f = bsdf_eval(surf, wo_local, bs.wi, bs.pdf);
    ok = !(max3(f) <= 0.0 || !(bs.pdf > 0.0));
    bs.weight = f / bs.pdf;  // as if the BSDF had sampled it; the mixture pdf follows
    bs.delta = false;
    // A guided direction has no lobe: a reflection counts as diffuse off a surface with a
    // diffuse lobe (Cycles' budgets, BOUNCE_*).
    bool diffuse = surf.type == MATERIAL_DIFFUSE ||
                   (HAS(FEATURE_PRINCIPLED) && surf.type == MATERIAL_PRINCIPLED && max3(surf.pr.w[5]) > 0.0);
    bs.kind = bs.wi.z < 0.0 ? BOUNCE_TRANSMISSION : (diffuse ? BOUNCE_DIFFUSE : BOUNCE_GLOSSY);
    return true;
}

// The sampled direction's density and weight under the mixture.
void guiding_sampled_pdf(GuidingVertex v, vec3 p, vec3 tangent, vec3 bitangent, vec3 ns, inout BsdfSample bs) {
    if (!(USES(TECH_GUIDING) && v.prob > 0.0 && !bs.delta)) return;
    vec3 wi = normalize(bs.wi.x * tangent + bs.wi.y * bitangent + bs.wi.z * ns);
    float pdf = mix(bs.pdf, guiding_vmm_pdf(v.first, v.lobes, p, wi), v.prob);
    bs.weight *= bs.pdf / pdf;
    bs.pdf = pdf;
}

// A training record at a guided vertex that continued in direction dir (pdf, the BSDF's own
// bsdf_pdf; delta: a delta lobe sampled it): the radiance and throughput it starts from.
void guiding_record(inout GuidingPath g, GuidingOptions o, GuidingVertex v, vec3 p, vec3 dir, float pdf,
                    float bsdf_pdf, bool delta, vec3 radiance, vec3 throughput) {
    if (!(USES(TECH_GUIDING) && o.record && v.guided && g.count < GUIDING_PATH_VERTICES)) return;
    guiding_samples[g.slot + g.count] = GuidingSample(p, v.region, guiding_pack_direction(dir), pdf, 0.0,
                                                      GUIDING_DISTANCE_INFINITE, delta ? 0.0 : bsdf_pdf, 0.0, -1.0, 0u);
    g.shadow_nee_prob = v.nee_prob;
    g.base[g.count] = luminance(radiance);
    g.norm[g.count] = luminance(throughput) * pdf;
    g.shadow_record = g.count;
    g.open = g.count++;
    g.travelled = 0.0;
}

// Russian roulette's view of the throughput (PathState.roulette_throughput).
vec3 guiding_roulette_throughput(vec3 roulette_throughput, vec3 throughput) {
    return USES(TECH_GUIDING) ? roulette_throughput : throughput;
}

// The path ended with `radiance`: each record's contribution (what the path gained after it)
// and weight.
void guiding_path_end(GuidingPath g, vec3 radiance) {
    if (!USES(TECH_GUIDING)) return;
    float end = luminance(radiance);
    for (uint k = 0u; k < g.count; ++k) {  // non-finite: the host drops it
        float gained = max(end - g.base[k], 0.0);
        guiding_samples[g.slot + k].weight = g.norm[k] > 0.0 ? gained / g.norm[k] : 0.0;
        guiding_samples[g.slot + k].contribution = g.norm[k] > 0.0 ? gained : 0.0;
        guiding_samples[g.slot + k].nee_light = g.nee[k];
    }
}

// ---- the passes of thesis 4.7 ------------------------------------------------------------

// Guiding Lobes pass (thesis 4.7, figs. 4.18-4.19): in the inset at the bottom left (a third
// of the width, lat-long 2:1), the VMM of the probe pixel's first hit (guiding_probe_x/y;
// -1: the image centre); elsewhere the per-region spheres the camera ray meets before its
// first hit, and a white cross on the probe pixel.
vec3 guiding_lobes_pass(uvec2 pixel, vec3 origin, vec3 dir, float first_t) {
    uint iw = max(params.width / 3u, 2u), ih = min(max(iw / 2u, 1u), params.height);
    int px = tech.guiding.probe_x >= 0 ? min(tech.guiding.probe_x, int(params.width) - 1) : int(params.width / 2u);
    int py = tech.guiding.probe_y >= 0 ? min(tech.guiding.probe_y, int(params.height) - 1) : int(params.height / 2u);
    if (pixel.x < iw && pixel.y >= params.height - ih) {
        vec3 o, d;
        float t0, t1, c;
        bool seen = camera_ray(vec2(px, py) + 0.5, vec2(0.0), o, d, t0, t1, c);  // the lens' centre
        if (seen) traceRayEXT(tlas, gl_RayFlagsOpaqueEXT, 0xff, 0, 0, MISS_SCENE, o, t0, d, t1, 0);
        else hit.t = -1.0;
        vec2 uv = vec2((float(pixel.x) + 0.5) / float(iw), (float(pixel.y - (params.height - ih)) + 0.5) / float(ih));
        return guiding_inset_colour(o + hit.t * d, hit.t >= 0.0, uv);
    }
    if ((int(pixel.x) == px && abs(int(pixel.y) - py) <= 2) || (int(pixel.y) == py && abs(int(pixel.x) - px) <= 2))
        return vec3(1.0);
    return guiding_sphere_colour(origin, dir, min(first_t, INFINITY_F), tech.guiding.lobes_phase);
}

// The guiding passes of a pixel.
struct GuidingPixel {
    vec3 regions;
    vec3 lobes;
    float components;
};

GuidingPixel guiding_pixel() { return GuidingPixel(vec3(0.0), vec3(0.0), 0.0); }

// The passes at the first hit, of the frame's first sample only (weighted by the frame's
// samples): the lobes pass traces a ray through the region TLAS, which for every sample would
// cost about as much as the path itself. It is in the pipelines that show it only
// (TECH_GUIDING_LOBES).
void guiding_add_sample(inout GuidingPixel px, GuidingOptions o, uint s, uvec2 pixel, vec3 origin, vec3 dir,
                        float first_t) {
    if (!(USES(TECH_GUIDING) && o.on && s == 0u)) return;
    float n = float(params.sample_count);
    uint region = first_t < INFINITY_F ? guiding_region_at(origin + first_t * dir) : NO_INDEX;
    px.regions = n * guiding_region_colour(region);
    if (region != NO_INDEX)
        px.components = n * float(guiding_regions[region].lobe_count) / float(max(tech.guiding.max_components, 1u));
    if (USES(TECH_GUIDING_LOBES)) px.lobes = n * guiding_lobes_pass(pixel, origin, dir, first_t);
}

void guiding_write_passes(GuidingPixel px, uint pixel_index) {
    if (!USES(TECH_GUIDING)) return;
    film_add(PASS_GUIDING_REGIONS, pixel_index, vec4(px.regions, 0.0));
    film_add(PASS_GUIDING_COMPONENTS, pixel_index, vec4(px.components, 0.0, 0.0, 0.0));
    film_add(PASS_GUIDING_LOBES, pixel_index, vec4(px.lobes, 0.0));
}
#endif
#endif
