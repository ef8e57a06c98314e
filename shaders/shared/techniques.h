// Settings and records of the thesis' techniques that cross the host/device boundary
// (DESIGN: "One settings struct per technique"). Polyglot like types.h, which includes it.
// PX_DEFAULT gives C++ members their defaults; GLSL ignores it.
#ifndef PARALLAX_SHARED_TECHNIQUES_H
#define PARALLAX_SHARED_TECHNIQUES_H

#ifdef __cplusplus
#define PX_DEFAULT(v) = v
#else
#define PX_DEFAULT(v)
#endif

// Technique bits: specialization constant TECHNIQUES (constant_id 3), part of the pipeline key.
PX_CONST uint TECH_IC = 1u << 0;

// Programs: which ray-generation shader a ray-tracing pipeline starts (part of its key).
PX_CONST uint PROGRAM_CAMERA = 0;         // raygen.rgen: camera paths into the film
PX_CONST uint PROGRAM_IC_HEMISPHERE = 1;  // techniques/ic_hemisphere.rgen: cache entry rays
PX_CONST uint PROGRAM_PREVIEW = 2;        // preview.rgen: first-hit shading (RenderParams.preview)

// FrameParams.mode
PX_CONST uint FRAME_RENDER = 0;      // camera paths accumulate into the film
PX_CONST uint FRAME_IC_PREPARE = 1;  // camera paths only queue cache entries (thesis 4.4)

// ---- irradiance cache (thesis 3.2.3, 4.4; Ward et al. 1988; Ward & Heckbert 1992) ----------
// Stratified hemisphere of one entry: IC_THETA x IC_PHI cosine-weighted rays (thesis eq. 3.20).
PX_CONST uint IC_THETA = 10;
PX_CONST uint IC_PHI = 20;
PX_CONST uint IC_STRATA = IC_THETA * IC_PHI;
PX_CONST float IC_MAX_RADIUS_FACTOR = 64.0;  // R <= 64 * min_radius (Krivanek et al. 2008 clamp)
PX_CONST float IC_QUERY_T = 1e-3;            // t_max of the zero-length cache query ray

struct IcParams {
    uint enabled PX_DEFAULT(0);             // ic
    float accuracy PX_DEFAULT(0.2f);        // a: influence radius a*R, weight threshold 1/a
    float min_radius PX_DEFAULT(0.1f);      // lower clamp of the harmonic-mean distance R (m)
    float create_prob PX_DEFAULT(0.01f);    // uncovered diffuse vertex -> creation request
    float update_prob PX_DEFAULT(1e-5f);    // per pixel and frame: refresh one entry (host)
    uint nee_samples PX_DEFAULT(1);         // light samples per vertex of hemisphere paths
    uint gradients PX_DEFAULT(0);           // Ward & Heckbert rotational + translational
    float gradient_max PX_DEFAULT(5.0f);    // clamp of the relative gradients' length
    uint visibility_check PX_DEFAULT(1);    // Ward 1988: reject entries in front of the point
    uint prepare_frames PX_DEFAULT(50);     // most frames that only fill the cache (host)
    uint capacity PX_DEFAULT(65536);        // entries
    uint rebuild_interval PX_DEFAULT(1);    // frames between BLAS rebuilds (refits in between)
    uint highlight PX_DEFAULT(0);           // IC Irradiance pass: colour only (thesis fig. 4.13)
    uint queue_capacity PX_DEFAULT(0);      // derived by the host: requests one frame may queue
};

// Every technique's settings, one buffer (BINDING_TECH_PARAMS).
struct TechniqueParams {
    IcParams ic;
};

// One cache entry. The influence sphere (centre position, radius accuracy * radius) is also
// an AABB in BINDING_IC_AABBS, the geometry of the cache's own acceleration structure.
struct IcEntry {
    vec3 position;
    float radius;       // R: harmonic mean of the hemisphere rays' hit distances, clamped
    vec3 normal;
    uint updates;       // hemisphere estimates blended into this entry
    vec3 irradiance;    // indirect irradiance E (direct light comes from NEE at the query)
    float pad0;
    vec3 grad_t;        // translational gradient of luminance / luminance (1/m)
    float pad1;
    vec3 grad_r;        // rotational gradient of luminance / luminance (1/rad)
    float pad2;
};

// A creation request, queued by camera paths (BINDING_IC_QUEUE after a 16-byte counter).
struct IcRequest {
    vec3 position;
    uint pixel;
    vec3 normal;
    uint sample_index;
};

// Work for the hemisphere dispatch, sorted and assigned slots by the host.
PX_CONST uint IC_JOB_CREATE = 0;
PX_CONST uint IC_JOB_UPDATE = 1;
struct IcJob {
    vec3 position;
    uint slot;
    vec3 normal;
    uint kind;
};

// One hemisphere ray's result.
struct IcSample {
    vec3 radiance;
    float distance;  // to the first hit; INFINITY_F (1e30) for an escaped ray
};

#endif
