// Material node programs (types.h NODE_*): Cycles shader node graphs compiled on the host
// (parallax_core/nodes.py) into a register machine run at every hit, as Cycles runs its graphs
// in the SVM (intern/cycles/kernel/svm/). A program sets the Material fields its graph drives.
#ifndef PARALLAX_NODES_GLSL
#define PARALLAX_NODES_GLSL

layout(set = 0, binding = BINDING_NODE_PROGRAMS, scalar) readonly buffer NodeProgramBuffer { uint node_words[]; };

float node_float(uint at) { return uintBitsToFloat(node_words[at]); }

// Bob Jenkins' lookup3 final mix of three words, as Cycles hashes lattice points (hash_uint3).
uint hash_rotate(uint x, uint k) { return (x << k) | (x >> (32u - k)); }

uint hash_uint3(uint x, uint y, uint z) {
    uint a = 0xdeadbeefu + (3u << 2) + 13u, b = a, c = a;
    c += z;
    b += y;
    a += x;
    c ^= b; c -= hash_rotate(b, 14u);
    a ^= c; a -= hash_rotate(c, 11u);
    b ^= a; b -= hash_rotate(a, 25u);
    c ^= b; c -= hash_rotate(b, 16u);
    a ^= c; a -= hash_rotate(c, 4u);
    b ^= a; b -= hash_rotate(a, 14u);
    c ^= b; c -= hash_rotate(b, 24u);
    return c;
}

// Perlin's improved noise in 3D with Cycles' gradients and hash (kernel/svm/noise.h).
float perlin_gradient(uint hash, vec3 p) {
    uint h = hash & 15u;
    float u = h < 8u ? p.x : p.y;
    float v = h < 4u ? p.y : (h == 12u || h == 14u ? p.x : p.z);
    return ((h & 1u) != 0u ? -u : u) + ((h & 2u) != 0u ? -v : v);
}

float perlin_3d(vec3 p) {
    vec3 cell = floor(p), f = p - cell;
    uvec3 i = uvec3(ivec3(cell));
    vec3 w = f * f * f * (f * (f * 6.0 - 15.0) + 10.0);  // fade
    float corner[8];
    for (uint k = 0u; k < 8u; ++k) {
        uvec3 o = uvec3(k & 1u, (k >> 1) & 1u, k >> 2);
        corner[k] = perlin_gradient(hash_uint3(i.x + o.x, i.y + o.y, i.z + o.z), f - vec3(o));
    }
    float x0 = mix(corner[0], corner[1], w.x), x1 = mix(corner[2], corner[3], w.x);
    float x2 = mix(corner[4], corner[5], w.x), x3 = mix(corner[6], corner[7], w.x);
    return mix(mix(x0, x1, w.y), mix(x2, x3, w.y), w.z);
}

// Signed noise: repeats every 100000 (float precision), scaled to about -1..1 (Cycles' snoise_3d).
float signed_noise_3d(vec3 p) {
    vec3 correction = 0.5 * vec3(greaterThanEqual(abs(p), vec3(1000000.0)));
    p = p - 100000.0 * trunc(p / 100000.0) + correction;  // fmod
    return 0.9820 * perlin_3d(p);
}

// Fractal Brownian motion of that noise (Cycles' noise_fbm): detail octaves (and a fraction of
// one more), each `lacunarity` times finer and `roughness` times weaker.
float noise_fbm(vec3 p, float detail, float roughness, float lacunarity, bool normalize) {
    detail = clamp(detail, 0.0, 15.0);
    roughness = max(roughness, 0.0);
    float scale = 1.0, amplitude = 1.0, max_amplitude = 0.0, sum = 0.0;
    for (int k = 0; k <= int(detail); ++k) {
        sum += signed_noise_3d(scale * p) * amplitude;
        max_amplitude += amplitude;
        amplitude *= roughness;
        scale *= lacunarity;
    }
    float remainder = detail - floor(detail);
    float value = normalize ? 0.5 * sum / max_amplitude + 0.5 : sum;
    if (remainder != 0.0) {
        float sum2 = sum + signed_noise_3d(scale * p) * amplitude;
        value = mix(value, normalize ? 0.5 * sum2 / (max_amplitude + amplitude) + 0.5 : sum2, remainder);
    }
    return value;
}

// Cycles' hash_int3_to_float3 (PCG 3D, hash_pcg3d_i, on wrapping signed ints): a Voronoi
// cell's point offset and colour.
vec3 hash_cell(ivec3 v) {
    v = v * 1664525 + 1013904223;
    v.x += v.y * v.z; v.y += v.z * v.x; v.z += v.x * v.y;
    v ^= v >> 16;
    v.x += v.y * v.z; v.y += v.z * v.x; v.z += v.x * v.y;
    return vec3(v & 0x7fffffff) * (1.0 / 2147483648.0);
}

// Cycles' voronoi_distance of d = a - b by metric (0 Euclidean, 1 Manhattan, 2 Chebychev,
// 3 Minkowski); `bound`: voronoi_distance_bound (no root), which orders cells the same way.
float voronoi_distance(vec3 d, uint metric, float exponent, bool bound) {
    d = abs(d);
    if (metric == 0u) return bound ? dot(d, d) : length(d);
    if (metric == 1u) return d.x + d.y + d.z;
    if (metric == 2u) return max(max(d.x, d.y), d.z);
    vec3 e = pow(d, vec3(exponent));
    return bound ? e.x + e.y + e.z : pow(e.x + e.y + e.z, 1.0 / exponent);
}

