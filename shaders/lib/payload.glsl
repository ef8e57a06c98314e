// Ray payloads shared by raygen, hit and miss shaders. Shading happens in raygen: the
// closest-hit shader only reports what was hit.
// Before a trace, instance and primitive name the triangle the ray starts on (NO_INDEX: none),
// which self_skip.rahit ignores; the closest-hit shader overwrites them with what was hit.
// Shadow rays carry the same payload (t >= 0: occluded).
struct HitPayload {
    float t;  // < 0: miss
    uint instance;
    uint primitive;
    vec2 barycentrics;
};

// The irradiance cache query (shaders/techniques/irradiance_cache.glsl): where, and the
// weighted sums its any-hit shader adds every usable entry to.
struct IcQuery {
    vec3 position;
    vec3 normal;
    vec3 weighted_irradiance;  // sum of w_i E_i(x)
    float weight;              // sum of w_i
    vec2 weighted_gradients;   // sum of w_i (|grad_t|, |grad_r|)
    float nearest_distance;    // of the nearest usable entry (IC Radius)
    float nearest_radius;      // its validity radius, accuracy * R_i
    uint found;                // usable entries seen
};

// The guiding region query (shaders/techniques/guiding_field.glsl): the region found (NO_INDEX:
// none) and, for the lobes pass' sphere rays, the hit distance.
struct GuidingQuery {
    uint region;
    float t;
};
