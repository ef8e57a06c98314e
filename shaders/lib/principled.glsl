// Principled BSDF v2 as Cycles 4.x/5.0 builds it (svm closure.h, bsdf_microfacet.h), in the
// local shading frame of bsdf.glsl. Layers from the top, each attenuating the ones below by
// its estimated albedo (Cycles' closure_layering_weight: w *= 1 - max(albedo / w)):
//   sheen        Charlie microfibre NDF (Estevez & Kulla 2017) with Neubelt & Pettineo's
//                visibility, normalised to albedo <= 1 -- an approximation of Cycles' LTC
//                microfibre sheen (Zeltner et al. 2022), whose fitted table we do not have
//   coat         GGX reflection, real dielectric Fresnel at Coat IOR, single scatter; then
//                the layers below are tinted by coat_tint^(1 / cos theta_t) (Beer, as Cycles)
//   metal        GGX reflection with the F82-tint Fresnel (Kutz et al. 2021, "Novel aspects
//                of the Adobe Standard Material"), weight metallic; below: x (1 - metallic)
//   transmission rough glass (Walter et al. 2007) with the generalized-Schlick Fresnel
//                mix(F0(ior) tint, 1, s), transmission tinted by sqrt(base colour);
//                below: x (1 - transmission)
//   specular     GGX reflection, same Fresnel form at the IOR-Level-adjusted IOR
//   diffuse      Lambert of the base colour (subsurface is rendered as diffuse)
// Multiscatter GGX (the node's default) scales metal and specular by 1 + F_ms (1 - E) / E and
// the glass by 1 / E_glass, as bsdf.glsl's lobes. The layering albedo of coat and specular
// is mix(F0 tint, 1, S(r, mu, eta)) from the SPEC_S table (Cycles' ggx_gen_schlick_ior_s).
// All lobes are sampled by one-sample MIS (Veach 1997 sec. 9.2.4): a lobe is picked with
// probability proportional to its estimated albedo, and the sample's weight and pdf are those
// of the whole mixture, so bsdf_eval gives the same pdf for NEE + MIS.
// Smooth lobes are kept rough: alpha >= PRINCIPLED_MIN_ALPHA (no delta lobes in the mixture).

const float PRINCIPLED_MIN_ALPHA = 1e-3;
const float SHEEN_MIN_ALPHA = 0.01;  // scripts/ggx_albedo_tables.py
const uint PRINCIPLED_LOBES = 6u;    // sheen, coat, metal, glass, specular, diffuse

struct Principled {
    vec3 w[PRINCIPLED_LOBES];     // lobe weights after layering (0: absent)
    float cdf[PRINCIPLED_LOBES];  // lobe selection: cdf[i] = P(lobe <= i)
    float sheen_alpha, sheen_norm;
    float coat_alpha, coat_eta;
    float alpha;                  // base roughness^2 (metal, glass, specular)
    vec3 metal_f0, metal_b, metal_ms;
    float glass_eta, glass_ms;    // glass: relative IOR across the surface (flipped inside)
    vec3 glass_f0, glass_tint;
    float spec_eta;
    vec3 spec_f0, spec_ms;
};

float avg3(vec3 v) { return (v.x + v.y + v.z) * (1.0 / 3.0); }

float f0_from_ior(float eta) { return sqr((eta - 1.0) / (eta + 1.0)); }

float ior_from_f0(float f0) {
    float r = sqrt(clamp(f0, 0.0, 0.99));
    return (1.0 + r) / (1.0 - r);
}

// Cycles' generalized Schlick with exponent < 0: the real Fresnel curve's position between
// F0 and 1, s = (F - F0) / (1 - F0), moves the tinted F0 towards 1.
float fresnel_s(float cos_i, float eta) {
    float f0 = f0_from_ior(eta);
    return clamp((fresnel_dielectric(cos_i, eta) - f0) / max(1.0 - f0, 1e-6), 0.0, 1.0);
}

// F82-tint (Kutz et al. 2021): Schlick minus b mu (1 - mu)^6, b set so that
// F(acos(1/7)) = tint x Schlick(acos(1/7)).
vec3 f82_b(vec3 f0, vec3 tint) {
    const float f = 6.0 / 7.0;
    float f5 = sqr(sqr(f)) * f;
    return mix(f0, vec3(1.0), f5) * (7.0 / (f5 * f)) * (1.0 - tint);
}

vec3 fresnel_f82(float mu, vec3 f0, vec3 b) {
    float m = clamp(1.0 - mu, 0.0, 1.0);
    float m5 = sqr(sqr(m)) * m;
    return clamp(mix(f0, vec3(1.0), m5) - b * (mu * m5 * m), 0.0, 1.0);
}

