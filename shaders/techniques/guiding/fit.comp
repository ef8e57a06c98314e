#version 460
// Guiding mixtures trained on the device (issue 13; the thesis' future work): the frame's
// training samples are binned by region, lit before unlit, with a stable counting sort (COUNT,
// SCAN, SCATTER), POSITIONS sums their positions in parts, then one workgroup per region runs
// the host fit's algorithm (em.cpp, parallax.cpp; Ruppert, Herholz & Lensch 2020) on that
// batch's lit samples (an unlit sample adds nothing to the EM's sums, only to the counts):
// weighted stepwise EM with the previous statistics decayed, MAP priors on the weights and the
// mean cosine, split (chi^2 divergence and PCA) and merge (closed-form chi^2 of two lobes
// against one), parallax distances, and writes the GuidingRegion/GuidingLobe records the
// sampler reads, and learns the region's guiding probability (selection.h) on the batch.
// REFINE applies the host's adaptive refinement (device_fit.h) to the fit state. Every
// reduction has a fixed order (fixed per-thread sample ranges, then a fixed tree): no float
// atomics, so a fixed input gives the same mixtures from run to run. In float, where
// the host is double. Loops are [[dont_unroll]]: llvmpipe compiles the unrolled shader 4x
// slower (lavapipe's first dispatch).
#extension GL_GOOGLE_include_directive : require
#extension GL_EXT_scalar_block_layout : require
#extension GL_EXT_control_flow_attributes : require
#include "../../shared/types.h"
#include "../../shared/guiding_fit.h"

#define G GUIDING_FIT_GROUP
#define K_MAX GUIDING_MAX_COMPONENTS
layout(local_size_x = GUIDING_FIT_GROUP) in;

layout(push_constant, scalar) uniform PushBlock { GuidingFitPush pc; };
layout(set = 0, binding = GUIDING_FIT_BINDING_SAMPLES, scalar) readonly buffer Samples { GuidingSample samples[]; };
layout(set = 0, binding = GUIDING_FIT_BINDING_REGIONS, scalar) buffer Regions { GuidingRegion regions[]; };
layout(set = 0, binding = GUIDING_FIT_BINDING_LOBES, scalar) buffer Lobes { GuidingLobe lobes[]; };
layout(set = 0, binding = GUIDING_FIT_BINDING_STATE, scalar) buffer State { GuidingFitRegion states[]; };
layout(set = 0, binding = GUIDING_FIT_BINDING_STATE_LOBES, scalar) buffer StateLobes { GuidingFitLobe state_lobes[]; };
layout(set = 0, binding = GUIDING_FIT_BINDING_COUNTS, scalar) buffer Counts { uint counts[]; };
layout(set = 0, binding = GUIDING_FIT_BINDING_STARTS, scalar) buffer Starts { uint starts[]; };
layout(set = 0, binding = GUIDING_FIT_BINDING_SORTED, scalar) buffer Sorted { uint sorted_index[]; };
layout(set = 0, binding = GUIDING_FIT_BINDING_PENDING, scalar) buffer Pending { GuidingSample pending_samples[]; };
layout(set = 0, binding = GUIDING_FIT_BINDING_TALLY, scalar) buffer Tally { GuidingFitTally tally[]; };
layout(set = 0, binding = GUIDING_FIT_BINDING_SPLITS, scalar) readonly buffer Splits { GuidingFitSplit splits[]; };
layout(set = 0, binding = GUIDING_FIT_BINDING_SCAN_PARTIALS, scalar) buffer ScanPartials { uint scan_partials[]; };
layout(set = 0, binding = GUIDING_FIT_BINDING_POSITION_PARTS, scalar) buffer PositionParts { vec4 position_parts[]; };

const float PI = 3.14159265358979;
const float KAPPA_MIN = 1e-3;  // GUIDING_KAPPA_MIN, kKappaMin

// ---- counting sort -------------------------------------------------------------------------
// A sample's bin: 2 r for region r's lit samples (weight > 0: all the EM reads), 2 r + 1 for
// its unlit ones (only counted, and their positions averaged), 2 region_count when it is no
// sample (an empty slot, pdf 0) or is rejected as the host's add_samples rejects it. The host
// also looks up samples without a region from their position; the trace loop always sets one
// inside the scene's box.
uint bin_of(uint i) {
    GuidingSample s = samples[i];
    bool ok = s.pdf > 0.0 && !isinf(s.pdf) && !isnan(s.pdf) && s.weight >= 0.0 && !isinf(s.weight) &&
              !isnan(s.distance) && !any(isnan(s.position)) && !any(isinf(s.position));
    return ok && s.region < pc.region_count ? 2u * s.region + (s.weight > 0.0 ? 0u : 1u) : 2u * pc.region_count;
}

// COUNT: a thread per block counts its samples per bin (counts[] was zeroed by the host).
void pass_count() {
    uint b = gl_GlobalInvocationID.x;
    if (b >= pc.block_count) return;
    uint end = min(pc.sample_count, (b + 1u) * pc.block_size);
    [[dont_unroll]] for (uint i = b * pc.block_size; i < end; ++i) counts[bin_of(i) * pc.block_count + b] += 1u;
}

// The exclusive prefix sum of counts[0 .. (regions + 1) * blocks) in three passes over tiles
// of GUIDING_FIT_SCAN_TILE counts, a workgroup each (the classic reduce-then-scan, as surveyed
// by Merrill & Garland 2016): REDUCE, PARTIALS, APPLY. Integer sums are exact, so the order of
// the additions does not matter: the result is the serial scan's.
uint scan_total() { return (2u * pc.region_count + 1u) * pc.block_count; }

// SCAN_REDUCE: partials[tile] = the sum of the tile's counts (coalesced strided reads).
shared uint scan_part[G];
void pass_scan_reduce() {
    uint t = gl_LocalInvocationID.x, total = scan_total();
    uint lo = gl_WorkGroupID.x * GUIDING_FIT_SCAN_TILE, hi = min(total, lo + GUIDING_FIT_SCAN_TILE);
    uint sum = 0u;
    [[dont_unroll]] for (uint j = lo + t; j < hi; j += G) sum += counts[j];
    scan_part[t] = sum;
    [[dont_unroll]] for (uint s = G / 2u; s > 0u; s >>= 1u) {
        barrier();
        if (t < s) scan_part[t] += scan_part[t + s];
    }
    if (t == 0u) scan_partials[gl_WorkGroupID.x] = scan_part[0];
}

