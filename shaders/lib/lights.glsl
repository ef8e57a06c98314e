// Light sampling for next event estimation, and the matching densities for MIS when a
// BSDF-sampled ray hits a light. Local lights (emissive triangles, sphere, spot, rect, disk)
// are picked through the light tree by their importance at the shading point, distant ones
// (sun, env) from light_cdf by power (without a tree, light_cdf holds every light). Emissive
// triangles are sampled uniformly within the solid angle they subtend (spherical triangles,
// Arvo 1995) where that is large, by area where it is small (the choice depends on the
// shading point and the triangle only, so MIS re-derives it); spheres uniformly within the
// cone they subtend (Soft Falloff: a disk facing the point, by area), rectangles/disks by
// area, the sun within its cone, the environment map by its luminance * sin(theta) table.
// All pdfs are per solid angle and include the selection probability; delta lights report
// pdf = selection probability.

struct LightSample {
    vec3 wi;
    float dist;       // to the sampled point (INFINITY_F for distant lights)
    vec3 radiance;    // arriving radiance (delta lights: irradiance-like, already / d^2)
    float pdf;
    bool delta;
};

// ---- light selection --------------------------------------------------------------------
// Light tree (Conty Estevez & Kulla 2018, sec. 4-5): a node's importance from p is its power
// times a bound of its emitters' cosine towards p over the squared distance to the node's
// centre, clamped to half the node's bounding radius (no 1/d^2 peak at its centre; a clamp at
// the full radius made every node around p look alike: 4-8x more variance on many_emitters). The
// angle to p, less the normal cone's theta_o and the bounding sphere's angular radius
// theta_u, bounds the emission angle from below; past theta_e no emitter of the node can
// reach p. Two-sided emitters (triangles) bound their normals up to sign, and the angle is
// taken from the nearer of +-axis. The receiver term bounds |cos| at p's surface (normal n,
// either side: it may transmit; n = 0: none). The importance depends on (p, n) alone, and
// MIS re-derives it from the previous vertex's position and geometric normal.
// The angle differences are taken on cosines and sines (cos_minus): no acos/asin/cos per node,
// which made the tree walk the costliest part of a light sample.
float light_tree_importance(uint node, vec3 p, vec3 n_p) {
    LightTreeNode n = light_tree[node];
    vec3 h = 0.5 * (n.bounds_max - n.bounds_min);
    float r2 = dot(h, h);
    vec3 pc = p - 0.5 * (n.bounds_min + n.bounds_max);
    float d2 = dot(pc, pc);
    float cos_factor = 1.0;
    if (d2 > r2) {
        vec2 u = vec2(sqrt(1.0 - r2 / d2), sqrt(r2 / d2));  // theta_u: (cos, sin)
        if (n.cos_o > -1.0) {
            float c = dot(n.axis, pc) * inversesqrt(d2);
            c = clamp((n.flags & LIGHT_NODE_TWO_SIDED) != 0u ? abs(c) : c, -1.0, 1.0);  // two-sided: from +-axis
            vec2 t = cos_minus(cos_minus(vec2(c, sqrt(1.0 - c * c)), vec2(n.cos_o, n.sin_o)), u);
            // 1e-3: float rounding in the sines must not cut off a node that reaches p
            if (t.x < n.cos_e - 1e-3) return 0.0;
            cos_factor = t.x;
        }
        float nn = dot(n_p, n_p);
        if (nn > 0.0) {
            float c = clamp(abs(dot(n_p, pc)) * inversesqrt(d2 * nn), 0.0, 1.0);
            cos_factor *= cos_minus(vec2(c, sqrt(1.0 - c * c)), u).x;
        }
    }
    return n.power * cos_factor / max(max(d2, 0.25 * r2), 1e-30);
}

// Probability of stepping from `parent` into its child `node`, as light_tree_sample does.
float light_tree_step(uint parent, uint node, vec3 p, vec3 n) {
    uint c = light_tree[parent].child;
    float il = light_tree_importance(c, p, n), ir = light_tree_importance(c + 1u, p, n);
    if (!(il + ir > 0.0)) return 0.0;
    float pl = il / (il + ir);
    return node == c ? pl : 1.0 - pl;
}

