// Guiding mixtures fitted on the device (issue 13; shaders/techniques/guiding/fit.comp,
// native/src/techniques/guiding/device_fit.h): the fit's own descriptor set and records.
// Polyglot like types.h; include types.h first (GuidingSample, GuidingRegion, GuidingLobe).
#ifndef PARALLAX_SHARED_GUIDING_FIT_H
#define PARALLAX_SHARED_GUIDING_FIT_H

// Bindings of the fit's descriptor set (set 0 of its compute pipeline, not the renderer's).
PX_CONST uint GUIDING_FIT_BINDING_SAMPLES = 0;     // GuidingSample[], the frame's records (read)
PX_CONST uint GUIDING_FIT_BINDING_REGIONS = 1;     // GuidingRegion[], what the sampler reads
PX_CONST uint GUIDING_FIT_BINDING_LOBES = 2;       // GuidingLobe[regions * GUIDING_MAX_COMPONENTS]
PX_CONST uint GUIDING_FIT_BINDING_STATE = 3;       // GuidingFitRegion[regions]
PX_CONST uint GUIDING_FIT_BINDING_STATE_LOBES = 4; // GuidingFitLobe[regions * GUIDING_MAX_COMPONENTS]
PX_CONST uint GUIDING_FIT_BINDING_COUNTS = 5;      // uint[(2 regions + 1) * blocks], bin-major; then offsets
PX_CONST uint GUIDING_FIT_BINDING_STARTS = 6;      // uint[2 regions + 2]: first sorted slot of each bin, total
PX_CONST uint GUIDING_FIT_BINDING_SORTED = 7;      // uint[samples]: sample indices, by bin, stable
PX_CONST uint GUIDING_FIT_BINDING_PENDING = 8;     // GuidingSample[regions * pending_capacity]: lit
                                                   // samples of regions still below min_samples
PX_CONST uint GUIDING_FIT_BINDING_TALLY = 9;       // GuidingFitTally[regions] (host-visible: the host's
                                                   // refinement reads it after the fit)
PX_CONST uint GUIDING_FIT_BINDING_SPLITS = 10;     // GuidingFitSplit[split_count]: the REFINE pass' work
PX_CONST uint GUIDING_FIT_BINDING_SCAN_PARTIALS = 11; // uint[tiles]: a sum, then a prefix, per scan tile
PX_CONST uint GUIDING_FIT_BINDING_POSITION_PARTS = 12; // vec4[regions * position_parts]: POSITIONS' sums
PX_CONST uint GUIDING_FIT_BINDING_COUNT = 13;

PX_CONST uint GUIDING_FIT_GROUP = 64;  // threads per workgroup (the EM: one workgroup per region)
PX_CONST uint GUIDING_FIT_SCAN_TILE = 1024;  // counts per workgroup of the scan (a multiple of the group)

// Passes of fit.comp, dispatched in this order with a barrier after each (counts[] zeroed first):
PX_CONST uint GUIDING_FIT_PASS_COUNT = 0;          // a thread per block: its samples' bins
// the exclusive prefix sum over (bin, block), bin-major, in tiles of GUIDING_FIT_SCAN_TILE:
PX_CONST uint GUIDING_FIT_PASS_SCAN_REDUCE = 1;    // a workgroup per tile: the tile's sum
PX_CONST uint GUIDING_FIT_PASS_SCAN_PARTIALS = 2;  // one workgroup: the tiles' prefixes, the total
PX_CONST uint GUIDING_FIT_PASS_SCAN_APPLY = 3;     // a workgroup per tile: first slots, starts[]
PX_CONST uint GUIDING_FIT_PASS_SCATTER = 4;        // a thread per block: stable scatter
PX_CONST uint GUIDING_FIT_PASS_POSITIONS = 5;      // position_parts workgroups per region: position sums
PX_CONST uint GUIDING_FIT_PASS_EM = 6;             // a workgroup per region: EM, split/merge, records
// After EM, only when the host decided to refine regions (device_fit.h), a workgroup per split:
PX_CONST uint GUIDING_FIT_PASS_REFINE = 7;   // the child inherits the parent's state (field.cpp refine)

