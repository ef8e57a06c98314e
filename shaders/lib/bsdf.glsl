// BSDFs in a local shading frame (z = shading normal). Each returns f * |cos(theta_i)|
// ("eval") and the solid-angle pdf of its sampler, so MIS can weigh any direction.
//   diffuse     Lambert (two-sided)
//   conductor   GGX microfacet, alpha = roughness^2, Fresnel = colour (Cycles Glossy BSDF),
//               height-correlated Smith G2, visible-normal sampling (Heitz 2018)
//   dielectric  smooth or rough GGX glass (Walter et al. 2007), colour tints both lobes
//   principled  Cycles' Principled BSDF v2, a layered mixture of lobes (principled.glsl)
// Either GGX lobe may carry Cycles' multiscatter energy compensation (Surface.ms).

#include "../shared/ggx_tables.h"

const float DELTA_ALPHA = 1e-4;  // alpha below this: a perfect mirror / smooth glass

struct BsdfSample {
    vec3 wi;
    vec3 weight;  // f * |cos| / pdf
    float pdf;    // 0 for delta lobes' pdf-free use; set to 1 with delta = true
    bool delta;
    uint kind;    // BOUNCE_*: the budget the bounce counts towards (Cycles' label)
};

// Kinds of bounce, as Cycles labels a sampled lobe (path_state_next): reflection off a diffuse
// lobe (Lambert, Principled's diffuse and sheen), other reflection (glossy and mirror), and
// any transmission. Cycles' Diffuse, Glossy and Transmission bounce budgets count them.
const uint BOUNCE_DIFFUSE = 0u;
const uint BOUNCE_GLOSSY = 1u;
const uint BOUNCE_TRANSMISSION = 2u;


// ---- GGX ------------------------------------------------------------------------------
float ggx_d(vec3 m, float alpha) {
    float a2 = alpha * alpha;
    float c2 = m.z * m.z;
    return a2 / (PI * sqr(c2 * (a2 - 1.0) + 1.0));
}

float ggx_lambda(vec3 w, float alpha) {
    float c2 = w.z * w.z;
    if (c2 >= 1.0) return 0.0;
    float tan2 = max(0.0, 1.0 - c2) / max(c2, 1e-12);
    return 0.5 * (-1.0 + sqrt(1.0 + alpha * alpha * tan2));
}

float ggx_g1(vec3 w, float alpha) { return 1.0 / (1.0 + ggx_lambda(w, alpha)); }
float ggx_g2(vec3 wo, vec3 wi, float alpha) { return 1.0 / (1.0 + ggx_lambda(wo, alpha) + ggx_lambda(wi, alpha)); }

// Visible normal for wo.z > 0 (Heitz 2018, "Sampling the GGX Distribution of Visible Normals").
vec3 ggx_sample_vndf(vec3 wo, float alpha, vec2 u) {
    vec3 vh = normalize(vec3(alpha * wo.x, alpha * wo.y, wo.z));
    float lensq = vh.x * vh.x + vh.y * vh.y;
    vec3 t1 = lensq > 0.0 ? vec3(-vh.y, vh.x, 0.0) * inversesqrt(lensq) : vec3(1.0, 0.0, 0.0);
    vec3 t2 = cross(vh, t1);
    float r = sqrt(u.x);
    float phi = 2.0 * PI * u.y;
    float p1 = r * cos(phi);
    float p2 = r * sin(phi);
    float s = 0.5 * (1.0 + vh.z);
    p2 = (1.0 - s) * sqrt(max(0.0, 1.0 - p1 * p1)) + s * p2;
    vec3 nh = p1 * t1 + p2 * t2 + sqrt(max(0.0, 1.0 - p1 * p1 - p2 * p2)) * vh;
    return normalize(vec3(alpha * nh.x, alpha * nh.y, max(1e-6, nh.z)));
}

// Density of the visible normal m seen from wo: G1(wo) max(0, wo.m) D(m) / wo.z.
float ggx_vndf_pdf(vec3 wo, vec3 m, float alpha) {
    return ggx_g1(wo, alpha) * max(0.0, dot(wo, m)) * ggx_d(m, alpha) / wo.z;
}

// ---- multiscatter energy compensation ---------------------------------------------------
float ggx_table(uint i) {
    uint w = ggx_table_words[i >> 1];
    return float((i & 1u) != 0u ? (w >> 16) : (w & 0xffffu)) * (1.0 / 65535.0);
}

// Linear interpolation on a grid of n points over [0, 1]: cell and fraction of x.
uint ggx_table_cell(float x, uint n, out float f) {
    float g = clamp(x, 0.0, 1.0) * float(n - 1u);
    uint i = min(uint(g), n - 2u);
    f = g - float(i);
    return i;
}