// One root-to-leaf walk choosing each child with probability proportional to its
// importance (u is rescaled and reused at every level): the light index, or NO_INDEX when
// no light can reach p, and the walk's probability.
uint light_tree_sample(vec3 p, vec3 n_p, float u, out float prob) {
    uint n = 0u;
    prob = 1.0;
    while ((light_tree[n].flags & LIGHT_NODE_LEAF) == 0u) {
        uint c = light_tree[n].child;
        float il = light_tree_importance(c, p, n_p), ir = light_tree_importance(c + 1u, p, n_p);
        if (!(il + ir > 0.0)) {
            prob = 0.0;
            return NO_INDEX;
        }
        float pl = il / (il + ir);  // as light_tree_step
        if (u < pl) {
            u /= pl;
            prob *= pl;
            n = c;
        } else {
            u = (u - pl) / (1.0 - pl);
            prob *= 1.0 - pl;
            n = c + 1u;
        }
        u = min(u, 0.99999994);
    }
    return light_tree[n].child;
}

// Probability that light_tree_sample from p returns light `index` (its leaf's walk).
float light_tree_pdf(uint index, vec3 p, vec3 n_p) {
    uint n = lights[index].tree_node;
    if (n == NO_INDEX) return 0.0;
    float prob = 1.0;
    while (n != 0u && prob > 0.0) {
        uint parent = light_tree[n].parent;
        prob *= light_tree_step(parent, n, p, n_p);
        n = parent;
    }
    return prob;
}

bool light_tree_on() { return scene.light_tree_nodes > 0u; }

// Probability of picking light `index` from light_cdf: all lights, or with the tree the
// distant ones (sun, env) after the tree was not chosen.
float light_cdf_pick_pdf(uint index) {
    float p = light_cdf[index + 1u] - light_cdf[index];
    return light_tree_on() ? (1.0 - scene.light_tree_prob) * p : p;
}

// Probability that sample_light from p (surface normal n) picks light `index`.
float light_pick_pdf(uint index, vec3 p, vec3 n) {
    if (light_tree_on() && lights[index].tree_node != NO_INDEX)
        return scene.light_tree_prob * light_tree_pdf(index, p, n);
    return light_cdf_pick_pdf(index);
}

// Cycles' spot cone: smoothstep over the blend region, no extra cosine (Cycles >= 4.0).
float spot_attenuation(Light l, vec3 from_light) {
    float c = dot(from_light, l.direction);
    if (l.spot_smooth <= 0.0) return c > l.cos_half_angle ? 1.0 : 0.0;
    return smoothstep(0.0, 1.0, (c - l.cos_half_angle) / l.spot_smooth);
}

// ---- environment ----------------------------------------------------------------------
// atan2 refined by one Newton step: Vulkan allows atan/asin 4096 ulp, and lavapipe's are off
// by up to ~4e-4 rad, which moved texel edges away from where env_sample puts them (a sample
// near an edge then got the neighbour's radiance and MIS pdf: fireflies next to a bright sun).
float atan2_accurate(float y, float x) {
    float a = atan(y, x);
    float c = cos(a), s = sin(a);
    float den = x * c + y * s;  // |(x, y)| cos(error) > 0 unless x = y = 0
    return den > 0.0 ? a + (y * c - x * s) / den : a;
}

// Blender's equirectangular mapping: u = 0.5 - atan2(y, x) / 2pi,
// v = 0.5 + atan2(z, hypot(x, y)) / pi; texel row 0 is the top (v = 1).
vec2 env_direction_to_uv(vec3 d) {
    return vec2(0.5 - atan2_accurate(d.y, d.x) * (0.5 * INV_PI), 0.5 + atan2_accurate(d.z, length(d.xy)) * INV_PI);
}

