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
// floor(q) or floor(q)+1 with mean q), each weighted 1/q. A pixel sample splits off at most
// max_splits copies, its own and its copies' splits together: each split shares what is left
// of that budget among the path and its copies. Copies beyond the first go to a per-pixel
// queue (at most adrrs.slots entries per pixel and dispatch). The split dispatch
// (FRAME_ADRRS_SPLITS) spreads the entries over its invocations: one traces an entry's copies
// and, depth first, the copies they split off, and writes their sums into the entry; the sums
// dispatch (FRAME_ADRRS_SPLIT_SUMS) adds a pixel's entries to its film in queue order, so the
// image does not depend on which invocation traced what. An entry holds at most one sample's
// budget of copies, so no pixel's splits hold up the whole dispatch.

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
    // [local]: the pixel's entries; [P + i]: the i-th active pixel
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

// The j-th of n paths' share of `budget` copies: an even split, the remainder to the first.
uint adrrs_budget_share(uint budget, uint n, uint j) { return budget / n + (j < budget % n ? 1u : 0u); }

// EARS' statistics and factors (it shares the estimate and the queue above).
#include "ears.glsl"

#ifdef PX_TRACE_LOOP
// ---- hooks of the trace loop (lib/integrator.glsl, techniques.glsl) ----------------------

// Whether ADRRS' adjoint rho/pi E describes what the continuation brings: near-Lambertian
// lobes only (thesis eq. 4.1's directionally uniform f_BSDF). At a glossy vertex the
// BSDF-sampled continuation also carries its MIS share of the direct light, which the
// cache's indirect E lacks: there ADRRS ended most paths at the rr_min floor (Veach MIS: 3.7x
// MIS' relMSE at equal time), and the throughput roulette decides instead.
bool adrrs_lambertian(Surface surf, float roughness) {
    return surf.type == MATERIAL_DIFFUSE || (surf.type == MATERIAL_PRINCIPLED && roughness >= ADRRS_MIN_ROUGHNESS);
}

// A path's use of ADRRS.
struct AdrrsOptions {
    bool on;                // roulette and split by the adjoint (needs a pixel estimate)
    bool first_vertex_only; // estimate frame: end after the first non-delta vertex's emission, NEE and cache
    float estimate;         // luminance of the pixel estimate I~
    uint local;             // the pixel's slot in this dispatch's split queue
    uint pixels;            // pixels of this dispatch
    uint budget;            // copies the path may still split off
    bool split_copy;        // a copy of the split dispatch: its splits go to the invocation's stack
    bool half_sample;       // the sample belongs to adaptive sampling's half buffer: so do its copies
};

AdrrsOptions adrrs_no_options() { return AdrrsOptions(false, false, 0.0, 0u, 0u, 0u, false, false); }

// The split dispatch's entries still to trace in this invocation (trace_split_entry): a copy's
// own splits wait here, at most ADRRS_STACK of them.
const uint ADRRS_STACK = 4u;
AdrrsSplit adrrs_stack[ADRRS_STACK];
uint adrrs_stack_size = 0u;

// Copies the path may split off now: its budget, while there is room to queue them.
uint adrrs_copies_left(AdrrsOptions o) {
    bool room = o.split_copy ? adrrs_stack_size < ADRRS_STACK : adrrs_words[o.local] < tech.adrrs.slots;
    return room ? o.budget : 0u;
}

// Queues `split` for the pixel's split dispatch (a camera path), or for this invocation (a copy).
// The caller checked adrrs_copies_left, so neither overflows.
void adrrs_queue(AdrrsOptions o, AdrrsSplit split) {
    if (o.split_copy) {
        adrrs_stack[adrrs_stack_size++] = split;
        return;
    }
    uint entries = adrrs_words[o.local];
    adrrs_splits[o.local * tech.adrrs.slots + entries] = split;
    adrrs_words[o.local] = entries + 1u;
    if (entries == 0u) adrrs_words[o.pixels + atomicAdd(adrrs_active_count, 1u)] = o.local;
}

