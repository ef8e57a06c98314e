// Random numbers of one path sample: each draw (rnd: 1D, rnd2: 2D) takes the next "slot" of a
// shuffled, Owen-scrambled Sobol (0,2)-sequence (Burley 2020, "Practical Hash-based Owen
// Scrambling", JCGT 9(4)). A slot's samples of one pixel are points of one randomised net, so
// the pixel jitter, the first vertices' light and BSDF samples and so on are stratified over
// the pixel's samples (Cycles' Sobol-Burley); every slot has its own index shuffle and
// scrambles, seeded by the pixel and slot, so slots are independent ("padding"). A sample's
// numbers depend only on its pixel, seed and index within the pixel: deterministic on every
// device, and the same however samples are split into frames and dispatches.

// TEA, 16 rounds (Zafar et al. 2010): seeds from two words.
uint tea(uint v0, uint v1) {
    uint s0 = 0u;
    for (int n = 0; n < 16; n++) {
        s0 += 0x9e3779b9u;
        v0 += ((v1 << 4) + 0xa341316cu) ^ (v1 + s0) ^ ((v1 >> 5) + 0xc8013ea4u);
        v1 += ((v0 << 4) + 0xad90777du) ^ (v0 + s0) ^ ((v0 >> 5) + 0x7e95761eu);
    }
    return v0;
}

// A 32-bit integer hash (Wellons' "lowbias32").
uint hash_u32(uint x) {
    x ^= x >> 16;
    x *= 0x7feb352du;
    x ^= x >> 15;
    x *= 0x846ca68bu;
    x ^= x >> 16;
    return x;
}

// Laine-Karras permutation with Burley's constants (2020, sec. 3): bit k of the result
// depends on bits <= k of x only, so on bit-reversed values it is a nested uniform (Owen)
// scramble.
uint lk_permute(uint x, uint seed) {
    x += seed;
    x ^= x * 0x6c50b47cu;
    x ^= x * 0xb82f1e52u;
    x ^= x * 0xc7afe638u;
    x ^= x * 0x8d22f6e6u;
    return x;
}

// Sobol's second dimension, bit-reversed: the generator matrix is Pascal's triangle mod 2,
// whose blocks [[P, 0], [P, P]] make it five masked shifts.
uint sobol_dim1_reversed(uint i) {
    i ^= (i & 0xaaaaaaaau) >> 1;
    i ^= (i & 0xccccccccu) >> 2;
    i ^= (i & 0xf0f0f0f0u) >> 4;
    i ^= (i & 0xff00ff00u) >> 8;
    i ^= (i & 0xffff0000u) >> 16;
    return i;
}

struct Rng {
    uint seed;   // the pixel's (or stream's) scramble seed
    uint index;  // sample index within the pixel
    uint slot;   // next draw
};

// Sample `index` of a pixel; `stream` separates frame kinds (render, training, ...) and seeds.
Rng rng_pixel(uint pixel_index, uint stream, uint index) {
    return Rng(hash_u32(pixel_index ^ hash_u32(stream)), index, 0u);
}

// Sample `s` of this dispatch at a pixel (FrameParams, common.glsl): samples are numbered per
// pixel across frames and dispatch shares; the special frames (cache prepare, ADRRS estimate,
// guiding training) carry a flag in their frame number's high bits and have streams of their
// own (their mode).
Rng rng_frame_sample(uint pixel_index, uint s) {
    uint first = (params.frame & 0x0fffffffu) * params.samples_per_frame + params.sample_offset;
    return rng_pixel(pixel_index, params.seed * 0x9e3779b9u + params.mode, first + s);
}

// An independent uniform stream (one scrambled point per slot) from a seed.
Rng rng_stream(uint seed) { return Rng(hash_u32(seed ^ 0x5bd1e995u), 0u, 0u); }

// The next slot's scrambled Sobol point: the index is shuffled by an Owen scramble of its
// reversed bits, which keeps any aligned block of 2^m indices a (0,m,2)-net; then each
// coordinate is Owen-scrambled (Burley 2020, listing 3 with a 2D Sobol base).
uvec2 rng_slot(inout Rng r, bool two) {
    uint s = hash_u32(r.seed + r.slot * 0x9e3779b9u);
    r.slot++;
    uint i = bitfieldReverse(lk_permute(bitfieldReverse(r.index), s));
    uint x = bitfieldReverse(lk_permute(i, hash_u32(s ^ 0x68bc21ebu)));
    uint y = two ? bitfieldReverse(lk_permute(sobol_dim1_reversed(i), hash_u32(s ^ 0x02e5be93u))) : 0u;
    return uvec2(x, y);
}

// Floats in [0, 1) from the top 24 bits.
float rnd(inout Rng r) { return float(rng_slot(r, false).x >> 8) * (1.0 / 16777216.0); }

vec2 rnd2(inout Rng r) { return vec2(rng_slot(r, true) >> 8) * (1.0 / 16777216.0); }

// A 2D point and a 1D number (BSDF and light sampling: u.xy place the sample, u.z picks the lobe
// or light): two slots.
vec3 rnd3(inout Rng r) {
    vec2 xy = rnd2(r);
    return vec3(xy, rnd(r));
}
