// Efficiency-aware Russian roulette and splitting (Rath, Grittmann, Herholz, Weier & Slusallek
// 2022, "EARS"): the factor q of a path's continuation at a non-delta vertex x minimises
// variance x cost of the image. With the path's throughput v, the pixel estimate I, the second
// moment and cost of the continuation's estimate Lr(x) learnt per cell, and the image's cost
// and relative variance per sample:
//
//     q = v / sqrt(I^2 + eps^2) * sqrt(E[Lr^2] / C(x)) * sqrt(C_image / V_image)
//
// and, where the second moment says split, the variance Var[Lr] in place of E[Lr^2] (as their
// implementation does: split only where both agree). q < 1 is a roulette, q > 1 a
// split into q expected copies: the machinery of adrrs.glsl (pixel estimate, split queue), which
// this file only feeds with q. Any q keeps the estimate unbiased.
//
// Statistics: a path remembers its first EARS_PATH_VERTICES decisions (the cell, its throughput
// after the decision, its radiance and rays when the continuation started) and at its end
// records, per decision, Lr = (radiance gained since) / throughput and the rays traced since. The records
// are summed per cell of a hashed grid (rrs_grid cells along the scene's longest axis, times
// the 6 signed normal axes) in 64-bit fixed point, so the sums do not depend on the order the
// paths add them in. The host turns one iteration's sums into the factors the next one uses
// (native/src/techniques/ears.cpp).

layout(set = 0, binding = BINDING_EARS_CELLS, scalar) buffer EarsCellBuffer { EarsCell ears_cells[]; };
layout(set = 0, binding = BINDING_EARS_FACTORS, scalar) readonly buffer EarsFactorBuffer { EarsFactor ears_factors[]; };
layout(set = 0, binding = BINDING_EARS_PIXELS, scalar) buffer EarsPixelBuffer { EarsPixel ears_pixels[]; };
layout(set = 0, binding = BINDING_EARS_RECORDS, scalar) buffer EarsRecordBuffer { EarsRecord ears_records[]; };

bool ears_on() { return USES(TECH_EARS) && tech.adrrs.mode == RRS_EARS; }

// Adds x >= 0 to the 64-bit fixed-point sum (lo, hi), rounding stochastically with u: the high
// word takes x's multiples of 2^32 units, the low word the rest with its carry.
#define EARS_ADD_FIXED(LO, HI, X, U)                                                        \
    {                                                                                       \
        float ears_units_ = (X) * EARS_FIXED_SCALE + (U);                                   \
        uint ears_high_ = uint(ears_units_ * (1.0 / 4294967296.0));                         \
        uint ears_low_ = uint(min(ears_units_ - float(ears_high_) * 4294967296.0, 4294967040.0)); \
        if (ears_low_ != 0u) {                                                              \
            uint ears_old_ = atomicAdd(LO, ears_low_);                                      \
            if (ears_old_ + ears_low_ < ears_old_) ears_high_++;                            \
        }                                                                                   \
        if (ears_high_ != 0u) atomicAdd(HI, ears_high_);                                    \
    }

// The cell of (p, n): 1 + its packed coordinates and signed normal axis (0: outside the grid).
uint ears_key(vec3 p, vec3 n) {
    if (!(tech.adrrs.ears_cell > 0.0) || any(isnan(p)) || any(isinf(p))) return 0u;
    ivec3 c = ivec3(floor((p - tech.adrrs.ears_min) / tech.adrrs.ears_cell));
    uint grid = tech.adrrs.grid;
    if (any(lessThan(c, ivec3(0))) || any(greaterThanEqual(c, ivec3(int(grid))))) return 0u;
    vec3 a = abs(n);
    uint axis = a.x >= a.y && a.x >= a.z ? 0u : a.y >= a.z ? 1u : 2u;
    uint dir = 2u * axis + (n[axis] < 0.0 ? 1u : 0u);
    return 1u + ((uint(c.z) * grid + uint(c.y)) * grid + uint(c.x)) * 6u + dir;
}

// The slot holding `key` (claimed for it when `claim`), NO_INDEX where none is found within
// EARS_PROBES linear probes. Which slot a key gets depends on the order paths claim them; what
// a key's slot holds does not.
uint ears_slot(uint key, bool claim) {
    if (key == 0u) return NO_INDEX;
    uint mask = tech.adrrs.ears_slots - 1u;
    uint slot = hash_u32(key) & mask;
    for (uint i = 0u; i < EARS_PROBES; ++i, slot = (slot + 1u) & mask) {
        uint found = ears_cells[slot].key;
        if (found == key) return slot;
        if (found == 0u) {
            if (!claim) return NO_INDEX;
            found = atomicCompSwap(ears_cells[slot].key, 0u, key);
            if (found == 0u || found == key) return slot;
        }
    }
    return NO_INDEX;
}

#ifdef PX_TRACE_LOOP
// ---- hooks of the trace loop (lib/integrator.glsl via techniques.glsl, adrrs.glsl) ---------

// A path's open records: the decisions it survived, waiting for its end. trace_path keeps
// only their count; the records wait in the invocation's slots of BINDING_EARS_RECORDS (paths
// of one invocation follow each other), not in the path's state across its rays.
struct EarsPath {
    uint base;      // the invocation's first record (NO_INDEX: none)
    uint count;
    bool starting;  // the last record's continuation starts at the next segment
};