float ggx_table_1d(uint offset, uint n, float x) {
    float fx;
    uint ix = ggx_table_cell(x, n, fx);
    return mix(ggx_table(offset + ix), ggx_table(offset + ix + 1u), fx);
}

float ggx_table_2d(uint offset, uint n, float x, float y) {  // table[x][y]
    float fx;
    uint ix = ggx_table_cell(x, n, fx);
    return mix(ggx_table_1d(offset + ix * n, n, y), ggx_table_1d(offset + (ix + 1u) * n, n, y), fx);
}

float ggx_table_3d(uint offset, uint n, float x, float y, float z) {  // table[x][y][z]
    float fx;
    uint ix = ggx_table_cell(x, n, fx);
    return mix(ggx_table_2d(offset + ix * n * n, n, y, z), ggx_table_2d(offset + (ix + 1u) * n * n, n, y, z), fx);
}

#include "principled.glsl"

struct Surface {
    uint type;
    vec3 albedo;  // base colour (x texture)
    float alpha;  // GGX roughness
    float eta;    // dielectric: IOR on the far side / IOR on the side of wo (after flip)
    vec3 ms;      // multiscatter energy compensation factor of the whole lobe (1: single scatter)
    Principled pr;  // MATERIAL_PRINCIPLED: its lobes (principled_setup)
};

bool surface_is_delta(Surface s) {
    return s.type != MATERIAL_DIFFUSE && s.type != MATERIAL_PRINCIPLED && s.alpha < DELTA_ALPHA;
}

// Multiscatter GGX as Cycles does it (Kulla & Conty 2017, "Revisiting Physically Based
// Shading at Imageworks"; Turquin 2019): the single-scatter lobe times
// 1 + F_ms (1 - E) / E, E = E(mu_o) its albedo with F = 1, F_ms = F E_avg / (1 - F (1 - E_avg))
// the multi-bounce Fresnel of a lobe of colour F (1/E when F = 1). Glass: 1 / E_glass(mu_o),
// the albedo of reflection + refraction at its relative IOR. Call once wo is known.
void surface_multiscatter(inout Surface s, float mu) {
    s.ms = vec3(1.0);
    if (s.alpha < DELTA_ALPHA || s.type == MATERIAL_DIFFUSE || s.type == MATERIAL_EMISSION ||
        s.type == MATERIAL_PRINCIPLED) return;  // principled_setup handles its own lobes
    float rough = sqrt(s.alpha);
    if (s.type == MATERIAL_CONDUCTOR) {
        float e = max(ggx_table_2d(GGX_E_OFFSET, 32u, rough, mu), 1e-3);
        float e_avg = ggx_table_1d(GGX_EAVG_OFFSET, 32u, rough);
        vec3 f = clamp(s.albedo, 0.0, 1.0);
        vec3 f_ms = f * e_avg / (1.0 - f * (1.0 - e_avg));
        s.ms = 1.0 + f_ms * ((1.0 - e) / e);
        return;
    }
    float ior = s.eta >= 1.0 ? s.eta : 1.0 / s.eta;
    float z = sqrt((ior - 1.0) / (ior + 1.0));
    uint offset = s.eta >= 1.0 ? GLASS_E_OFFSET : GLASS_INV_E_OFFSET;
    s.ms = vec3(1.0 / max(ggx_table_3d(offset, 32u, rough, mu, z), 1e-3));
}

// ---- evaluation ----------------------------------------------------------------------
// f(wo, wi) |wi.z| and the sampling pdf. wo.z > 0 is guaranteed by the caller.
vec3 bsdf_eval(Surface s, vec3 wo, vec3 wi, out float pdf) {
    pdf = 0.0;
    if (s.type == MATERIAL_DIFFUSE) {
        if (wi.z <= 0.0) return vec3(0.0);
        pdf = wi.z * INV_PI;
        return s.albedo * (wi.z * INV_PI);
    }
    if (HAS(FEATURE_PRINCIPLED) && s.type == MATERIAL_PRINCIPLED) return principled_eval(s.pr, wo, wi, pdf);
    if (s.type == MATERIAL_EMISSION || s.alpha < DELTA_ALPHA) return vec3(0.0);
    if (HAS(FEATURE_CONDUCTOR) && s.type == MATERIAL_CONDUCTOR) {
        if (wi.z <= 0.0) return vec3(0.0);
        vec3 m = normalize(wo + wi);
        float d = ggx_d(m, s.alpha);
        pdf = ggx_g1(wo, s.alpha) * d / (4.0 * wo.z);
        return s.albedo * s.ms * (d * ggx_g2(wo, wi, s.alpha) / (4.0 * wo.z));
    }
    if (!HAS(FEATURE_DIELECTRIC)) return vec3(0.0);
    // rough dielectric
    if (wi.z > 0.0) {
        vec3 m = normalize(wo + wi);
        float f = fresnel_dielectric(dot(wo, m), s.eta);
        float d = ggx_d(m, s.alpha);
        pdf = ggx_g1(wo, s.alpha) * d / (4.0 * wo.z) * f;
        return s.albedo * s.ms * (f * d * ggx_g2(wo, wi, s.alpha) / (4.0 * wo.z));
    }
    if (wi.z == 0.0) return vec3(0.0);
    vec3 m = normalize(wo + s.eta * wi);  // generalized half vector (Walter et al. eq. 16)
    if (m.z < 0.0) m = -m;
    float wo_m = dot(wo, m), wi_m = dot(wi, m);
    if (wo_m <= 0.0 || wi_m >= 0.0) return vec3(0.0);
    float f = fresnel_dielectric(wo_m, s.eta);
    float d = ggx_d(m, s.alpha);
    float denom = sqr(wo_m + s.eta * wi_m);
    float jacobian = s.eta * s.eta * abs(wi_m) / denom;  // d omega_m / d omega_i (eq. 17)
    pdf = ggx_vndf_pdf(wo, m, s.alpha) * (1.0 - f) * jacobian;
    // Walter eq. 21 times |wi.z|; no 1/eta^2 radiance scaling, as in Cycles.
    return s.albedo * s.ms * ((1.0 - f) * d * ggx_g2(wo, wi, s.alpha) * wo_m * jacobian / wo.z);
}

