// The one configurable trace loop (DESIGN: "One configurable trace loop"). Unidirectional
// path tracing with BSDF sampling (METHOD_PT), next event estimation (METHOD_NEE), or both
// combined by MIS (METHOD_MIS, Veach 1997 ch. 9, multi-sample model with N light samples
// and one BSDF sample per vertex).
//
// trace_path runs the stages of each path vertex: emission (emission_stage), the vertex's
// surface (vertex_stage), direct light (direct_light_stage, NEE), continuation
// (continuation_stage: BSDF or guided sampling) and roulette (roulette_stage). The
// techniques (thesis ch. 4) join in through hooks, declared in shaders/techniques/ (one file
// each, listed in techniques.glsl), which fold away where the pipeline does not use them.
// METHOD and the other specialisation constants: shared/specialization.h.

layout(set = 0, binding = BINDING_TLAS) uniform accelerationStructureEXT tlas;
layout(location = 0) rayPayloadEXT HitPayload hit;
layout(location = 1) rayPayloadEXT HitPayload shadow_hit;
// Declared, never traced. NVIDIA's ray-tracing compiler (on GPUs without RT cores traversal
// runs inside the pipeline) makes faster or slower code by the size of the payloads the raygen
// declares, used or not, and differently per pipeline, with no order: on an H100 the
// technique-free NEE soup ran at 1.71 G rays/s with 1, 5 or 15 unused words and at 1.84-1.88
// with 10, 14, 16 or 32. PAYLOAD_RESERVE (vec4s) is chosen per method where that was measured
// (Session::pipeline_key); lavapipe drops it. bench/results/gpu_payload_reserve.
struct PayloadReserve { vec4 words[PAYLOAD_RESERVE]; };
layout(location = 2) rayPayloadEXT PayloadReserve payload_reserve;

#include "camera.glsl"
#include "nodes.glsl"

struct PathOptions {
    uint max_depth;       // non-discrete bounces; emission one segment further still counts
    uint depth_leeway;    // discrete (delta) bounces that do not count towards max_depth
    uint rr_start_depth;  // Russian roulette from this bounce on (0: never)
    uint light_samples;   // NEE samples per vertex
    bool from_camera;     // the first segment is a camera ray (sees only camera-visible lights)
    bool skip_first_emission;  // cache hemisphere rays: the entry's direct light is NEE's
    // Where the path starts: a camera or hemisphere ray (throughput 1, no bounces), or a split
    // copy (resume): the ray to a vertex whose emission and NEE the path that split counted.
    vec3 throughput;
    uint bounces;
    uint discrete;
    uint kind_bounces;  // bounces of each kind so far (PathState.kind_bounces)
    float min_ray_pdf;  // PathState.min_ray_pdf so far
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
    opt.throughput = vec3(1.0);
    opt.bounces = 0u;
    opt.discrete = 0u;
    opt.kind_bounces = 0u;
    opt.min_ray_pdf = INFINITY_F;
    opt.resume = false;
    opt.self_instance = NO_INDEX;
    opt.self_primitive = NO_INDEX;
    return opt;
}

// A vertex's NEE shadow ray, traced later: just before the path's next ray, or when the path
// ends. Its vertex's surface, shading frame and BSDF are then no longer live across the trace
// call, and the shadow and path rays are traced at the same point of every loop iteration.
// With the empty calls (EMPTY_SHADOW_CALLS), on the H200 guided MIS frames cost 12-20% less,
// NEE and MIS frames in light behind glass 11-19% less, NEE on clocks 6% more
// (bench/results/gpu_nee/README.md); lavapipe runs as fast as before.
struct ShadowRay {
    vec3 origin;
    float t_max;
    vec3 dir;
    uint self_instance;
    vec3 contribution;  // 0: no shadow ray pending
    uint self_primitive;
};