// Exclusive scan of scan_part[0 .. G) in place (Hillis & Steele 1986; log2 G steps); returns
// the sum of all G values.
uint scan_group() {
    uint t = gl_LocalInvocationID.x;
    barrier();
    uint own = scan_part[t];
    [[dont_unroll]] for (uint s = 1u; s < G; s <<= 1u) {
        uint add = t >= s ? scan_part[t - s] : 0u;
        barrier();
        scan_part[t] += add;
        barrier();
    }
    uint total = scan_part[G - 1u];
    barrier();
    scan_part[t] -= own;  // inclusive -> exclusive
    barrier();
    return total;
}

// SCAN_PARTIALS (one workgroup): partials[] becomes each tile's exclusive prefix; thread t
// owns a contiguous run of the tiles. starts[2 regions + 1] = the total.
void pass_scan_partials() {
    uint t = gl_LocalInvocationID.x;
    uint tiles = (scan_total() + GUIDING_FIT_SCAN_TILE - 1u) / GUIDING_FIT_SCAN_TILE;
    uint run_len = (tiles + G - 1u) / G;
    uint lo = min(tiles, t * run_len), hi = min(tiles, lo + run_len);
    uint sum = 0u;
    [[dont_unroll]] for (uint j = lo; j < hi; ++j) sum += scan_partials[j];
    scan_part[t] = sum;
    uint total = scan_group();
    uint run = scan_part[t];
    [[dont_unroll]] for (uint j = lo; j < hi; ++j) {
        uint c = scan_partials[j];
        scan_partials[j] = run;
        run += c;
    }
    if (t == 0u) starts[2u * pc.region_count + 1u] = total;
}

// SCAN_APPLY: each tile, staged in shared memory (coalesced), is scanned locally (thread t a
// run of GUIDING_FIT_SCAN_TILE / G entries) and offset by its prefix: counts[bin * blocks +
// block] becomes that (bin, block)'s first sorted slot and starts[bin] its block 0's.
shared uint scan_tile[GUIDING_FIT_SCAN_TILE];
void pass_scan_apply() {
    const uint R = GUIDING_FIT_SCAN_TILE / G;
    uint t = gl_LocalInvocationID.x, total = scan_total();
    uint lo = gl_WorkGroupID.x * GUIDING_FIT_SCAN_TILE, hi = min(total, lo + GUIDING_FIT_SCAN_TILE);
    [[dont_unroll]] for (uint j = lo + t; j < hi; j += G) scan_tile[j - lo] = counts[j];
    barrier();
    uint sum = 0u;
    [[dont_unroll]] for (uint k = t * R; k < t * R + R && lo + k < hi; ++k) sum += scan_tile[k];
    scan_part[t] = sum;
    scan_group();
    uint run = scan_partials[gl_WorkGroupID.x] + scan_part[t];
    [[dont_unroll]] for (uint k = t * R; k < t * R + R && lo + k < hi; ++k) {
        uint c = scan_tile[k];
        scan_tile[k] = run;
        run += c;
    }
    barrier();
    [[dont_unroll]] for (uint j = lo + t; j < hi; j += G) {
        counts[j] = scan_tile[j - lo];
        if (j % pc.block_count == 0u) starts[j / pc.block_count] = scan_tile[j - lo];
    }
}

void pass_scatter() {  // in sample order within a block, blocks in order: stable
    uint b = gl_GlobalInvocationID.x;
    if (b >= pc.block_count) return;
    uint end = min(pc.sample_count, (b + 1u) * pc.block_size);
    [[dont_unroll]] for (uint i = b * pc.block_size; i < end; ++i) {
        uint c = bin_of(i) * pc.block_count + b;
        sorted_index[counts[c]] = i;
        counts[c] += 1u;
    }
}

// ---- vMF helpers (vmm.cpp in float) ------------------------------------------------------
float expm1_(float x) { return abs(x) < 1e-2 ? x * (1.0 + x * (0.5 + x / 6.0)) : exp(x) - 1.0; }
float vmf_log_norm(float kappa) {
    if (kappa < KAPPA_MIN) return -log(4.0 * PI);
    return log(kappa) - log(2.0 * PI) - log(-expm1_(-2.0 * kappa));
}
// A3(kappa) = coth(kappa) - 1/kappa; its series below 0.5 (float cancels in coth - 1/kappa).
float mean_cosine(float k) {
    if (k < 0.5) {
        float k2 = k * k;
        return k * (1.0 / 3.0 - k2 * (1.0 / 45.0 - k2 * (2.0 / 945.0 - k2 / 4725.0)));
    }
    if (k > 20.0) return 1.0 - 1.0 / k;
    return 1.0 / tanh(k) - 1.0 / k;
}
float mean_cosine_derivative(float k) {
    if (k < 0.5) {
        float k2 = k * k;
        return 1.0 / 3.0 - k2 * (1.0 / 15.0 - k2 * (2.0 / 189.0 - k2 / 675.0));
    }
    if (k > 20.0) return 1.0 / (k * k);
    float s = sinh(k);
    return 1.0 / (k * k) - 1.0 / (s * s);
}
// The ML kappa for a mean cosine r (Banerjee et al. 2005's estimate refined by Newton's method).
float kappa_from_mean_cosine(float r) {
    if (!(r > 0.0)) return 0.0;
    if (r >= 0.95) return 1.0 / max(1.0 - r, 1e-30);
    float lo = 0.0, hi = 20.0;
    float k = min(r * (3.0 - r * r) / (1.0 - r * r), hi);
    [[dont_unroll]] for (int i = 0; i < 40; ++i) {
        float f = mean_cosine(k) - r;
        if (f > 0.0) hi = k; else lo = k;
        float next = k - f / mean_cosine_derivative(k);
        if (!(next > lo && next < hi)) next = 0.5 * (lo + hi);
        if (abs(next - k) <= 1e-6 * k) return next;
        k = next;
    }
    return k;
}
void make_basis(vec3 n, out vec3 t, out vec3 b) {  // Duff et al. 2017, as vmm.cpp
    float s = n.z >= 0.0 ? 1.0 : -1.0;
    float a = -1.0 / (s + n.z);
    float c = n.x * n.y * a;
    t = vec3(1.0 + s * n.x * n.x * a, s * c, -s * n.x);
    b = vec3(c, s + n.y * n.y * a, -n.y);
}
vec3 unpack_direction(uint packed) {  // GuidingSample.direction (octahedral snorm16 x 2)
    vec2 p = unpackSnorm2x16(packed);
    vec3 w = vec3(p, 1.0 - abs(p.x) - abs(p.y));
    if (w.z < 0.0) w.xy = (1.0 - abs(w.yx)) * vec2(w.x >= 0.0 ? 1.0 : -1.0, w.y >= 0.0 ? 1.0 : -1.0);
    return normalize(w);
}

