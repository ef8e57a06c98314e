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

// Sets the fields `m`'s program drives at a hit with texture coordinates uv, clamped as
// Cycles clamps those inputs of its closures.
void run_node_program(inout Material m, SurfaceHit sh) {
    if (!HAS(FEATURE_NODES) || m.program == NO_INDEX) return;
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
            reg[dst] = vec4(sh.uv, 0.0, 0.0);
            break;
        case NODE_GENERATED:
            reg[dst] = vec4(sh.generated, 0.0);
            break;
        case NODE_NOISE:
            reg[dst].x = noise_fbm(reg[a].xyz, reg[arg & 0xffu].x, reg[(arg >> 8) & 0xffu].x, reg[(arg >> 16) & 0xffu].x,
                                   (arg >> 24) != 0u);
            break;
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
            reg[dst] = vec4(node_vector_math(arg & 0xffu, reg[a].xyz, reg[b].xyz, reg[(arg >> 8) & 0xffu].xyz, reg[arg >> 16].x), 0.0);
            break;
        case NODE_CURVES: {  // Cycles' svm_node_curves (3 channels) and svm_node_curve (1)
            uint size = arg & 0xffffu, channels = arg >> 24;
            float min_x = node_float(pc), range_x = node_float(pc + 1u) - min_x;
            vec3 x = reg[a].xyz, y = x;
            for (uint k = 0u; k < channels; ++k)
                y[k] = node_curve_lookup(pc + 2u + k, channels, size, (x[k] - min_x) / range_x, (arg & 0x10000u) != 0u);
            reg[dst].xyz = (1.0 - reg[b].x) * x + reg[b].x * y;
            pc += 2u + channels * size;
            break;
        }
        case NODE_HSV: {  // Cycles' svm_node_hsv
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
            default: m.sheen_weight = max(v.x, 0.0); break;
            }
        }
        }
    }
}
#endif