// GGX D with sin^2 from the tangent components: keeps near-mirror lobes accurate in float.
float ggx_d_precise(vec3 m, float alpha) {
    float a2 = alpha * alpha;
    return a2 / (PI * sqr(m.z * m.z * a2 + dot(m.xy, m.xy)));
}

// Multiscatter factor 1 + F_ms (1 - E) / E of a reflection lobe with hemispherical Fresnel
// average f_avg (Kulla & Conty 2017), as surface_multiscatter does for the conductor.
vec3 principled_ms(float rough, float mu, vec3 f_avg) {
    float e = max(ggx_table_2d(GGX_E_OFFSET, 32u, rough, mu), 1e-3);
    float e_avg = ggx_table_1d(GGX_EAVG_OFFSET, 32u, rough);
    vec3 f = clamp(f_avg, 0.0, 1.0);
    return 1.0 + f * e_avg / (1.0 - f * (1.0 - e_avg)) * ((1.0 - e) / e);
}

// Hemispherical average of the dielectric Fresnel (Kulla & Conty 2017's fit, eta >= 1).
float fresnel_dielectric_avg(float eta) {
    eta = max(eta, 1.0);
    return (eta - 1.0) / (4.08567 + 1.00071 * eta);
}

// Directional albedo of a GGX reflection layer with Fresnel mix(f0, 1, s) at IOR eta.
vec3 principled_layer_albedo(float rough, float mu, float eta, vec3 f0) {
    if (eta <= 1.0) return f0;
    float z = sqrt((eta - 1.0) / (eta + 1.0));
    return mix(f0, vec3(1.0), ggx_table_3d(SPEC_S_OFFSET, 16u, rough, mu, z));
}

float sheen_albedo(float rough, float mu) { return 2.0 * ggx_table_2d(SHEEN_E_OFFSET, 32u, rough, mu); }

