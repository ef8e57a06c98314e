// The one configurable trace loop (DESIGN: "One configurable trace loop"). Unidirectional
// path tracing with BSDF sampling (METHOD_PT), next event estimation (METHOD_NEE), or both
// combined by MIS (METHOD_MIS, Veach 1997 ch. 9, multi-sample model with N light samples
// and one BSDF sample per vertex).
layout(constant_id = 0) const uint METHOD = METHOD_MIS;

#include "../techniques/irradiance_cache.glsl"
#include "../techniques/adrrs.glsl"
#include "../techniques/guiding_field.glsl"

layout(set = 0, binding = BINDING_TLAS) uniform accelerationStructureEXT tlas;
layout(location = 0) rayPayloadEXT HitPayload hit;
layout(location = 1) rayPayloadEXT HitPayload shadow_hit;

struct PathOptions {
    uint max_depth;       // non-discrete bounces; emission one segment further still counts
    uint depth_leeway;    // discrete (delta) bounces that do not count towards max_depth
    uint rr_start_depth;  // Russian roulette from this bounce on (0: never)
    uint light_samples;   // NEE samples per vertex
    bool from_camera;     // the first segment is a camera ray (sees only camera-visible lights)
    bool skip_first_emission;  // cache hemisphere rays: the entry's direct light is NEE's
    bool ic_use;          // shade diffuse vertices from the irradiance cache where it has entries
    bool ic_glossy;       // ... and glossy ones (ADRRS' estimate, thesis 4.4 "IC on glossy")
    bool ic_create;       // queue cache creation requests at uncovered diffuse vertices
    bool ic_prepare;      // prepare frame: stop at the first diffuse vertex after the query
    bool first_vertex_only;  // end after the first non-delta vertex's emission, NEE and cache
    bool adrrs;           // roulette and split by the adjoint (needs a pixel estimate)
    float adrrs_estimate; // luminance of the pixel estimate I~
    uint adrrs_local;     // the pixel's slot in this dispatch's split queue
    uint adrrs_pixels;    // pixels of this dispatch
    uint adrrs_samples;   // samples per pixel of this dispatch (the split budget's multiple)
    uint pixel;           // for creation requests (their order on the host)
    bool guiding;         // guided sampling where the region has a mixture (TECH_GUIDING)
    bool guiding_record;  // record training samples at the first guided vertices ...
    uint guiding_slot;    // ... into guiding_samples[slot * GUIDING_PATH_VERTICES + k]
    // Where the path starts: a camera or hemisphere ray (throughput 1, no bounces), or a split
    // copy (resume): the ray to a vertex whose emission and NEE the path that split counted.
    vec3 throughput;
    uint bounces;
    uint discrete;
    bool resume;
    // The triangle the first ray starts on (NO_INDEX: a camera or cache ray, off any surface).
    uint self_instance;
    uint self_primitive;
};

// Options for a plain path from the frame's settings; callers change what differs.
PathOptions path_options() {
    PathOptions opt;
    opt.max_depth = params.max_depth;
    opt.depth_leeway = params.depth_leeway;
    opt.rr_start_depth = params.rr_start_depth;
    opt.light_samples = max(params.light_samples, 1u);
    opt.from_camera = false;
    opt.skip_first_emission = false;
    opt.ic_use = false;
    opt.ic_glossy = false;
    opt.ic_create = false;
    opt.ic_prepare = false;
    opt.first_vertex_only = false;
    opt.adrrs = false;
    opt.adrrs_estimate = 0.0;
    opt.adrrs_local = 0u;
    opt.adrrs_pixels = 0u;
    opt.adrrs_samples = 1u;
    opt.pixel = 0u;
    opt.guiding = false;
    opt.guiding_record = false;
    opt.guiding_slot = 0u;
    opt.throughput = vec3(1.0);
    opt.bounces = 0u;
    opt.discrete = 0u;
    opt.resume = false;
    opt.self_instance = NO_INDEX;
    opt.self_primitive = NO_INDEX;
    return opt;
}

