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
// Efficiency-aware RR and splitting (EARS): with TECH_ADRRS, whose pixel estimate and split
// queue it shares, the factors come from EARS' learnt statistics instead of the adjoint window.
PX_CONST uint TECH_EARS = 1u << 3;
// With TECH_GUIDING: the Guiding Lobes pass is in the film. Only then does the pipeline hold
// the region TLAS' procedural hit group and trace into it (guiding_lobes_pass): on lavapipe
// each traceRayEXT is a traversal inlined at compile, on GPUs without RT cores a procedural
// hit group in a pipeline slowed its every ray (bench/results/gpu_ic_consistent).
PX_CONST uint TECH_GUIDING_LOBES = 1u << 4;

// Programs: which ray-generation shader a ray-tracing pipeline starts (part of its key).
PX_CONST uint PROGRAM_CAMERA = 0;         // raygen.rgen: camera paths into the film
PX_CONST uint PROGRAM_IC_HEMISPHERE = 1;  // techniques/ic_hemisphere.rgen: cache entry rays
PX_CONST uint PROGRAM_PREVIEW = 2;        // preview.rgen: first-hit shading (RenderParams.preview)
PX_CONST uint PROGRAM_COUNT = 3;

// FrameParams.mode
PX_CONST uint FRAME_RENDER = 0;      // camera paths accumulate into the film
PX_CONST uint FRAME_IC_PREPARE = 1;  // camera paths only queue cache entries (thesis 4.4)
PX_CONST uint FRAME_ADRRS_ESTIMATE = 2;  // camera paths to the first non-delta vertex build ADRRS' pixel estimate
PX_CONST uint FRAME_ADRRS_SPLITS = 3;    // the split queue's entries, spread over the invocations, are traced
PX_CONST uint FRAME_ADRRS_SPLIT_SUMS = 4;  // one invocation per pixel with splits adds its entries' sums to the film

// ---- irradiance cache (thesis 3.2.3, 4.4; Ward et al. 1988; Ward & Heckbert 1992) ----------
// Stratified hemisphere of one entry: theta x phi cosine-weighted rays (thesis eq. 3.20). The
// thesis' mode uses its 10 x 20; consistent mode starts entries from 6 x 12 and refines them by
// refreshes (each one averages another hemisphere in): its paths correct what the cache misses,
// so cheap early entries pay, and the refreshes make the cache sharper as the render goes on
// (bench/results/cpu_ic_refine). IC_STRATA, the larger, sizes the sample buffer.
PX_CONST uint IC_THETA = 10;
PX_CONST uint IC_PHI = 20;
PX_CONST uint IC_THETA_CONSISTENT = 6;
PX_CONST uint IC_PHI_CONSISTENT = 12;
PX_CONST uint IC_STRATA = IC_THETA * IC_PHI;
PX_CONST float IC_MAX_RADIUS_FACTOR = 64.0;  // R <= 64 * min_radius (Krivanek et al. 2008 clamp)
// The lookup grid (ic_lookup; built by the host, ic_grid in irradiance_cache.cpp): level l
// has cubic cells of side IcParams.grid_cell * 2^l, grid_cell = 2 a R_min. An entry is listed
// in the cells that its influence sphere (radius a R) overlaps at the finest level whose side
// is at least the sphere's diameter: at most 2 x 2 x 2 cells. A query reads the one cell
// around it at each level in use. R spans [R_min, 64 R_min], hence 7 levels. Each level has a
// hash table of its own, so a query never reads one entry twice. BINDING_IC_GRID begins with
// IC_GRID_HEADER words, level l's first bucket and its bucket count - 1 (a power of two), then
// every bucket's first place in BINDING_IC_GRID_ENTRIES, and one past the last. Each place is
// an IcCandidate: the entry's sphere travels with the list, so the query rejects the entries
// whose sphere misses it without reading them.
PX_CONST uint IC_GRID_LEVELS = 7;
PX_CONST uint IC_GRID_HEADER = 2 * IC_GRID_LEVELS;
// IcParams.mode (the setting ic_mode)
PX_CONST uint IC_MODE_CONSISTENT = 0;  // paths go on past the cache; the image shrinks them toward it (ic_combine)
PX_CONST uint IC_MODE_THESIS = 1;      // paths end at cached vertices (thesis 4.4): biased, smooth
PX_CONST uint IC_QUERY_MAX_ENTRIES = 4;  // consistent mode: a query ends after this many usable entries
// Consistent mode: a pixel's sample reuses its previous query within this share of the nearest
// entry's reach, at normals this close (cosine; irradiance_cache.glsl, IcReuse).
PX_CONST float IC_REUSE_REACH = 0.25;
PX_CONST float IC_REUSE_COS = 0.99;

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
    uint highlight;                         // IC Irradiance pass: colour only (thesis fig. 4.13)
    uint mode;                              // ic_mode: IC_MODE_CONSISTENT or IC_MODE_THESIS
    uint queue_capacity PX_DEFAULT(0);      // derived by the host: requests between host steps
    uint shade PX_DEFAULT(0);               // derived by the host: paths are shaded from the cache
                                            // (ic on); ADRRS alone builds it for its adjoint only
    float grid_cell PX_DEFAULT(0);          // derived by the host: the lookup grid's finest cell side
    uint grid_levels PX_DEFAULT(0);         // ... bit l: level l lists entries
    float prepare_create_prob PX_DEFAULT(0);  // derived by the host: create_prob in prepare frames
    uint theta PX_DEFAULT(IC_THETA);        // derived by the host: the entries' hemisphere strata
    uint phi PX_DEFAULT(IC_PHI);            // ... in theta and phi (IC_THETA_CONSISTENT ...)
    uint reuse_stamp PX_DEFAULT(0);         // derived by the host: IcReuseRecord.stamp while the entries stay
};