uvec2 env_texel(vec2 uv) {  // uv may leave [0,1] by rounding (at the seam, the poles)
    uint col = min(uint(clamp(uv.x, 0.0, 1.0) * float(scene.env_width)), scene.env_width - 1u);
    uint row = min(uint(clamp(1.0 - uv.y, 0.0, 1.0) * float(scene.env_height)), scene.env_height - 1u);
    return uvec2(col, row);
}

vec3 env_radiance(vec3 d) {
    if (!HAS(FEATURE_ENV_MAP) || scene.env_width == 0u) return scene.env_color;
    uvec2 t = env_texel(env_direction_to_uv(d));
    return env_texels[t.y * scene.env_width + t.x];
}

// Solid-angle pdf of sampling direction d from the environment (selection excluded).
float env_pdf(vec3 d) {
    if (!HAS(FEATURE_ENV_MAP) || scene.env_width == 0u) return 1.0 / (4.0 * PI);
    if (scene.env_total <= 0.0) return 0.0;
    uvec2 t = env_texel(env_direction_to_uv(d));
    uint w = scene.env_width, h = scene.env_height;
    float sin_theta = length(d.xy);  // not sqrt(1 - z^2): that cancels near the poles
    if (sin_theta <= 0.0) return 0.0;
    float p_row = env_marginal[t.y + 1u] - env_marginal[t.y];
    float p_col = env_conditional[t.y * (w + 1u) + t.x + 1u] - env_conditional[t.y * (w + 1u) + t.x];
    return p_row * p_col * float(w * h) / (2.0 * PI * PI * sin_theta);
}

vec3 env_sample(vec2 u, out float pdf) {
    if (!HAS(FEATURE_ENV_MAP) || scene.env_width == 0u) {
        pdf = 1.0 / (4.0 * PI);
        return uniform_sphere(u);
    }
    uint w = scene.env_width, h = scene.env_height;
    uint row = sample_env_marginal(0u, h, u.y);
    float p_row = env_marginal[row + 1u] - env_marginal[row];
    float v_in = clamp((u.y - env_marginal[row]) / max(p_row, 1e-20), 0.0, 0.99999994);
    uint col = sample_env_conditional(row * (w + 1u), w, u.x);
    float c0 = env_conditional[row * (w + 1u) + col], c1 = env_conditional[row * (w + 1u) + col + 1u];
    float u_in = clamp((u.x - c0) / max(c1 - c0, 1e-20), 0.0, 0.99999994);
    float uu = (float(col) + u_in) / float(w);
    float vv = 1.0 - (float(row) + v_in) / float(h);
    float phi = 2.0 * PI * (0.5 - uu);
    float theta = PI * (1.0 - vv);
    float sin_theta = sin(theta);
    vec3 d = vec3(sin_theta * cos(phi), sin_theta * sin(phi), cos(theta));
    pdf = sin_theta > 0.0 ? p_row * (c1 - c0) * float(w * h) / (2.0 * PI * PI * sin_theta) : 0.0;
    return d;
}

// ---- emissive triangles -----------------------------------------------------------------
// Solid angles below this are sampled by area: the spherical construction loses precision in
// float (1 - q^2 below cancels) and the area density is nearly uniform in solid angle there.
// Above TRI_SPHERICAL_MAX the triangle nearly fills the hemisphere and its angles approach pi.
const float TRI_SPHERICAL_MIN = 1e-3;
const float TRI_SPHERICAL_MAX = 6.2;

bool triangle_sampled_spherical(float omega) { return omega >= TRI_SPHERICAL_MIN && omega <= TRI_SPHERICAL_MAX; }

// Solid angle of triangle light l seen from p: Van Oosterom & Strackee 1983,
// tan(omega / 2) = |a . (b x c)| / (1 + a.b + b.c + c.a) for unit vectors a, b, c.
float triangle_solid_angle(Light l, vec3 p) {
    vec3 a = normalize(l.position - p);
    vec3 b = normalize(l.position + l.axis_u - p);
    vec3 c = normalize(l.position + l.axis_v - p);
    float num = abs(dot(a, cross(b, c)));
    float den = 1.0 + dot(a, b) + dot(b, c) + dot(c, a);
    float omega = 2.0 * atan2_accurate(num, den);
    return omega > 0.0 ? omega : 0.0;  // NaN (p on a vertex) -> 0: area sampling
}