// One octave of Cycles' 3D Voronoi: voronoi_f1 (feature 0), voronoi_f2 (1), voronoi_smooth_f1
// (2, over 5^3 cells). A cell's colour is the hash that places its point.
void voronoi_octave(vec3 coord, uint feature, uint metric, float exponent, float randomness, float smoothness,
                    out float dist, out vec3 color, out vec3 position) {
    vec3 cell_f = floor(coord), local = coord - cell_f;
    ivec3 cell = ivec3(cell_f);
    int r = feature == 2u ? 2 : 1;
    float d1 = 3.402823466e38, d2 = d1, h = -1.0;  // F1, F2 (smooth F1: d1 its distance, h its weight)
    vec3 c1 = vec3(0.0), c2 = c1, p1 = c1, p2 = c1;
    for (int k = -r; k <= r; ++k)
        for (int j = -r; j <= r; ++j)
            for (int i = -r; i <= r; ++i) {
                vec3 offset = vec3(i, j, k), c = hash_cell(cell + ivec3(i, j, k)), point = offset + c * randomness;
                float d = voronoi_distance(point - local, metric, exponent, feature == 0u);
                if (feature == 2u) {
                    if (h == -1.0) d1 = 0.0;
                    h = h == -1.0 ? 1.0 : smoothstep(0.0, 1.0, 0.5 + 0.5 * (d1 - d) / smoothness);
                    float correction = smoothness * h * (1.0 - h);
                    d1 = mix(d1, d, h) - correction;
                    correction /= 1.0 + 3.0 * smoothness;
                    c1 = mix(c1, c, h) - correction;
                    p1 = mix(p1, point, h) - correction;
                } else if (d < d1) {
                    d2 = d1; c2 = c1; p2 = p1;
                    d1 = d; c1 = c; p1 = point;
                } else if (d < d2) {
                    d2 = d; c2 = c; p2 = point;
                }
            }
    if (feature == 0u) d1 = voronoi_distance(p1 - local, metric, exponent, false);
    dist = feature == 1u ? d2 : d1;
    color = feature == 1u ? c2 : c1;
    position = cell_f + (feature == 1u ? p2 : p1);
}

// Cycles' 3D Voronoi Texture (svm_node_tex_voronoi, fractal_voronoi_x_fx): octaves summed as
// fBm, with lerps for the position. The output (modes >> 5): 0 distance, 1 colour, 2 position.
vec4 node_voronoi(vec3 coord, float scale, float detail, float roughness, float lacunarity, float smoothness,
                  float exponent, float randomness, uint modes) {
    uint feature = modes & 3u, metric = (modes >> 2) & 3u;
    detail = clamp(detail, 0.0, 15.0);
    roughness = clamp(roughness, 0.0, 1.0);
    randomness = clamp(randomness, 0.0, 1.0);
    smoothness = clamp(smoothness / 2.0, 0.0, 0.5);
    if (feature == 2u && smoothness == 0.0) feature = 0u;
    coord *= scale;
    float amplitude = 1.0, max_amplitude = 0.0, octave_scale = 1.0, dist = 0.0;
    vec3 color = vec3(0.0), position = vec3(0.0);
    for (int i = 0; i <= int(ceil(detail)); ++i) {
        float d;
        vec3 c, p;
        voronoi_octave(coord * octave_scale, feature, metric, exponent, randomness, smoothness, d, c, p);
        if (detail == 0.0 || roughness == 0.0) {
            max_amplitude = 1.0; dist = d; color = c; position = p;
            break;
        }
        float weight = amplitude;
        if (float(i) > detail) {  // the fraction of one more octave
            float remainder = detail - floor(detail);
            if (remainder == 0.0) break;
            max_amplitude = mix(max_amplitude, max_amplitude + amplitude, remainder);
            weight *= remainder;
            position = mix(position, mix(position, p / octave_scale, amplitude), remainder);
        } else {
            max_amplitude += amplitude;
            position = mix(position, p / octave_scale, amplitude);
        }
        dist += d * weight;
        color += c * weight;
        octave_scale *= lacunarity;
        amplitude *= roughness;
    }
    if ((modes & 16u) != 0u) {  // normalize
        dist /= max_amplitude * voronoi_distance(vec3(0.5 + 0.5 * randomness), metric, exponent, false) *
                (feature == 1u ? 2.0 : 1.0);
        color /= max_amplitude;
    }
    uint output_ = modes >> 5;
    return output_ == 0u ? vec4(dist) : output_ == 1u ? vec4(color, 1.0) : vec4(scale != 0.0 ? position / scale : vec3(0.0), 0.0);
}

// Cycles' svm_wave at p (scaled): modes bit 0 rings (else bands), bits 1-2 the direction (X, Y,
// Z, diagonal / spherical), bits 3-4 the profile (sine, saw, triangle).
float node_wave(vec3 p, uint modes, float distortion, float detail, float detail_scale, float detail_roughness,
                float phase) {
    p = (p + 0.000001) * 0.999999;  // as Cycles: off the unit coordinates
    uint direction = (modes >> 1) & 3u, profile = modes >> 3;
    float n;
    if ((modes & 1u) == 0u) n = direction == 3u ? (p.x + p.y + p.z) * 10.0 : p[direction] * 20.0;
    else n = length(direction == 3u ? p : p * vec3(notEqual(uvec3(0u, 1u, 2u), uvec3(direction)))) * 20.0;
    n += phase;
    if (distortion != 0.0) n += distortion * (noise_fbm(p * detail_scale, detail, detail_roughness, 2.0, true) * 2.0 - 1.0);
    if (profile == 0u) return 0.5 + 0.5 * sin(n - 1.57079632679);
    n /= 6.28318530718;
    return profile == 1u ? n - floor(n) : abs(n - floor(n + 0.5)) * 2.0;
}

