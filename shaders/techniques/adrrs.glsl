// Adjoint-driven Russian roulette and splitting (thesis 3.2.4, 4.5; Vorba & Krivanek 2016).
//
// At a non-delta vertex x, after its emission and NEE are counted, the rest of the path (its
// BSDF-sampled continuation) is expected to bring v * L_r,ind(x): the path throughput v times
// the indirect light reflected at x, approximated with the cache as rho(x)/pi * E_IC(x)
// (rho: the lobe's directional albedo, the "directionally uniform" f_BSDF of thesis eq. 4.1;
// the reference dropped it). E_IC is read from the adjoint grid, the cache's entries averaged
// per cell and normal direction by the host: a few loads instead of a cache query (a
// procedural-geometry traversal that costs several rays) at every vertex. Zero variance would have every path bring the pixel value I, so
// the window is centred on C = I~ / (rho/pi E_IC) (eq. 4.1), bounded by delta- = 2C/(1+s) and
// delta+ = s delta- (eqs. 4.2, 4.3). Per colour channel the comparison of v with C is made on
// the luminance of v * rho/pi * E against that of I~, so a zero channel never makes C infinite.
// Below the window the continuation survives with q = max(v/delta-, rr_min) and is weighted
// 1/q; above it the path is split into q = v/delta+ expected copies (an expected-value split:
// floor(q) or floor(q)+1 with mean q), each weighted 1/q, at most max_splits per pixel sample
// (a pixel's budget in a dispatch of n samples is n max_splits copies, in at most
// adrrs.slots queue entries). Copies beyond the first go to a per-pixel queue that a later
// dispatch of the same frame traces (FRAME_ADRRS_SPLITS); their own splits join the queue.

// The weight-window factor for r = v / C: q < 1 roulette (survival probability), q > 1
// split (expected copies), 1 inside the window [delta-, delta+] = [2/(1+s), 2s/(1+s)] C.
float adrrs_window_factor(float r, float window, float rr_min, bool splitting) {
    float lower = 2.0 / (1.0 + window), upper = window * lower;
    if (r < lower) return max(r / lower, rr_min);
    if (r > upper && splitting) return r / upper;
    return 1.0;  // inside the window (or NaN: leave the path alone)
}

// Expected-value split (Vorba & Krivanek 2016): floor(q) copies with probability
// 1 - frac(q), else floor(q) + 1, so the expected count is q; u uniform in [0, 1).
uint adrrs_split_copies(float q, float u) {
    uint copies = uint(q);
    return u < q - float(copies) ? copies + 1u : copies;
}

#ifndef PX_ADRRS_MATH_ONLY
layout(set = 0, binding = BINDING_ADRRS_ESTIMATE, scalar) buffer AdrrsEstimateBuffer { vec4 adrrs_estimates[]; };
layout(set = 0, binding = BINDING_ADRRS_QUEUE, scalar) buffer AdrrsQueueBuffer {
    uint adrrs_active_count;  // pixels of this dispatch with queued splits
    uint adrrs_pad0, adrrs_pad1, adrrs_pad2;
    // [2 local]: entries, [2 local + 1]: copies queued so far; [2 P + i]: the i-th active pixel
    uint adrrs_words[];
};
layout(set = 0, binding = BINDING_ADRRS_SPLITS, scalar) buffer AdrrsSplitBuffer { AdrrsSplit adrrs_splits[]; };
layout(set = 0, binding = BINDING_ADRRS_ADJOINT, scalar) readonly buffer AdrrsAdjointBuffer { vec4 adrrs_adjoint[]; };

// The cached indirect irradiance around (p, n) from the adjoint grid; false where no entry
// reached the cell (no adjoint: no decision).
bool adrrs_adjoint_irradiance(vec3 p, vec3 n, out vec3 irradiance) {
    irradiance = vec3(0.0);
    if (!(tech.adrrs.grid_cell > 0.0)) return false;
    ivec3 c = ivec3(floor((p - tech.adrrs.grid_min) / tech.adrrs.grid_cell));
    uvec3 dims = uvec3(tech.adrrs.grid_nx, tech.adrrs.grid_ny, tech.adrrs.grid_nz);
    if (any(lessThan(c, ivec3(0))) || any(greaterThanEqual(uvec3(c), dims))) return false;
    vec3 a = abs(n);
    uint axis = a.x >= a.y && a.x >= a.z ? 0u : a.y >= a.z ? 1u : 2u;
    uint dir = 2u * axis + (n[axis] < 0.0 ? 1u : 0u);
    vec4 v = adrrs_adjoint[((uint(c.z) * dims.y + uint(c.y)) * dims.x + uint(c.x)) * 6u + dir];
    if (!(v.w > 0.0)) return false;
    irradiance = v.rgb;
    return true;
}

// The pixel estimate I~ (rgb) and whether there is one yet.
bool adrrs_pixel_estimate(uint pixel_index, out vec3 estimate) {
    vec4 e = adrrs_estimates[pixel_index];
    estimate = e.w > 0.0 ? e.rgb / e.w : vec3(0.0);
    float l = luminance(estimate);
    return e.w > 0.0 && l > 1e-8 && !isinf(l);
}

// q for a path of throughput v at a vertex of directional albedo rho and cached irradiance E,
// in a pixel of estimate luminance I~: < 1 roulette, > 1 split, 1 inside the window.
float adrrs_factor(vec3 throughput, vec3 albedo, vec3 irradiance, float estimate) {
    float r = luminance(throughput * albedo * irradiance) * INV_PI / estimate;  // v / C
    return adrrs_window_factor(r, tech.adrrs.window, tech.adrrs.rr_min, tech.adrrs.splitting != 0u);
}

// Copies pixel `local` may still queue in this dispatch of `samples` samples per pixel.
uint adrrs_copies_left(uint local, uint samples) {
    if (adrrs_words[2u * local] >= tech.adrrs.slots) return 0u;  // no queue entry left
    uint budget = tech.adrrs.max_splits * samples, queued = adrrs_words[2u * local + 1u];
    return budget - min(queued, budget);
}

uint adrrs_copies_queued(uint local) { return adrrs_words[2u * local + 1u]; }

// Queues `split` for pixel `local` of this dispatch (P pixels). The caller checked
// adrrs_copies_left, so the pixel's slots never overflow.
void adrrs_queue(uint local, uint P, AdrrsSplit split) {
    uint entries = adrrs_words[2u * local];
    adrrs_splits[local * tech.adrrs.slots + entries] = split;
    adrrs_words[2u * local] = entries + 1u;
    adrrs_words[2u * local + 1u] += split.copies;
    if (entries == 0u) adrrs_words[2u * P + atomicAdd(adrrs_active_count, 1u)] = local;
}
#endif
