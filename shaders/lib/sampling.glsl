// Warps from [0,1)^2 to directions and points, with their densities.

vec2 concentric_disk(vec2 u) {  // Shirley & Chiu 1997, unit disk
    vec2 o = 2.0 * u - 1.0;
    if (o.x == 0.0 && o.y == 0.0) return vec2(0.0);
    float r, theta;
    if (abs(o.x) > abs(o.y)) {
        r = o.x;
        theta = (PI / 4.0) * (o.y / o.x);
    } else {
        r = o.y;
        theta = (PI / 2.0) - (PI / 4.0) * (o.x / o.y);
    }
    return r * vec2(cos(theta), sin(theta));
}

vec3 cosine_hemisphere(vec2 u) {  // pdf = cos(theta) / pi
    vec2 d = concentric_disk(u);
    return vec3(d, sqrt(max(0.0, 1.0 - dot(d, d))));
}

vec3 uniform_sphere(vec2 u) {  // pdf = 1 / (4 pi)
    float z = 1.0 - 2.0 * u.x;
    float r = sqrt(max(0.0, 1.0 - z * z));
    float phi = 2.0 * PI * u.y;
    return vec3(r * cos(phi), r * sin(phi), z);
}

// 1 - cos(theta_max) from sin^2(theta_max), accurate for tiny cones.
float one_minus_cos_from_sin2(float sin2) {
    return sin2 < 1e-3 ? 0.5 * sin2 + 0.125 * sin2 * sin2 : 1.0 - sqrt(max(0.0, 1.0 - sin2));
}

// (cos, sin) of max(0, a - b) for angles a, b in [0, pi] given as (cos, sin):
// cos(a - b) = cos a cos b + sin a sin b, sin(a - b) = sin a cos b - cos a sin b.
vec2 cos_minus(vec2 a, vec2 b) {
    if (a.x >= b.x) return vec2(1.0, 0.0);  // a <= b
    return vec2(a.x * b.x + a.y * b.y, max(0.0, a.y * b.x - a.x * b.y));
}

// Uniform direction in the cone around +z with 1 - cos(theta_max) = omc; pdf = 1 / (2 pi omc).
vec3 uniform_cone(vec2 u, float omc) {
    float one_minus_cos = u.x * omc;
    float cos_t = 1.0 - one_minus_cos;
    float sin_t = sqrt(max(0.0, one_minus_cos * (2.0 - one_minus_cos)));
    float phi = 2.0 * PI * u.y;
    return vec3(sin_t * cos(phi), sin_t * sin(phi), cos_t);
}

// Index i with cdf[i] <= u < cdf[i+1] in cdf[first .. first+count], cdf[first] = 0.
#define PX_SAMPLE_CDF(NAME, ARRAY)                              \
    uint NAME(uint first, uint count, float u) {                \
        uint lo = 0u, hi = count;                               \
        while (hi - lo > 1u) {                                  \
            uint mid = (lo + hi) >> 1;                          \
            if (ARRAY[first + mid] <= u) lo = mid; else hi = mid; \
        }                                                       \
        return lo;                                              \
    }
PX_SAMPLE_CDF(sample_light_cdf, light_cdf)
PX_SAMPLE_CDF(sample_env_marginal, env_marginal)
PX_SAMPLE_CDF(sample_env_conditional, env_conditional)

// Stratum (j, k) of an m x n stratified cosine-weighted hemisphere (Ward & Heckbert 1992;
// thesis eq. 3.20): theta = asin(sqrt((j + u.x) / m)), phi = 2 pi (k + u.y) / n. Every stratum
// has the same cosine-weighted measure, so one ray per stratum is cos(theta)/pi distributed.
vec3 stratified_cosine_hemisphere(uint j, uint k, uint m, uint n, vec2 u) {
    float sin2 = (float(j) + u.x) / float(m);
    float sin_t = sqrt(sin2), cos_t = sqrt(max(0.0, 1.0 - sin2));
    float phi = 2.0 * PI * (float(k) + u.y) / float(n);
    return vec3(sin_t * cos(phi), sin_t * sin(phi), cos_t);
}

// A point on a camera aperture of radius 1, uniform in area (Cycles' camera_sample_aperture):
// a disk below 3 blades, else the regular polygon whose corners lie on the unit circle, turned
// by `rotation`; x is divided by the anamorphic `ratio`.
vec2 aperture_sample(vec2 u, float blades, float rotation, float ratio) {
    vec2 p;
    if (blades < 3.0) {
        p = concentric_disk(u);
    } else {
        // u.x picks the triangle (the centre and two neighbouring corners, at rotation +-
        // half_angle for corner 0) and, rescaled, the distance from the centre (the density
        // grows with it); u.y the place across the triangle.
        float half_angle = PI / blades;
        float corner = min(floor(u.x * blades), blades - 1.0);
        float s = sqrt(u.x * blades - corner);
        vec2 q = s * vec2(cos(half_angle), (1.0 - 2.0 * u.y) * sin(half_angle));
        float turn = rotation + 2.0 * corner * half_angle;
        p = vec2(cos(turn) * q.x - sin(turn) * q.y, sin(turn) * q.x + cos(turn) * q.y);
    }
    return vec2(p.x / ratio, p.y);
}
