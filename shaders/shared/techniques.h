// Settings and records of the thesis' techniques that cross the host/device boundary
// (DESIGN: "One settings struct per technique"). Polyglot like types.h, which includes it.
// The user settings' defaults and ranges are their rows' (the techniques' tables, e.g.
// ic_table() in native/src/techniques/irradiance_cache.cpp); PX_DEFAULT gives the fields the
// host derives theirs (GLSL ignores it).
#ifndef PARALLAX_SHARED_TECHNIQUES_H
#define PARALLAX_SHARED_TECHNIQUES_H

#ifdef __cplusplus
#define PX_DEFAULT(v) = v
#else
#define PX_DEFAULT(v)
#endif

// Technique bits: specialization constant TECHNIQUES (constant_id 3), part of the pipeline key.
PX_CONST uint TECH_IC = 1u << 0;     // the irradiance cache exists (built for shading or for ADRRS)
PX_CONST uint TECH_ADRRS = 1u << 1;  // adjoint-driven Russian roulette and splitting
PX_CONST uint TECH_GUIDING = 1u << 2;  // path guiding (region tree, VMM sampling, training samples)

// Programs: which ray-generation shader a ray-tracing pipeline starts (part of its key).
PX_CONST uint PROGRAM_CAMERA = 0;         // raygen.rgen: camera paths into the film
PX_CONST uint PROGRAM_IC_HEMISPHERE = 1;  // techniques/ic_hemisphere.rgen: cache entry rays
PX_CONST uint PROGRAM_PREVIEW = 2;        // preview.rgen: first-hit shading (RenderParams.preview)
PX_CONST uint PROGRAM_COUNT = 3;

// FrameParams.mode
PX_CONST uint FRAME_RENDER = 0;      // camera paths accumulate into the film
PX_CONST uint FRAME_IC_PREPARE = 1;  // camera paths only queue cache entries (thesis 4.4)
PX_CONST uint FRAME_ADRRS_ESTIMATE = 2;  // camera paths to the first non-delta vertex build ADRRS' pixel estimate
PX_CONST uint FRAME_ADRRS_SPLITS = 3;    // one invocation per queued pixel traces its split paths

// ---- irradiance cache (thesis 3.2.3, 4.4; Ward et al. 1988; Ward & Heckbert 1992) ----------
// Stratified hemisphere of one entry: IC_THETA x IC_PHI cosine-weighted rays (thesis eq. 3.20).
PX_CONST uint IC_THETA = 10;
PX_CONST uint IC_PHI = 20;
PX_CONST uint IC_STRATA = IC_THETA * IC_PHI;
PX_CONST float IC_MAX_RADIUS_FACTOR = 64.0;  // R <= 64 * min_radius (Krivanek et al. 2008 clamp)
PX_CONST float IC_QUERY_T = 1e-3;            // t_max of the zero-length cache query ray

struct IcParams {
    uint enabled;                           // ic
    float accuracy;                         // a: influence radius a*R, weight threshold 1/a
    float min_radius;                       // lower clamp of the harmonic-mean distance R (m)
    float create_prob;                      // uncovered diffuse vertex -> creation request
    float update_prob;                      // per pixel and frame: refresh one entry (host)
    uint nee_samples;                       // light samples per vertex of hemisphere paths
    uint gradients;                         // Ward & Heckbert rotational + translational
    float gradient_max;                     // clamp of the relative gradients' length
    uint visibility_check;                  // Ward 1988: reject entries in front of the point
    uint prepare_frames;                    // most frames that only fill the cache (host)
    uint capacity;                          // entries
    uint rebuild_interval;                  // frames between BLAS rebuilds (refits in between)
    uint highlight;                         // IC Irradiance pass: colour only (thesis fig. 4.13)
    uint queue_capacity PX_DEFAULT(0);      // derived by the host: requests one frame may queue
    uint shade PX_DEFAULT(0);               // derived by the host: paths are shaded from the cache
                                            // (ic on); ADRRS alone builds it for its adjoint only
};

// ---- ADRRS (thesis 3.2.4, 4.5; Vorba & Krivanek 2016) -------------------------------------
PX_CONST uint ADRRS_ESTIMATE_IC = 0;     // N spp to the first non-delta vertex: NEE + cache
PX_CONST uint ADRRS_ESTIMATE_IMAGE = 1;  // the running accumulated image, blurred

struct AdrrsParams {
    uint enabled;                        // adrrs
    uint splitting;                      // adrrs_splitting: split above the window (else RR only)
    float window;                        // adrrs_window: s, delta+ = s delta-
    float rr_min;                        // adrrs_rr_min: lowest survival probability
    uint max_splits;                     // adrrs_max_splits: extra paths per pixel sample
    uint estimate_spp;                   // adrrs_estimate_spp: estimate frames (ic), or the
                                         // samples before the first image estimate (image)
    uint estimate;                       // adrrs_estimate: ADRRS_ESTIMATE_IC or _IMAGE
    uint ic_glossy;                      // adrrs_ic_glossy: the ic estimate reads the cache at
                                         // glossy vertices too (thesis 4.4 "IC on glossy")
    uint slots PX_DEFAULT(0);            // derived by the host: queue entries per pixel
    // Derived by the host: the adjoint grid (BINDING_ADRRS_ADJOINT), the cache's entries
    // averaged per cell and per normal direction (the 6 signed axes).
    vec3 grid_min PX_DEFAULT((vec3{0.0f, 0.0f, 0.0f}));
    float grid_cell PX_DEFAULT(0.0f);  // cell edge (0: no grid yet)
    uint grid_nx PX_DEFAULT(0), grid_ny PX_DEFAULT(0), grid_nz PX_DEFAULT(0);
    uint grid_pad PX_DEFAULT(0);
};

// A split path (BINDING_ADRRS_QUEUE): the ray that reached the vertex where it was split,
// traced again by each copy, which then samples its own continuation there. The vertex's
// emission and NEE were counted once, by the path that split.
struct AdrrsSplit {
    vec3 origin;
    float t_min;
    vec3 direction;
    float t_max;
    vec3 throughput;  // of each copy: the path's throughput / q
    uint rng;         // seeds the copies' streams
    uint bounces;     // bounces | discrete << 16
    uint copies;      // paths to trace from this entry
    uint flags;       // ADRRS_SPLIT_CAMERA_RAY: the ray was the camera ray; ADRRS_SPLIT_HALF; kind counts
    uint segments;    // segments the path had traced up to the vertex
    uint self_instance;   // the triangle the ray starts on (NO_INDEX: none)
    uint self_primitive;
    float min_ray_pdf;    // the path's (PathState.min_ray_pdf)
};
PX_CONST uint ADRRS_SPLIT_CAMERA_RAY = 1u;
PX_CONST uint ADRRS_SPLIT_HALF = 2u;  // queued by a sample of adaptive sampling's half buffer
PX_CONST uint ADRRS_SPLIT_KIND_SHIFT = 2u;  // flags >> this: the path's kind bounce counts

#include "guiding.h"

// Every technique's settings, one buffer (BINDING_TECH_PARAMS).
struct TechniqueParams {
    IcParams ic;
    AdrrsParams adrrs;
    GuidingParams guiding;
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