// FRAME_ADRRS_ESTIMATE: camera paths to the first non-delta vertex build the pixel estimate.
bool adrrs_estimate_frame() { return USES(TECH_ADRRS) && params.mode == FRAME_ADRRS_ESTIMATE; }
// FRAME_ADRRS_SPLITS: the dispatch traces the split queue's entries (adrrs_split_*);
// FRAME_ADRRS_SPLIT_SUMS: it adds them to the film.
bool adrrs_split_frame() { return USES(TECH_ADRRS) && params.mode == FRAME_ADRRS_SPLITS; }
bool adrrs_split_sums_frame() { return USES(TECH_ADRRS) && params.mode == FRAME_ADRRS_SPLIT_SUMS; }

// The ADRRS pass of a pixel: its estimate (rgb) while rendering.
struct AdrrsPixel {
    vec3 estimate;
};

// Camera paths of pixel `local` of this dispatch (P pixels); render frames read the pixel's
// estimate and empty its split queue.
AdrrsOptions adrrs_camera_options(uint pixel_index, uint local, uint P, out AdrrsPixel px) {
    AdrrsOptions o = adrrs_no_options();
    o.first_vertex_only = adrrs_estimate_frame();
    px.estimate = vec3(0.0);
    if (USES(TECH_ADRRS) && params.mode == FRAME_RENDER) {
        o.on = adrrs_pixel_estimate(pixel_index, px.estimate);
        o.estimate = luminance(px.estimate);
        o.local = local;
        o.pixels = P;
        adrrs_words[local] = 0u;  // this dispatch's queue of the pixel starts empty
    }
    return o;
}

// Each pixel sample starts with the whole split budget.
void adrrs_sample_options(inout AdrrsOptions o, bool half_sample) {
    o.budget = tech.adrrs.max_splits;
    o.half_sample = half_sample;
}

// Estimate frames sum the pixel's radiance into the estimate; true: the film is left alone.
bool adrrs_frame_output(vec3 sum_radiance, uint pixel_index) {
    if (!adrrs_estimate_frame()) return false;
    adrrs_estimates[pixel_index] += vec4(sum_radiance, float(params.sample_count));
    return true;
}

void adrrs_write_passes(AdrrsPixel px, uint pixel_index) {
    if (USES(TECH_ADRRS)) film_add(PASS_ADRRS_ESTIMATE, pixel_index, vec4(px.estimate * float(params.sample_count), 0.0));
}

// The vertex's cached indirect irradiance from the adjoint alone, where the cache itself was
// not queried (ic_vertex left the vertex).
void adrrs_vertex_adjoint(AdrrsOptions o, Surface surf, bool delta, vec3 p, vec3 n, bool resumed,
                          inout bool found, inout vec3 irradiance) {
    bool ic_surface = surf.type == MATERIAL_DIFFUSE || !delta;
    if (USES(TECH_ADRRS) && ic_surface && !resumed && o.on)
        found = adrrs_adjoint_irradiance(p, n, irradiance);  // the adjoint alone
}