// ---- one region's state, in shared memory ------------------------------------------------
// No function-local arrays: llvmpipe turns their dynamic indexing into branch ladders (slow
// to compile); per-sample and per-lobe values live in shared memory instead.
shared uint s_count;
shared vec3 s_pivot;
// The batch: s_pend samples kept from earlier frames (pending_samples[s_pend_base ..]), then
// this frame's lit ones (samples[sorted_index[s_lo ..]]); batch index j covers both.
shared uint s_pend, s_pend_base, s_lo;
shared float s_weight[K_MAX], s_kappa[K_MAX], s_distance[K_MAX];  // distance <= 0: infinite
shared vec3 s_mu[K_MAX];
// statistics: this fit's (previous + batch) and the previous batches' decayed
shared vec4 s_stat[K_MAX], s_prev[K_MAX];      // xyz: sum w g omega, w: sum w g
shared vec2 s_stat2[K_MAX], s_prev2[K_MAX];    // x: sum g, y: sum w g / d
// the mixture prepared for evaluation: log(pi_k C_k), kappa (0: uniform), mu
shared float e_logwc[K_MAX], e_kappa[K_MAX];
shared vec3 e_mu[K_MAX];
shared uint e_count;
// a chunk of G samples: direction, weight (0: none), term of the split divergence, and the
// responsibilities c_g[sample * K_MAX + lobe]
shared vec3 c_w[G];
shared float c_weight[G], c_inv_d[G], c_logv[G], c_term[G];
shared float c_g[G * K_MAX];
// reductions
shared vec4 red_a[G];
shared vec4 red_b[G];
shared float s_ll, s_mean_w, s_div[K_MAX];
shared uint s_order[K_MAX], s_order_count, s_splits;
shared float s_sel[GUIDING_SELECTION_CANDIDATES + 1];  // the batch's score per candidate, then its weight

// Tree sum of red_a/red_b over the workgroup (fixed order); the result is in [0].
void reduce2() {
    uint t = gl_LocalInvocationID.x;
    [[dont_unroll]] for (uint s = G / 2u; s > 0u; s >>= 1u) {
        barrier();
        if (t < s) {
            red_a[t] += red_a[t + s];
            red_b[t] += red_b[t + s];
        }
    }
    barrier();
}

// Per-lobe partial sums of the four quarters of the workgroup (thread t: lobe t % 16,
// samples of quarter t / 16), summed in order into red_a/red_b[lobe].
void reduce_quarters(vec4 a, vec4 b) {
    uint t = gl_LocalInvocationID.x;
    barrier();
    red_a[t] = a;
    red_b[t] = b;
    barrier();
    vec4 sa = vec4(0.0), sb = vec4(0.0);
    if (t < K_MAX) {
        [[dont_unroll]] for (uint q = 0u; q < G / K_MAX; ++q) {
            sa += red_a[t + q * K_MAX];
            sb += red_b[t + q * K_MAX];
        }
    }
    barrier();
    if (t < K_MAX) {
        red_a[t] = sa;
        red_b[t] = sb;
    }
    barrier();
}

// Sample j of the batch seen from the pivot (parallax.cpp make_batch): with parallax its
// direction is normalize(x + d w - pivot) and its distance |x + d w - pivot|.
// (Member by member: the two blocks' GuidingSample are different SPIR-V types.)
GuidingSample batch_sample(uint j) {
    if (j < s_pend) {
        uint i = s_pend_base + j;
        return GuidingSample(pending_samples[i].position, pending_samples[i].region, pending_samples[i].direction,
                             pending_samples[i].pdf, pending_samples[i].weight, pending_samples[i].distance,
                             pending_samples[i].bsdf_pdf, pending_samples[i].contribution,
                             pending_samples[i].nee_light, 0u);
    }
    return samples[sorted_index[s_lo + j - s_pend]];
}

void load_sample(uint j, out vec3 w, out float weight, out float pdf, out float inv_d) {
    GuidingSample g = batch_sample(j);
    w = unpack_direction(g.direction);
    weight = g.weight;
    pdf = g.pdf;
    inv_d = 0.0;
    if (g.distance >= 0.0 && g.distance < GUIDING_DISTANCE_INFINITE) {
        float d = g.distance;
        inv_d = 1.0 / max(d, 1e-30);
        if (pc.parallax != 0u) {
            vec3 to = g.position + w * d - s_pivot;
            float len = length(to);
            if (len > 1e-6 * (d + length(g.position - s_pivot))) {
                w = to / len;
                inv_d = 1.0 / len;
            }
        }
    }
}

void prepare_lobes() {  // em.cpp Lobes: thread k prepares lobe k
    uint k = gl_LocalInvocationID.x;
    barrier();
    if (k == 0u) e_count = s_count;
    if (k < s_count) {
        bool uniform_lobe = s_kappa[k] < KAPPA_MIN;
        e_logwc[k] = s_weight[k] > 0.0 ? log(s_weight[k]) + vmf_log_norm(s_kappa[k]) : -1e30;
        e_kappa[k] = uniform_lobe ? 0.0 : s_kappa[k];
        e_mu[k] = s_mu[k];
    }
    barrier();
}

// Loads the chunk of samples [j0, j0 + G) of the batch (ending at hi) and each one's
// responsibilities under the prepared lobes (log-sum-exp; em.cpp responsibilities), and the
// split divergence's term f^2 / (V q) - 2 f / q with f = w q / mean weight.
void load_chunk(uint j0, uint hi) {
    uint t = gl_LocalInvocationID.x;
    uint n = e_count;
    uint j = j0 + t;
    vec3 w = vec3(0.0, 0.0, 1.0);
    float weight = 0.0, pdf = 1.0, inv_d = 0.0;
    if (j < hi) load_sample(j, w, weight, pdf, inv_d);
    if (!(weight > 0.0)) weight = 0.0;
    uint base = t * K_MAX;
    float mx = -1e30;
    [[dont_unroll]] for (uint k = 0u; k < n; ++k) {
        vec3 d = e_mu[k] - w;
        float v = e_logwc[k] - 0.5 * e_kappa[k] * dot(d, d);
        c_g[base + k] = v;
        mx = max(mx, v);
    }
    float logv = -1e30;
    if (mx > -1e29) {
        float sum = 0.0;
        [[dont_unroll]] for (uint k = 0u; k < n; ++k) {
            float e = exp(c_g[base + k] - mx);
            c_g[base + k] = e;
            sum += e;
        }
        float inv = 1.0 / sum;
        [[dont_unroll]] for (uint k = 0u; k < n; ++k) c_g[base + k] *= inv;
        logv = mx + log(sum);
    } else {
        [[dont_unroll]] for (uint k = 0u; k < n; ++k) c_g[base + k] = 0.0;
    }
    float f = weight * pdf / s_mean_w;
    float term = f * f / (exp(logv) * pdf) - 2.0 * f / pdf;
    c_w[t] = w;
    c_weight[t] = weight;
    c_inv_d[t] = inv_d;
    c_logv[t] = logv;
    c_term[t] = weight > 0.0 && !isinf(term) && !isnan(term) ? term : 0.0;
    barrier();
}