// Cycles' brick_noise: an integer hash of a brick's row and number, 0..1.
float brick_noise(uint n) {
    n = (n + 1013u) & 0x7fffffffu;
    n = (n >> 13) ^ n;
    uint nn = (n * (n * n * 60493u + 19990303u) + 1376312589u) & 0x7fffffffu;
    return 0.5 * (float(nn) / 1073741824.0);
}

// Cycles' svm_brick and svm_node_tex_brick at p (scaled): the colour (rgb) and the mortar (w).
// Words from `at`: the offset and squash amounts, then their frequencies (a byte each).
vec4 node_brick(vec3 p, vec3 color1, vec3 color2, vec3 mortar_color, float mortar_size, float mortar_smooth, float bias,
                float brick_width, float row_height, uint at) {
    uint offset_frequency = node_words[at + 2u] & 0xffu, squash_frequency = (node_words[at + 2u] >> 8) & 0xffu;
    int row = int(floor(p.y / row_height));
    float offset = 0.0;
    if (offset_frequency != 0u && squash_frequency != 0u) {  // (C's % keeps the sign: divisible or not)
        if (uint(abs(row)) % squash_frequency == 0u) brick_width *= node_float(at + 1u);
        if (uint(abs(row)) % offset_frequency == 0u) offset = brick_width * node_float(at);
    }
    int brick = int(floor((p.x + offset) / brick_width));
    float x = (p.x + offset) - brick_width * float(brick), y = p.y - row_height * float(row);
    float tint = clamp(brick_noise(uint((row << 16) + (brick & 0xffff))) + bias, 0.0, 1.0);
    float min_dist = min(min(x, y), min(brick_width - x, row_height - y));
    float mortar = min_dist >= mortar_size ? 0.0 :
                   mortar_smooth == 0.0 ? 1.0 : smoothstep(0.0, 1.0, (1.0 - min_dist / mortar_size) / mortar_smooth);
    return vec4(mix(mix(color1, color2, tint), mortar_color, mortar), mortar);
}

float node_safe_divide(float a, float b) { return b != 0.0 ? a / b : 0.0; }

vec3 node_safe_normalize(vec3 a) { float t = length(a); return t != 0.0 ? a * (1.0 / t) : a; }

// Cycles' safe_powf (compatible_powf): 0 for a negative base and a fractional exponent.
float node_safe_pow(float a, float b) {
    if (a < 0.0 && b != trunc(b)) return 0.0;
    if (b == 0.0) return 1.0;
    if (a == 0.0) return 0.0;
    return a < 0.0 ? (mod(b, 2.0) == 0.0 ? 1.0 : -1.0) * pow(-a, b) : pow(a, b);
}

float node_wrap(float value, float high, float low) {  // Cycles' wrapf
    float span = high - low;
    return span != 0.0 ? value - span * floor((value - low) / span) : low;
}

float node_smooth_min(float a, float b, float k) {  // Cycles' smoothminf
    if (k == 0.0) return min(a, b);
    float h = max(k - abs(a - b), 0.0) / k;
    return min(a, b) - h * h * h * k * (1.0 / 6.0);
}

// Blender's Math node as Cycles computes it (svm_math_float: division, root, power and modulo
// are safe).
float node_math(uint op, float a, float b, float c) {
    switch (op) {
    case 0u: return a + b;
    case 1u: return a - b;
    case 2u: return a * b;
    case 3u: return b != 0.0 ? a / b : 0.0;
    case 4u: return a < 0.0 && b != floor(b) ? 0.0 : (a < 0.0 ? (mod(b, 2.0) == 0.0 ? 1.0 : -1.0) * pow(-a, b) : pow(a, b));
    case 5u: return min(a, b);
    case 6u: return max(a, b);
    case 7u: return a < b ? 1.0 : 0.0;
    case 8u: return a > b ? 1.0 : 0.0;
    case 9u: return abs(a);
    case 10u: return a > 0.0 ? sqrt(a) : 0.0;
    case 11u: return a * b + c;
    case 12u: return floor(a);
    case 13u: return ceil(a);
    case 14u: return a - floor(a);
    case 15u: return b != 0.0 ? a - b * trunc(a / b) : 0.0;  // fmod
    case 16u: return sin(a);
    case 17u: return cos(a);
    case 18u: return floor(a + 0.5);
    case 19u: return sign(a);
    case 20u: return exp(a);
    case 21u: return min(max(a, b), c);  // Clamp (min max)
    case 22u: return a > 0.0 && b > 0.0 ? node_safe_divide(log(a), log(b)) : 0.0;  // safe_logf
    case 23u: return a > 0.0 ? 1.0 / sqrt(a) : 0.0;
    case 24u: return trunc(a);
    case 25u: return floor(node_safe_divide(a, b)) * b;
    case 26u: return node_wrap(a, b, c);
    case 27u: return b != 0.0 ? abs(fract((a - b) / (b * 2.0)) * b * 2.0 - b) : 0.0;  // pingpongf
    case 28u: return node_smooth_min(a, b, c);
    case 29u: return -node_smooth_min(-a, -b, c);
    case 30u: return a == b || abs(a - b) <= max(c, 1.1920929e-7) ? 1.0 : 0.0;  // Compare (FLT_EPSILON)
    case 31u: return tan(a);
    case 32u: a = clamp(a, -1.0, 1.0); return atan(a, sqrt((1.0 - a) * (1.0 + a)));  // asin, to float precision
    case 33u: a = clamp(a, -1.0, 1.0); return atan(sqrt((1.0 - a) * (1.0 + a)), a);  // acos
    case 34u: return atan(a);
    case 35u: return a == 0.0 && b == 0.0 ? 0.0 : atan(a, b);  // compatible_atan2
    case 36u: return sinh(a);
    case 37u: return cosh(a);
    case 38u: return tanh(a);
    case 39u: return a * (3.14159265358979 / 180.0);
    case 40u: return a * (180.0 / 3.14159265358979);
    default: return b != 0.0 ? a - floor(a / b) * b : 0.0;  // 41: Floored Modulo
    }
}

