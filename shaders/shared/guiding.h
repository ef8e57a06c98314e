// Path guiding with parallax-aware von Mises-Fisher mixtures (thesis 3.2.5-3.2.8, 4.6;
// Ruppert, Herholz & Lensch 2020): the records the host fit (native/src/techniques/guiding/)
// and the shaders (shaders/techniques/guiding.glsl) exchange. Polyglot, included by
// techniques.h (include types.h, never this file alone). Every record is a multiple of
// 16 bytes with each vec3 followed by a 4-byte scalar, so scalar and std430 layouts agree.
#ifndef PARALLAX_SHARED_GUIDING_H
#define PARALLAX_SHARED_GUIDING_H

// Lobes per region: region r owns lobes[r * GUIDING_MAX_COMPONENTS .. + lobe_count).
PX_CONST uint GUIDING_MAX_COMPONENTS = 16;
// Below this concentration a lobe is sampled and evaluated as the uniform sphere.
PX_CONST float GUIDING_KAPPA_MIN = 1e-3;
// Sample distances at or above this (and negative ones) mean "no next vertex": the light
// came from infinitely far (environment, sun) and parallax leaves the sample's direction.
PX_CONST float GUIDING_DISTANCE_INFINITE = 1e29;
// GuidingParams.training_spp: train for the whole render.
PX_CONST uint GUIDING_KEEP_TRAINING = 0;
// Training records at least this many frames (fits: stepwise EM needs several batches), however
// many samples per pixel a frame holds.
PX_CONST uint GUIDING_MIN_TRAINING_FRAMES = 8;

// guiding_fit: where the mixtures are fitted (issue 13).
PX_CONST uint GUIDING_FIT_CPU = 0;     // the host (field.h): readback, reservoirs, refinement
PX_CONST uint GUIDING_FIT_DEVICE = 1;  // compute passes (device_fit.h): no readback
PX_CONST uint GUIDING_FIT_AUTO = 2;    // device on a GPU, cpu on lavapipe (where each is faster)

// User settings (issue 12; the same names with a guiding_ prefix in Session.set_params and
// --set): defaults and ranges are guiding_table()'s (native/src/techniques/guiding/guiding.cpp).
struct GuidingParams {
    uint enabled;                            // guiding
    float prob;                              // guiding_prob: one-sample MIS, P(sample the VMM)
    uint parallax;                           // guiding_parallax: lobes aim at their targets
    uint training_spp;                       // guiding_training_spp (GUIDING_KEEP_TRAINING: always)
    uint min_samples;                        // guiding_min_samples: a region fits once it has these
    uint max_components;                     // guiding_max_components, <= GUIDING_MAX_COMPONENTS
    uint split_merge;                        // guiding_split_merge
    uint region_splits;                      // guiding_region_splits: 2^k initial regions
    uint region_threshold;                   // guiding_region_threshold: lit samples before a region splits (0: never)
    uint max_regions;                        // adaptive refinement stops at this many regions
    int probe_x;                             // guiding_probe_x: pixel of the Guiding Lobes pass (-1: centre)
    int probe_y;                             // guiding_probe_y
    float lobes_phase;                       // guiding_lobes_phase: the Guiding Lobes pass' spheres sit
                                             // at their regions' centres (-1) or, in [0, 1), move
                                             // through them (thesis fig. 4.20; the add-on's Animate
                                             // Lobes derives it from the timeline)
    uint record_stride PX_DEFAULT(1);        // derived by the host: pixel i records in frames f
                                             // with i % stride == f % stride, into path slot i / stride
    uint record_samples PX_DEFAULT(1);       // derived by the host: with stride 1, a pixel's samples
                                             // s < record_samples of a frame record, into slot
                                             // s * pixels + i (a frame's samples train, up to
                                             // GUIDING_MAX_RECORD_PATHS paths)
    uint fit;                                // guiding_fit: GUIDING_FIT_CPU, _DEVICE or _AUTO
    uint adaptive_prob;                      // guiding_adaptive_prob: prob learnt per region
    uint adaptive_nee;                       // guiding_adaptive_nee: NEE's probability learnt per region
};