// MAP direction and concentration of statistics worth n effective samples (em.cpp).
void lobe_from_stats(vec4 st, float n, inout vec3 mu, out float kappa) {
    float rl = length(st.xyz);
    if (rl > 0.0) mu = st.xyz / rl;
    float r = st.w > 0.0 ? min(rl / st.w, 1.0) : 0.0;
    float a = pc.mean_cosine_prior_strength;
    r = n + a > 0.0 ? (r * n + pc.mean_cosine_prior * a) / (n + a) : pc.mean_cosine_prior;
    r = min(r, mean_cosine(pc.kappa_max));
    kappa = min(kappa_from_mean_cosine(r), pc.kappa_max);
}

void stat_sums(out float W, out float N) {  // the same order on every thread
    W = 0.0;
    N = 0.0;
    [[dont_unroll]] for (uint k = 0u; k < s_count; ++k) {
        W += s_stat[k].w;
        N += s_stat2[k].x;
    }
}

// M-step (em.cpp m_step) of every lobe from s_stat: thread k does lobe k.
void m_step() {
    uint k = gl_LocalInvocationID.x;
    barrier();
    float W, N;
    stat_sums(W, N);
    if (W > 0.0 && k < s_count) {
        vec4 st = s_stat[k];
        float n = N * st.w / W;
        s_weight[k] = (n + pc.weight_prior) / (N + float(s_count) * pc.weight_prior);
        vec3 mu = s_mu[k];
        float kappa;
        lobe_from_stats(st, n, mu, kappa);
        s_mu[k] = mu;
        s_kappa[k] = kappa;
        s_distance[k] = s_stat2[k].y > 0.0 ? st.w / s_stat2[k].y : -1.0;  // harmonic mean
    }
    barrier();
}

// EM iterations on the batch [lo, hi) with s_prev; s_stat = s_prev + this batch's (em.cpp run_em).
uint run_em(uint lo, uint hi) {
    uint t = gl_LocalInvocationID.x;
    uint k = t % K_MAX, q = t / K_MAX;
    float prev_ll = 0.0;
    uint it = 0u;
    while (it < pc.max_iterations) {
        prepare_lobes();
        uint n = e_count;
        vec4 a = vec4(0.0), b = vec4(0.0);  // sum w g omega, sum w g | sum g, sum w g / d, ll, wsum
        [[dont_unroll]] for (uint j0 = lo; j0 < hi; j0 += G) {
            load_chunk(j0, hi);
            [[dont_unroll]] for (uint i = q * K_MAX; i < (q + 1u) * K_MAX; ++i) {
                float wt = c_weight[i];
                if (!(wt > 0.0)) continue;
                if (k == 0u && c_logv[i] > -1e29) b.zw += vec2(wt * c_logv[i], wt);
                if (k < n) {
                    float gk = c_g[i * K_MAX + k], wg = wt * gk;
                    a += vec4(c_w[i] * wg, wg);
                    b.xy += vec2(gk, wg * c_inv_d[i]);
                }
            }
            barrier();
        }
        reduce_quarters(a, b);
        if (t == 0u) s_ll = red_b[0].w > 0.0 ? red_b[0].z / red_b[0].w : -1e30;
        if (t < n) {
            s_stat[t] = s_prev[t] + red_a[t];
            s_stat2[t] = s_prev2[t] + red_b[t].xy;
        }
        m_step();
        float cur = s_ll;
        ++it;
        if (it > 1u && abs(cur - prev_ll) <= pc.tolerance * abs(prev_ll)) break;
        prev_ll = cur;
    }
    return it;
}