// Blender's Vector Math node as Cycles computes it (svm_vector_math), op: VECTOR_MATH_OPS; a
// float result (Dot Product, Distance, Length) in all three components. 29: the Gamma node
// (svm_math_gamma_color of a by s).
vec3 node_vector_math(uint op, vec3 a, vec3 b, vec3 c, float s) {
    switch (op) {
    case 0u: return a + b;
    case 1u: return a - b;
    case 2u: return a * b;
    case 3u: return vec3(node_safe_divide(a.x, b.x), node_safe_divide(a.y, b.y), node_safe_divide(a.z, b.z));
    case 4u: return a * b + c;
    case 5u: return cross(a, b);
    case 6u: return dot(b, b) != 0.0 ? dot(a, b) / dot(b, b) * b : vec3(0.0);  // project
    case 7u: { vec3 n = node_safe_normalize(b); return a - 2.0 * n * dot(a, n); }
    case 8u: return refract(a, node_safe_normalize(b), s);  // GLSL's is Cycles' refract
    case 9u: return faceforward(a, b, c);  // a where dot(c, b) < 0, else -a
    case 10u: return vec3(dot(a, b));
    case 11u: return vec3(distance(a, b));
    case 12u: return vec3(length(a));
    case 13u: return a * s;
    case 14u: return node_safe_normalize(a);
    case 15u: return abs(a);
    case 16u: return vec3(node_safe_pow(a.x, b.x), node_safe_pow(a.y, b.y), node_safe_pow(a.z, b.z));
    case 17u: return sign(a);
    case 18u: return min(a, b);
    case 19u: return max(a, b);
    case 20u: return floor(a);
    case 21u: return ceil(a);
    case 22u: return a - floor(a);
    case 23u: return mix(a - b * trunc(a / b), vec3(0.0), equal(b, vec3(0.0)));  // safe_modulo
    case 24u: return vec3(node_wrap(a.x, b.x, c.x), node_wrap(a.y, b.y, c.y), node_wrap(a.z, b.z, c.z));
    case 25u: return floor(vec3(node_safe_divide(a.x, b.x), node_safe_divide(a.y, b.y), node_safe_divide(a.z, b.z))) * b;
    case 26u: return sin(a);
    case 27u: return cos(a);
    case 28u: return tan(a);
    default: return s == 0.0 ? vec3(1.0) : mix(a, pow(a, vec3(s)), greaterThan(a, vec3(0.0)));
    }
}

// Cycles' rgb_to_hsv and hsv_to_rgb (util/color.h).
vec3 node_rgb_to_hsv(vec3 rgb) {
    float cmax = max(rgb.r, max(rgb.g, rgb.b)), delta = cmax - min(rgb.r, min(rgb.g, rgb.b));
    float s = cmax != 0.0 ? delta / cmax : 0.0, h = 0.0;
    if (s != 0.0) {
        vec3 c = (vec3(cmax) - rgb) / delta;
        h = (rgb.r == cmax ? c.b - c.g : (rgb.g == cmax ? 2.0 + c.r - c.b : 4.0 + c.g - c.r)) / 6.0;
        if (h < 0.0) h += 1.0;
    }
    return vec3(h, s, cmax);
}

vec3 node_hsv_to_rgb(vec3 hsv) {
    float s = hsv.y, v = hsv.z;
    if (s == 0.0) return vec3(v);
    float h = hsv.x == 1.0 ? 0.0 : hsv.x * 6.0, i = floor(h), f = h - i;
    float p = v * (1.0 - s), q = v * (1.0 - s * f), t = v * (1.0 - s * (1.0 - f));
    if (i == 0.0) return vec3(v, t, p);
    if (i == 1.0) return vec3(q, v, p);
    if (i == 2.0) return vec3(p, v, t);
    if (i == 3.0) return vec3(p, q, v);
    if (i == 4.0) return vec3(t, p, v);
    return vec3(v, p, q);
}

// One channel of an interpolated table of `size` rows `stride` floats apart from word `at`
// (Cycles' float_ramp_lookup / rgb_ramp_lookup): beyond 0..1 along its end segments if
// extrapolate, else clamped.
float node_curve_lookup(uint at, uint stride, uint size, float f, bool extrapolate) {
    if (extrapolate && (f < 0.0 || f > 1.0)) {
        bool low = f < 0.0;
        float t0 = node_float(low ? at : at + (size - 1u) * stride);
        float t1 = node_float(low ? at + stride : at + (size - 2u) * stride);
        return t0 + (t0 - t1) * (low ? -f : f - 1.0) * float(size - 1u);
    }
    f = clamp(f, 0.0, 1.0) * float(size - 1u);
    uint i = min(uint(f), size - 1u);
    float t = f - float(i), v = node_float(at + i * stride);
    return t > 0.0 ? (1.0 - t) * v + t * node_float(at + (i + 1u) * stride) : v;
}

// Map Range as Cycles' svm_node_map_range (then its Clamp node) or, on one component,
// svm_node_vector_map_range; flags: NODE_MAP_RANGE's second word.
float node_map_range(float v, float from_min, float from_max, float to_min, float to_max, float steps, uint flags) {
    uint kind = (flags >> 8) & 0xffu;
    bool vector = (flags >> 24) != 0u;
    float span = from_max - from_min;
    if (span == 0.0 && !vector) return 0.0;
    float f = node_safe_divide(v - from_min, span);
    if (kind == 1u) {
        f = steps > 0.0 ? floor(f * (steps + 1.0)) / steps : 0.0;
    } else if (kind >= 2u) {  // smoothstep / smootherstep, of the reversed range flipped
        bool flip = from_min > from_max && !vector;
        float t = clamp(flip ? (v - from_max) / -span : f, 0.0, 1.0);
        t = kind == 2u ? (3.0 - 2.0 * t) * (t * t) : t * t * t * (t * (t * 6.0 - 15.0) + 10.0);
        f = flip ? 1.0 - t : t;
    }
    float r = to_min + f * (to_max - to_min);
    return (flags & 1u) != 0u ? clamp(r, min(to_min, to_max), max(to_min, to_max)) : r;
}

