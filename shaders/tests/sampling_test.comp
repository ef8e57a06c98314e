#version 460
#extension GL_GOOGLE_include_directive : require
// Runs one sampling routine of the real shader library many times so tests can compare
// sampled directions against the routine's own pdf (chi-square, tests/unit).
//   routine < TEST_EVAL: sample.  io[2i] = (wi, pdf), io[2i+1] = (weight.x, eval.x, eval pdf, ok)
//   routine >= TEST_EVAL: evaluate at io[2i].xyz. io[2i+1] = (f cos .x, pdf, 0, 0) for BSDFs,
//                         (radiance.x, light pdf, 0, 0) for lights (sums over all lights)
// BSDFs: test_params = (wo, roughness), test_param0 = ior, albedo 1.
// Lights: test_params.xyz = shading point, w != 0: surface normal +z there (else none);
// sampling includes light selection.
#include "../lib/common.glsl"
#include "../lib/rng.glsl"
#include "../lib/sampling.glsl"
#include "../lib/bsdf.glsl"
#include "../lib/lights.glsl"
#define PX_ADRRS_MATH_ONLY
#include "../techniques/adrrs.glsl"

layout(local_size_x = 64) in;
layout(set = 0, binding = BINDING_TEST_IO, scalar) buffer TestIo { vec4 io[]; };

// Guiding routines: GuidingLobe i is stored as 3 vec4 after the 2 * test_count sample slots.
GuidingLobe test_lobe(uint i) {
    uint b = 2u * params.test_count + 3u * i;
    vec4 a = io[b], c = io[b + 1u], d = io[b + 2u];
    GuidingLobe l;
    l.mu = a.xyz;
    l.kappa = a.w;
    l.weight = c.x;
    l.norm = c.y;
    l.exp_m2k = c.z;
    l.distance = c.w;
    l.target = d.xyz;
    l.cdf = d.w;
    return l;
}
#define GUIDING_FETCH_LOBE(i) test_lobe(i)
#include "../techniques/guiding.glsl"

const uint TEST_EVAL = 16u;

// Sum over all lights of the density with which sample_light produces direction wi from p,
// and of the radiance arriving along wi (every light, occluded or not). Built from the
// functions the integrator uses for MIS when a BSDF ray hits a light, so the chi-square
// tests cover those too (triangle_light_pdf, analytic_light_hit, distant_radiance).
float light_pdf_all(vec3 p, vec3 n, vec3 wi, out vec3 radiance) {
    float pdf = 0.0;
    radiance = vec3(0.0);
    for (uint i = 0u; i < scene.light_count; ++i) {
        Light l = lights[i];
        if (l.type == LIGHT_TRIANGLE) {  // Moller-Trumbore
            vec3 pv = cross(wi, l.axis_v);
            float det = dot(l.axis_u, pv);
            if (abs(det) < 1e-12) continue;
            vec3 tv = p - l.position;
            float bu = dot(tv, pv) / det;
            vec3 qv = cross(tv, l.axis_u);
            float bv = dot(wi, qv) / det;
            float t = dot(l.axis_v, qv) / det;
            if (bu < 0.0 || bv < 0.0 || bu + bv > 1.0 || t <= 0.0) continue;
            pdf += triangle_light_pdf(i, p, n, t, dot(l.direction, wi));
            radiance += l.radiance;
        } else if (l.type != LIGHT_SUN && l.type != LIGHT_ENV) {
            float t, lp;
            vec3 le;
            if (analytic_light_hit(i, p, n, wi, INFINITY_F, t, le, lp)) {
                pdf += lp;
                radiance += le;
            }
        }
    }
    float distant_pdf;
    radiance += distant_radiance(wi, false, distant_pdf);
    return pdf + distant_pdf;
}