// ---- sampling ------------------------------------------------------------------------
bool bsdf_sample(Surface s, vec3 wo, vec3 u, out BsdfSample bs) {
    bs.delta = false;
    bs.pdf = 0.0;
    bs.weight = vec3(0.0);
    bs.wi = vec3(0.0, 0.0, 1.0);
    bs.kind = s.type == MATERIAL_DIFFUSE ? BOUNCE_DIFFUSE : BOUNCE_GLOSSY;
    if (s.type == MATERIAL_EMISSION) return false;
    if (HAS(FEATURE_PRINCIPLED) && s.type == MATERIAL_PRINCIPLED) return principled_sample(s.pr, wo, u, bs);
    if (s.type == MATERIAL_DIFFUSE) {
        bs.wi = cosine_hemisphere(u.xy);
        bs.pdf = bs.wi.z * INV_PI;
        bs.weight = s.albedo;
        return bs.wi.z > 0.0;
    }
    if (HAS(FEATURE_CONDUCTOR) && s.type == MATERIAL_CONDUCTOR) {
        if (s.alpha < DELTA_ALPHA) {
            bs.wi = vec3(-wo.xy, wo.z);
            bs.pdf = 1.0;
            bs.delta = true;
            bs.weight = s.albedo;
            return true;
        }
        vec3 m = ggx_sample_vndf(wo, s.alpha, u.xy);
        bs.wi = reflect(-wo, m);
        if (bs.wi.z <= 0.0) return false;
        bs.pdf = ggx_vndf_pdf(wo, m, s.alpha) / (4.0 * dot(wo, m));
        bs.weight = s.albedo * s.ms * (ggx_g2(wo, bs.wi, s.alpha) / ggx_g1(wo, s.alpha));
        return true;
    }
    if (!HAS(FEATURE_DIELECTRIC)) return false;
    // dielectric
    vec3 m = s.alpha < DELTA_ALPHA ? vec3(0.0, 0.0, 1.0) : ggx_sample_vndf(wo, s.alpha, u.xy);
    float wo_m = dot(wo, m);
    float f = fresnel_dielectric(wo_m, s.eta);
    bool reflect_lobe = u.z < f;
    if (reflect_lobe) {
        bs.wi = reflect(-wo, m);
        if (bs.wi.z <= 0.0) return false;
    } else {
        bs.wi = refract(-wo, m, 1.0 / s.eta);
        if (bs.wi.z >= 0.0 || dot(bs.wi, bs.wi) == 0.0) return false;
        bs.kind = BOUNCE_TRANSMISSION;
    }
    if (s.alpha < DELTA_ALPHA) {
        bs.delta = true;
        bs.pdf = 1.0;
        bs.weight = s.albedo;  // F / P(lobe) = 1
        return true;
    }
    if (reflect_lobe) {
        bs.pdf = ggx_vndf_pdf(wo, m, s.alpha) / (4.0 * wo_m) * f;
    } else {
        float wi_m = dot(bs.wi, m);
        bs.pdf = ggx_vndf_pdf(wo, m, s.alpha) * (1.0 - f) * s.eta * s.eta * abs(wi_m) / sqr(wo_m + s.eta * wi_m);
    }
    bs.weight = s.albedo * s.ms * (ggx_g2(wo, bs.wi, s.alpha) / ggx_g1(wo, s.alpha));
    return true;
}