// The lookup grid's bucket of cell (x, y, z) in a level's table of bucket_mask + 1 buckets: a
// hash (Teschner et al. 2003). Cells that share a bucket share its list; the query tests each
// entry's sphere, so a collision costs time, never a wrong answer.
#ifdef __cplusplus
inline
#endif
uint ic_grid_bucket(int x, int y, int z, uint bucket_mask) {
    return ((uint(x) * 73856093u) ^ (uint(y) * 19349663u) ^ (uint(z) * 83492791u)) & bucket_mask;
}

// ---- Russian roulette and splitting: ADRRS (thesis 3.2.4, 4.5; Vorba & Krivanek 2016) and
// EARS (Rath et al. 2022) ------------------------------------------------------------------
// AdrrsParams.mode (the setting rrs)
PX_CONST uint RRS_OFF = 0;    // the throughput roulette alone
PX_CONST uint RRS_ADRRS = 1;  // the thesis' adjoint-driven weight window
PX_CONST uint RRS_EARS = 2;   // efficiency-aware factors from learnt statistics
PX_CONST uint ADRRS_ESTIMATE_IC = 0;     // N spp to the first non-delta vertex: NEE + cache
PX_CONST uint ADRRS_ESTIMATE_IMAGE = 1;  // the running accumulated image, blurred

struct AdrrsParams {
    uint mode;                           // rrs: RRS_OFF, RRS_ADRRS or RRS_EARS
    uint splitting;                      // adrrs_splitting: split above the window (else RR only)
    float window;                        // adrrs_window: s, delta+ = s delta-
    float rr_min;                        // adrrs_rr_min: lowest survival probability
    uint max_splits;                     // adrrs_max_splits: extra paths per pixel sample
    uint estimate_spp;                   // adrrs_estimate_spp: estimate frames (ic), or the
                                         // samples before the first image estimate (image)
    uint estimate;                       // adrrs_estimate: ADRRS_ESTIMATE_IC or _IMAGE
    uint ic_glossy;                      // adrrs_ic_glossy: the ic estimate reads the cache at
                                         // glossy vertices too (thesis 4.4 "IC on glossy")
    uint grid;                           // rrs_grid: EARS' cells along the scene's longest axis
    uint min_records;                    // rrs_min_records: EARS' records a cell needs for factors
    uint slots PX_DEFAULT(0);            // derived by the host: queue entries per pixel
    // Derived by the host: the adjoint grid (BINDING_ADRRS_ADJOINT), the cache's entries
    // averaged per cell and per normal direction (the 6 signed axes).
    vec3 grid_min PX_DEFAULT((vec3{0.0f, 0.0f, 0.0f}));
    float grid_cell PX_DEFAULT(0.0f);  // cell edge (0: no grid yet)
    uint grid_nx PX_DEFAULT(0), grid_ny PX_DEFAULT(0), grid_nz PX_DEFAULT(0);
    uint grid_pad PX_DEFAULT(0);
    // Derived by the host for EARS (techniques/ears.h): the statistics' grid (`grid` cells
    // along the scene's longest axis, hashed into ears_slots), and the image's factors.
    vec3 ears_min PX_DEFAULT((vec3{0.0f, 0.0f, 0.0f}));
    float ears_cell PX_DEFAULT(0.0f);        // cell edge (0: no grid, EARS records nothing)
    uint ears_slots PX_DEFAULT(0);           // hash slots (a power of two)
    uint ears_learn PX_DEFAULT(0);           // paths record statistics (a pixel estimate exists)
    uint ears_active PX_DEFAULT(0);          // the factors hold statistics: paths decide by them
    float ears_scale PX_DEFAULT(1.0f);       // S: the image's mean luminance, the records' unit
    float ears_image_factor PX_DEFAULT(0.0f);  // sqrt(image cost / image relative variance)
    uint ears_threads PX_DEFAULT(0);           // invocations with records in BINDING_EARS_RECORDS
    float ears_pad1 PX_DEFAULT(0.0f), ears_pad2 PX_DEFAULT(0.0f);
};