// The state of a path between its vertices (the techniques' own: TechniquePath).
struct PathState {
    vec3 origin;  // the segment being traced: origin + t dir, t in [t_min, t_max]
    float t_min;
    vec3 dir;
    float t_max;
    uint self_instance;  // the triangle the segment starts on (NO_INDEX: none)
    uint self_primitive;
    vec3 throughput;
    // Russian roulette's view of the throughput: as if the BSDF had sampled every direction.
    // A guided direction's weight carries 1/p of the mixture, small where the mixture aims at
    // the light; roulette on it would end the very paths guiding sends towards the light (the
    // lamp behind glass is reached only after the roulette depth). Any survival probability
    // keeps the estimate unbiased: the path's weight is divided by it.
    vec3 roulette_throughput;
    vec3 albedo_throughput;
    bool albedo_done;
    bool prev_delta;  // the camera ray counts as delta: nothing to weigh it against
    float prev_pdf;
    vec3 prev_ng;     // geometric normal at the segment's origin (the light tree's receiver)
    uint bounces, discrete;
    // Cycles' diffuse, glossy and transmission bounces, 10 bits each at 10 x BOUNCE_* (counted
    // up to 1023) where the pipeline carries the budgets (LIMIT_KIND_BOUNCES).
    uint kind_bounces;
    // The smallest pdf of the non-delta BSDF samples so far (Cycles' min_ray_pdf; +inf: none),
    // where the pipeline carries Filter Glossy (LIMIT_BLUR_GLOSSY).
    float min_ray_pdf;
    ShadowRay pending;
};

// A surface vertex of the path: its hit, BSDF and shading frame.
struct Vertex {
    SurfaceHit sh;
    Surface surf;
    float roughness;  // the scattering material's
    vec3 ng, ns;      // facing the side the path arrives from (glass: ng keeps its side)
    vec3 tangent, bitangent;
    vec3 wo_local;
    bool delta;
};

#include "../techniques/techniques.glsl"