// ADRRS on the continuation of a non-delta vertex v, whose cached (or adjoint) irradiance is
// ic's: roulette or split by the adjoint. The split copies start on the segment that reached
// the vertex (ps' origin, dir, t_min, t_max). Returns whether ADRRS decided (the throughput
// roulette then stands aside); `killed`: the path ends. With EARS (ears.glsl) q comes from its
// statistics instead; `ears_slot` is where the path records the decision for them (ears_open;
// NO_INDEX: nowhere), `ears_pass` sums its factors for the RRS passes. A split copy's first
// vertex (`resumed`) is the one it was split at: it does not decide again. A split spends the
// path's budget (o.budget) on its copies and shares the rest among them and the path.
bool adrrs_continuation(inout AdrrsOptions o, IcVertex ic, Vertex v, bool resumed, inout PathState ps, uint segments,
                        bool camera_segment, inout Rng rng, out bool killed, out uint ears_slot, inout vec4 ears_pass) {
    killed = false;
    ears_slot = NO_INDEX;
    if (!(USES(TECH_ADRRS) && o.on && !v.delta) || resumed) return false;
    float q;
    bool decided;
    if (USES(TECH_EARS)) {
        decided = ears_factor(ps.throughput, v.sh.p, v.ns, o.estimate, ears_pass, q, ears_slot);
        if (tech.adrrs.splitting == 0u) q = min(q, 1.0);
    } else {
        decided = ic.found && adrrs_lambertian(v.surf, v.roughness);
        q = decided ? adrrs_factor(ps.throughput, v.surf.albedo, ic.irradiance, o.estimate) : 1.0;
    }
    if (!decided) return false;  // (EARS without statistics yet: the path learns, the roulette decides)
    if (q < 1.0) {
        if (rnd(rng) >= q) {
            killed = true;
            return true;
        }
        ps.throughput /= q;
        ps.roulette_throughput /= q;
    } else if (q > 1.0) {
        // Within the path's split budget: q is capped before the expected-value
        // split, so every copy's weight 1/q stays exact.
        q = min(q, 1.0 + float(adrrs_copies_left(o)));
        uint copies = adrrs_split_copies(q, rnd(rng));
        ps.throughput /= q;
        ps.roulette_throughput /= q;
        if (copies > 1u) {
            uint budget = o.budget - (copies - 1u);  // what the path and its copies share
            o.budget = adrrs_budget_share(budget, copies, 0u);
            // The path's kind counts (PathState.kind_bounces, 30 bits) ride above the flags.
            uint flags = (camera_segment ? ADRRS_SPLIT_CAMERA_RAY : 0u) | (o.half_sample ? ADRRS_SPLIT_HALF : 0u) |
                         (ps.kind_bounces << ADRRS_SPLIT_KIND_SHIFT);
            uint seed = uint(rnd(rng) * 4294967040.0) ^ (segments << 24);
            adrrs_queue(o, AdrrsSplit(ps.origin, ps.t_min, ps.dir, ps.t_max, ps.throughput, seed,
                                      ps.bounces | (ps.discrete << 16), copies - 1u, flags, segments,
                                      ps.self_instance, ps.self_primitive, ps.min_ray_pdf, budget, vec3(0.0), 0u, 0u));
        }
    }
    return true;
}

// ---- the split queue (FRAME_ADRRS_SPLITS, FRAME_ADRRS_SPLIT_SUMS) -------------------------
// The split dispatch's invocations take the queue's entries (active pixel i, entry k) in turns
// of P (trace_split_queue in raygen.rgen). Each writes its entry's sums; a
// copy that fails (a NaN, a lost path) adds nothing. The sums dispatch has one invocation per
// pixel with splits, which adds them up in queue order: one writer per pixel, so the film's
// sums stay deterministic.

// The i-th active pixel of this dispatch (P pixels), if there is one: its slot and its index.
bool adrrs_split_pixel(uint i, uint P, out uint local, out uint pixel_index) {
    local = 0u;
    pixel_index = 0u;
    if (i >= adrrs_active_count) return false;
    local = adrrs_words[P + i];
    // The pixel the camera dispatch traced at launch index `local` (through adaptive sampling's
    // active list where it has one).
    uvec2 pixel;
    if (!dispatch_pixel(uvec2(local % gl_LaunchSizeEXT.x, local / gl_LaunchSizeEXT.x), pixel)) return false;
    pixel_index = pixel.y * params.width + pixel.x;
    return true;
}

uint adrrs_split_entries(uint local) { return adrrs_words[local]; }
AdrrsSplit adrrs_split_entry(uint local, uint k) { return adrrs_splits[local * tech.adrrs.slots + k]; }

void adrrs_split_result(uint local, uint k, vec3 radiance, uint rays, uint paths) {
    uint e = local * tech.adrrs.slots + k;
    adrrs_splits[e].radiance = radiance;
    adrrs_splits[e].rays = rays;
    adrrs_splits[e].paths = paths;
}

// A copy's own ADRRS options: the pixel's estimate; its splits stay in the invocation.
AdrrsOptions adrrs_split_options(uint pixel_index, uint local, uint P) {
    AdrrsOptions o = adrrs_no_options();
    vec3 estimate;
    o.on = adrrs_pixel_estimate(pixel_index, estimate);
    o.estimate = luminance(estimate);
    o.local = local;
    o.pixels = P;
    o.split_copy = true;
    return o;
}

void adrrs_split_write(uint pixel_index, vec3 sum, uint rays, uint paths) {
    film_add(PASS_COMBINED, pixel_index, vec4(sum, 0.0));
    film_add(PASS_ADRRS_SPLITS, pixel_index, vec4(float(paths), 0.0, 0.0, 0.0));
    ray_count[pixel_index] += rays;
}
#endif
#endif
