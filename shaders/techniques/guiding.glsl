// Path guiding, device side (thesis 3.2.6, 4.6.4-4.6.5; Jakob 2012; Ruppert et al. 2020):
// the vMF density in its stable form, vMF sampling after Jakob 2012, the parallax lobe
// direction, the mixture's density and sampling, and the training sample's direction packing.
// Pure functions. The mixture functions read lobes through GUIDING_FETCH_LOBE(i), which the
// includer defines before including this file (a read of the lobe buffer in the trace loop, of
// the test buffer in shaders/tests/sampling_test.comp); without it they are left out.
// Host mirror: native/src/techniques/guiding/vmm.cpp.
#ifndef PARALLAX_GUIDING_GLSL
#define PARALLAX_GUIDING_GLSL

// Octahedral unit vector (Cigolle et al. 2014) in two snorm16 (GuidingSample.direction).
uint guiding_pack_direction(vec3 w) {
    vec2 p = w.xy / (abs(w.x) + abs(w.y) + abs(w.z));
    if (w.z < 0.0) p = (1.0 - abs(p.yx)) * vec2(p.x >= 0.0 ? 1.0 : -1.0, p.y >= 0.0 ? 1.0 : -1.0);
    return packSnorm2x16(p);
}

vec3 guiding_unpack_direction(uint packed) {
    vec2 p = unpackSnorm2x16(packed);
    vec3 w = vec3(p, 1.0 - abs(p.x) - abs(p.y));
    if (w.z < 0.0) w.xy = (1.0 - abs(w.yx)) * vec2(w.x >= 0.0 ? 1.0 : -1.0, w.y >= 0.0 ? 1.0 : -1.0);
    return normalize(w);
}

// v(w | mu, kappa) = norm exp(kappa (mu.w - 1)) (thesis eq. 3.27), with mu.w - 1 written as
// -|mu - w|^2 / 2, which keeps its precision for the sharp lobes (kappa up to 5e4).
float vmf_pdf(vec3 mu, float kappa, float norm, vec3 w) {
    if (kappa < GUIDING_KAPPA_MIN) return 0.25 * INV_PI;
    vec3 d = mu - w;
    return norm * exp(-0.5 * kappa * dot(d, d));
}

// Jakob 2012, eq. 9: 1 - cos(theta) = -log(u + (1 - u) exp(-2 kappa)) / kappa, computed as
// 1 - cos directly so that sin(theta) stays exact near the mean; phi uniform.
vec3 vmf_sample(vec3 mu, float kappa, float exp_m2k, vec2 u) {
    if (kappa < GUIDING_KAPPA_MIN) return uniform_sphere(u);
    float a = u.x + (1.0 - u.x) * exp_m2k;
    float omc = a > 0.0 ? min(-log(a) / kappa, 2.0) : 2.0;
    float sin_t = sqrt(max(0.0, omc * (2.0 - omc)));
    float phi = 2.0 * PI * u.y;
    vec3 t, b;
    make_basis(mu, t, b);
    return normalize(sin_t * cos(phi) * t + sin_t * sin(phi) * b + (1.0 - omc) * mu);
}

// The lobe's mean direction at x: towards its target with parallax (thesis eq. 4.5), else mu.
vec3 guiding_lobe_mu(GuidingLobe l, vec3 x) {
    if (l.distance > 0.0) {
        vec3 d = l.target - x;
        float len2 = dot(d, d);
        if (len2 > 1e-12 * l.distance * l.distance) return d * inversesqrt(len2);
    }
    return l.mu;
}

#ifdef GUIDING_FETCH_LOBE
// Mixture density at x of direction wi (thesis eq. 3.28), lobes first .. first + count - 1.
float guiding_vmm_pdf(uint first, uint count, vec3 x, vec3 wi) {
    float p = 0.0;
    for (uint k = 0u; k < min(count, GUIDING_MAX_COMPONENTS); ++k) {
        GuidingLobe l = GUIDING_FETCH_LOBE(first + k);
        p += l.weight * vmf_pdf(guiding_lobe_mu(l, x), l.kappa, l.norm, wi);
    }
    return p;
}

// A direction from the mixture at x: u.x picks a lobe by weight, u.yz sample it (thesis 4.6.4).
// Its density is guiding_vmm_pdf(first, count, x, wi) (all lobes contribute).
vec3 guiding_vmm_sample(uint first, uint count, vec3 x, vec3 u) {
    uint n = min(count, GUIDING_MAX_COMPONENTS);
    uint k = 0u;
    while (k + 1u < n && u.x >= GUIDING_FETCH_LOBE(first + k).cdf) ++k;
    GuidingLobe l = GUIDING_FETCH_LOBE(first + k);
    return vmf_sample(guiding_lobe_mu(l, x), l.kappa, l.exp_m2k, u.yz);
}
#endif

#endif