// ---- EARS' statistics (BINDING_EARS_CELLS, BINDING_EARS_FACTORS) -----------------------------
PX_CONST uint EARS_PROBES = 8;          // linear probes of the hash table
PX_CONST uint EARS_PATH_VERTICES = 2;   // decisions of one path that record statistics (its first ones:
                                        // 8 made lavapipe 1.3x slower when they were arrays in the path's state)
PX_CONST float EARS_FIXED_SCALE = 65536.0;  // sums are 64-bit fixed point (two uints) in 1/65536
PX_CONST float EARS_MAX_RECORD = 1e10;  // a record's (Lr/S)^2 is clamped here
PX_CONST float EARS_MAX_VARIANCE = 1e4; // a pixel's relative variance per sample is clamped here
// The metric EARS minimises is relMSE's, (x - I)^2 / (I^2 + EARS_EPSILON^2) per pixel: each
// path weight and pixel variance is taken relative to sqrt(I^2 + EARS_EPSILON^2) (Rath et al.
// take I + 1e-2; this is Mueller et al.'s relMSE, I^2 + 0.01, not bench.converge's r^2 + 1e-3).
PX_CONST float EARS_EPSILON = 0.1;
// A path's open record (BINDING_EARS_RECORDS): kept in memory, not in the path's state across
// its rays.
struct EarsRecord {
    uint slot;         // the cell's slot
    float throughput;  // luminance of the throughput after the decision
    float radiance;    // luminance of the path's radiance when its continuation started
    uint rays;         // the path's rays then
};
// One cell of the learning table (BINDING_EARS_CELLS): this iteration's records summed as 64-bit
// fixed point (lo, hi words: the shaders add with a carry, so sums are the same whatever the order).
struct EarsCell {
    uint key;      // 1 + packed cell and normal direction (0: empty slot)
    uint count;    // records
    uint lr_lo, lr_hi;    // sum of Lr / S
    uint lr2_lo, lr2_hi;  // sum of (Lr / S)^2
    uint cost_lo, cost_hi;  // sum of the rays the continuation traced
};
// Per pixel (BINDING_EARS_PIXELS), over the iteration: the radiance (luminance) of its odd and
// of its even samples, each with their split copies (A and B), how many of each (k_a, k_b) and
// the rays of them all. (A/k_a - B/k_b)^2 / (1/k_a + 1/k_b) estimates the variance of one sample
// without needing the pixel's mean; the host divides it by the metric's I^2 + eps^2.
struct EarsPixel {
    float odd_sum, even_sum;
    uint odd_samples, even_samples;
    uint rays;
    uint pad;
};
// What a slot's paths decide by (the host's fit of the last iteration).
struct EarsFactor {
    float second_moment;  // E[Lr^2] / cost (Rath et al. 2022, earsFactorR)
    float variance;       // Var[Lr] / cost (earsFactorS)
    float cost;           // cost / the image's cost per sample (the RRS Cost pass)
    float pad;
};

// A split path (BINDING_ADRRS_SPLITS): the ray that reached the vertex where it was split,
// traced again by each copy, which then samples its own continuation there. The vertex's
// emission and NEE were counted once, by the path that split. The split dispatch traces the
// copies (and the copies they split off in turn) and writes their sums into the entry
// (radiance, rays, paths), which the sums dispatch adds to the pixel in queue order.
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
    uint budget;          // copies the entry's copies may still split off, all together
    vec3 radiance;        // written by the split dispatch: the copies' radiance, summed
    uint rays;            // ... their rays
    uint paths;           // ... the paths traced (the copies and those they split off)
};
PX_CONST float ADRRS_MIN_ROUGHNESS = 0.5;  // Principled lobes this rough count as Lambertian for ADRRS' adjoint
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

// A place in a lookup grid bucket's list (BINDING_IC_GRID_ENTRIES): an entry's influence
// sphere and its slot.
struct IcCandidate {
    vec3 position;
    float reach;  // accuracy * R, the sphere's radius
    uint slot;    // in BINDING_IC_ENTRIES
};

// Consistent mode: a pixel's last query (BINDING_IC_REUSE), which its next samples reuse near
// it until the entries change (irradiance_cache.glsl, IcReuse).
struct IcReuseRecord {
    vec3 position;
    float radius;    // the nearest entry's reach; 0: none
    vec3 normal;
    uint stamp;      // IcParams.reuse_stamp when it was made
    vec3 irradiance;
    uint gradients;  // packHalf2x16 of the entries' mean |g_t|, |g_r|
};

// One cache entry. Its influence sphere (centre position, radius accuracy * radius) decides
// the lookup grid's cells that list it.
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