EarsPath ears_path() {
    EarsPath e;
    uint invocation = gl_LaunchIDEXT.y * gl_LaunchSizeEXT.x + gl_LaunchIDEXT.x;
    e.base = invocation < tech.adrrs.ears_threads ? invocation * EARS_PATH_VERTICES : NO_INDEX;
    e.count = 0u;
    e.starting = false;
    return e;
}

// EARS' factor for a path of throughput v at (p, n) in a pixel of estimate luminance I; false
// where the vertex's cell has no statistics yet (the throughput roulette decides). `slot`: the
// cell's slot for the path's record (NO_INDEX: none). `pass` sums the path's factors and
// counts them, and holds the learnt relative cost at its first decision (the RRS passes).
bool ears_factor(vec3 throughput, vec3 p, vec3 n, float estimate, inout vec4 pass, out float q, out uint slot) {
    q = 1.0;
    slot = NO_INDEX;
    if (!ears_on() || tech.adrrs.ears_learn == 0u) return false;
    slot = ears_slot(ears_key(p, n), true);
    if (slot == NO_INDEX || tech.adrrs.ears_active == 0u) return false;
    EarsFactor f = ears_factors[slot];
    if (!(f.second_moment > 0.0)) return false;
    float w = luminance(throughput) / sqrt(sqr(estimate) + sqr(EARS_EPSILON));
    float q_r = w * sqrt(f.second_moment) * tech.adrrs.ears_image_factor;
    float q_s = w * sqrt(f.variance) * tech.adrrs.ears_image_factor;
    // Roulette by the second moment; split only where the variance agrees (Rath et al.'s code).
    q = q_r > 1.0 ? max(q_s, 1.0) : q_r;
    q = max(q, tech.adrrs.rr_min);
    if (isnan(q)) q = 1.0;
    pass += vec4(q, 1.0, pass.y == 0.0 ? vec2(f.cost, 1.0) : vec2(0.0));
    return true;
}

// The path survived a decision at `slot` with throughput v (after 1/q): its record opens; the
// continuation starts with the next segment (ears_continuation_start).
void ears_open(inout EarsPath e, uint slot, vec3 throughput) {
    if (!ears_on() || slot == NO_INDEX || e.base == NO_INDEX || e.count >= EARS_PATH_VERTICES) return;
    ears_records[e.base + e.count].slot = slot;
    ears_records[e.base + e.count].throughput = luminance(throughput);
    e.count++;
    e.starting = true;
}

// Before the segment that starts a continuation (the vertex's own NEE is counted by then).
void ears_continuation_start(inout EarsPath e, vec3 radiance, uint rays) {
    if (!ears_on() || !e.starting) return;
    ears_records[e.base + e.count - 1u].radiance = luminance(radiance);
    ears_records[e.base + e.count - 1u].rays = rays;
    e.starting = false;
}

// The path ended with `radiance` after `rays`: each open record adds its Lr / S, (Lr / S)^2
// and cost to its cell's sums.
void ears_path_end(inout EarsPath e, vec3 radiance, uint rays, inout Rng rng) {
    if (!ears_on()) return;
    float total = luminance(radiance);
    if (isnan(total) || isinf(total)) return;
    uint n = e.starting ? e.count - 1u : e.count;  // a record whose continuation never started
    for (uint i = 0u; i < n; ++i) {
        EarsRecord r = ears_records[e.base + i];
        float lr = max(total - r.radiance, 0.0) / max(r.throughput, 1e-20) / tech.adrrs.ears_scale;
        lr = min(lr, sqrt(EARS_MAX_RECORD));
        uint s = r.slot;
        atomicAdd(ears_cells[s].count, 1u);
        EARS_ADD_FIXED(ears_cells[s].lr_lo, ears_cells[s].lr_hi, lr, rnd(rng));
        EARS_ADD_FIXED(ears_cells[s].lr2_lo, ears_cells[s].lr2_hi, lr * lr, rnd(rng));
        EARS_ADD_FIXED(ears_cells[s].cost_lo, ears_cells[s].cost_hi, float(rays - r.rays), 0.0);
    }
}

// The image's cost and relative variance per sample: a pixel's camera dispatch (n samples from
// its `first`, with `sum_odd` the radiance of its odd ones) adds its halves and its rays to
// its EarsPixel; its split dispatch adds its copies' radiance to the halves they belong to.
// One writer per pixel and dispatch: no atomics.
void ears_pixel_frame(uint pixel_index, vec3 sum, vec3 sum_odd, uint first, uint n, uint rays) {
    if (!ears_on() || tech.adrrs.ears_learn == 0u) return;
    uint odd = (first + n) / 2u - first / 2u;
    EarsPixel e = ears_pixels[pixel_index];
    e.odd_sum += luminance(sum_odd);
    e.even_sum += luminance(sum - sum_odd);
    e.odd_samples += odd;
    e.even_samples += n - odd;
    e.rays += rays;
    ears_pixels[pixel_index] = e;
}

void ears_split_frame(uint pixel_index, vec3 sum, vec3 sum_odd, uint rays) {
    if (!ears_on() || tech.adrrs.ears_learn == 0u) return;
    ears_pixels[pixel_index].odd_sum += luminance(sum_odd);
    ears_pixels[pixel_index].even_sum += luminance(sum - sum_odd);
    ears_pixels[pixel_index].rays += rays;
}
#endif