// Splits (em.cpp split_components): each lobe's chi^2 divergence between the batch's
// radiance and the mixture, then a PCA split of the worst lobes, largest divergence first.
uint split_lobes(uint lo, uint hi, float total_samples) {
    uint t = gl_LocalInvocationID.x;
    uint kk = t % K_MAX, q = t / K_MAX;
    // the batch's mean weight, zero-weight samples included
    float wsum = 0.0;
    [[dont_unroll]] for (uint j = lo + t; j < hi; j += G) {
        float weight = batch_sample(j).weight;
        if (weight > 0.0) wsum += weight;
    }
    barrier();
    red_a[t] = vec4(wsum, 0.0, 0.0, 0.0);
    red_b[t] = vec4(0.0);
    reduce2();
    wsum = red_a[0].x;
    float n_all = max(total_samples, 1.0);
    if (!(wsum > 0.0)) return 0u;
    if (t == 0u) s_mean_w = wsum / n_all;
    prepare_lobes();  // the mixture before any split: responsibilities refer to it
    uint n = e_count;
    float d = 0.0;
    [[dont_unroll]] for (uint j0 = lo; j0 < hi; j0 += G) {
        load_chunk(j0, hi);
        if (kk < n)
            [[dont_unroll]] for (uint i = q * K_MAX; i < (q + 1u) * K_MAX; ++i) d += c_g[i * K_MAX + kk] * c_term[i];
        barrier();
    }
    reduce_quarters(vec4(d, 0.0, 0.0, 0.0), vec4(0.0));
    if (t < n) s_div[t] = red_a[t].x / n_all + s_weight[t];
    barrier();
    if (t == 0u) {  // candidates by divergence, descending (stable)
        float W, N;
        stat_sums(W, N);
        uint c = 0u;
        [[dont_unroll]] for (uint k = 0u; k < n; ++k) {
            if (!(W > 0.0) || !(s_div[k] >= pc.split_threshold) || !(N * s_stat[k].w / W > pc.split_min_samples))
                continue;
            uint p = c++;
            while (p > 0u && s_div[s_order[p - 1u]] < s_div[k]) {
                s_order[p] = s_order[p - 1u];
                --p;
            }
            s_order[p] = k;
        }
        s_order_count = c;
        s_splits = 0u;
    }
    barrier();
    uint candidates = s_order_count;
    [[dont_unroll]] for (uint c = 0u; c < candidates; ++c) {
        if (s_count >= pc.max_components) break;
        uint k = s_order[c];
        vec3 tb, bb;
        make_basis(s_mu[k], tb, bb);
        // PCA of lobe k's samples in the tangent plane of its mean
        vec4 a = vec4(0.0), b = vec4(0.0);  // sw, mx, my, sxx | sxy, syy
        [[dont_unroll]] for (uint j0 = lo; j0 < hi; j0 += G) {
            load_chunk(j0, hi);
            float w = c_weight[t] * c_g[t * K_MAX + k];
            if (w > 0.0) {
                float x = dot(c_w[t], tb), y = dot(c_w[t], bb);
                a += vec4(w, w * x, w * y, w * x * x);
                b += vec4(w * x * y, w * y * y, 0.0, 0.0);
            }
            barrier();
        }
        red_a[t] = a;
        red_b[t] = b;
        reduce2();
        if (t == 0u) {
            float sw = red_a[0].x;
            if (sw > 0.0) {
                float mx = red_a[0].y / sw, my = red_a[0].z / sw;
                float cxx = red_a[0].w / sw - mx * mx, cxy = red_b[0].x / sw - mx * my, cyy = red_b[0].y / sw - my * my;
                float half_ = 0.5 * (cxx + cyy), diff = 0.5 * (cxx - cyy);
                float lambda = half_ + sqrt(diff * diff + cxy * cxy);
                if (lambda > 0.0) {
                    float ex = 1.0, ey = 0.0;
                    if (abs(cxy) > 1e-30) {
                        ex = lambda - cyy;
                        ey = cxy;
                    } else if (cyy > cxx) {
                        ex = 0.0;
                        ey = 1.0;
                    }
                    float el = sqrt(ex * ex + ey * ey);
                    vec3 centre = s_mu[k] + tb * mx + bb * my;
                    vec3 offset = (tb * ex + bb * ey) * (sqrt(lambda) / el);
                    uint j = s_count++;
                    s_mu[j] = normalize(centre - offset);
                    s_mu[k] = normalize(centre + offset);
                    s_kappa[j] = s_kappa[k];
                    s_weight[k] *= 0.5;
                    s_weight[j] = s_weight[k];
                    s_distance[j] = s_distance[k];
                    // the lobe's history goes half to each child, along the child's direction
                    float r = 0.5 * length(s_prev[k].xyz);
                    s_prev[k].w *= 0.5;
                    s_prev2[k] *= 0.5;
                    s_prev[j] = vec4(s_mu[j] * r, s_prev[k].w);
                    s_prev2[j] = s_prev2[k];
                    s_prev[k].xyz = s_mu[k] * r;
                    r = 0.5 * length(s_stat[k].xyz);
                    s_stat[k].w *= 0.5;
                    s_stat2[k] *= 0.5;
                    s_stat[j] = vec4(s_mu[j] * r, s_stat[k].w);
                    s_stat2[j] = s_stat2[k];
                    s_stat[k].xyz = s_mu[k] * r;
                    ++s_splits;
                }
            }
        }
        barrier();
    }
    return s_splits;
}

// log of the integral of v_i v_j / v_m over the sphere, in closed form (em.cpp log_cross).
float log_cross(vec3 mi, float ki, vec3 mj, float kj, vec3 mm, float km) {
    ki = ki < KAPPA_MIN ? 0.0 : ki;
    kj = kj < KAPPA_MIN ? 0.0 : kj;
    km = km < KAPPA_MIN ? 0.0 : km;
    vec3 eta = mi * ki + mj * kj - mm * km;
    float h = length(eta);
    float c = ki + kj - km;
    float log_int = log(2.0 * PI) + h + (h > 1e-6 ? log(-expm1_(-2.0 * h) / h) : log(2.0));
    return vmf_log_norm(ki) + vmf_log_norm(kj) - vmf_log_norm(km) - c + log_int;
}

float merge_metric(uint k, uint l, vec3 mmu, float mkappa) {
    float wk = s_weight[k], wl = s_weight[l];
    if (!(wk + wl > 0.0)) return 0.0;
    float ak = wk / (wk + wl), al = wl / (wk + wl);
    vec3 mk = s_mu[k], ml = s_mu[l];
    float kk = s_kappa[k], kl = s_kappa[l];
    float sum = ak * ak * exp(min(log_cross(mk, kk, mk, kk, mmu, mkappa), 80.0)) +
                2.0 * ak * al * exp(min(log_cross(mk, kk, ml, kl, mmu, mkappa), 80.0)) +
                al * al * exp(min(log_cross(ml, kl, ml, kl, mmu, mkappa), 80.0));
    return max(sum - 1.0, 0.0);
}

// Merges pairs while the best pair's metric is below the threshold (em.cpp merge_components):
// the pairs' metrics in parallel, the best one (the first in (k, l) order) merged by thread 0.
shared float s_pair_metric[K_MAX * (K_MAX - 1u) / 2u];
shared uint s_best_pair;
shared bool s_merge_done;
uint merge_lobes() {
    uint t = gl_LocalInvocationID.x;
    uint merges = 0u;
    while (s_count > 1u) {
        float W, N;
        stat_sums(W, N);
        uint n = s_count;
        uint p = 0u;
        [[dont_unroll]] for (uint k = 0u; k < n; ++k)
            [[dont_unroll]] for (uint l = k + 1u; l < n; ++l, ++p) {
                if (p % G != t) continue;
                vec4 c = s_stat[k] + s_stat[l];
                vec3 mu = s_weight[k] >= s_weight[l] ? s_mu[k] : s_mu[l];
                float kappa;
                lobe_from_stats(c, W > 0.0 ? N * c.w / W : 0.0, mu, kappa);
                s_pair_metric[p] = merge_metric(k, l, mu, kappa);
            }
        barrier();
        if (t == 0u) {
            float best = 1e30;
            uint bk = 0u, bl = 0u;
            p = 0u;
            [[dont_unroll]] for (uint k = 0u; k < n; ++k)
                [[dont_unroll]] for (uint l = k + 1u; l < n; ++l, ++p)
                    if (s_pair_metric[p] < best) {
                        best = s_pair_metric[p];
                        bk = k;
                        bl = l;
                    }
            s_merge_done = !(best <= pc.merge_threshold);
            if (!s_merge_done) {  // statistics add up; lobe bl is replaced by the last one
                s_stat[bk] += s_stat[bl];
                s_stat2[bk] += s_stat2[bl];
                if (s_weight[bl] > s_weight[bk]) s_mu[bk] = s_mu[bl];
                uint last = n - 1u;
                s_stat[bl] = s_stat[last];
                s_stat2[bl] = s_stat2[last];
                s_stat[last] = vec4(0.0);
                s_stat2[last] = vec2(0.0);
                s_mu[bl] = s_mu[last];
                s_kappa[bl] = s_kappa[last];
                s_weight[bl] = s_weight[last];
                s_distance[bl] = s_distance[last];
                s_count = last;
            }
        }
        barrier();
        if (s_merge_done) break;
        m_step();
        ++merges;
    }
    barrier();
    return merges;
}