// Training samples: each recording path fills up to GUIDING_PATH_VERTICES slots (its first
// guided vertices); at most GUIDING_MAX_RECORD_PATHS paths record per frame (32 MB of records).
PX_CONST uint GUIDING_PATH_VERTICES = 4;
PX_CONST uint GUIDING_MAX_RECORD_PATHS = 1u << 18;
// Guided (and recording) vertices: diffuse, or glossy with roughness above this (the
// reference's 0.3; sharper lobes are left to the BSDF).
PX_CONST float GUIDING_MIN_ROUGHNESS = 0.3;
// guiding_adaptive_prob (native/src/techniques/guiding/selection.h): a region samples its
// mixture only where that puts 1 + this much density on the integrand (geometric mean) against
// BSDF sampling alone: a mixture costs its evaluations at every guided vertex, and guiding every
// vertex made a path 1.5x as costly on lavapipe (veach_mis, 160 px), 1.7x on the H200.
PX_CONST float GUIDING_SELECTION_MARGIN = 0.5;
// guiding_adaptive_nee (selection.h): NEE in full where it brings this share of the light at a
// region's vertices, less in proportion below, down to the least probability of NEE.
PX_CONST float GUIDING_NEE_SHARE = 0.05;
PX_CONST float GUIDING_NEE_MIN_PROB = 0.1;
// Its candidates: j / GUIDING_SELECTION_CANDIDATES, j = 0 .. GUIDING_SELECTION_CANDIDATES - 1.
PX_CONST uint GUIDING_SELECTION_CANDIDATES = 10;

// One vMF lobe as the sampling shader reads it (thesis eq. 3.27, Jakob 2012):
// v(w) = norm * exp(kappa (dot(mu, w) - 1)), norm = kappa / (2 pi (1 - exp(-2 kappa))).
// With a finite distance (parallax), the lobe's mean direction at x is normalize(target - x)
// (thesis eq. 4.5); mu is its direction from the region's pivot.
struct GuidingLobe {
    vec3 mu;          // unit mean direction seen from the region's pivot
    float kappa;      // concentration; < GUIDING_KAPPA_MIN: uniform
    float weight;     // mixture weight pi_k (the weights of a region sum to 1)
    float norm;       // kappa / (2 pi (1 - exp(-2 kappa))); 1 / (4 pi) for a uniform lobe
    float exp_m2k;    // exp(-2 kappa), for sampling
    float distance;   // harmonic-mean distance from the pivot to the light; -1: infinite or parallax off
    vec3 target;      // pivot + distance * mu (valid when distance > 0)
    float cdf;        // weight of lobes 0..k of the region (selection; the last one is 1)
};

// One guiding region: its box (also in the region TLAS of the lobes pass) and its mixture.
struct GuidingRegion {
    vec3 aabb_min;
    uint lobe_count;  // active lobes; 0: not trained yet (sample the BSDF only)
    vec3 aabb_max;
    uint fits;        // fits done so far
    vec3 pivot;       // mean position of the region's samples: where mu and distances refer to
    uint samples;     // training samples received (saturating)
    float prob;       // probability of sampling the mixture (guiding_selection.h; 0: BSDF only)
    float score_bsdf;    // the learnt scores (mean log density on the integrand) of BSDF sampling alone ...
    float score_chosen;  // ... and of prob (tests, stats)
    float nee_prob;   // probability of NEE at its guided vertices (guiding_adaptive_nee; 1: always)
};

// One node of the region tree (regions.h), in a storage buffer: the shaders find a point's
// region by walking it from node 0 (a handful of loads; cheaper than a ray query). Inner
// node: link = first child << 2 | axis, the child holding p is first + (p[axis] >= split);
// leaf: link = region << 2 | GUIDING_NODE_LEAF. Points outside the scene box walk to the
// nearest region.
PX_CONST uint GUIDING_NODE_LEAF = 3;
struct GuidingNode {
    float split;
    uint link;
};

// One training sample, written by the trace loop at a non-specular vertex (thesis 4.6.2).
struct GuidingSample {
    vec3 position;    // the vertex
    uint region;      // its guiding region (NO_INDEX: the host looks it up from the position)
    uint direction;   // sampled direction, octahedral, packSnorm2x16 (guiding_pack_direction)
    float pdf;        // density the direction was sampled with (solid angle, MIS mixture)
    float weight;     // incident luminance along it (weighted by the path colour) / pdf (>= 0; NEE-credited)
    float distance;   // to the next non-specular vertex; >= GUIDING_DISTANCE_INFINITE: none
    float bsdf_pdf;   // the BSDF's own density of the direction (0: a delta lobe sampled it)
    float contribution;  // luminance the path gained along it (the weight * luminance(throughput) * pdf)
    float nee_light;  // luminance the vertex's shadow ray brought, as with NEE always taken (0:
                      // blocked; < 0: none traced)
    uint reserved;
};

#endif