// The lobes of Material m (base colour already textured) seen from wo.z = mu.
// eta: the surface's relative IOR for the glass (ior, or 1 / ior from inside).
Principled principled_setup(Material m, vec3 base, float eta, float mu, bool multiscatter) {
    Principled p;
    vec3 w = vec3(1.0);
    float r = max(m.roughness, sqrt(PRINCIPLED_MIN_ALPHA));
    p.alpha = r * r;
    vec3 est[PRINCIPLED_LOBES];  // estimated albedo of each lobe per unit weight (selection)
    for (uint i = 0u; i < PRINCIPLED_LOBES; ++i) { p.w[i] = vec3(0.0); est[i] = vec3(0.0); }

    // sheen
    p.sheen_alpha = max(sqr(m.sheen_roughness), SHEEN_MIN_ALPHA);
    p.sheen_norm = 1.0;
    if (m.sheen_weight > 0.0 && max3(m.sheen_tint) > 0.0) {
        float e = sheen_albedo(m.sheen_roughness, mu);
        p.sheen_norm = 1.0 / max(e, 1.0);
        est[0] = vec3(min(e, 1.0));
        p.w[0] = w * m.sheen_weight * m.sheen_tint;
        w *= clamp(1.0 - max3(m.sheen_weight * m.sheen_tint * est[0]), 0.0, 1.0);
    }
    // coat
    float coat_ior = max(m.coat_ior, 1.0);
    float cr = max(m.coat_roughness, sqrt(PRINCIPLED_MIN_ALPHA));
    p.coat_alpha = cr * cr;
    p.coat_eta = coat_ior;
    if (m.coat_weight > 0.0) {
        if (coat_ior > 1.0) {
            est[1] = principled_layer_albedo(cr, mu, coat_ior, vec3(f0_from_ior(coat_ior)));
            p.w[1] = w * m.coat_weight;
            w *= clamp(1.0 - m.coat_weight * est[1].x, 0.0, 1.0);
        }
        if (m.coat_tint != vec3(1.0)) {
            float cos_t = sqrt(max(1.0 - (1.0 - mu * mu) / sqr(coat_ior), 1e-6));
            w *= mix(vec3(1.0), pow(max(m.coat_tint, vec3(0.0)), vec3(1.0 / cos_t)), min(m.coat_weight, 1.0));
        }
    }
    // metal
    vec3 base1 = clamp(base, 0.0, 1.0);
    p.metal_f0 = base1;
    p.metal_b = f82_b(base1, min(m.specular_tint, vec3(1.0)));
    p.metal_ms = vec3(1.0);
    if (m.metallic > 0.0) {
        p.w[2] = w * m.metallic;
        est[2] = fresnel_f82(mu, p.metal_f0, p.metal_b);
        if (multiscatter)  // F_avg of F82-tint: mix(f0, 1, 1/21) - b / 126
            p.metal_ms = principled_ms(r, mu, mix(p.metal_f0, vec3(1.0), 1.0 / 21.0) - p.metal_b / 126.0);
        w *= 1.0 - m.metallic;
    }
    // transmission
    p.glass_eta = eta;
    p.glass_f0 = f0_from_ior(m.ior) * m.specular_tint;
    p.glass_tint = sqrt(base1);
    p.glass_ms = 1.0;
    if (m.transmission > 0.0) {
        p.w[3] = w * m.transmission;
        vec3 f = mix(p.glass_f0, vec3(1.0), fresnel_s(mu, eta));
        est[3] = f + (1.0 - f) * p.glass_tint;
        if (multiscatter) {
            float ior = eta >= 1.0 ? eta : 1.0 / eta;
            uint offset = eta >= 1.0 ? GLASS_E_OFFSET : GLASS_INV_E_OFFSET;
            p.glass_ms = 1.0 / max(ggx_table_3d(offset, 32u, r, mu, sqrt((ior - 1.0) / (ior + 1.0))), 1e-3);
        }
        w *= 1.0 - m.transmission;
    }
    // specular, at the IOR Level-adjusted IOR (two-sided: never flipped)
    float f0 = f0_from_ior(m.ior);
    p.spec_eta = m.ior;
    if (m.specular_ior_level != 0.5) {
        f0 *= 2.0 * m.specular_ior_level;
        p.spec_eta = ior_from_f0(f0);
        if (m.ior < 1.0) p.spec_eta = 1.0 / p.spec_eta;
    }
    p.spec_f0 = f0 * m.specular_tint;
    p.spec_ms = vec3(1.0);
    if (p.spec_eta != 1.0 && max3(w) > 0.0) {
        p.w[4] = w;
        est[4] = principled_layer_albedo(r, mu, p.spec_eta, p.spec_f0);
        if (multiscatter) {
            float real_f0 = f0_from_ior(p.spec_eta);
            float s = clamp((fresnel_dielectric_avg(p.spec_eta) - real_f0) / max(1.0 - real_f0, 1e-6), 0.0, 1.0);
            p.spec_ms = principled_ms(r, mu, mix(p.spec_f0, vec3(1.0), s));
        }
        w *= clamp(1.0 - max3(est[4]), 0.0, 1.0);
    }
    // diffuse
    p.w[5] = w * max(base, vec3(0.0));
    est[5] = vec3(1.0);

    float total = 0.0;
    for (uint i = 0u; i < PRINCIPLED_LOBES; ++i) {
        total += max3(p.w[i]) > 0.0 ? max(avg3(p.w[i] * est[i]), 1e-4) : 0.0;
        p.cdf[i] = total;
    }
    for (uint i = 0u; i < PRINCIPLED_LOBES; ++i) p.cdf[i] = total > 0.0 ? p.cdf[i] / total : 1.0;
    return p;
}

float principled_prob(Principled p, uint i) { return p.cdf[i] - (i == 0u ? 0.0 : p.cdf[i - 1u]); }

// GGX reflection lobe without Fresnel: D G2 / (4 wo.z) (x |wi.z| included), pdf by VNDF.
float ggx_reflection(vec3 wo, vec3 wi, float alpha, out vec3 m, out float pdf) {
    m = normalize(wo + wi);
    float d = ggx_d_precise(m, alpha);
    pdf = ggx_g1(wo, alpha) * d / (4.0 * wo.z);
    return d * ggx_g2(wo, wi, alpha) / (4.0 * wo.z);
}