// ---- the learnt guiding probability (selection.h) -----------------------------------------
// Müller et al. 2019 learn the fraction of BSDF sampling by gradient descent; as in the host
// field, here a grid of candidates a_j = j / GUIDING_SELECTION_CANDIDATES is scored on the training
// records: S(a) += (C / p) log(a p_vmm(w) + (1 - a) p_bsdf(w)), the largest S wins.

// The prepared mixture's density at x of direction w, as the sampler evaluates it
// (guiding.glsl guiding_vmm_pdf: with parallax a lobe with a target aims at it from x).
float mixture_pdf(vec3 x, vec3 w) {
    float p = 0.0;
    [[dont_unroll]] for (uint k = 0u; k < e_count; ++k) {
        vec3 mu = e_mu[k];
        if (pc.parallax != 0u && s_distance[k] > 0.0) {
            vec3 to = s_pivot + s_mu[k] * s_distance[k] - x;
            float len2 = dot(to, to);
            if (len2 > 1e-12 * s_distance[k] * s_distance[k]) mu = to * inversesqrt(len2);
        }
        vec3 d = mu - w;
        p += exp(e_logwc[k] - 0.5 * e_kappa[k] * dot(d, d));
    }
    return p;
}

// The batch's sums (field.cpp learn_selection, SelectionStats::add) with the mixture just
// fitted, over its lit samples [0, hi), each at its own position and recorded direction (as
// the host field scores them). Thread t sums its samples t, t + G, ... into c_g[t K_MAX + j]
// (free after the EM; K_MAX > the candidates; j = the candidates: the weight), then thread j
// adds column j over the threads in order into s_sel[j]: a fixed order.
void score_selection(uint hi) {
    const uint C = GUIDING_SELECTION_CANDIDATES;
    uint t = gl_LocalInvocationID.x;
    prepare_lobes();
    uint base = t * K_MAX;
    [[dont_unroll]] for (uint j = 0u; j <= C; ++j) c_g[base + j] = 0.0;
    [[dont_unroll]] for (uint i = t; i < hi; i += G) {
        GuidingSample g = batch_sample(i);
        float c = g.contribution, p = g.pdf, pb = g.bsdf_pdf;  // pb 0: a delta lobe sampled it
        if (!(c > 0.0 && p > 0.0 && pb > 0.0) || isinf(c) || isinf(p) || isinf(pb)) continue;
        float pg = mixture_pdf(g.position, unpack_direction(g.direction));
        if (!(pg >= 0.0) || isinf(pg)) continue;
        float w = c / p;
        [[dont_unroll]] for (uint j = 0u; j < C; ++j) {
            float a = float(j) / float(C);
            c_g[base + j] += w * log(a * pg + (1.0 - a) * pb);
        }
        c_g[base + C] += w;
    }
    barrier();
    if (t <= C) {
        float m = 0.0;
        [[dont_unroll]] for (uint u = 0u; u < G; ++u) m += c_g[u * K_MAX + t];
        s_sel[t] = m;
    }
    barrier();
}

// Region r's probability from its sums (selection.cpp choose_selection): the candidate of
// largest score, 0 unless it gains log(1 + GUIDING_SELECTION_MARGIN) per unit of weight;
// guiding_prob while nothing was learnt or with adaptive_prob off. Writes the sampler's record
// and the sums the host's global rule reads (GuidingFitTally). Thread 0.
void write_selection(uint r) {
    const uint C = GUIDING_SELECTION_CANDIDATES;
    float n = states[r].selection_weight, m0 = states[r].selection_score[0];
    float prob = pc.prob, bsdf = 0.0, chosen = 0.0;
    if (pc.adaptive_prob != 0u && n > 0.0) {
        uint best = 0u;
        [[dont_unroll]] for (uint j = 1u; j < C; ++j)
            if (states[r].selection_score[j] > states[r].selection_score[best]) best = j;
        chosen = states[r].selection_score[best];
        if (!(chosen - m0 >= log(1.0 + GUIDING_SELECTION_MARGIN) * n)) {
            best = 0u;
            chosen = m0;
        }
        prob = float(best) / float(C);
        bsdf = m0;
    }
    regions[r].prob = prob;
    tally[r].prob = prob;
    regions[r].score_bsdf = n > 0.0 ? bsdf / n : 0.0;
    regions[r].score_chosen = n > 0.0 ? chosen / n : 0.0;
    tally[r].score_bsdf = bsdf;
    tally[r].score_chosen = chosen;
    tally[r].weight = n;
}

// The tally's counts (write_selection adds its sums). Thread 0.
void write_tally(uint r, GuidingFitRegion st) {
    tally[r].received = st.count != 0u ? st.received : 0u;
    tally[r].samples = st.samples;
    tally[r].fits = st.fits;
}

// POSITIONS: workgroup (r, part) sums the positions of one of position_parts equal parts of
// region r's samples, lit and unlit (a region's samples are many: one workgroup alone would
// walk them serially); EM adds the parts in order for the pivot.
void pass_positions() {
    uint r = gl_WorkGroupID.x / pc.position_parts, part = gl_WorkGroupID.x % pc.position_parts;
    uint t = gl_LocalInvocationID.x;
    if (r >= pc.region_count) return;
    uint lo = starts[2u * r], n = starts[2u * r + 2u] - lo, size = (n + pc.position_parts - 1u) / pc.position_parts;
    uint a = lo + min(n, part * size), b = lo + min(n, part * size + size);
    vec3 sum = vec3(0.0);
    [[dont_unroll]] for (uint j = a + t; j < b; j += G) sum += samples[sorted_index[j]].position;
    red_a[t] = vec4(sum, 0.0);
    red_b[t] = vec4(0.0);
    reduce2();
    if (t == 0u) position_parts[gl_WorkGroupID.x] = red_a[0];
}