// Blender's Mix blend types as Cycles computes them (svm_mix), factor t.
vec3 node_blend(uint mode, float t, vec3 c1, vec3 c2) {
    float tm = 1.0 - t;
    switch (mode) {
    case 0u: return tm * c1 + t * c2;
    case 1u: return c1 + t * c2;
    case 2u: return c1 * (tm + t * c2);
    case 3u: return c1 - t * c2;
    case 4u: return 1.0 - (tm + t * (1.0 - c2)) * (1.0 - c1);
    case 5u: return tm * c1 + t * abs(c1 - c2);
    case 6u: return tm * c1 + t * min(c1, c2);
    case 7u: return tm * c1 + t * max(c1, c2);
    case 8u: return mix(1.0 - (tm + 2.0 * t * (1.0 - c2)) * (1.0 - c1), c1 * (tm + 2.0 * t * c2), lessThan(c1, vec3(0.5)));
    default: {  // 9: Divide, where the divisor is not 0
        vec3 safe = mix(c2, vec3(1.0), equal(c2, vec3(0.0)));
        return mix(tm * c1 + t * c1 / safe, c1, equal(c2, vec3(0.0)));
    }
    }
}

// ---- geometry and Cycles' Bump (kernel/svm/displace.h svm_node_set_bump) ----------------
// Cycles evaluates a Bump's height three times: at the hit, and with its coordinates moved by
// the ray differentials dPdx, dPdy times the node's filter width. Without ray differentials,
// the offsets here run along the triangle's edges p1 - p0 and p2 - p0, each as long as the
// filter width times a camera pixel's footprint at the hit (what Cycles' camera differentials
// give a primary hit); every coordinate moves with the same barycentric step. Where the height
// is smooth at that scale the bumped normal is its surface gradient either way (the offsets'
// length cancels out of svm_node_set_bump).

// A pixel's width in world units at point p, seen from the camera.
float pixel_footprint(vec3 p) {
    if (scene.camera_type == CAMERA_ORTHOGRAPHIC) return (scene.camera_window.y - scene.camera_window.x) / float(params.width);
    vec3 eye = vec3(scene.camera_to_world[0].w, scene.camera_to_world[1].w, scene.camera_to_world[2].w);
    float angle = scene.camera_type == CAMERA_PANORAMA ? 2.0 * PI / float(params.width)
                                                       : (scene.camera_window.y - scene.camera_window.x) / float(params.width);
    return angle * length(p - eye);
}

// Barycentric step of bump offset `offset` (1: along edge 1, 2: along edge 2) of filter width
// `width`, and the world-space move it makes.
vec2 bump_step(SurfaceHit sh, uint offset, float width, out vec3 moved) {
    moved = vec3(0.0);
    if (offset == 0u) return vec2(0.0);
    InstanceInfo inst = instances[sh.instance];
    uvec3 idx = indices[meshes[inst.mesh].first_triangle + sh.primitive];
    vec3 edge = transform_vector(inst.object_to_world, positions[offset == 1u ? idx.y : idx.z] - positions[idx.x]);
    float step = width * pixel_footprint(sh.p) / max(length(edge), 1e-20);
    moved = step * edge;
    return offset == 1u ? vec2(step, 0.0) : vec2(0.0, step);
}

// The object-space position and uv at barycentrics b (of vertices 1, 2) of the hit's triangle.
vec3 object_point(SurfaceHit sh, vec2 b, out vec2 uv) {
    InstanceInfo inst = instances[sh.instance];
    MeshInfo mesh = meshes[inst.mesh];
    uint tri = mesh.first_triangle + sh.primitive;
    uvec3 idx = indices[tri];
    vec3 w = vec3(1.0 - b.x - b.y, b);
    uv = mesh.has_uvs != 0u ? w.x * corner_uvs[3u * tri] + w.y * corner_uvs[3u * tri + 1u] + w.z * corner_uvs[3u * tri + 2u]
                            : vec2(0.0);
    return w.x * positions[idx.x] + w.y * positions[idx.y] + w.z * positions[idx.z];
}

