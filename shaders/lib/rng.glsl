// Random numbers: a TEA hash (16 rounds, Zafar et al. 2010) seeds one PCG stream per pixel
// and frame, which that frame's samples then share; deterministic for a fixed seed and
// samples per frame on a given device.

uint tea(uint v0, uint v1) {
    uint s0 = 0u;
    for (int n = 0; n < 16; n++) {
        s0 += 0x9e3779b9u;
        v0 += ((v1 << 4) + 0xa341316cu) ^ (v1 + s0) ^ ((v1 >> 5) + 0xc8013ea4u);
        v1 += ((v0 << 4) + 0xad90777du) ^ (v0 + s0) ^ ((v0 >> 5) + 0x7e95761eu);
    }
    return v0;
}

// PCG-RXS-M-XS 32 (O'Neill 2014); returns a float in [0, 1).
float rnd(inout uint state) {
    state = state * 747796405u + 2891336453u;
    uint word = ((state >> ((state >> 28u) + 4u)) ^ state) * 277803737u;
    word = (word >> 22u) ^ word;
    return float(word >> 8) * (1.0 / 16777216.0);
}

vec2 rnd2(inout uint state) { return vec2(rnd(state), rnd(state)); }