void main() {
    uint i = gl_GlobalInvocationID.x;
    if (i >= params.test_count) return;
    uint routine = params.test_routine % TEST_EVAL;
    bool eval_mode = params.test_routine >= TEST_EVAL;
    Rng rng = rng_stream(tea(i, params.seed));

    if (routine == TEST_LIGHT) {
        vec3 p = params.test_params.xyz;
        vec3 n = params.test_params.w != 0.0 ? vec3(0.0, 0.0, 1.0) : vec3(0.0);  // receiver normal
        if (eval_mode) {
            vec3 radiance;
            float pdf = light_pdf_all(p, n, normalize(io[2u * i].xyz), radiance);
            io[2u * i + 1u] = vec4(radiance.x, pdf, 0.0, 0.0);
            return;
        }
        LightSample ls;
        bool ok = sample_light(p, n, vec3(rnd(rng), rnd(rng), rnd(rng)), ls);
        io[2u * i] = vec4(ls.wi, ok ? ls.pdf : 0.0);
        io[2u * i + 1u] = vec4(ls.radiance.x, ls.dist, ok ? 1.0 : 0.0, ls.delta ? 1.0 : 0.0);
        return;
    }

    if (routine == TEST_RNG) {
        Rng r = rng_pixel(uint(params.test_params.x), params.seed, i);
        r.slot = uint(params.test_param0);
        io[2u * i] = vec4(rnd2(r), rnd(r), 0.0);
        io[2u * i + 1u] = vec4(rnd2(r), rnd(r), 0.0);
        return;
    }
    if (routine == TEST_APERTURE) {  // test_params = (blades, rotation, ratio, 0)
        vec4 t = params.test_params;
        io[2u * i] = vec4(aperture_sample(rnd2(rng), t.x, t.y, t.z), 0.0, 0.0);
        io[2u * i + 1u] = vec4(0.0);
        return;
    }
    if (routine == TEST_ADRRS) {  // test_params = (r = v/C, s, rr_min, splitting)
        vec4 t = params.test_params;
        float q = adrrs_window_factor(t.x, t.y, t.z, t.w != 0.0);
        float u = rnd(rng);
        // Copies that go on: below the window 1 if the path survives roulette, else 0.
        float copies = q < 1.0 ? (u < q ? 1.0 : 0.0) : float(adrrs_split_copies(q, u));
        io[2u * i] = vec4(q, copies, copies / q, 0.0);
        io[2u * i + 1u] = vec4(0.0);
        return;
    }
    if (routine == TEST_IC_HEMISPHERE) {  // test_params.xy: theta x phi strata; sample i in stratum i mod theta phi
        uint theta = uint(params.test_params.x), phi = uint(params.test_params.y), stratum = i % (theta * phi);
        vec3 wi = stratified_cosine_hemisphere(stratum / phi, stratum % phi, theta, phi, rnd2(rng));
        io[2u * i] = vec4(wi, wi.z * INV_PI);
        io[2u * i + 1u] = vec4(1.0, wi.z * INV_PI, wi.z * INV_PI, 1.0);
        return;
    }

    if (routine == TEST_GUIDING_VMF || routine == TEST_GUIDING_VMM) {
        vec3 x = params.test_params.xyz;
        uint lobes = uint(params.test_param0);
        GuidingLobe l = test_lobe(0u);
        if (eval_mode) {
            vec3 wi = normalize(io[2u * i].xyz);
            float pdf = routine == TEST_GUIDING_VMF ? vmf_pdf(guiding_lobe_mu(l, x), l.kappa, l.norm, wi)
                                                    : guiding_vmm_pdf(0u, lobes, x, wi);
            io[2u * i + 1u] = vec4(0.0, pdf, 0.0, 0.0);
            return;
        }
        vec3 u = vec3(rnd(rng), rnd(rng), rnd(rng));
        vec3 wi;
        float pdf;
        if (routine == TEST_GUIDING_VMF) {
            wi = vmf_sample(guiding_lobe_mu(l, x), l.kappa, l.exp_m2k, u.xy);
            pdf = vmf_pdf(guiding_lobe_mu(l, x), l.kappa, l.norm, wi);
        } else {
            wi = guiding_vmm_sample(0u, lobes, x, u);
            pdf = guiding_vmm_pdf(0u, lobes, x, wi);
        }
        io[2u * i] = vec4(wi, pdf);
        io[2u * i + 1u] = vec4(1.0, 0.0, pdf, 1.0);
        return;
    }

    if (routine == TEST_GUIDING_PACK) {  // io[2i].xyz: a direction; out: packed bits, unpacked
        uint packed = guiding_pack_direction(normalize(io[2u * i].xyz));
        io[2u * i + 1u] = vec4(uintBitsToFloat(packed), guiding_unpack_direction(packed));
        return;
    }

    if (routine == TEST_PRINCIPLED) {  // the Material follows the samples (types.h)
        uint b = 2u * params.test_count;
        vec4 v0 = io[b], v1 = io[b + 1u], v2 = io[b + 2u], v3 = io[b + 3u], v4 = io[b + 4u], v5 = io[b + 5u];
        Material m;
        m.base_color = v0.xyz;
        m.roughness = v0.w;
        m.ior = params.test_param0 >= 1.0 ? params.test_param0 : 1.0 / params.test_param0;
        m.specular_tint = v1.xyz;
        m.metallic = v1.w;
        m.coat_tint = v2.xyz;
        m.coat_weight = v2.w;
        m.sheen_tint = v3.xyz;
        m.sheen_weight = v3.w;
        m.transmission = v4.x;
        m.specular_ior_level = v4.y;
        m.coat_roughness = v4.z;
        m.coat_ior = v4.w;
        m.sheen_roughness = v5.x;
        vec3 wo = normalize(params.test_params.xyz);
        Principled p = principled_setup(m, m.base_color, params.test_param0, wo.z, v5.y > 0.5);
        if (eval_mode) {  // (f cos) summed over rgb / 3 and the pdf
            float pdf;
            vec3 f = principled_eval(p, wo, normalize(io[2u * i].xyz), pdf);
            io[2u * i + 1u] = vec4(avg3(f), pdf, 0.0, 0.0);
            return;
        }
        BsdfSample bs;
        bool ok = principled_sample(p, wo, vec3(rnd(rng), rnd(rng), rnd(rng)), bs);
        float eval_pdf = 0.0;
        vec3 f = ok ? principled_eval(p, wo, bs.wi, eval_pdf) : vec3(0.0);
        io[2u * i] = vec4(bs.wi, ok ? bs.pdf : 0.0);
        io[2u * i + 1u] = vec4(avg3(bs.weight), avg3(f), eval_pdf, ok ? 1.0 : 0.0);
        return;
    }

    Surface s;
    s.type = routine == TEST_DIFFUSE ? MATERIAL_DIFFUSE
           : (routine == TEST_CONDUCTOR || routine == TEST_CONDUCTOR_MS) ? MATERIAL_CONDUCTOR : MATERIAL_DIELECTRIC;
    s.albedo = vec3(1.0);
    s.alpha = params.test_params.w * params.test_params.w;
    s.eta = params.test_param0;
    vec3 wo = normalize(params.test_params.xyz);
    s.ms = vec3(1.0);
    if (routine == TEST_CONDUCTOR_MS || routine == TEST_DIELECTRIC_MS) surface_multiscatter(s, wo.z);
    if (eval_mode) {
        float pdf;
        vec3 f = bsdf_eval(s, wo, normalize(io[2u * i].xyz), pdf);
        io[2u * i + 1u] = vec4(f.x, pdf, 0.0, 0.0);
        return;
    }
    BsdfSample bs;
    bool ok = bsdf_sample(s, wo, vec3(rnd(rng), rnd(rng), rnd(rng)), bs);
    float eval_pdf = 0.0;
    vec3 f = ok ? bsdf_eval(s, wo, bs.wi, eval_pdf) : vec3(0.0);
    io[2u * i] = vec4(bs.wi, ok ? bs.pdf : 0.0);
    io[2u * i + 1u] = vec4(bs.weight.x, f.x, eval_pdf, ok ? 1.0 : 0.0);
}