void pass_em() {
    uint r = gl_WorkGroupID.x;
    uint t = gl_LocalInvocationID.x;
    if (r >= pc.region_count) return;
    // This frame's samples of the region: lit ones in [lo, mid), unlit ones in [mid, hi).
    uint lo = starts[2u * r], mid = starts[2u * r + 1u], hi = starts[2u * r + 2u];
    vec3 position_sum = vec3(0.0);  // of all of them
    [[dont_unroll]] for (uint p = 0u; p < pc.position_parts; ++p)
        position_sum += position_parts[r * pc.position_parts + p].xyz;
    GuidingFitRegion st = states[r];
    float batch_n = float(hi - lo);
    float nonzero = float(mid - lo);
    if (batch_n > 0.0) {  // running mean of the positions: the pivot (parallax.h)
        float total = st.position_count + batch_n;
        st.position_mean += (position_sum / batch_n - st.position_mean) * (batch_n / total);
        st.position_count = total;
        st.samples = uint(min(float(st.samples) + batch_n, 4294967040.0));
        st.received = uint(min(float(st.received) + nonzero, 4294967040.0));  // lit: refinement
    }
    // A region fits once it has min_samples lit samples, and more than 2K ("EM only when
    // N > 2K", em.cpp fit_batch); until then its lit samples wait in pending_samples across
    // frames (field.cpp: rarely lit regions train too).
    uint k0 = st.count != 0u ? st.count : min(pc.initial_components, pc.max_components);
    float lit = float(st.pending) + nonzero;
    bool fit = lit >= float(max(pc.min_samples, 2u * k0 + 1u));
    uint pend_base = r * pc.pending_capacity;
    if (!fit) {  // keep this frame's lit samples, in order, as many as fit
        uint p = st.pending, kept = min(mid - lo, pc.pending_capacity - p);
        [[dont_unroll]] for (uint j = t; j < kept; j += G) {
            uint i = sorted_index[lo + j];
            uint d = pend_base + p + j;
            pending_samples[d].position = samples[i].position;
            pending_samples[d].region = samples[i].region;
            pending_samples[d].direction = samples[i].direction;
            pending_samples[d].pdf = samples[i].pdf;
            pending_samples[d].weight = samples[i].weight;
            pending_samples[d].distance = samples[i].distance;
            pending_samples[d].bsdf_pdf = samples[i].bsdf_pdf;
            pending_samples[d].contribution = samples[i].contribution;
            pending_samples[d].nee_light = samples[i].nee_light;
        }
        barrier();  // every thread has read states[r] before it is written
        if (t == 0u) {
            st.pending = p + kept;
            st.pending_zero += batch_n - nonzero;
            states[r] = st;
            regions[r].samples = st.samples;
            write_tally(r, st);
            write_selection(r);  // guiding_prob until the region learnt its own
        }
        return;
    }
    float total_samples = st.pending_zero + float(st.pending) + batch_n;
    uint base = r * K_MAX;
    if (t == 0u) {
        s_count = st.count;
        s_pivot = st.position_mean;
        s_mean_w = 1.0;
        s_pend = st.pending;
        s_pend_base = pend_base;
        s_lo = lo;
    }
    if (t < K_MAX) {
        GuidingFitLobe l = state_lobes[base + t];
        s_mu[t] = l.mu;
        s_kappa[t] = l.kappa;
        s_weight[t] = l.weight;
        s_distance[t] = l.distance;
        s_stat[t] = vec4(l.stat_direction, l.stat_weight);
        s_stat2[t] = vec2(l.stat_count, l.stat_inv_distance);
    }
    barrier();
    uint n0 = s_count;
    if (n0 == 0u && t < k0) {  // a first fit: a Fibonacci sphere of lobes (em.cpp initialise)
        float golden = PI * (3.0 - sqrt(5.0));
        float z = 1.0 - (2.0 * float(t) + 1.0) / float(k0);
        float rr = sqrt(max(0.0, 1.0 - z * z));
        s_mu[t] = vec3(rr * cos(golden * float(t)), rr * sin(golden * float(t)), z);
        s_kappa[t] = pc.kappa0;
        s_weight[t] = 1.0 / float(k0);
        s_distance[t] = -1.0;
        s_stat[t] = vec4(0.0);
        s_stat2[t] = vec2(0.0);
    }
    // With parallax a lobe with a target keeps aiming at it from the moved pivot (move_pivot).
    if (n0 != 0u && pc.parallax != 0u && t < n0 && s_distance[t] > 0.0) {
        vec3 target = regions[r].pivot + s_mu[t] * s_distance[t];
        vec3 to = target - s_pivot;
        float len = length(to);
        if (len > 1e-6 * s_distance[t]) {
            s_mu[t] = to / len;
            s_distance[t] = len;
            s_stat[t].xyz = s_mu[t] * length(s_stat[t].xyz);
            s_stat2[t].y = s_stat[t].w / len;
        }
    }
    barrier();
    if (t == 0u && n0 == 0u) s_count = k0;
    if (t < K_MAX) {  // previous statistics, decayed
        s_prev[t] = s_stat[t] * pc.decay;
        s_prev2[t] = s_stat2[t] * pc.decay;
    }
    barrier();
    uint batch_end = st.pending + (mid - lo);  // batch indices [0, batch_end): the lit samples
    uint iterations = run_em(0u, batch_end);
    st.new_samples += lit;
    st.pending = 0u;
    st.pending_zero = 0.0;
    uint splits = 0u, merges = 0u;
    if (pc.split_merge != 0u) {
        splits = split_lobes(0u, batch_end, total_samples);
        if (splits != 0u) iterations += run_em(0u, batch_end);
        if (st.new_samples > pc.merge_min_samples) {
            merges = merge_lobes();
            st.new_samples = 0.0;
        }
    }
    barrier();
    uint n = s_count;
    if (pc.adaptive_prob != 0u) score_selection(batch_end);
    // Records: the fit state and what the sampler reads (vmm.cpp write_gpu_lobes).
    if (t < K_MAX) {
        GuidingFitLobe l;
        bool on = t < n;
        l.mu = on ? s_mu[t] : vec3(0.0);
        l.kappa = on ? s_kappa[t] : 0.0;
        l.weight = on ? s_weight[t] : 0.0;
        l.distance = on ? s_distance[t] : -1.0;
        l.stat_direction = on ? s_stat[t].xyz : vec3(0.0);
        l.stat_weight = on ? s_stat[t].w : 0.0;
        l.stat_count = on ? s_stat2[t].x : 0.0;
        l.stat_inv_distance = on ? s_stat2[t].y : 0.0;
        state_lobes[base + t] = l;
        GuidingLobe g;
        g.mu = l.mu;
        g.target = vec3(0.0);
        g.distance = -1.0;
        if (on) {
            float total = 0.0, cdf = 0.0;
            [[dont_unroll]] for (uint k = 0u; k < n; ++k) {
                total += s_weight[k];
                if (k <= t) cdf += s_weight[k];
            }
            bool uniform_lobe = l.kappa < KAPPA_MIN;
            g.kappa = uniform_lobe ? 0.0 : l.kappa;
            g.weight = l.weight;
            g.norm = exp(vmf_log_norm(l.kappa));
            g.exp_m2k = uniform_lobe ? 1.0 : exp(-2.0 * l.kappa);
            if (pc.parallax != 0u && l.distance > 0.0) {
                g.distance = l.distance;
                g.target = s_pivot + l.mu * l.distance;
            }
            g.cdf = t + 1u == n ? 1.0 : cdf / total;
        } else {
            g.kappa = 0.0;
            g.weight = 0.0;
            g.norm = 0.0;
            g.exp_m2k = 0.0;
            g.distance = 0.0;
            g.cdf = 0.0;
        }
        lobes[base + t] = g;
    }
    if (t == 0u) {
        st.count = n;
        st.fits += 1u;
        st.iterations = iterations;
        st.splits = splits;
        st.merges = merges;
        st.log_likelihood = s_ll;
        states[r] = st;
        regions[r].lobe_count = n;
        regions[r].fits = st.fits;
        regions[r].pivot = s_pivot;
        regions[r].samples = st.samples;
        if (pc.adaptive_prob != 0u) {  // the earlier batches' sums decay as the statistics do
            states[r].selection_samples = states[r].selection_samples * pc.decay + total_samples;
            states[r].selection_weight = states[r].selection_weight * pc.decay + s_sel[GUIDING_SELECTION_CANDIDATES];
            [[dont_unroll]] for (uint j = 0u; j < GUIDING_SELECTION_CANDIDATES; ++j)
                states[r].selection_score[j] = states[r].selection_score[j] * pc.decay + s_sel[j];
        }
        write_tally(r, st);
        write_selection(r);
    }
}