struct PathResult {
    vec3 radiance;
    float first_t;      // distance to the first hit (INFINITY_F: none)
    vec3 first_normal;  // shading normal of the first hit
    vec3 albedo;        // at the first non-delta vertex, through delta vertices
    uint segments;      // ray segments traced (camera ray included)
    uint rays;          // all rays traced (shadow rays included)
    vec3 ic_irradiance; // cache value at the first diffuse vertex (0: no entry there)
    vec2 ic_gradients;  // its entries' mean |g_t|, |g_r|
};

// Path rays that leave a surface where it may touch another through which light passes start
// on it, as Cycles' do: the origin is the hit point moved a few ulps back against the ray's
// direction (leave_surface, 8 ulps), so a surface touching this one (a glass cube resting on a
// floor) lies ahead at t > 0, and self_skip.rahit ignores the triangle itself. Both the
// refracted ray out of the cube's bottom face and the glass' internal reflection there then
// meet the floor, and a floor bounce under the cube enters the glass through its bottom face,
// so every exit from the glass has its entry. Such rays (self_instance set) are not opaque.
// Everywhere else (may_touch_transmission false) rays start past the surface (offset_ray) and
// are opaque: no any-hit calls, a third faster on lavapipe; there no light passes a surface
// touching another, so nothing is found at a contact but unlit, unseen faces. Rays off any
// surface (camera, cache and reflected shadow rays) are opaque too.
uint surface_ray_flags(uint self_instance) {
    return (!HAS(FEATURE_TRANSMISSION) || self_instance == NO_INDEX) ? gl_RayFlagsOpaqueEXT : gl_RayFlagsNoneEXT;
}

// Whether surface point p of `instance` may touch a surface that transmits light: on a
// transmissive instance, or inside the grown box of one (SceneInfo.contact_lo/hi).
bool may_touch_transmission(uint instance, vec3 p) {
    if (!HAS(FEATURE_TRANSMISSION)) return false;
    if ((instances[instance].flags & INSTANCE_FLAG_TRANSMITS) != 0u) return true;
    for (uint k = 0u; k < scene.contact_box_count; ++k)
        if (all(greaterThanEqual(p, scene.contact_lo[k])) && all(lessThanEqual(p, scene.contact_hi[k]))) return true;
    return false;
}

// 8 ulps back, not offset_ray's 256: from further behind a tessellated convex surface, rays
// leaving near an edge at grazing angles hit the neighbouring triangle (a furnace sphere of
// diffuse + mirror + glass gained 1.4% energy that way).
vec3 leave_surface(vec3 p, vec3 ng, vec3 dir, bool contact) {
    if (!contact) return offset_ray(p, dot(dir, ng) > 0.0 ? ng : -ng);
    return offset_ray_scaled(p, dot(dir, ng) > 0.0 ? -ng : ng, 1.0 / 32.0);
}

// Whether any vertex of this pipeline's paths takes NEE: PT does only where the irradiance
// cache or ADRRS' estimate ends a path.
// (A mask, not an || of specialisation constants: glslang 11 emits invalid SPIR-V for that.)
const uint NEE_USED = uint(METHOD != METHOD_PT) | (TECHNIQUES & (TECH_IC | TECH_ADRRS));

// A vertex's NEE shadow ray, traced later: just before the path's next ray, or when the path
// ends. Its vertex's surface, shading frame and BSDF are then no longer live across the trace
// call, and the shadow and path rays are traced at the same point of every loop iteration.
// With the empty calls below, on the H200 guided MIS frames cost 12-20% less, NEE and MIS
// frames in light behind glass 11-19% less, NEE on clocks 6% more
// (bench/results/gpu_nee/README.md); lavapipe runs as fast as before.
struct ShadowRay {
    vec3 origin;
    float t_max;
    vec3 dir;
    uint self_instance;
    vec3 contribution;  // 0: no shadow ray pending
    uint self_primitive;
    uint record;        // the guiding record sampled at the ray's vertex (NO_INDEX: none)
};

ShadowRay no_shadow_ray(vec3 origin, vec3 dir) {
    return ShadowRay(origin, 0.0, dir, NO_INDEX, vec3(0.0), NO_INDEX, NO_INDEX);
}

// 1 (GPUs): paths without a pending shadow ray make an empty trace call (cull mask 0, zero
// length) all the same; without them NEE and MIS frames in light behind glass cost 14-16%
// more on the H200. 0 (lavapipe): they skip it; the empty calls cost lavapipe 8% there.
layout(constant_id = 4) const uint EMPTY_SHADOW_CALLS = 1u;