// A direction uniformly distributed in the spherical triangle abc of solid angle omega
// (Arvo 1995, "Stratified sampling of spherical triangles", fig. 2): u.x picks the area of
// the sub-triangle a b c' (c' on arc ac), u.y a point on arc b c'. The cosines that would
// cancel for small triangles are written as products of sines (cos(x - al) - cos(al) =
// 2 sin(x/2) sin(al - x/2), 1 - cos c = |a - b|^2 / 2).
vec3 sample_spherical_triangle(vec3 a0, vec3 b0, vec3 c0, float omega, vec2 u) {
    // c' moves along arc ac: make that the longest arc (b the vertex of the largest angle),
    // where 1 - q^2 cancels least. For thin triangles (slivers, grazing views) other labels
    // put a few % too few samples near a sharp vertex (measured in float32).
    float dab = dot(a0, b0), dbc = dot(b0, c0), dca = dot(c0, a0);
    vec3 a = a0, b = b0, c = c0;
    if (dab <= min(dbc, dca)) { a = b0; b = c0; c = a0; }
    else if (dbc < dca) { a = c0; b = a0; c = b0; }
    vec3 nab = cross(a, b), nac = cross(a, c);
    float inv = inversesqrt(dot(nab, nab) * dot(nac, nac));
    float cos_al = dot(nab, nac) * inv;
    float sin_al = abs(dot(a, cross(b, c))) * inv;  // |nab x nac| = |det(a, b, c)|
    float area = u.x * omega;
    float al = atan2_accurate(sin_al, cos_al);
    float s = sin(area - al);
    float t = cos(area - al);
    float h = sin(0.5 * area);
    float uu = 2.0 * h * sin(al - 0.5 * area);              // t - cos(al)
    vec3 ab = a - b;
    float v = sin(area) * cos_al + sin_al * (2.0 * h * h - 0.5 * dot(ab, ab));  // s + sin(al) cos(c)
    float q = ((v * t - uu * s) * cos_al - v) / ((v * s + uu * t) * sin_al);  // cos of arc a c'
    q = clamp(q, -1.0, 1.0);
    vec3 c_perp = normalize(c - dot(c, a) * a);
    vec3 c2 = q * a + sqrt(max(0.0, (1.0 - q) * (1.0 + q))) * c_perp;
    // uniform in the sub-triangle: cos of the arc from b, linear in u.y (1 - cos as |.|^2 / 2)
    vec3 bc2 = b - c2;
    float omz = u.y * 0.5 * dot(bc2, bc2);  // 1 - z
    float z = 1.0 - omz;
    vec3 w = c2 - dot(c2, b) * b;
    float wl = length(w);
    if (!(wl > 0.0)) return b;
    return normalize(z * b + sqrt(max(0.0, omz * (2.0 - omz))) * (w / wl));
}