// f |wi.z| of lobe i and the pdf of its own sampler.
vec3 principled_lobe_eval(Principled p, uint i, vec3 wo, vec3 wi, out float pdf) {
    pdf = 0.0;
    if (i == 3u) {  // glass
        float a = p.alpha, eta = p.glass_eta;
        if (wi.z > 0.0) {
            vec3 m;
            float f = ggx_reflection(wo, wi, a, m, pdf);
            vec3 fr = mix(p.glass_f0, vec3(1.0), fresnel_s(dot(wo, m), eta));
            vec3 ft = (1.0 - fr) * p.glass_tint;
            float pr = avg3(fr) / max(avg3(fr) + avg3(ft), 1e-12);
            pdf *= pr;
            return fr * (f * p.glass_ms);
        }
        if (wi.z == 0.0) return vec3(0.0);
        vec3 m = normalize(wo + eta * wi);  // generalized half vector (Walter eq. 16)
        if (m.z < 0.0) m = -m;
        float wo_m = dot(wo, m), wi_m = dot(wi, m);
        if (wo_m <= 0.0 || wi_m >= 0.0) return vec3(0.0);
        vec3 fr = mix(p.glass_f0, vec3(1.0), fresnel_s(wo_m, eta));
        vec3 ft = (1.0 - fr) * p.glass_tint;
        float pt = avg3(ft) / max(avg3(fr) + avg3(ft), 1e-12);
        float d = ggx_d_precise(m, a);
        float jacobian = eta * eta * abs(wi_m) / sqr(wo_m + eta * wi_m);  // Walter eq. 17
        pdf = ggx_vndf_pdf(wo, m, a) * pt * jacobian;
        return ft * (p.glass_ms * d * ggx_g2(wo, wi, a) * wo_m * jacobian / wo.z);
    }
    if (wi.z <= 0.0) return vec3(0.0);
    if (i == 0u) {  // sheen: D_charlie(h) V(wo, wi) |wi.z|, sampled cosine-weighted
        pdf = wi.z * INV_PI;
        vec3 h = normalize(wo + wi);
        float d = (2.0 + 1.0 / p.sheen_alpha) * pow(max(dot(h.xy, h.xy), 0.0), 0.5 / p.sheen_alpha) * (0.5 * INV_PI);
        float v = 1.0 / (4.0 * (wi.z + wo.z - wi.z * wo.z));
        return vec3(p.sheen_norm * d * v * wi.z);
    }
    if (i == 5u) {
        pdf = wi.z * INV_PI;
        return vec3(wi.z * INV_PI);
    }
    vec3 m;
    if (i == 1u) {
        float f = ggx_reflection(wo, wi, p.coat_alpha, m, pdf);
        return vec3(f * fresnel_dielectric(dot(wo, m), p.coat_eta));
    }
    float f = ggx_reflection(wo, wi, p.alpha, m, pdf);
    if (i == 2u) return fresnel_f82(dot(wo, m), p.metal_f0, p.metal_b) * p.metal_ms * f;
    return mix(p.spec_f0, vec3(1.0), fresnel_s(dot(wo, m), p.spec_eta)) * p.spec_ms * f;  // specular
}

vec3 principled_eval(Principled p, vec3 wo, vec3 wi, out float pdf) {
    vec3 f = vec3(0.0);
    pdf = 0.0;
    for (uint i = 0u; i < PRINCIPLED_LOBES; ++i) {
        if (max3(p.w[i]) <= 0.0) continue;
        float lobe_pdf;
        f += p.w[i] * principled_lobe_eval(p, i, wo, wi, lobe_pdf);
        pdf += principled_prob(p, i) * lobe_pdf;
    }
    return f;
}

bool principled_sample(Principled p, vec3 wo, vec3 u, out BsdfSample bs) {
    bs.delta = false;
    bs.pdf = 0.0;
    bs.weight = vec3(0.0);
    bs.wi = vec3(0.0, 0.0, 1.0);
    uint i = 0u;
    while (i + 1u < PRINCIPLED_LOBES && u.z >= p.cdf[i]) ++i;
    bs.kind = (i == 0u || i == 5u) ? BOUNCE_DIFFUSE : BOUNCE_GLOSSY;  // sheen, diffuse: Cycles' diffuse labels
    float lo = i == 0u ? 0.0 : p.cdf[i - 1u];
    float uz = clamp((u.z - lo) / max(p.cdf[i] - lo, 1e-12), 0.0, 0.99999994);  // reused below
    if (max3(p.w[i]) <= 0.0) return false;
    if (i == 0u || i == 5u) {
        bs.wi = cosine_hemisphere(u.xy);
    } else {
        float a = i == 1u ? p.coat_alpha : p.alpha;
        vec3 m = ggx_sample_vndf(wo, a, u.xy);
        float wo_m = dot(wo, m);
        bool refl = true;
        if (i == 3u) {
            vec3 fr = mix(p.glass_f0, vec3(1.0), fresnel_s(wo_m, p.glass_eta));
            vec3 ft = (1.0 - fr) * p.glass_tint;
            refl = uz * (avg3(fr) + avg3(ft)) < avg3(fr);
        }
        bs.wi = refl ? reflect(-wo, m) : refract(-wo, m, 1.0 / p.glass_eta);
        if (!refl && (bs.wi.z >= 0.0 || dot(bs.wi, bs.wi) == 0.0)) return false;
        if (!refl) bs.kind = BOUNCE_TRANSMISSION;
        if (refl && bs.wi.z <= 0.0) return false;
    }
    if (i != 3u && bs.wi.z <= 0.0) return false;
    vec3 f = principled_eval(p, wo, bs.wi, bs.pdf);
    if (!(bs.pdf > 0.0)) return false;
    bs.weight = f / bs.pdf;
    return true;
}