// Traces the pending shadow ray and adds its light where nothing is in the way. The guiding
// record sampled at its vertex (g_base: the radiance when it was sampled) counts that light as
// already there: a vertex's own NEE is not light arriving along its sampled direction.
void trace_pending_shadow(inout ShadowRay pending, inout PathResult res, inout vec4 g_base) {
    if (NEE_USED == 0u) return;
    bool pending_ray = max3(pending.contribution) > 0.0;
    if (!pending_ray) {
        if (EMPTY_SHADOW_CALLS == 0u) return;
    }
    if (pending_ray) res.rays++;
    shadow_hit.t = 0.0;
    shadow_hit.instance = pending.self_instance;
    shadow_hit.primitive = pending.self_primitive;
    traceRayEXT(tlas, surface_ray_flags(pending.self_instance) | gl_RayFlagsTerminateOnFirstHitEXT | gl_RayFlagsSkipClosestHitShaderEXT,
                pending_ray ? 0xffu : 0u, 0, 0, MISS_SHADOW, pending.origin, 0.0, pending.dir,
                pending_ray ? pending.t_max : 0.0, 1);
    if (pending_ray && shadow_hit.t < 0.0) {
        res.radiance += pending.contribution;
        if (USES(TECH_GUIDING) && pending.record != NO_INDEX) g_base[pending.record] += luminance(pending.contribution);
    }
    pending.contribution = vec3(0.0);
}

// The material of a mix chain whose BSDF scatters at this hit (Material.mix_next). One
// uniform number picks link i with probability w_i prod_{j<i} (1 - w_j) and is rescaled at
// each link it passes, so one draw serves the whole chain. Estimating the chosen lobe's
// integral on its own (with its own NEE/BSDF MIS) is an unbiased one-sample estimator of
// the mixture f = sum_i P(i) f_i: stochastic selection of BSDF components, as pbrt-v4's
// MixMaterial resolves a mix to one material at the intersection (pbrt-v3's MixMaterial
// instead sums scaled BxDFs), i.e. Veach's one-sample model over lobes (Veach 1997,
// sec. 9.2.4). The host guarantees the chain ends within MIX_CHAIN_MAX materials.
Material select_mix_material(Material head, inout Rng rng) {
    Material m = head;
    if (!HAS(FEATURE_MIX) || head.mix_next < 0) return m;
    float u = rnd(rng);
    for (uint i = 1u; i < MIX_CHAIN_MAX && m.mix_next >= 0; ++i) {
        if (u < m.mix_weight) break;
        // u >= w and u < 1 imply w < 1; the rescaled u is uniform on [0,1) again.
        u = min((u - m.mix_weight) / (1.0 - m.mix_weight), 0.99999994);
        m = materials[m.mix_next];
    }
    return m;
}

// Weight of emission found by a ray that left a vertex by BSDF sampling (pdf prev_pdf, or
// delta / a camera ray) and hit an emitter that NEE samples with density light_pdf.
float emission_weight(bool prev_delta, float prev_pdf, float light_pdf, uint light_samples) {
    if (METHOD == METHOD_PT || prev_delta) return 1.0;
    if (METHOD == METHOD_NEE) return 0.0;
    return mis_weight(prev_pdf, float(light_samples) * light_pdf);
}