// ---- adaptive refinement (field.cpp GuidingField::refine; thesis 4.6.3) -------------------
// The host split region `parent` at `plane` (device_fit.cpp); the new region `child` inherits
// its mixture, records and pivot. Each half keeps half of the statistics and of new_samples;
// the pending lit samples go to the half holding their position (in order), their unlit count
// in the same proportion; both start counting received lit samples and their pivot afresh.
// The learnt probability's sums are halved too (its choice and per-sample moments stay).
void pass_refine() {
    uint i = gl_WorkGroupID.x;
    uint t = gl_LocalInvocationID.x;
    if (i >= pc.split_count) return;
    GuidingFitSplit sp = splits[i];
    uint p = sp.parent, c = sp.child;
    if (t < K_MAX) {
        GuidingFitLobe l = state_lobes[p * K_MAX + t];
        l.stat_direction *= 0.5;
        l.stat_weight *= 0.5;
        l.stat_count *= 0.5;
        l.stat_inv_distance *= 0.5;
        state_lobes[p * K_MAX + t] = l;
        state_lobes[c * K_MAX + t] = l;
        lobes[c * K_MAX + t] = lobes[p * K_MAX + t];
    }
    if (t != 0u) return;
    GuidingFitRegion st = states[p];
    uint base_p = p * pc.pending_capacity, base_c = c * pc.pending_capacity;
    uint lower = 0u, upper = 0u;
    [[dont_unroll]] for (uint j = 0u; j < st.pending; ++j) {
        uint src = base_p + j;
        uint dst = pending_samples[src].position[sp.axis] >= sp.plane ? base_c + upper++ : base_p + lower++;
        if (dst != src) pending_samples[dst] = pending_samples[src];  // dst <= src on the parent's side
    }
    float kept = float(st.pending);
    float fl = kept > 0.0 ? float(lower) / kept : 0.5, fu = kept > 0.0 ? float(upper) / kept : 0.5;
    st.new_samples *= 0.5;
    st.position_count = 0.0;
    st.received = 0u;
    GuidingFitRegion sc = st;
    sc.pending = upper;
    sc.pending_zero = st.pending_zero * fu;
    st.pending = lower;
    st.pending_zero *= fl;
    states[p] = st;
    states[c] = sc;
    states[p].selection_samples *= 0.5;
    states[c].selection_samples = states[p].selection_samples;
    states[p].selection_weight *= 0.5;
    states[c].selection_weight = states[p].selection_weight;
    [[dont_unroll]] for (uint j = 0u; j < GUIDING_SELECTION_CANDIDATES; ++j) {
        float m = 0.5 * states[p].selection_score[j];
        states[p].selection_score[j] = m;
        states[c].selection_score[j] = m;
    }
    GuidingRegion rp = regions[p];
    GuidingRegion rc = rp;
    rp.aabb_max[sp.axis] = sp.plane;
    rc.aabb_min[sp.axis] = sp.plane;
    regions[p] = rp;
    regions[c] = rc;
    tally[p].received = 0u;
    tally[p].score_bsdf *= 0.5;
    tally[p].score_chosen *= 0.5;
    tally[p].weight *= 0.5;
    tally[c] = tally[p];
}

void main() {
    if (pc.pass == GUIDING_FIT_PASS_COUNT) pass_count();
    else if (pc.pass == GUIDING_FIT_PASS_SCAN_REDUCE) pass_scan_reduce();
    else if (pc.pass == GUIDING_FIT_PASS_SCAN_PARTIALS) { if (gl_WorkGroupID.x == 0u) pass_scan_partials(); }
    else if (pc.pass == GUIDING_FIT_PASS_SCAN_APPLY) pass_scan_apply();
    else if (pc.pass == GUIDING_FIT_PASS_SCATTER) pass_scatter();
    else if (pc.pass == GUIDING_FIT_PASS_POSITIONS) pass_positions();
    else if (pc.pass == GUIDING_FIT_PASS_EM) pass_em();
    else pass_refine();
}