struct PathResult {
    vec3 radiance;
    float first_t;      // distance to the first hit (INFINITY_F: none)
    vec3 first_normal;  // shading normal of the first hit
    vec3 albedo;        // at the first non-delta vertex, through delta vertices
    uint segments;      // ray segments traced (camera ray included)
    uint rays;          // all rays traced (shadow rays included)
    uint shadow_rays;   // NEE shadow rays traced ...
    uint shadow_lit;    // ... and those that reached their light (NEE Visibility pass)
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

// Whether any vertex of this pipeline's paths takes NEE: PT does only where a technique ends a
// path with it (TECHNIQUES_ENDING_WITH_NEE).
// (A mask, not an || of specialisation constants: glslang 11 emits invalid SPIR-V for that.)
const uint NEE_USED = uint(METHOD != METHOD_PT) | TECHNIQUES_ENDING_WITH_NEE;

ShadowRay no_shadow_ray(vec3 origin, vec3 dir) {
    return ShadowRay(origin, 0.0, dir, NO_INDEX, vec3(0.0), NO_INDEX);
}

// Traces the pending shadow ray and adds its light where nothing is in the way.
// EMPTY_SHADOW_CALLS 1 (GPUs): paths without a pending shadow ray make an empty trace call (cull
// mask 0, zero length) all the same; without them NEE and MIS frames in light behind glass cost
// 14-16% more on the H200. 0 (lavapipe): they skip it; the empty calls cost lavapipe 8% there.
void trace_pending_shadow(inout PathState ps, inout PathResult res, inout TechniquePath tp) {
    if (NEE_USED == 0u) return;
    bool pending_ray = max3(ps.pending.contribution) > 0.0;
    if (!pending_ray) {
        if (EMPTY_SHADOW_CALLS == 0u) {
            guiding_shadow_traced(tp.guiding, false, false, vec3(0.0));
            return;
        }
    }
    if (pending_ray) {
        res.rays++;
        res.shadow_rays++;
    }
    shadow_hit.t = 0.0;
    shadow_hit.instance = ps.pending.self_instance;
    shadow_hit.primitive = ps.pending.self_primitive;
    traceRayEXT(tlas, surface_ray_flags(ps.pending.self_instance) | gl_RayFlagsTerminateOnFirstHitEXT | gl_RayFlagsSkipClosestHitShaderEXT,
                pending_ray ? 0xffu : 0u, 0, 0, MISS_SHADOW, ps.pending.origin, 0.0, ps.pending.dir,
                pending_ray ? ps.pending.t_max : 0.0, 1);
    bool lit = pending_ray && shadow_hit.t < 0.0;
    if (lit) {
        res.radiance += ps.pending.contribution;
        res.shadow_lit++;
    }
    guiding_shadow_traced(tp.guiding, pending_ray, lit, ps.pending.contribution);
    ps.pending.contribution = vec3(0.0);
}

// The material of a mix chain whose BSDF scatters at this hit (Material.mix_next). One
// uniform number picks link i with probability w_i prod_{j<i} (1 - w_j) and is rescaled at
// each link it passes, so one draw serves the whole chain. Estimating the chosen lobe's
// integral on its own (with its own NEE/BSDF MIS) is an unbiased one-sample estimator of
// the mixture f = sum_i P(i) f_i: stochastic selection of BSDF components, as pbrt-v4's
// MixMaterial resolves a mix to one material at the intersection (pbrt-v3's MixMaterial
// instead sums scaled BxDFs), i.e. Veach's one-sample model over lobes (Veach 1997,
// sec. 9.2.4). The host guarantees the chain ends within MIX_CHAIN_MAX materials.
Material select_mix_material(Material head, inout SurfaceHit sh, vec3 wo, inout Rng rng) {
    Material m = head;
    if (!HAS(FEATURE_MIX) || head.mix_next < 0) return m;
    float u = rnd(rng);
    for (uint i = 1u; i < MIX_CHAIN_MAX && m.mix_next >= 0; ++i) {
        if (u < m.mix_weight) break;
        // u >= w and u < 1 imply w < 1; the rescaled u is uniform on [0,1) again.
        u = min((u - m.mix_weight) / (1.0 - m.mix_weight), 0.99999994);
        m = materials[m.mix_next];
        run_node_program(m, sh, wo);  // its inputs (and normal), and the weight of the next step
    }
    return m;
}

// Weight of emission found by a ray that left a vertex by BSDF sampling (pdf prev_pdf, or
// delta / a camera ray) and hit an emitter that NEE samples with density light_pdf, light_rate
// times at that vertex on average (light samples x the probability of taking NEE there).
float emission_weight(bool prev_delta, float prev_pdf, float light_pdf, float light_rate) {
    if (METHOD == METHOD_PT || prev_delta) return 1.0;
    if (METHOD == METHOD_NEE) return 0.0;
    return mis_weight(prev_pdf, light_rate * light_pdf);
}

// Cycles' light paths. Scattering events before the path's current vertex, every bounce
// counted as Cycles' bounce does (ps.bounces leaves out the leeway's discrete bounces).
uint scatter_count(PathState ps, PathOptions opt) {
    return ps.bounces + min(ps.discrete, opt.depth_leeway);
}

// Whether a contribution is direct light for Cycles' clamps: a camera path's emission seen
// directly or found by the first vertex's BSDF ray (at most one scatter before it), or the
// first vertex's NEE (none); Cycles' film_write_emission_or_background_pass (bounce - 1) and
// film_write_direct_light. The cache's hemisphere paths carry indirect light only.
bool direct_light(PathState ps, PathOptions opt, uint most_scatters) {
    return opt.from_camera && scatter_count(ps, opt) <= most_scatters;
}

// Cycles' sample clamp (film_clamp_light): a contribution whose |R| + |G| + |B| exceeds the
// limit (3x the setting, FrameParams) is scaled down to it, keeping its hue. Biased: off (an
// infinite limit) unless set.
vec3 clamp_light(vec3 contribution, bool direct) {
    if (!LIMITS(LIMIT_CLAMP)) return contribution;
    float limit = direct ? params.clamp_direct : params.clamp_indirect;
    float sum = abs(contribution.r) + abs(contribution.g) + abs(contribution.b);
    return sum > limit ? contribution * (limit / sum) : contribution;
}

// Whether a bounce budget of Cycles' light paths is spent: the path's emission at this vertex
// still counts, its scattering does not (Cycles' PATH_RAY_TERMINATE_AFTER_TRANSPARENT).
bool kind_budget_spent(PathState ps) {
    if (!LIMITS(LIMIT_KIND_BOUNCES)) return false;
    uvec3 counts = (uvec3(ps.kind_bounces) >> uvec3(0u, 10u, 20u)) & 1023u;
    return any(greaterThan(counts, uvec3(params.diffuse_bounces, params.glossy_bounces, params.transmission_bounces)));
}

void count_kind_bounce(inout PathState ps, uint kind) {
    if (!LIMITS(LIMIT_KIND_BOUNCES)) return;
    uint shift = 10u * kind;
    if (((ps.kind_bounces >> shift) & 1023u) < 1023u) ps.kind_bounces += 1u << shift;
}

PathResult path_result() {
    return PathResult(vec3(0.0), INFINITY_F, vec3(0.0), vec3(0.0), 0u, 0u, 0u, 0u);
}

PathState path_state(vec3 origin, vec3 dir, float t_min, float t_max, PathOptions opt) {
    PathState ps;
    ps.origin = origin;
    ps.t_min = t_min;
    ps.dir = dir;
    ps.t_max = t_max;
    ps.self_instance = opt.self_instance;
    ps.self_primitive = opt.self_primitive;
    ps.throughput = opt.throughput;
    ps.roulette_throughput = opt.throughput;
    ps.albedo_throughput = vec3(1.0);
    ps.albedo_done = false;
    ps.prev_delta = true;
    ps.prev_pdf = 0.0;
    ps.prev_ng = vec3(0.0);
    ps.bounces = opt.bounces;
    ps.discrete = opt.discrete;
    ps.kind_bounces = opt.kind_bounces;
    ps.min_ray_pdf = opt.min_ray_pdf;
    ps.pending = no_shadow_ray(origin, dir);
    return ps;
}

// Emission stage: the light the segment just traced finds (analytic lights along it, the
// world where it escapes, the emitter it hits) and the first hit's depth and normal. False:
// the path escaped; else sh and mat are the surface hit.
bool emission_stage(inout PathState ps, inout PathResult res, TechniquePath tp, PathOptions opt,
                    out SurfaceHit sh, out Material mat) {
    float t_surface = hit.t < 0.0 ? ps.t_max : hit.t;
    bool camera_ray = opt.from_camera && res.segments == 1u;
    // A split copy re-traces the ray to its vertex, whose emission and NEE are counted.
    float emission_scale = ((opt.skip_first_emission || opt.resume) && res.segments == 1u) ? 0.0 : 1.0;
    bool direct = direct_light(ps, opt, 1u);
    float light_rate = float(opt.light_samples) * guiding_previous_nee_prob(tp.guiding);

    // Analytic lights are not in the TLAS: test them against this segment. As in Cycles they
    // do not occlude (shadow rays ignore them too): every one along the segment adds its
    // emission and the ray goes on to what lies behind.
    for (uint i = scene.analytic_first; HAS(FEATURE_SPHERE_LIGHTS | FEATURE_AREA_LIGHTS) && i < analytic_end(camera_ray); ++i) {
        float t_light, light_pdf;
        vec3 light_radiance;
        if (!analytic_light_hit(i, ps.origin, ps.prev_ng, ps.dir, t_surface, t_light, light_radiance, light_pdf)) continue;
        res.radiance += clamp_light(ps.throughput * light_radiance * (emission_scale * emission_weight(ps.prev_delta, ps.prev_pdf, light_pdf, light_rate)), direct);
        if (res.segments == 1u) res.first_t = min(res.first_t, t_light);
    }
    if (hit.t < 0.0) {  // escaped
        guiding_escaped(tp.guiding);
        float light_pdf;
        vec3 le = distant_radiance(ps.dir, camera_ray, light_pdf);
        res.radiance += clamp_light(ps.throughput * le * (emission_scale * emission_weight(ps.prev_delta, ps.prev_pdf, light_pdf, light_rate)), direct);
        return false;
    }

    sh = fetch_surface(hit.instance, hit.primitive, hit.barycentrics);
    mat = materials[sh.material];
    run_node_program(mat, sh, -ps.dir);
    vec3 wo = -ps.dir;
    guiding_hit(tp.guiding, hit.t);
    if (res.segments == 1u) {
        res.first_t = min(res.first_t, hit.t);  // a light in front keeps its distance
        res.first_normal = dot(sh.ns, wo) >= 0.0 ? sh.ns : -sh.ns;
    }
    if (max3(mat.emission) > 0.0 && emission_scale > 0.0) {
        float lp = 0.0;
        if (METHOD == METHOD_MIS && !ps.prev_delta) {
            uint light = instances[sh.instance].light_offset + sh.primitive;
            lp = triangle_light_pdf(light, ps.origin, ps.prev_ng, hit.t, dot(sh.ng, ps.dir));
        }
        res.radiance += clamp_light(ps.throughput * mat.emission * emission_weight(ps.prev_delta, ps.prev_pdf, lp, light_rate), direct);
    }
    return true;
}

// Cycles' Filter Glossy (surface_shader_prepare_closures): a path that took a bounce it was
// unlikely to take (min_ray_pdf, the smallest BSDF pdf so far, below blur_glossy) sees glossy
// and glass lobes blurred to GGX alpha >= sqrt(1 - blur_pdf) / 2, blur_pdf = min_ray_pdf /
// blur_glossy: caustics seen after a diffuse bounce become rough, so NEE and MIS find them.
// Biased (the lobes are no longer the material's); alpha is roughness^2 here as in Cycles.
// The energy compensation follows the blurred roughness (Cycles keeps the original's).
void blur_glossy(inout Material m, float min_ray_pdf) {
    if (!LIMITS(LIMIT_BLUR_GLOSSY) || m.type == MATERIAL_DIFFUSE) return;
    float blur_pdf = params.filter_glossy * min_ray_pdf;
    if (blur_pdf >= 1.0) return;
    float min_roughness = sqrt(sqrt(1.0 - blur_pdf) * 0.5);
    m.roughness = max(m.roughness, min_roughness);
    m.coat_roughness = max(m.coat_roughness, min_roughness);
}

// ---- bumped normals (a node program's Bump or Normal Map), as Cycles treats them ----------
bool is_bumped(SurfaceHit sh) { return HAS(FEATURE_NODES) && any(notEqual(sh.ns, sh.ns_smooth)); }

// Cycles' ensure_valid_specular_reflection: n (facing wo, like ng) tilted towards ng just
// enough that the mirror direction of wo rises above the surface by min(0.9 wo.ng, 0.01).
// In the frame z = ng, x = n's part across ng, the tilted n' = (x, 0, z) solves
// 2 (n'.wo) z - wo.z = t, a quadratic in z^2 with one root on the right side.
vec3 valid_reflection_normal(vec3 ng, vec3 wo, vec3 n) {
    float wz = dot(wo, ng), t = min(0.9 * wz, 0.01);
    if (dot(ng, 2.0 * dot(n, wo) * n - wo) >= t) return n;
    vec3 across = n - dot(n, ng) * ng;
    vec3 x = dot(across, across) > 1e-20 ? normalize(across) : n;
    float wx = dot(wo, x);
    float a = wx * wx + wz * wz, b = 2.0 * (a + wz * t), c = (t + wz) * (t + wz);
    float root = sqrt(max(b * b - 4.0 * a * c, 0.0));
    float z2 = 0.25 * (wx < 0.0 ? b + root : b - root) / a;
    return sqrt(max(1.0 - z2, 0.0)) * x + sqrt(max(z2, 0.0)) * ng;
}

// Cycles' bump_shadowing_term (Conty Estevez et al. 2019, "A Microfacet-Based Shadowing
// Function to Solve the Bump Terminator Problem") for light leaving along wi at a vertex whose
// normal was bumped: 0 where wi and the bumped normal lie on opposite sides of the smooth
// surface (evaluations; sampled directions of diffuse surfaces), and for diffuse surfaces the
// GGX G1 of alpha^2 = tan^2(bump angle) / 8 at wi's angle to the smooth normal.
float bump_shadowing(Vertex v, vec3 wi, bool eval) {
    if (!is_bumped(v.sh)) return 1.0;
    vec3 smooth_n = dot(v.ns, v.sh.ns) > 0.0 ? v.sh.ns_smooth : -v.sh.ns_smooth;  // on v.ns's side
    float cos_si = dot(smooth_n, wi), cos_sn = dot(smooth_n, v.ns);
    bool diffuse = v.surf.type == MATERIAL_DIFFUSE;
    if (cos_si * cos_sn * dot(v.ns, wi) < 0.0 && (eval || diffuse)) return 0.0;
    float cos_i = abs(cos_si), cos_d = abs(cos_sn);
    if (!diffuse || cos_d >= 1.0 || cos_i >= 1.0) return 1.0;
    if (cos_i < 1e-6) return 0.0;
    float alpha = sqrt(clamp(0.125 * (1.0 / (cos_d * cos_d) - 1.0), 0.0, 1.0));
    return ggx_g1(vec3(sqrt(1.0 - cos_i * cos_i), 0.0, cos_i), alpha);
}

// The vertex's BSDF and shading frame. False: its material (of the mix chain) is an emitter,
// which scatters nothing.
bool vertex_stage(SurfaceHit sh, Material mat, vec3 dir, float min_ray_pdf, inout Rng rng, out Vertex v) {
    // Emission was the head material's; the BSDF may come from its mix chain.
    mat = select_mix_material(mat, sh, -dir, rng);
    if (mat.type == MATERIAL_EMISSION) return false;
    blur_glossy(mat, min_ray_pdf);

    // Shading frame. Reflective materials are two-sided: face the normals towards wo.
    // Glass keeps the geometric side to know whether the ray enters or leaves.
    vec3 wo = -dir;
    bool front = dot(sh.ng, wo) > 0.0;
    v.sh = sh;
    v.ng = front ? sh.ng : -sh.ng;
    v.ns = front ? sh.ns : -sh.ns;
    if (is_bumped(sh)) v.ns = valid_reflection_normal(v.ng, wo, v.ns);
    else if (dot(v.ns, wo) <= 1e-6) v.ns = v.ng;  // shading normal facing away from the viewer
    v.surf.type = mat.type;
    v.surf.albedo = material_albedo(mat, sh.uv);
    v.surf.alpha = mat.roughness * mat.roughness;
    v.surf.eta = front ? mat.ior : 1.0 / mat.ior;
    make_basis(v.ns, v.tangent, v.bitangent);
    v.wo_local = vec3(dot(wo, v.tangent), dot(wo, v.bitangent), dot(wo, v.ns));
    v.surf.ms = vec3(1.0);
    if ((mat.flags & MATERIAL_FLAG_MULTISCATTER) != 0u) surface_multiscatter(v.surf, v.wo_local.z);
    if (HAS(FEATURE_PRINCIPLED) && mat.type == MATERIAL_PRINCIPLED)
        v.surf.pr = principled_setup(mat, v.surf.albedo, v.surf.eta, v.wo_local.z, (mat.flags & MATERIAL_FLAG_MULTISCATTER) != 0u);
    v.roughness = mat.roughness;
    v.delta = surface_is_delta(v.surf);
    return true;
}

// Direct light stage: next event estimation (Veach 1997 eq. 9.8 / 9.13 weights for MIS). A
// vertex where the path ends (last_vertex) takes its direct light from NEE alone (no BSDF
// sample follows to share it). The vertex's last light sample's shadow ray waits for the next
// path ray (see ShadowRay); the others are traced here.
void direct_light_stage(inout PathState ps, inout PathResult res, inout TechniquePath tp, PathOptions opt, Vertex v,
                        TechniqueVertex tv, bool last_vertex, inout Rng rng) {
    // NEE where guiding learnt that it pays (1 elsewhere); taken, it counts 1 / nee_prob.
    float nee_prob = guiding_nee_prob(tv.guiding, last_vertex);
    if (nee_prob < 1.0 && rnd(rng) >= nee_prob) return;
    for (uint k = 0u; k < opt.light_samples; ++k) {
        if (k > 0u) trace_pending_shadow(ps, res, tp);  // the previous sample's
        LightSample ls;
        vec3 u = rnd3(rng);
        if (!sample_light(v.sh.p, v.sh.ng, u, ls)) continue;
        vec3 wi_local = vec3(dot(ls.wi, v.tangent), dot(ls.wi, v.bitangent), dot(ls.wi, v.ns));
        float bsdf_pdf;
        vec3 f = bsdf_eval(v.surf, v.wo_local, wi_local, bsdf_pdf) * bump_shadowing(v, ls.wi, true);
        if (max3(f) <= 0.0 || max3(ls.radiance) <= 0.0) continue;
        bsdf_pdf = guiding_continuation_pdf(tv.guiding, bsdf_pdf, v.sh.p, ls.wi);
        float light_rate = float(opt.light_samples) * nee_prob;
        float w = (METHOD == METHOD_MIS && !ls.delta && !last_vertex) ? mis_weight(light_rate * ls.pdf, bsdf_pdf) : 1.0;
        ps.pending.contribution = clamp_light(ps.throughput * f * ls.radiance * (w / (ls.pdf * light_rate)),
                                              direct_light(ps, opt, 0u));
        // Aim the shadow ray from its origin at the sampled point itself (a direction
        // kept from the unmoved point misses grazing lights), stopping short of it.
        // A shadow ray through the surface (transmission) leaves on it; one on the side the
        // path came from leaves from the usual offset: a surface touching this one there
        // belongs to an object the ray then starts inside (the glass cube over the floor),
        // which blocks it all the same, and opaque rays need no any-hit calls.
        ps.pending.origin = offset_ray(v.sh.p, v.ng);
        ps.pending.dir = ls.wi;
        ps.pending.t_max = INFINITY_F;
        if (ls.dist < INFINITY_F) {
            vec3 to_light = v.sh.p + ls.wi * ls.dist - ps.pending.origin;
            ps.pending.t_max = length(to_light);
            ps.pending.dir = to_light / ps.pending.t_max;
            ps.pending.t_max *= 1.0 - 1e-4;
        }
        ps.pending.self_instance = dot(ls.wi, v.ng) < 0.0 ? v.sh.instance : NO_INDEX;
        ps.pending.self_primitive = v.sh.primitive;
    }
}

// Continuation stage: the path's next segment, sampled from the BSDF or, at a guided vertex,
// from the region's mixture (guiding_sample). False: the path ends.
bool continuation_stage(inout PathState ps, PathResult res, inout TechniquePath tp, PathOptions opt,
                        TechniqueOptions topt, Vertex v, TechniqueVertex tv, inout Rng rng) {
    BsdfSample bs;
    bool sampled;
    if (!guiding_sample(tv.guiding, v.surf, v.wo_local, v.sh.p, v.tangent, v.bitangent, v.ns, rng, bs, sampled))
        sampled = bsdf_sample(v.surf, v.wo_local, rnd3(rng), bs);
    if (!sampled) return false;
    if (is_bumped(v.sh)) {
        // As Cycles' samplers (bsdf_microfacet_sample, bsdf_diffuse_sample), a bumped normal's
        // sample on the wrong side of the geometric surface ends the path.
        vec3 wi = bs.wi.x * v.tangent + bs.wi.y * v.bitangent + bs.wi.z * v.ns;
        if ((dot(v.ng, wi) < 0.0) != (bs.kind == BOUNCE_TRANSMISSION)) return false;
        bs.weight *= bump_shadowing(v, wi, false);
    }
    ps.roulette_throughput *= bs.weight;
    // The BSDF's own pdf, before guiding mixes its own in (Cycles' unguided_bsdf_pdf).
    float bsdf_pdf = bs.pdf;
    if (LIMITS(LIMIT_BLUR_GLOSSY) && !bs.delta) ps.min_ray_pdf = min(ps.min_ray_pdf, bsdf_pdf);
    guiding_sampled_pdf(tv.guiding, v.sh.p, v.tangent, v.bitangent, v.ns, bs);
    ps.throughput *= bs.weight;
    count_kind_bounce(ps, bs.kind);
    if (bs.delta) {
        ps.discrete++;
        if (ps.discrete > opt.depth_leeway) ps.bounces++;
        if (!ps.albedo_done) ps.albedo_throughput *= bs.weight;
    } else {
        ps.bounces++;
    }
    ps.prev_delta = bs.delta;
    ps.prev_pdf = bs.pdf;
    guiding_continued(tp.guiding, tv.guiding);
    ps.dir = normalize(bs.wi.x * v.tangent + bs.wi.y * v.bitangent + bs.wi.z * v.ns);
    guiding_record(tp.guiding, topt.guiding, tv.guiding, v.sh.p, ps.dir, bs.pdf, bsdf_pdf, bs.delta, res.radiance,
                   ps.throughput);
    bool contact = may_touch_transmission(v.sh.instance, v.sh.p);
    ps.origin = leave_surface(v.sh.p, v.ng, ps.dir, contact);
    ps.self_instance = contact ? v.sh.instance : NO_INDEX;
    ps.self_primitive = v.sh.primitive;
    ps.prev_ng = v.sh.ng;
    ps.t_min = 0.0;
    ps.t_max = INFINITY_F;
    return max3(ps.throughput) > 0.0;
}

// Roulette stage: Russian roulette on the throughput: survival probability
// sqrt(max(throughput)), at most 1, as Cycles (path_state_continuation_probability). Against
// max(throughput) it lowers variance x rays per path by 10-13% on the Cornell box and the
// atrium (bench.variance). False: the path ends.
bool roulette_stage(inout PathState ps, PathOptions opt, inout Rng rng) {
    if (opt.rr_start_depth > 0u && ps.bounces >= opt.rr_start_depth) {
        float survive = min(1.0, sqrt(max3(guiding_roulette_throughput(ps.roulette_throughput, ps.throughput))));
        if (rnd(rng) >= survive) return false;
        ps.throughput /= survive;
        ps.roulette_throughput /= survive;
    }
    return true;
}

// One path from (origin, dir) over [t_min, t_max]; `tp` comes from technique_path or the
// pixel's previous path, and returns what the techniques recorded on this one (the cache's
// value at its first diffuse vertex).
PathResult trace_path(vec3 origin, vec3 dir, float t_min, float t_max, PathOptions opt, TechniqueOptions topt,
                      inout TechniquePath tp, inout Rng rng) {
    PathResult res = path_result();
    PathState ps = path_state(origin, dir, t_min, t_max, opt);
    tp = technique_next_path(topt, tp);
    EarsPath ears = ears_path();  // EARS' records of the path's decisions
    for (;;) {
        // No vertex precedes the first ray, so no shadow ray can be pending: every path of a
        // warp skips this call alike (an empty call there cost the H200 a quarter of its rays,
        // bench/results/shadow_calls_h200).
        if (res.segments > 0u) {
            trace_pending_shadow(ps, res, tp);
            techniques_light_resolved(tp, res.radiance);
        }
        ears_continuation_start(ears, res.radiance, res.rays);
        hit.instance = ps.self_instance;
        hit.primitive = ps.self_primitive;
        traceRayEXT(tlas, surface_ray_flags(ps.self_instance), 0xff, 0, 0, MISS_SCENE, ps.origin, ps.t_min, ps.dir, ps.t_max, 0);
        res.rays++;
        res.segments++;
        SurfaceHit sh;
        Material mat;
        if (!emission_stage(ps, res, tp, opt, sh, mat)) break;
        if (ps.bounces > opt.max_depth || kind_budget_spent(ps)) break;
        Vertex v;
        if (!vertex_stage(sh, mat, ps.dir, ps.min_ray_pdf, rng, v)) break;
        if (!ps.albedo_done && !v.delta) {
            res.albedo = ps.albedo_throughput * v.surf.albedo;
            ps.albedo_done = true;
        }
        // A split copy re-traces the ray to its vertex, whose emission and NEE are counted.
        bool resumed = opt.resume && res.segments == 1u;
        // The techniques at the vertex: guiding's mixture, the cache (which may shade the
        // vertex and end the path after its NEE, or end it now), ADRRS' adjoint.
        TechniqueVertex tv = techniques_vertex(tp, topt, v, hit.t, resumed, ps.throughput, res.segments, res.radiance, rng);
        if (tv.ic.stop) break;
        if ((METHOD != METHOD_PT || tv.last) && !v.delta && !resumed) direct_light_stage(ps, res, tp, opt, v, tv, tv.last, rng);
        if (tv.last) break;
        // ADRRS may roulette or split the continuation in place of the throughput roulette.
        bool killed;
        uint ears_slot;
        bool adrrs_decided = adrrs_continuation(topt.adrrs, tv.ic, v, resumed, ps, res.segments,
                                                opt.from_camera && res.segments == 1u, rng, killed, ears_slot, tp.ears);
        if (killed) break;
        ears_open(ears, ears_slot, ps.throughput);
        if (!continuation_stage(ps, res, tp, opt, topt, v, tv, rng)) break;
        if (!adrrs_decided && !roulette_stage(ps, opt, rng)) break;
    }
    trace_pending_shadow(ps, res, tp);
    techniques_light_resolved(tp, res.radiance);
    guiding_path_end(tp.guiding, res.radiance);
    ears_path_end(ears, res.radiance, res.rays, rng);
    return res;
}
