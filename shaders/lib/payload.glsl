// Ray payloads shared by raygen, hit and miss shaders. Shading happens in raygen: the
// closest-hit shader only reports what was hit.
struct HitPayload {
    float t;  // < 0: miss
    uint instance;
    uint primitive;
    vec2 barycentrics;
};