// Push constants: the pass, sizes and the FitOptions (em.h) in float.
struct GuidingFitPush {
    uint pass;
    uint sample_count;      // GuidingSample slots
    uint region_count;      // bins 2 r (lit), 2 r + 1 (unlit) of region r; bin 2 region_count: dropped
    uint block_size;        // samples per block of the counting sort
    uint block_count;
    uint max_components;
    uint initial_components;
    uint max_iterations;
    float kappa0;
    float kappa_max;
    float tolerance;
    float weight_prior;
    float mean_cosine_prior;
    float mean_cosine_prior_strength;
    float decay;
    uint split_merge;
    float split_threshold;
    float split_min_samples;
    float merge_threshold;
    float merge_min_samples;
    uint parallax;
    uint min_samples;       // guiding_min_samples: a region fits once it has this many lit samples
    uint pending_capacity;  // max(min_samples, 2 max_components + 1)
    uint split_count;       // GuidingFitSplit records (REFINE)
    uint position_parts;    // POSITIONS splits each region's samples into this many equal parts
    float prob;             // guiding_prob: a region's probability before it learnt its own
    uint adaptive_prob;     // guiding_adaptive_prob: learn it (selection.h); 0: always prob
    uint reserved;
};

// A region's fit state (its mixture lives in GuidingFitLobe records).
struct GuidingFitRegion {
    vec3 position_mean;   // of every sample received: the pivot
    float position_count;
    uint count;           // lobes (0: untrained)
    uint fits;
    float new_samples;    // samples since the last merge check
    uint samples;         // received (saturating)
    uint iterations;      // the last fit's EM iterations, splits and merges
    uint splits;
    uint merges;
    float log_likelihood; // the last fit's weighted mean log density
    uint pending;         // lit samples kept from earlier frames (not fitted yet) ...
    float pending_zero;   // ... and the unlit ones they came with (only counted)
    uint received;        // lit samples received since the region was made (refinement; saturating)
    // The learnt guiding probability's sums (selection.h SelectionStats), decayed with the
    // mixture's statistics: the samples they stand for (lit and unlit), then per candidate
    // j / GUIDING_SELECTION_CANDIDATES the score, the sum of (C / p) log p_a, and the sum of C / p.
    float selection_samples;
    float selection_score[GUIDING_SELECTION_CANDIDATES];
    float selection_weight;
    uint reserved1;
};

// What the host reads of a region after a fit (32 bytes), written by EM and REFINE: its
// refinement's counts and the learnt probability's sums (GuidingField::guiding_pays).
struct GuidingFitTally {
    uint received;  // lit samples received since the region was made; 0 without a mixture
    uint samples;   // GuidingFitRegion.samples, fits: a child inherits them (as the host
    uint fits;      // field's records do), so the session's stats subtract them
    float prob;     // GuidingRegion.prob: the sampler's probability of the mixture
    float score_bsdf;    // selection_score[0] (BSDF sampling alone) and that of the chosen
    float score_chosen;  // probability; 0 while nothing was learnt or with adaptive_prob off
    float weight;        // selection_weight
    uint reserved2;
};

// One region split by the host (RegionTree::split): `parent` keeps the lower half of its box
// along `axis`, the new region `child` the upper half (position[axis] >= plane).
struct GuidingFitSplit {
    uint parent;
    uint child;
    uint axis;
    float plane;
};

// One lobe of a region's mixture and its sufficient statistics (em.h ComponentStats):
// stat_weight = sum w g, stat_direction = sum w g omega, stat_count = sum g,
// stat_inv_distance = sum w g / d.
struct GuidingFitLobe {
    vec3 mu;
    float kappa;
    vec3 stat_direction;
    float stat_weight;
    float weight;
    float distance;       // harmonic mean from the pivot; <= 0: infinitely far
    float stat_count;
    float stat_inv_distance;
};

#endif
