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

// The guiding region query (shaders/techniques/guiding_field.glsl): the region found (NO_INDEX:
// none) and, for the lobes pass' sphere rays, the hit distance.
struct GuidingQuery {
    uint region;
    float t;
};