// ---- sampling -------------------------------------------------------------------------
bool sample_one_light(uint index, vec3 p, vec2 u, out LightSample ls) {
    Light l = lights[index];
    ls.delta = false;
    ls.dist = INFINITY_F;
    ls.radiance = vec3(0.0);
    ls.pdf = 0.0;
    ls.wi = vec3(0.0, 0.0, 1.0);
    if (HAS(FEATURE_TRIANGLE_LIGHTS) && l.type == LIGHT_TRIANGLE) {
        float omega = triangle_solid_angle(l, p);
        if (triangle_sampled_spherical(omega)) {
            vec3 a = normalize(l.position - p);
            vec3 b = normalize(l.position + l.axis_u - p);
            vec3 c = normalize(l.position + l.axis_v - p);
            ls.wi = sample_spherical_triangle(a, b, c, omega, u);
            vec3 n = cross(l.axis_u, l.axis_v);
            float t = dot(n, l.position - p) / dot(n, ls.wi);  // onto the triangle's plane
            if (!(t > 0.0) || isinf(t) || any(isnan(ls.wi))) return false;
            // The construction loses a few ulps of its arcs (more for slivers): clamp the
            // point's barycentrics into the triangle so the shadow ray aims at the emitter.
            vec3 q = p + t * ls.wi - l.position;
            float uu = dot(l.axis_u, l.axis_u), uv = dot(l.axis_u, l.axis_v), vv = dot(l.axis_v, l.axis_v);
            float qu = dot(q, l.axis_u), qv = dot(q, l.axis_v);
            float det = uu * vv - uv * uv;
            // (1e-6 inside: a point exactly on an edge may miss the triangle in a hit test)
            vec2 bc = max(vec2(vv * qu - uv * qv, uu * qv - uv * qu) / det, vec2(1e-6));
            bc *= (1.0 - 1e-6) / max(1.0 - 1e-6, bc.x + bc.y);
            vec3 to = l.position + bc.x * l.axis_u + bc.y * l.axis_v - p;
            ls.dist = length(to);
            ls.wi = to / ls.dist;
            if (!(ls.dist > 0.0)) return false;
            ls.pdf = 1.0 / omega;
            ls.radiance = l.radiance;
            return true;
        }
        float su = sqrt(u.x);
        vec3 q = l.position + (1.0 - su) * l.axis_u + (u.y * su) * l.axis_v;
        vec3 to = q - p;
        float d2 = dot(to, to);
        ls.dist = sqrt(d2);
        ls.wi = to / ls.dist;
        float cos_l = abs(dot(l.direction, ls.wi));  // emits from both sides
        if (cos_l <= 0.0 || l.area <= 0.0) return false;
        ls.pdf = d2 / (l.area * cos_l);
        ls.radiance = l.radiance;
        return true;
    }
    if (HAS(FEATURE_SPHERE_LIGHTS) && (l.type == LIGHT_SPHERE || l.type == LIGHT_SPOT)) {
        vec3 to = l.position - p;
        float d2 = dot(to, to);
        float d = sqrt(d2);
        vec3 axis = to / d;
        if ((l.flags & LIGHT_FLAG_SOFT_FALLOFF) != 0u) {
            // Soft Falloff: a disk of radius r facing p, sampled uniformly by area (pdf 1/(pi r^2)
            // -> dist^2 / (pi r^2 cos_l) per solid angle); the spot cone is evaluated along the
            // sampled direction (Cycles' point_light_sample / spot_light_sample, is_sphere off).
            if (!(d > 0.0)) return false;
            vec3 t, b;
            make_basis(-axis, t, b);
            vec2 o = l.radius * concentric_disk(u);
            vec3 to_q = to + o.x * t + o.y * b;
            ls.dist = length(to_q);
            ls.wi = to_q / ls.dist;
            float cos_l = dot(axis, ls.wi);  // disk normal -axis . -wi
            float att = l.type == LIGHT_SPOT ? spot_attenuation(l, -ls.wi) : 1.0;
            if (cos_l <= 0.0 || att <= 0.0) return false;
            ls.pdf = ls.dist * ls.dist / (l.area * cos_l);
            ls.radiance = l.radiance * att;
            return true;
        }
        float att = l.type == LIGHT_SPOT ? spot_attenuation(l, -axis) : 1.0;
        if (att <= 0.0) return false;
        if (l.radius <= 0.0) {  // point light: delta, radiance field holds the intensity
            ls.wi = axis;
            ls.dist = d;
            ls.radiance = l.radiance * att / d2;
            ls.pdf = 1.0;
            ls.delta = true;
            return true;
        }
        float r2 = l.radius * l.radius;
        if (d2 <= r2) return false;  // inside the light
        float omc = one_minus_cos_from_sin2(r2 / d2);
        vec3 t, b;
        make_basis(axis, t, b);
        vec3 local = uniform_cone(u, omc);
        ls.wi = normalize(local.x * t + local.y * b + local.z * axis);
        // distance to the near intersection with the sphere
        float proj = dot(to, ls.wi);
        float disc = r2 - (d2 - proj * proj);
        ls.dist = proj - sqrt(max(0.0, disc));
        ls.pdf = 1.0 / (2.0 * PI * omc);
        ls.radiance = l.radiance * att;
        return true;
    }
    if (HAS(FEATURE_SUN) && l.type == LIGHT_SUN) {
        if (l.cos_half_angle >= 1.0) {
            ls.wi = l.direction;
            ls.radiance = l.radiance;
            ls.pdf = 1.0;
            ls.delta = true;
            return true;
        }
        vec3 t, b;
        make_basis(l.direction, t, b);
        float omc = 1.0 - l.cos_half_angle;
        vec3 local = uniform_cone(u, omc);
        ls.wi = normalize(local.x * t + local.y * b + local.z * l.direction);
        ls.pdf = 1.0 / (2.0 * PI * omc);
        ls.radiance = l.radiance;
        return true;
    }
    if (HAS(FEATURE_AREA_LIGHTS) && (l.type == LIGHT_RECT || l.type == LIGHT_DISK)) {
        vec2 o = l.type == LIGHT_RECT ? u - 0.5 : 0.5 * concentric_disk(u);
        vec3 q = l.position + o.x * l.axis_u + o.y * l.axis_v;
        vec3 to = q - p;
        float d2 = dot(to, to);
        ls.dist = sqrt(d2);
        ls.wi = to / ls.dist;
        float cos_l = -dot(l.direction, ls.wi);  // one-sided: emits along direction
        if (cos_l <= 0.0 || l.area <= 0.0) return false;
        ls.pdf = d2 / (l.area * cos_l);
        ls.radiance = l.radiance;
        return true;
    }
    if (!HAS(FEATURE_ENV)) return false;
    // environment
    ls.wi = env_sample(u, ls.pdf);
    ls.radiance = env_radiance(ls.wi);
    return ls.pdf > 0.0;
}