PathResult trace_path(vec3 origin, vec3 dir, float t_min, float t_max, PathOptions opt, inout Rng rng) {
    PathResult res;
    res.radiance = vec3(0.0);
    res.first_t = INFINITY_F;
    res.first_normal = vec3(0.0);
    res.albedo = vec3(0.0);
    res.segments = 0u;
    res.rays = 0u;
    res.ic_irradiance = vec3(0.0);
    res.ic_gradients = vec2(0.0);
    bool ic_recorded = false;
    vec3 throughput = opt.throughput;
    // Russian roulette's view of the throughput: as if the BSDF had sampled every direction.
    // A guided direction's weight carries 1/p of the mixture, small where the mixture aims at
    // the light; roulette on it would end the very paths guiding sends towards the light (the
    // lamp behind glass is reached only after the roulette depth). Any survival probability
    // keeps the estimate unbiased: the path's weight is divided by it.
    vec3 roulette_throughput = opt.throughput;
    vec3 albedo_throughput = vec3(1.0);
    bool albedo_done = false;
    bool prev_delta = true;  // the camera ray counts as delta: nothing to weigh it against
    float prev_pdf = 0.0;
    vec3 prev_ng = vec3(0.0);  // geometric normal at the segment's origin (the light tree's receiver)
    uint bounces = opt.bounces, discrete = opt.discrete;
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
    vec4 g_base = vec4(0.0);  // luminance of the radiance when each record was sampled
    vec4 g_norm = vec4(0.0);  // luminance of the throughput after its sampling weight * pdf
    uint g_count = 0u;
    uint g_open = NO_INDEX;  // the record whose next non-specular vertex is not reached yet
    float g_travelled = 0.0; // path length from that record's vertex to this segment's origin
    uint g_slot = opt.guiding_slot * GUIDING_PATH_VERTICES;
    uint self_instance = opt.self_instance, self_primitive = opt.self_primitive;
    ShadowRay pending = no_shadow_ray(origin, dir);

    for (;;) {
        trace_pending_shadow(pending, res, g_base);
        hit.instance = self_instance;
        hit.primitive = self_primitive;
        traceRayEXT(tlas, surface_ray_flags(self_instance), 0xff, 0, 0, MISS_SCENE, origin, t_min, dir, t_max, 0);
        res.rays++;
        res.segments++;
        float t_surface = hit.t < 0.0 ? t_max : hit.t;
        bool camera_ray = opt.from_camera && res.segments == 1u;
        // A split copy re-traces the ray to its vertex, whose emission and NEE are counted.
        bool resumed = opt.resume && res.segments == 1u;
        float emission_scale = ((opt.skip_first_emission || opt.resume) && res.segments == 1u) ? 0.0 : 1.0;

        // Analytic lights are not in the TLAS: test them against this segment. As in Cycles they
        // do not occlude (shadow rays ignore them too): every one along the segment adds its
        // emission and the ray goes on to what lies behind.
        for (uint i = scene.analytic_first; HAS(FEATURE_SPHERE_LIGHTS | FEATURE_AREA_LIGHTS) && i < analytic_end(camera_ray); ++i) {
            float t_light, light_pdf;
            vec3 light_radiance;
            if (!analytic_light_hit(i, origin, prev_ng, dir, t_surface, t_light, light_radiance, light_pdf)) continue;
            res.radiance += throughput * light_radiance * (emission_scale * emission_weight(prev_delta, prev_pdf, light_pdf, opt.light_samples));
            if (res.segments == 1u) res.first_t = min(res.first_t, t_light);
        }
        if (hit.t < 0.0) {  // escaped: its record keeps the infinite distance
            if (USES(TECH_GUIDING) && g_open != NO_INDEX) guiding_samples[g_slot + g_open].distance = GUIDING_DISTANCE_INFINITE;
            float light_pdf;
            vec3 le = distant_radiance(dir, camera_ray, light_pdf);
            res.radiance += throughput * le * (emission_scale * emission_weight(prev_delta, prev_pdf, light_pdf, opt.light_samples));
            break;
        }

        SurfaceHit sh = fetch_surface(hit.instance, hit.primitive, hit.barycentrics);
        Material mat = materials[sh.material];
        vec3 wo = -dir;
        // The open record's distance, final unless this vertex turns out delta (below).
        if (USES(TECH_GUIDING) && g_open != NO_INDEX) guiding_samples[g_slot + g_open].distance = g_travelled + hit.t;
        if (res.segments == 1u) {
            res.first_t = min(res.first_t, hit.t);  // a light in front keeps its distance
            res.first_normal = dot(sh.ns, wo) >= 0.0 ? sh.ns : -sh.ns;
        }
        if (max3(mat.emission) > 0.0 && emission_scale > 0.0) {
            float lp = 0.0;
            if (METHOD == METHOD_MIS && !prev_delta) {
                uint light = instances[sh.instance].light_offset + sh.primitive;
                lp = triangle_light_pdf(light, origin, prev_ng, hit.t, dot(sh.ng, dir));
            }
            res.radiance += throughput * mat.emission * emission_weight(prev_delta, prev_pdf, lp, opt.light_samples);
        }
        if (bounces > opt.max_depth) break;
        // Emission above is the head material's; the BSDF may come from its mix chain.
        mat = select_mix_material(mat, rng);
        if (mat.type == MATERIAL_EMISSION) break;

        // Shading frame. Reflective materials are two-sided: face the normals towards wo.
        // Glass keeps the geometric side to know whether the ray enters or leaves.
        bool front = dot(sh.ng, wo) > 0.0;
        vec3 ng = front ? sh.ng : -sh.ng;
        vec3 ns = front ? sh.ns : -sh.ns;
        if (dot(ns, wo) <= 1e-6) ns = ng;  // shading normal facing away from the viewer
        Surface surf;
        surf.type = mat.type;
        surf.albedo = material_albedo(mat, sh.uv);
        surf.alpha = mat.roughness * mat.roughness;
        surf.eta = front ? mat.ior : 1.0 / mat.ior;
        vec3 tangent, bitangent;
        make_basis(ns, tangent, bitangent);
        vec3 wo_local = vec3(dot(wo, tangent), dot(wo, bitangent), dot(wo, ns));
        surf.ms = vec3(1.0);
        if ((mat.flags & MATERIAL_FLAG_MULTISCATTER) != 0u) surface_multiscatter(surf, wo_local.z);
        if (HAS(FEATURE_PRINCIPLED) && mat.type == MATERIAL_PRINCIPLED)
            surf.pr = principled_setup(mat, surf.albedo, surf.eta, wo_local.z, (mat.flags & MATERIAL_FLAG_MULTISCATTER) != 0u);
        bool delta = surface_is_delta(surf);
        if (USES(TECH_GUIDING) && g_open != NO_INDEX) {
            if (delta) g_travelled += hit.t;  // through specular chains to the next real vertex
            else g_open = NO_INDEX;
        }
        // The guiding region's mixture at this vertex (none: BSDF sampling alone).
        bool g_vertex = USES(TECH_GUIDING) && opt.guiding && !delta && guiding_surface(surf, mat.roughness);
        uint g_region = NO_INDEX, g_lobes = 0u;
        if (g_vertex) {
            g_region = guiding_region_at(sh.p);
            if (g_region != NO_INDEX) g_lobes = guiding_regions[g_region].lobe_count;
        }
        float g_prob = g_lobes > 0u ? tech.guiding.prob : 0.0;
        uint g_first = g_region * GUIDING_MAX_COMPONENTS;
        if (!albedo_done && !delta) {
            res.albedo = albedo_throughput * surf.albedo;
            albedo_done = true;
        }

        // Irradiance cache at diffuse vertices (thesis 4.4): where entries cover this point the
        // path ends here with NEE + albedo/pi * E; elsewhere it may queue a new entry and goes on.
        // With ADRRS the cache's adjoint grid is read at every non-delta vertex (adrrs.glsl).
        bool ic_vertex = false, ic_found = false;
        vec3 irradiance = vec3(0.0);
        bool ic_surface = surf.type == MATERIAL_DIFFUSE || ((USES(TECH_ADRRS) || opt.ic_glossy) && !delta);
        if (USES(TECH_IC) && ic_surface && !resumed && (opt.ic_use || opt.ic_prepare)) {
            vec2 gradients;
            ic_found = ic_lookup(sh.p, ns, irradiance, gradients);
            if (!ic_recorded) {
                res.ic_irradiance = irradiance;
                res.ic_gradients = gradients;
                ic_recorded = true;
            }
            if (ic_found && opt.ic_use && (surf.type == MATERIAL_DIFFUSE || opt.ic_glossy)) {
                res.radiance += throughput * surf.albedo * INV_PI * irradiance;
                ic_vertex = true;
            } else if (!ic_found && opt.ic_create && rnd(rng) < tech.ic.create_prob) {
                ic_request(sh.p, ns, opt.pixel, res.segments);
            }
            if (opt.ic_prepare) {
                if (!ic_found) atomicAdd(ic_queue_uncovered, 1u);
                break;
            }
        } else if (USES(TECH_ADRRS) && ic_surface && !resumed && opt.adrrs) {
            ic_found = adrrs_adjoint_irradiance(sh.p, ns, irradiance);  // the adjoint alone
        }

        // Next event estimation (Veach 1997 eq. 9.8 / 9.13 weights for MIS). A vertex where the
        // path ends takes its direct light from NEE alone (no BSDF sample follows to share it).
        // The vertex's last light sample's shadow ray waits for the next path ray (see
        // ShadowRay); the others are traced here.
        bool last_vertex = ic_vertex || (opt.first_vertex_only && !delta);
        if ((METHOD != METHOD_PT || last_vertex) && !delta && !resumed) {
            for (uint k = 0u; k < opt.light_samples; ++k) {
                if (k > 0u) trace_pending_shadow(pending, res, g_base);  // the previous sample's
                LightSample ls;
                vec3 u = rnd3(rng);
                if (!sample_light(sh.p, sh.ng, u, ls)) continue;
                vec3 wi_local = vec3(dot(ls.wi, tangent), dot(ls.wi, bitangent), dot(ls.wi, ns));
                float bsdf_pdf;
                vec3 f = bsdf_eval(surf, wo_local, wi_local, bsdf_pdf);
                if (max3(f) <= 0.0 || max3(ls.radiance) <= 0.0) continue;
                // Guided vertex: the continuation's density is the one-sample MIS mixture.
                if (USES(TECH_GUIDING) && g_prob > 0.0)
                    bsdf_pdf = mix(bsdf_pdf, guiding_vmm_pdf(g_first, g_lobes, sh.p, ls.wi), g_prob);
                float w = (METHOD == METHOD_MIS && !ls.delta && !last_vertex) ? mis_weight(float(opt.light_samples) * ls.pdf, bsdf_pdf) : 1.0;
                pending.contribution = throughput * f * ls.radiance * (w / (ls.pdf * float(opt.light_samples)));
                // Aim the shadow ray from its origin at the sampled point itself (a direction
                // kept from the unmoved point misses grazing lights), stopping short of it.
                // A shadow ray through the surface (transmission) leaves on it; one on the side the
                // path came from leaves from the usual offset: a surface touching this one there
                // belongs to an object the ray then starts inside (the glass cube over the floor),
                // which blocks it all the same, and opaque rays need no any-hit calls.
                pending.origin = offset_ray(sh.p, ng);
                pending.dir = ls.wi;
                pending.t_max = INFINITY_F;
                if (ls.dist < INFINITY_F) {
                    vec3 to_light = sh.p + ls.wi * ls.dist - pending.origin;
                    pending.t_max = length(to_light);
                    pending.dir = to_light / pending.t_max;
                    pending.t_max *= 1.0 - 1e-4;
                }
                pending.self_instance = dot(ls.wi, ng) < 0.0 ? sh.instance : NO_INDEX;
                pending.self_primitive = sh.primitive;
                pending.record = NO_INDEX;
            }
        }
        if (last_vertex) break;

        // ADRRS (techniques/adrrs.glsl) on the continuation: roulette or split by the adjoint.
        bool adrrs_decided = false;
        if (USES(TECH_ADRRS) && opt.adrrs && ic_found && !delta) {
            float q = adrrs_factor(throughput, surf.albedo, irradiance, opt.adrrs_estimate);
            if (q < 1.0) {
                if (rnd(rng) >= q) break;
                throughput /= q;
                roulette_throughput /= q;
            } else if (q > 1.0) {
                // Within the pixel's split budget: q is capped before the expected-value
                // split, so every copy's weight 1/q stays exact.
                q = min(q, 1.0 + float(adrrs_copies_left(opt.adrrs_local, opt.adrrs_samples)));
                uint copies = adrrs_split_copies(q, rnd(rng));
                throughput /= q;
                roulette_throughput /= q;
                if (copies > 1u) {
                    uint flags = (opt.from_camera && res.segments == 1u) ? ADRRS_SPLIT_CAMERA_RAY : 0u;
                    uint seed = uint(rnd(rng) * 4294967040.0) ^ (res.segments << 24);
                    adrrs_queue(opt.adrrs_local, opt.adrrs_pixels,
                                AdrrsSplit(origin, t_min, dir, t_max, throughput, seed,
                                           bounces | (discrete << 16), copies - 1u, flags, res.segments,
                                           self_instance, self_primitive));
                }
            }
            adrrs_decided = true;
        }

        // Continue the path by sampling the BSDF, or at a guided vertex the region's VMM with
        // probability guiding_prob (one-sample MIS, Veach 1997 sec. 9.2.4: the direction's
        // weight is f cos / (p p_vmm + (1 - p) p_bsdf) whichever technique drew it).
        BsdfSample bs;
        if (USES(TECH_GUIDING) && g_prob > 0.0 && rnd(rng) < g_prob) {
            vec3 wi = guiding_vmm_sample(g_first, g_lobes, sh.p, rnd3(rng).zxy);
            bs.wi = vec3(dot(wi, tangent), dot(wi, bitangent), dot(wi, ns));
            vec3 f = bsdf_eval(surf, wo_local, bs.wi, bs.pdf);
            if (max3(f) <= 0.0 || !(bs.pdf > 0.0)) break;
            bs.weight = f / bs.pdf;  // as if the BSDF had sampled it; the mixture pdf follows
            bs.delta = false;
        } else if (!bsdf_sample(surf, wo_local, rnd3(rng), bs)) {
            break;
        }
        roulette_throughput *= bs.weight;
        if (USES(TECH_GUIDING) && g_prob > 0.0 && !bs.delta) {
            vec3 wi = normalize(bs.wi.x * tangent + bs.wi.y * bitangent + bs.wi.z * ns);
            float p = mix(bs.pdf, guiding_vmm_pdf(g_first, g_lobes, sh.p, wi), g_prob);
            bs.weight *= bs.pdf / p;
            bs.pdf = p;
        }
        throughput *= bs.weight;
        if (bs.delta) {
            discrete++;
            if (discrete > opt.depth_leeway) bounces++;
            if (!albedo_done) albedo_throughput *= bs.weight;
        } else {
            bounces++;
        }
        prev_delta = bs.delta;
        prev_pdf = bs.pdf;
        dir = normalize(bs.wi.x * tangent + bs.wi.y * bitangent + bs.wi.z * ns);
        if (USES(TECH_GUIDING) && opt.guiding_record && g_vertex && g_count < GUIDING_PATH_VERTICES) {
            guiding_samples[g_slot + g_count] = GuidingSample(sh.p, g_region, guiding_pack_direction(dir), bs.pdf, 0.0,
                                                              GUIDING_DISTANCE_INFINITE);
            g_base[g_count] = luminance(res.radiance);
            g_norm[g_count] = luminance(throughput) * bs.pdf;
            pending.record = g_count;
            g_open = g_count++;
            g_travelled = 0.0;
        }
        bool contact = may_touch_transmission(sh.instance, sh.p);
        origin = leave_surface(sh.p, ng, dir, contact);
        self_instance = contact ? sh.instance : NO_INDEX;
        self_primitive = sh.primitive;
        prev_ng = sh.ng;
        t_min = 0.0;
        t_max = INFINITY_F;
        if (max3(throughput) <= 0.0) break;
        // Russian roulette on the throughput: survival probability sqrt(max(throughput)), at most
        // 1, as Cycles (path_state_continuation_probability). Against max(throughput) it lowers
        // variance x rays per path by 10-13% on the Cornell box and the atrium (bench.variance).
        if (opt.rr_start_depth > 0u && bounces >= opt.rr_start_depth && !adrrs_decided) {
            float survive = min(1.0, sqrt(max3(USES(TECH_GUIDING) ? roulette_throughput : throughput)));
            if (rnd(rng) >= survive) break;
            throughput /= survive;
            roulette_throughput /= survive;
        }
    }
    trace_pending_shadow(pending, res, g_base);
    if (USES(TECH_GUIDING)) {
        float end = luminance(res.radiance);
        for (uint k = 0u; k < g_count; ++k)  // non-finite: the host drops it
            guiding_samples[g_slot + k].weight = g_norm[k] > 0.0 ? max(end - g_base[k], 0.0) / g_norm[k] : 0.0;
    }
    return res;
}