// NODE_UV, NODE_GENERATED, NODE_GEOMETRY, NODE_ATTRIBUTE: `word` = kind (attribute: slot) |
// offset << 8 | half filter width << 16.
vec4 node_geometry(uint op, uint word, SurfaceHit sh, vec3 wo) {
    uint kind = word & 0xffu, offset = (word >> 8) & 0xffu;
    bool back = dot(sh.ng, wo) < 0.0;  // Cycles' SD_BACKFACING: N and Ng face the viewer
    if (op == NODE_GEOMETRY) {
        if (kind == NODE_GEOMETRY_NORMAL) return vec4(back ? -sh.ns_smooth : sh.ns_smooth, 0.0);
        if (kind == NODE_GEOMETRY_TRUE_NORMAL) return vec4(back ? -sh.ng : sh.ng, 0.0);
        if (kind == NODE_GEOMETRY_INCOMING) return vec4(wo, 0.0);
        if (kind == NODE_GEOMETRY_BACKFACING) return vec4(back ? 1.0 : 0.0);
        if (kind == NODE_GEOMETRY_OBJECT_NORMAL) {  // the inverse normal transform: M^T N
            vec4 rows[3] = instances[sh.instance].object_to_world;
            vec3 n = back ? -sh.ns_smooth : sh.ns_smooth;
            return vec4(normalize(n.x * rows[0].xyz + n.y * rows[1].xyz + n.z * rows[2].xyz), 0.0);
        }
    }
    vec3 moved;
    vec2 b = sh.bary + bump_step(sh, offset, unpackHalf2x16(word >> 16).x, moved);
    if (offset == 0u && op == NODE_UV) return vec4(sh.uv, 0.0, 0.0);
    if (offset == 0u && op == NODE_GENERATED) return vec4(sh.generated, 0.0);
    if (op == NODE_GEOMETRY && kind == NODE_GEOMETRY_POSITION) return vec4(sh.p + moved, 0.0);
    if (op == NODE_ATTRIBUTE) {
        uint at = kind * scene.attribute_stride + 3u * (meshes[instances[sh.instance].mesh].first_triangle + sh.primitive);
        return (1.0 - b.x - b.y) * corner_attributes[at] + b.x * corner_attributes[at + 1u] + b.y * corner_attributes[at + 2u];
    }
    vec2 uv;
    vec3 p_object = object_point(sh, b, uv);
    if (op == NODE_UV) return vec4(uv, 0.0, 0.0);
    if (op == NODE_GENERATED) {
        MeshInfo mesh = meshes[instances[sh.instance].mesh];
        return vec4(p_object * mesh.texspace_scale + mesh.texspace_offset, 0.0);
    }
    return vec4(p_object, 0.0);  // NODE_GEOMETRY_OBJECT
}

// Cycles' svm_node_set_bump: the normal n (facing the viewer) tilted by the height's surface
// gradient, from the heights h = (centre, dx, dy) at bump_step's two offsets.
vec3 node_bump(SurfaceHit sh, vec3 n, vec3 h, float strength, float distance, uint word) {
    float width = unpackHalf2x16(word >> 16).x;
    vec3 dpdx, dpdy;
    bump_step(sh, 1u, width, dpdx);
    bump_step(sh, 2u, width, dpdy);
    vec3 rx = cross(dpdy, n), ry = cross(n, dpdx);
    float det = dot(dpdx, rx);
    vec3 surfgrad = (h.y - h.x) * rx + (h.z - h.x) * ry;
    if ((word & 1u) != 0u) distance = -distance;
    vec3 bumped = abs(det) * n - distance * sign(det) * surfgrad;
    if (dot(bumped, bumped) <= 1e-30 || det == 0.0) return n;
    return normalize(max(strength, 0.0) * normalize(bumped) + (1.0 - max(strength, 0.0)) * n);
}

// Cycles' Normal Map (kernel/svm/tex_coord.h svm_node_normal_map): a colour (0..1 per axis)
// as a normal, facing the viewer. Tangent space uses the mesh's MikkTSpace tangents and the
// interpolated (unnormalised) object-space normal, the strength scaling the tangent part; the
// other spaces mix with the shading normal by the strength.
vec3 node_normal_map(SurfaceHit sh, vec3 color, float strength, uint space, bool back) {
    vec3 c = 2.0 * (color - 0.5);
    vec3 n_shading = back ? -sh.ns_smooth : sh.ns_smooth;
    vec3 n;
    InstanceInfo inst = instances[sh.instance];
    if (space == NODE_NORMAL_MAP_TANGENT) {
        MeshInfo mesh = meshes[inst.mesh];
        if (mesh.has_tangents == 0u) return n_shading;  // as Cycles without the UV map's tangents
        uint tri = mesh.first_triangle + sh.primitive;
        vec3 w = vec3(1.0 - sh.bary.x - sh.bary.y, sh.bary);
        vec4 t = w.x * corner_tangents[3u * tri] + w.y * corner_tangents[3u * tri + 1u] + w.z * corner_tangents[3u * tri + 2u];
        vec3 normal;  // object space, on the winding side
        if (mesh.has_normals != 0u) {
            normal = w.x * corner_normals[3u * tri] + w.y * corner_normals[3u * tri + 1u] + w.z * corner_normals[3u * tri + 2u];
        } else {
            uvec3 idx = indices[tri];
            normal = normalize(cross(positions[idx.y] - positions[idx.x], positions[idx.z] - positions[idx.x]));
        }
        c.xy *= strength;
        c.z = mix(1.0, c.z, clamp(strength, 0.0, 1.0));
        vec3 b = (t.w < 0.0 ? -1.0 : 1.0) * cross(normal, t.xyz);
        n = c.x * t.xyz + c.y * b + c.z * normal;
        n = transform_vector(inst.normal_to_world, n);
        n = dot(n, n) > 0.0 ? normalize(n) : n;
        if (back) n = -n;
    } else {
        if (space >= NODE_NORMAL_MAP_BLENDER_OBJECT) c.yz = -c.yz;  // Blender's own convention
        n = c;
        if (space == NODE_NORMAL_MAP_OBJECT || space == NODE_NORMAL_MAP_BLENDER_OBJECT) n = transform_vector(inst.normal_to_world, n);
        n = dot(n, n) > 0.0 ? normalize(n) : n;
        if (back) n = -n;
        if (strength != 1.0) {
            n = n_shading + (n - n_shading) * max(strength, 0.0);
            n = dot(n, n) > 0.0 ? normalize(n) : n;
        }
    }
    return dot(n, n) > 0.0 && !any(isnan(n)) ? n : n_shading;
}