// Picks a light (by power, or through the tree) and samples it; ls.pdf includes the
// selection probability.
// n: the geometric normal at p (either sign), or 0 (the tree then ignores the receiver).
bool sample_light(vec3 p, vec3 n, vec3 u, out LightSample ls) {
    if (scene.light_count == 0u) return false;
    uint index;
    float select;
    float tree = light_tree_on() ? scene.light_tree_prob : 0.0;
    if (u.z < tree) {
        index = light_tree_sample(p, n, u.z / tree, select);
        if (index == NO_INDEX) return false;
        select *= tree;
    } else {
        float v = tree > 0.0 ? min((u.z - tree) / (1.0 - tree), 0.99999994) : u.z;
        index = sample_light_cdf(0u, scene.light_count, v);
        select = light_cdf_pick_pdf(index);
    }
    if (!(select > 0.0) || !sample_one_light(index, p, u.xy, ls)) return false;
    ls.pdf *= select;
    return ls.pdf > 0.0;
}

// ---- BSDF rays hitting lights ---------------------------------------------------------
// Density with which sample_light from o (normal n) would have produced the direction that hit
// triangle light `index` at distance t with cosine cos_l at the light (the same spherical/area
// choice).
float triangle_light_pdf(uint index, vec3 o, vec3 n, float t, float cos_l) {
    Light l = lights[index];
    float omega = triangle_solid_angle(l, o);
    if (triangle_sampled_spherical(omega)) return light_pick_pdf(index, o, n) / omega;
    return light_pick_pdf(index, o, n) * t * t / (l.area * max(abs(cos_l), 1e-8));
}