// Cycles' Fresnel and Layer Weight nodes (kernel/svm/fresnel.h) at normal n, viewer wo.
float node_fresnel(uint kind, float value, vec3 n, vec3 wo, bool back) {
    float cos_i = dot(wo, n);
    if (kind == 0u) {
        float eta = max(value, 1e-5);
        return fresnel_dielectric(cos_i, back ? 1.0 / eta : eta);
    }
    if (kind == 1u) {
        float eta = max(1.0 - value, 1e-5);
        return fresnel_dielectric(cos_i, back ? eta : 1.0 / eta);
    }
    float f = abs(cos_i);
    if (value != 0.5) {
        float blend = clamp(value, 0.0, 1.0 - 1e-5);
        f = pow(f, blend < 0.5 ? 2.0 * blend : 0.5 / (1.0 - blend));
    }
    return 1.0 - f;
}

// Sets the fields `m`'s program drives at a hit seen from direction wo, clamped as Cycles
// clamps those inputs of its closures; a stored normal (Bump, Normal Map) becomes sh.ns.
// Without a program sh.ns is the interpolated normal (a mix chain's other links may bump it).
void run_node_program(inout Material m, inout SurfaceHit sh, vec3 wo) {
    if (!HAS(FEATURE_NODES)) return;
    sh.ns = sh.ns_smooth;
    if (m.program == NO_INDEX) return;
    vec4 reg[NODE_REGISTERS];
    uint pc = m.program;
    for (;;) {
        uint word = node_words[pc];
        uint op = word & 0xffu, dst = (word >> 8) & 0xffu, a = (word >> 16) & 0xffu, b = word >> 24;
        if (op == NODE_END) break;
        uint arg = node_words[pc + 1u];  // every instruction has one word at least
        pc += 2u;
        switch (op) {
        case NODE_CONST:
            reg[dst] = vec4(uintBitsToFloat(arg), node_float(pc), node_float(pc + 1u), node_float(pc + 2u));
            pc += 3u;
            break;
        case NODE_UV:
        case NODE_GENERATED:
            if (!HAS(FEATURE_NODE_SURFACE)) {  // at the hit itself (no bump offset)
                reg[dst] = op == NODE_UV ? vec4(sh.uv, 0.0, 0.0) : vec4(sh.generated, 0.0);
                break;
            }
        case NODE_GEOMETRY:
        case NODE_ATTRIBUTE:
            if (HAS(FEATURE_NODE_SURFACE)) reg[dst] = node_geometry(op, arg, sh, wo);
            break;
        case NODE_BUMP: {
            vec3 h = vec3(reg[arg & 0xffu].x, reg[(arg >> 8) & 0xffu].x, reg[(arg >> 16) & 0xffu].x);
            if (HAS(FEATURE_NODE_SURFACE)) reg[dst].xyz = node_bump(sh, reg[arg >> 24].xyz, h, reg[a].x, reg[b].x, node_words[pc]);
            pc += 1u;
            break;
        }
        case NODE_NORMAL_MAP:
            if (HAS(FEATURE_NODE_SURFACE)) reg[dst].xyz = node_normal_map(sh, reg[a].rgb, reg[b].x, arg, dot(sh.ng, wo) < 0.0);
            break;
        case NODE_FRESNEL:
            if (HAS(FEATURE_NODE_SURFACE)) reg[dst].x = node_fresnel(arg, reg[a].x, reg[b].xyz, wo, dot(sh.ng, wo) < 0.0);
            break;
        case NODE_NOISE:
            if (HAS(FEATURE_NODE_TEXTURES)) reg[dst].x = noise_fbm(reg[a].xyz, reg[arg & 0xffu].x, reg[(arg >> 8) & 0xffu].x, reg[(arg >> 16) & 0xffu].x,
                                   (arg >> 24) != 0u);
            break;
        case NODE_VORONOI: {
            uint more = node_words[pc];
            if (HAS(FEATURE_NODE_TEXTURES)) reg[dst] = node_voronoi(reg[a].xyz, reg[b].x, reg[arg & 0xffu].x, reg[(arg >> 8) & 0xffu].x,
                                    reg[(arg >> 16) & 0xffu].x, reg[arg >> 24].x, reg[more & 0xffu].x,
                                    reg[(more >> 8) & 0xffu].x, more >> 16);
            pc += 1u;
            break;
        }
        case NODE_WAVE: {
            uint more = node_words[pc];
            if (HAS(FEATURE_NODE_TEXTURES)) reg[dst] = vec4(node_wave(reg[a].xyz * reg[b].x, more >> 8, reg[arg & 0xffu].x, reg[(arg >> 8) & 0xffu].x,
                                      reg[(arg >> 16) & 0xffu].x, reg[arg >> 24].x, reg[more & 0xffu].x));
            pc += 1u;
            break;
        }
        case NODE_BRICK: {
            uint more = node_words[pc];
            if (HAS(FEATURE_NODE_TEXTURES)) {
                vec4 c = node_brick(reg[a].xyz * reg[b].x, reg[arg & 0xffu].rgb, reg[(arg >> 8) & 0xffu].rgb,
                                    reg[(arg >> 16) & 0xffu].rgb, reg[arg >> 24].x, reg[more & 0xffu].x,
                                    reg[(more >> 8) & 0xffu].x, reg[(more >> 16) & 0xffu].x, reg[more >> 24].x, pc + 1u);
                reg[dst] = (node_words[pc + 3u] & 0x10000u) != 0u ? vec4(c.w) : vec4(c.rgb, 1.0);
            }
            pc += 4u;
            break;
        }
        case NODE_TEXTURE:
            reg[dst] = vec4(sample_texture(int(arg), reg[a].xy), 1.0);
            break;
        case NODE_AFFINE: {
            vec4 p = vec4(reg[a].xyz, 1.0);
            reg[dst].xyz = vec3(dot(vec4(uintBitsToFloat(arg), node_float(pc), node_float(pc + 1u), node_float(pc + 2u)), p),
                                dot(vec4(node_float(pc + 3u), node_float(pc + 4u), node_float(pc + 5u), node_float(pc + 6u)), p),
                                dot(vec4(node_float(pc + 7u), node_float(pc + 8u), node_float(pc + 9u), node_float(pc + 10u)), p));
            pc += 11u;
            break;
        }
        case NODE_MATH:
            reg[dst].x = node_math(arg & 0xffu, reg[a].x, reg[b].x, reg[arg >> 16].x);
            break;
        case NODE_MIX: {
            vec3 c = node_blend(arg & 0xffu, reg[(arg >> 8) & 0xffu].x, reg[a].rgb, reg[b].rgb);
            reg[dst].rgb = (arg & 0x10000u) != 0u ? clamp(c, 0.0, 1.0) : c;
            break;
        }
        case NODE_INVERT:
            reg[dst].rgb = mix(reg[a].rgb, 1.0 - reg[a].rgb, reg[b].x);
            break;
        case NODE_CONVERT:  // as Blender converts sockets: colour -> luminance, vector -> mean, float -> grey
            if (arg == 0u) reg[dst].x = dot(reg[a].rgb, vec3(0.2126, 0.7152, 0.0722));
            else if (arg == 1u) reg[dst].x = (reg[a].x + reg[a].y + reg[a].z) / 3.0;
            else reg[dst] = vec4(reg[a].xxx, 1.0);
            break;
        case NODE_MAP_RANGE: {
            uint flags = node_words[pc];
            reg[dst].x = node_map_range(reg[a].x, reg[arg & 0xffu].x, reg[(arg >> 8) & 0xffu].x, reg[(arg >> 16) & 0xffu].x,
                                        reg[arg >> 24].x, reg[(flags >> 16) & 0xffu].x, flags);
            pc += 1u;
            break;
        }
        case NODE_VECTOR_MATH:
            if (HAS(FEATURE_NODE_COLOR)) reg[dst] = vec4(node_vector_math(arg & 0xffu, reg[a].xyz, reg[b].xyz, reg[(arg >> 8) & 0xffu].xyz, reg[arg >> 16].x), 0.0);
            break;
        case NODE_CURVES: {  // Cycles' svm_node_curves (3 channels) and svm_node_curve (1)
            uint size = arg & 0xffffu, channels = arg >> 24;
            if (!HAS(FEATURE_NODE_COLOR)) channels = 0u;  // (no program of the scene has curves)
            float min_x = node_float(pc), range_x = node_float(pc + 1u) - min_x;
            vec3 x = reg[a].xyz, y = x;
            for (uint k = 0u; k < channels; ++k)
                y[k] = node_curve_lookup(pc + 2u + k, channels, size, (x[k] - min_x) / range_x, (arg & 0x10000u) != 0u);
            reg[dst].xyz = (1.0 - reg[b].x) * x + reg[b].x * y;
            pc += 2u + channels * size;
            break;
        }
        case NODE_HSV: {  // Cycles' svm_node_hsv
            if (!HAS(FEATURE_NODE_COLOR)) break;
            vec3 color = reg[a].rgb, hsv = node_rgb_to_hsv(color);
            float fac = reg[b].x;
            hsv = vec3(fract(hsv.x + reg[arg & 0xffu].x + 0.5), clamp(hsv.y * reg[(arg >> 8) & 0xffu].x, 0.0, 1.0),
                       hsv.z * reg[(arg >> 16) & 0xffu].x);
            reg[dst].rgb = max(fac * node_hsv_to_rgb(hsv) + (1.0 - fac) * color, vec3(0.0));
            break;
        }
        case NODE_RAMP: {  // Cycles' rgb_ramp_lookup
            uint size = arg & 0xffffu;
            float f = clamp(reg[a].x, 0.0, 1.0) * float(size - 1u);
            uint i = min(uint(f), size - 1u);
            float t = f - float(i);
            uint row = pc + 4u * i;
            vec4 c = vec4(node_float(row), node_float(row + 1u), node_float(row + 2u), node_float(row + 3u));
            if ((arg >> 16) != 0u && t > 0.0)
                c = mix(c, vec4(node_float(row + 4u), node_float(row + 5u), node_float(row + 6u), node_float(row + 7u)), t);
            reg[dst] = c;
            pc += 4u * size;
            break;
        }
        case NODE_SEPARATE:
            reg[dst].x = reg[a][arg];
            break;
        case NODE_COMBINE:
            reg[dst] = vec4(reg[a].x, reg[b].x, reg[arg].x, 1.0);
            break;
        default: {  // NODE_STORE
            vec4 v = reg[a];
            switch (arg) {
            case 0u: m.base_color = max(v.rgb, vec3(0.0)); break;
            case 1u: m.roughness = clamp(v.x, 0.0, 1.0); break;
            case 2u: m.metallic = clamp(v.x, 0.0, 1.0); break;
            case 3u: m.transmission = clamp(v.x, 0.0, 1.0); break;
            case 4u: m.coat_weight = max(v.x, 0.0); break;
            case 5u: m.specular_ior_level = max(v.x, 0.0); break;
            case 6u: m.mix_weight = clamp(v.x, 0.0, 1.0); break;
            case 7u: m.coat_roughness = clamp(v.x, 0.0, 1.0); break;
            case 8u: m.sheen_weight = max(v.x, 0.0); break;
            default:  // the normal (facing the viewer, as Cycles' N) on the geometric normal's side
                if (dot(v.xyz, v.xyz) > 1e-30) sh.ns = normalize(dot(sh.ng, wo) < 0.0 ? -v.xyz : v.xyz);
                break;
            }
        }
        }
    }
}
#endif