// Analytic light `index` (sphere, spot, rect, disk; not the sun) along the ray o + t d,
// 0 < t < t_max: true with t, radiance and pdf (incl. selection) as seen from o (normal n).
bool analytic_light_hit(uint index, vec3 o, vec3 n, vec3 d, float t_max, out float t, out vec3 radiance, out float pdf) {
    Light l = lights[index];
    t = t_max;
    radiance = vec3(0.0);
    pdf = 0.0;
    if (HAS(FEATURE_SPHERE_LIGHTS) && (l.type == LIGHT_SPHERE || l.type == LIGHT_SPOT)) {
        if (l.radius <= 0.0) return false;
        vec3 oc = o - l.position;
        if ((l.flags & LIGHT_FLAG_SOFT_FALLOFF) != 0u) {  // the disk facing o (see sample_one_light)
            float oc2 = dot(oc, oc);
            if (!(oc2 > 0.0)) return false;
            vec3 n = oc * inversesqrt(oc2);
            float denom = dot(d, n);
            if (denom >= 0.0) return false;
            t = dot(-oc, n) / denom;
            vec3 q = o + t * d - l.position;
            if (t <= 0.0 || t >= t_max || dot(q, q) > l.radius * l.radius) return false;
            float att = l.type == LIGHT_SPOT ? spot_attenuation(l, -d) : 1.0;
            radiance = l.radiance * att;
            pdf = att > 0.0 ? light_pick_pdf(index, o, n) * t * t / (l.area * -denom) : 0.0;
            return true;
        }
        float b = dot(oc, d);
        float c = dot(oc, oc) - l.radius * l.radius;
        if (c <= 0.0) return false;  // origin inside: ignore
        float disc = b * b - c;
        if (disc < 0.0) return false;
        t = -b - sqrt(disc);
        if (t <= 0.0 || t >= t_max) return false;
        float att = l.type == LIGHT_SPOT ? spot_attenuation(l, normalize(oc)) : 1.0;
        radiance = l.radiance * att;
        // outside a spot's cone sample_one_light gives up: NEE's density there is 0
        float omc = one_minus_cos_from_sin2(l.radius * l.radius / dot(oc, oc));
        pdf = att > 0.0 ? light_pick_pdf(index, o, n) / (2.0 * PI * omc) : 0.0;
        return true;
    }
    if (HAS(FEATURE_AREA_LIGHTS) && (l.type == LIGHT_RECT || l.type == LIGHT_DISK)) {
        float denom = dot(d, l.direction);
        if (denom >= 0.0) return false;  // back side or parallel: invisible
        t = dot(l.position - o, l.direction) / denom;
        if (t <= 0.0 || t >= t_max) return false;
        vec3 q = o + t * d - l.position;
        float su = dot(q, l.axis_u) / dot(l.axis_u, l.axis_u);
        float sv = dot(q, l.axis_v) / dot(l.axis_v, l.axis_v);
        bool inside = l.type == LIGHT_RECT ? (abs(su) <= 0.5 && abs(sv) <= 0.5) : (su * su + sv * sv <= 0.25);
        if (!inside) return false;
        radiance = l.radiance;
        pdf = light_pick_pdf(index, o, n) * t * t / (l.area * -denom);
        return true;
    }
    return false;
}

// Analytic lights a ray can see: camera rays only those visible to the camera (Blender's
// per-object ray visibility), which the host puts first.
uint analytic_end(bool camera_ray) {
    return scene.analytic_first + (camera_ray ? scene.analytic_camera_count : scene.analytic_count);
}

// Radiance and MIS pdf (incl. selection) of everything at infinity in direction d:
// the environment plus any sun disc containing d.
vec3 distant_radiance(vec3 d, bool camera_ray, out float pdf) {
    vec3 radiance = vec3(0.0);
    pdf = 0.0;
    if (HAS(FEATURE_ENV) && scene.env_light != NO_INDEX) {
        radiance += env_radiance(d);
        pdf += light_cdf_pick_pdf(scene.env_light) * env_pdf(d);
    }
    for (uint i = scene.analytic_first; HAS(FEATURE_SUN) && i < analytic_end(camera_ray); ++i) {
        Light l = lights[i];
        if (l.type != LIGHT_SUN || l.cos_half_angle >= 1.0) continue;
        if (dot(d, l.direction) >= l.cos_half_angle) {
            radiance += l.radiance;
            pdf += light_cdf_pick_pdf(i) / (2.0 * PI * (1.0 - l.cos_half_angle));
        }
    }
    return radiance;
}
