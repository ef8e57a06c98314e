#include "scene/scene.h"

#include "scene/light_tree.h"

#include "vk/pipeline.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <numeric>
#include <stdexcept>

namespace px {

namespace {

constexpr float kPi = 3.14159265358979f;

std::string shape_str(const std::vector<size_t>& s) {
    std::string r = "(";
    for (size_t i = 0; i < s.size(); ++i) r += (i ? ", " : "") + std::to_string(s[i]);
    return r + (s.size() == 1 ? ",)" : ")");
}

[[noreturn]] void bad(const std::string& msg) { throw std::invalid_argument("scene: " + msg); }

// Checked access to one named array: dtype kind, item size and trailing dimensions.
template <class T>
struct Arr {
    const T* data = nullptr;
    size_t rows = 0;  // first dimension
};

template <class T>
Arr<T> get(const SceneArrays& a, const std::string& name, char kind, std::vector<size_t> trailing,
           bool optional = false) {
    auto it = a.find(name);
    if (it == a.end()) {
        if (optional) return {};
        bad("missing array '" + name + "'");
    }
    const ArrayView& v = it->second;
    if (v.kind != kind || v.itemsize != sizeof(T))
        bad("array '" + name + "' has the wrong dtype (expected " +
            (kind == 'f' ? "float32" : kind == 'u' ? (sizeof(T) == 1 ? "uint8" : sizeof(T) == 2 ? "uint16" : "uint32") : "int32") + ")");
    bool ok = v.shape.size() == trailing.size() + 1;
    for (size_t i = 0; ok && i < trailing.size(); ++i) ok = v.shape[i + 1] == trailing[i];
    if (!ok) {
        std::vector<size_t> expect = {0};
        expect.insert(expect.end(), trailing.begin(), trailing.end());
        std::string e = shape_str(expect);
        e.replace(1, 1, "N");
        bad("array '" + name + "' has shape " + shape_str(v.shape) + ", expected " + e);
    }
    return {static_cast<const T*>(v.data), v.shape[0]};
}

bool finite3(const float* p) { return std::isfinite(p[0]) && std::isfinite(p[1]) && std::isfinite(p[2]); }
double max_abs3(const float* p) { return std::max({std::fabs(double(p[0])), std::fabs(double(p[1])), std::fabs(double(p[2]))}); }
double max3(const float* p) { return std::max({double(p[0]), double(p[1]), double(p[2])}); }
std::string num(double v) {
    char b[32];
    std::snprintf(b, sizeof b, "%g", v);
    return b;
}
// Double-precision vectors for derived quantities that may leave float32's range.
struct dvec3 {
    double x, y, z;
};
dvec3 d3(const float* p) { return {p[0], p[1], p[2]}; }
dvec3 dcross(dvec3 a, dvec3 b) { return {a.y * b.z - a.z * b.y, a.z * b.x - a.x * b.z, a.x * b.y - a.y * b.x}; }
double ddot(dvec3 a, dvec3 b) { return a.x * b.x + a.y * b.y + a.z * b.z; }
double dlength(dvec3 a) { return std::sqrt(ddot(a, a)); }
vec3 v3(const float* p) { return {p[0], p[1], p[2]}; }
vec3 operator+(vec3 a, vec3 b) { return {a.x + b.x, a.y + b.y, a.z + b.z}; }
vec3 operator-(vec3 a, vec3 b) { return {a.x - b.x, a.y - b.y, a.z - b.z}; }
vec3 operator*(vec3 a, float s) { return {a.x * s, a.y * s, a.z * s}; }
vec3 vmin(vec3 a, vec3 b) { return {std::min(a.x, b.x), std::min(a.y, b.y), std::min(a.z, b.z)}; }
vec3 vmax(vec3 a, vec3 b) { return {std::max(a.x, b.x), std::max(a.y, b.y), std::max(a.z, b.z)}; }
vec3 cross(vec3 a, vec3 b) { return {a.y * b.z - a.z * b.y, a.z * b.x - a.x * b.z, a.x * b.y - a.y * b.x}; }
float dot(vec3 a, vec3 b) { return a.x * b.x + a.y * b.y + a.z * b.z; }
float length(vec3 a) { return std::sqrt(dot(a, a)); }
vec3 normalize(vec3 a) {
    float l = length(a);
    return l > 0 ? a * (1.0f / l) : vec3{0, 0, 1};
}
float luminance(vec3 c) { return 0.2126f * c.x + 0.7152f * c.y + 0.0722f * c.z; }

vec3 transform_point(const vec4* rows, vec3 p) {
    return {rows[0].x * p.x + rows[0].y * p.y + rows[0].z * p.z + rows[0].w,
            rows[1].x * p.x + rows[1].y * p.y + rows[1].z * p.z + rows[1].w,
            rows[2].x * p.x + rows[2].y * p.y + rows[2].z * p.z + rows[2].w};
}

// Analytic light `i` of the light_* arrays in Cycles' units -> radiance (see DESIGN "Units
// match Cycles"). Derived values are computed in double, so an overflow is an error naming
// the light rather than an Inf in the light table. `weight` is its selection weight (emitted
// power, luminance); 0 for a light that emits nothing.
struct LightArrays {
    Arr<uint32_t> type;
    Arr<float> position, direction, axis_u, axis_v, radius, color, spot_size, spot_blend, sun_angle;
};

Light analytic_light(const LightArrays& a, size_t i, double scene_radius, double& weight) {
    const std::string id = "light " + std::to_string(i);
    const uint type = a.type.data[i];
    if (type < LIGHT_SPHERE || type > LIGHT_DISK) bad(id + ": unknown type " + std::to_string(type));
    const float *pos = a.position.data + 3 * i, *dir = a.direction.data + 3 * i, *u = a.axis_u.data + 3 * i,
                *v = a.axis_v.data + 3 * i, *color = a.color.data + 3 * i;
    const float radius = a.radius.data[i], spot_size = a.spot_size.data[i], spot_blend = a.spot_blend.data[i],
                sun_angle = a.sun_angle.data[i];
    if (!finite3(pos) || !finite3(dir) || !finite3(u) || !finite3(v) || !finite3(color) || !std::isfinite(radius) ||
        !std::isfinite(spot_size) || !std::isfinite(spot_blend) || !std::isfinite(sun_angle))
        bad(id + ": NaN or infinite value");
    const double dir_length = dlength(d3(dir));
    if (dir_length == 0) bad(id + ": zero direction");
    if (std::max({max_abs3(pos), max_abs3(u), max_abs3(v), std::fabs(double(radius))}) > SceneLimits::coordinate)
        bad(id + ": position or size beyond the coordinate limit of " + num(SceneLimits::coordinate) + " m");

    Light l{};
    l.type = type;
    l.position = v3(pos);
    const dvec3 d = d3(dir);
    const double sign = type == LIGHT_SUN ? -1.0 : 1.0;  // sun: the direction towards it
    l.direction = {float(sign * d.x / dir_length), float(sign * d.y / dir_length), float(sign * d.z / dir_length)};
    l.axis_u = v3(u);
    l.axis_v = v3(v);
    l.radius = std::max(radius, 0.0f);
    const double r = l.radius;
    double scale = 0;  // radiance = colour * scale
    switch (type) {
        case LIGHT_SPHERE:
        case LIGHT_SPOT:
            // Power P spread over 4π sr: intensity I = P / (4π). A sphere of radius r with
            // radiance L has I = L π r², so L = P / (4π · π r²). Radius 0: the radiance
            // field holds the intensity.
            scale = r > 0 ? 1.0 / (4 * kPi * kPi * r * r) : 1.0 / (4 * kPi);
            l.area = float(kPi * r * r);
            if (type == LIGHT_SPOT) {
                l.cos_half_angle = std::cos(std::min(std::max(spot_size, 0.0f), kPi) * 0.5f);
                l.spot_smooth = (1.0f - l.cos_half_angle) * std::min(std::max(spot_blend, 0.0f), 1.0f);
            }
            break;
        case LIGHT_SUN: {
            // Strength S is the irradiance at normal incidence; a disc of half-angle h has
            // projected solid angle π sin²h, so its radiance is S / (π sin²h).
            float half = std::min(std::max(sun_angle, 0.0f), kPi) * 0.5f;
            l.cos_half_angle = std::cos(half);
            double sin_h = std::sin(half);
            scale = sin_h > 1e-4 ? 1.0 / (kPi * sin_h * sin_h) : 1.0;
            if (sin_h <= 1e-4) l.cos_half_angle = 1.0f;  // delta
            break;
        }
        default: {  // LIGHT_RECT, LIGHT_DISK
            const double full_area = dlength(dcross(d3(u), d3(v)));
            const double area = type == LIGHT_RECT ? full_area : full_area * kPi * 0.25;
            l.area = float(area);
            // One-sided Lambertian emitter of power P: L = P / (π A).
            scale = l.area > 0 ? 1.0 / (kPi * area) : 0.0;
        }
    }
    const double c[3] = {std::max(double(color[0]), 0.0), std::max(double(color[1]), 0.0), std::max(double(color[2]), 0.0)};
    const double radiance[3] = {c[0] * scale, c[1] * scale, c[2] * scale};
    const double peak = std::max({radiance[0], radiance[1], radiance[2]});
    if (peak > SceneLimits::radiance)
        bad(id + ": emitted radiance " + num(peak) + " exceeds the limit of " + num(SceneLimits::radiance) +
            " (colour x power " + num(std::max({c[0], c[1], c[2]})) + " is too strong for its size)");
    l.radiance = {float(radiance[0]), float(radiance[1]), float(radiance[2])};
    const double lum = 0.2126 * radiance[0] + 0.7152 * radiance[1] + 0.0722 * radiance[2];
    switch (type) {
        case LIGHT_SPHERE:
        case LIGHT_SPOT:
            weight = r > 0 ? lum * 4 * kPi * kPi * r * r : lum * 4 * kPi;
            if (type == LIGHT_SPOT) weight *= std::max(0.05, 0.5 * (1.0 - l.cos_half_angle));
            break;
        case LIGHT_SUN:
            weight = lum * (l.cos_half_angle < 1 ? kPi * (1.0 - double(l.cos_half_angle) * l.cos_half_angle) : 1.0) * kPi *
                     scene_radius * scene_radius;
            break;
        default: weight = lum * kPi * l.area;
    }
    return l;
}

bool material_transmits(const Material& m) {
    return m.type == MATERIAL_DIELECTRIC || (m.type == MATERIAL_PRINCIPLED && m.transmission > 0.0f);
}

// Where rays leaving a surface must start contact-safe (integrator.glsl, may_touch_transmission):
// flags the instances with a transmitting material (through mix chains too) and puts their
// world boxes, grown by more than a ray offset, into info.contact_lo/hi. Beyond
// CONTACT_BOX_MAX boxes, runs of them in bvh_order are merged into their union.
void mark_transmission_contacts(const SceneGeometry& g, const std::vector<Material>& materials,
                                const ScenePlacement& placement, std::vector<InstanceInfo>& instances, SceneInfo& info) {
    auto chain_transmits = [&](int k) {  // a material or any link of its mix chain
        for (; k >= 0; k = materials[size_t(k)].mix_next)
            if (material_transmits(materials[size_t(k)])) return true;
        return false;
    };
    std::vector<bool> mesh_transmits(g.meshes.size(), false);
    for (size_t m = 0; m < g.meshes.size(); ++m)
        for (uint t = g.meshes[m].first_triangle; t < g.meshes[m].first_triangle + g.meshes[m].triangle_count && !mesh_transmits[m]; ++t)
            mesh_transmits[m] = chain_transmits(int(g.triangle_material[t]));
    std::vector<vec3> lo, hi;  // the placement's instances come with no flags set
    for (size_t i = 0; i < instances.size(); ++i) {
        if (!mesh_transmits[instances[i].mesh]) continue;
        instances[i].flags |= INSTANCE_FLAG_TRANSMITS;
        // offset_ray moves a point by at most 256 float32 ulps, about 3e-5 of its largest
        // coordinate: grow by 1e-3 of it (and 1e-4 m near the origin).
        vec3 a = placement.world_lo[i], b = placement.world_hi[i];
        float grow = 1e-3f * std::max({std::fabs(a.x), std::fabs(a.y), std::fabs(a.z), std::fabs(b.x), std::fabs(b.y),
                                       std::fabs(b.z)}) + 1e-4f;
        lo.push_back(a - vec3{grow, grow, grow}), hi.push_back(b + vec3{grow, grow, grow});
    }
    const size_t n = lo.size(), groups = std::min<size_t>(n, CONTACT_BOX_MAX);
    std::vector<uint32_t> order = bvh_order(lo, hi);
    info.contact_box_count = uint(groups);
    for (size_t k = 0; k < groups; ++k) {
        info.contact_lo[k] = {INFINITY, INFINITY, INFINITY}, info.contact_hi[k] = {-INFINITY, -INFINITY, -INFINITY};
        for (size_t j = k * n / groups; j < (k + 1) * n / groups; ++j)
            info.contact_lo[k] = vmin(info.contact_lo[k], lo[order[j]]), info.contact_hi[k] = vmax(info.contact_hi[k], hi[order[j]]);
    }
}

// FEATURE_LENS: the camera has depth of field or is a panorama.
bool camera_has_lens(const SceneInfo& info) {
    return info.aperture_radius > 0 || info.camera_type == CAMERA_PANORAMA;
}

// What the uploaded scene uses, for pipeline specialization.
uint scene_features(const SceneHost& s) {
    const SceneGeometry& g = *s.geometry;
    const std::vector<Material>& materials = s.materials->materials;
    uint f = 0;
    std::vector<bool> mesh_used(g.meshes.size(), false);
    for (const auto& inst : s.placement->instances) mesh_used[inst.mesh] = true;
    std::vector<bool> used(materials.size(), false);
    for (size_t m = 0; m < g.meshes.size(); ++m) {
        if (!mesh_used[m]) continue;
        const MeshInfo& mesh = g.meshes[m];
        if (mesh.has_normals) f |= FEATURE_SHADING_NORMALS;
        if (mesh.has_uvs) f |= FEATURE_UVS;
        for (uint t = mesh.first_triangle; t < mesh.first_triangle + mesh.triangle_count; ++t)
            used[g.triangle_material[t]] = true;
    }
    // Materials reached through a used material's mix chain are used too (acyclic, checked).
    for (size_t k = 0; k < materials.size(); ++k) {
        if (!used[k] || materials[k].mix_next < 0) continue;
        f |= FEATURE_MIX;
        for (int j = materials[k].mix_next; j >= 0 && !used[size_t(j)]; j = materials[size_t(j)].mix_next)
            used[size_t(j)] = true;
    }
    for (size_t k = 0; k < materials.size(); ++k) {
        if (!used[k]) continue;
        const Material& m = materials[k];
        if (m.type == MATERIAL_CONDUCTOR) f |= FEATURE_CONDUCTOR;
        if (m.type == MATERIAL_DIELECTRIC) f |= FEATURE_DIELECTRIC;
        if (m.type == MATERIAL_PRINCIPLED) f |= FEATURE_PRINCIPLED;
        if (material_transmits(m)) f |= FEATURE_TRANSMISSION;
        if (m.base_color_texture >= 0) f |= FEATURE_TEXTURES;
        if (m.program != NO_INDEX) f |= FEATURE_NODES | s.materials->program_features[k];
    }
    if (camera_has_lens(s.info)) f |= FEATURE_LENS;
    for (const auto& l : s.lights->lights) {
        switch (l.type) {
            case LIGHT_TRIANGLE: f |= FEATURE_TRIANGLE_LIGHTS; break;
            case LIGHT_SPHERE:
            case LIGHT_SPOT: f |= FEATURE_SPHERE_LIGHTS; break;
            case LIGHT_RECT:
            case LIGHT_DISK: f |= FEATURE_AREA_LIGHTS; break;
            case LIGHT_SUN: f |= FEATURE_SUN; break;
            case LIGHT_ENV: f |= FEATURE_ENV | (s.info.env_width ? FEATURE_ENV_MAP : 0u); break;
        }
    }
    return f;
}

// Positions, triangles, per-corner normals/uvs and meshes; triangles in bvh_order per mesh.
std::shared_ptr<const SceneGeometry> prepare_geometry(const SceneArrays& a, bool spatial_order) {
    auto out = std::make_shared<SceneGeometry>();
    SceneGeometry& g = *out;
    auto positions = get<float>(a, "positions", 'f', {3});
    auto indices = get<uint32_t>(a, "indices", 'u', {3});
    auto tri_mat = get<uint32_t>(a, "triangle_material", 'u', {});
    auto normals = get<float>(a, "corner_normals", 'f', {3, 3});
    auto uvs = get<float>(a, "corner_uvs", 'f', {3, 2});
    auto tangents = get<float>(a, "corner_tangents", 'f', {3, 4}, true);
    auto attributes = get<float>(a, "corner_attributes", 'f', {3, 4}, true);
    auto mesh_first = get<uint32_t>(a, "mesh_first_triangle", 'u', {});
    auto mesh_count = get<uint32_t>(a, "mesh_triangle_count", 'u', {});
    auto mesh_has_n = get<uint32_t>(a, "mesh_has_normals", 'u', {});
    auto mesh_has_uv = get<uint32_t>(a, "mesh_has_uvs", 'u', {});
    auto mesh_has_t = get<uint32_t>(a, "mesh_has_tangents", 'u', {}, true);
    auto materials_type = get<uint32_t>(a, "material_type", 'u', {});
    const size_t V = positions.rows, T = indices.rows, M = mesh_first.rows, K = materials_type.rows;
    if (V > 0xffffffffu || T > (1u << 28)) bad("too many vertices or triangles");
    if (tri_mat.rows != T) bad("triangle_material has " + std::to_string(tri_mat.rows) + " entries, expected " + std::to_string(T));
    if (normals.rows != 0 && normals.rows != T) bad("corner_normals must have 0 or " + std::to_string(T) + " rows");
    if (uvs.rows != 0 && uvs.rows != T) bad("corner_uvs must have 0 or " + std::to_string(T) + " rows");
    if (tangents.data && tangents.rows != 0 && tangents.rows != T)
        bad("corner_tangents must have 0 or " + std::to_string(T) + " rows");
    const size_t slots = attributes.data && T ? attributes.rows / T : 0;
    if (attributes.data && (slots * T != attributes.rows || slots > NODE_ATTRIBUTE_SLOTS))
        bad("corner_attributes must have a multiple of " + std::to_string(T) + " rows (up to " +
            std::to_string(NODE_ATTRIBUTE_SLOTS) + " slots of the triangles' corners)");
    if (mesh_count.rows != M || mesh_has_n.rows != M || mesh_has_uv.rows != M || (mesh_has_t.data && mesh_has_t.rows != M))
        bad("mesh_* arrays differ in length");
    for (size_t i = 0; i < V; ++i) {
        if (!finite3(positions.data + 3 * i)) bad("positions[" + std::to_string(i) + "] is NaN or infinite");
        if (max_abs3(positions.data + 3 * i) > SceneLimits::coordinate)
            bad("positions[" + std::to_string(i) + "] is beyond the coordinate limit of " + num(SceneLimits::coordinate) + " m");
    }
    for (size_t t = 0; t < T; ++t) {
        for (int k = 0; k < 3; ++k)
            if (indices.data[3 * t + k] >= V)
                bad("indices[" + std::to_string(t) + "] refers to vertex " + std::to_string(indices.data[3 * t + k]) +
                    ", but there are " + std::to_string(V) + " vertices");
        if (tri_mat.data[t] >= K)
            bad("triangle_material[" + std::to_string(t) + "] = " + std::to_string(tri_mat.data[t]) + " but there are " +
                std::to_string(K) + " materials");
    }
    g.positions.resize(V);
    for (size_t i = 0; i < V; ++i) g.positions[i] = v3(positions.data + 3 * i);
    g.indices.resize(T);
    g.triangle_material.assign(tri_mat.data, tri_mat.data + T);
    for (size_t t = 0; t < T; ++t) g.indices[t] = {indices.data[3 * t], indices.data[3 * t + 1], indices.data[3 * t + 2]};
    if (normals.rows) {
        g.corner_normals.resize(3 * T);
        for (size_t i = 0; i < 3 * T; ++i) {
            vec3 n = v3(normals.data + 3 * i);
            g.corner_normals[i] = finite3(normals.data + 3 * i) && length(n) > 0 ? normalize(n) : vec3{0, 0, 0};
        }
    }
    if (uvs.rows) {
        g.corner_uvs.resize(3 * T);
        for (size_t i = 0; i < 3 * T; ++i) {
            float u = uvs.data[2 * i], v = uvs.data[2 * i + 1];
            g.corner_uvs[i] = {std::isfinite(u) ? u : 0.0f, std::isfinite(v) ? v : 0.0f};
        }
    }
    const bool any_tangents = tangents.data && tangents.rows == T && T > 0;
    if (any_tangents) {  // a non-finite tangent is a zero one (the Normal Map then keeps the normal)
        g.corner_tangents.resize(3 * T);
        for (size_t i = 0; i < 3 * T; ++i) {
            const float* t = tangents.data + 4 * i;
            bool ok = finite3(t) && std::isfinite(t[3]);
            g.corner_tangents[i] = ok ? vec4{t[0], t[1], t[2], t[3] < 0.0f ? -1.0f : 1.0f} : vec4{0, 0, 0, 1};
        }
    }
    g.attribute_slots = uint32_t(slots);
    g.corner_attributes.resize(3 * T * slots);
    for (size_t i = 0; i < 3 * T * slots; ++i) {  // a non-finite value reads 0
        const float* v = attributes.data + 4 * i;
        g.corner_attributes[i] = finite3(v) && std::isfinite(v[3]) ? vec4{v[0], v[1], v[2], v[3]} : vec4{0, 0, 0, 0};
    }
    g.meshes.resize(M);
    for (size_t m = 0; m < M; ++m) {
        uint64_t first = mesh_first.data[m], count = mesh_count.data[m];
        if (first + count > T)
            bad("mesh " + std::to_string(m) + " covers triangles " + std::to_string(first) + ".." +
                std::to_string(first + count) + " but there are " + std::to_string(T));
        g.meshes[m] = {uint(first), uint(count), mesh_has_n.data[m] && normals.rows ? 1u : 0u,
                       mesh_has_uv.data[m] && uvs.rows ? 1u : 0u, {1, 1, 1}, {0, 0, 0},
                       any_tangents && mesh_has_t.data && mesh_has_t.data[m] ? 1u : 0u};
        if (!spatial_order || count < 2) continue;
        // Reorder this mesh's triangles for lavapipe's BVH builder (bvh_order).
        std::vector<vec3> tri_lo(count), tri_hi(count);
        for (size_t i = 0; i < count; ++i) {
            uvec3 tri = g.indices[first + i];
            tri_lo[i] = vmin(g.positions[tri.x], vmin(g.positions[tri.y], g.positions[tri.z]));
            tri_hi[i] = vmax(g.positions[tri.x], vmax(g.positions[tri.y], g.positions[tri.z]));
        }
        auto order = bvh_order(tri_lo, tri_hi);
        auto permute = [&](auto& vec, size_t per, size_t base = 0) {  // base: an attribute slot's start
            if (vec.empty()) return;
            std::vector<typename std::decay_t<decltype(vec)>::value_type> tmp(count * per);
            for (size_t i = 0; i < count; ++i)
                for (size_t k = 0; k < per; ++k) tmp[i * per + k] = vec[base + (first + order[i]) * per + k];
            std::copy(tmp.begin(), tmp.end(), vec.begin() + base + first * per);
        };
        permute(g.indices, 1);
        permute(g.triangle_material, 1);
        permute(g.corner_normals, 3);
        permute(g.corner_uvs, 3);
        permute(g.corner_tangents, 3);
        for (size_t slot = 0; slot < slots; ++slot) permute(g.corner_attributes, 3, slot * 3 * T);
    }
    // Object-space bounds (instance placement) and the materials the triangles need.
    g.mesh_lo.assign(M, {INFINITY, INFINITY, INFINITY});
    g.mesh_hi.assign(M, {-INFINITY, -INFINITY, -INFINITY});
    for (size_t m = 0; m < M; ++m)
        for (uint t = g.meshes[m].first_triangle; t < g.meshes[m].first_triangle + g.meshes[m].triangle_count; ++t)
            for (uint vi : {g.indices[t].x, g.indices[t].y, g.indices[t].z})
                g.mesh_lo[m] = vmin(g.mesh_lo[m], g.positions[vi]), g.mesh_hi[m] = vmax(g.mesh_hi[m], g.positions[vi]);
    // Generated coordinates: the texture space (location, half size) given, else (none, or a
    // row with NaN) the bounds, Blender's automatic one; as Cycles, a flat axis keeps scale 1
    // (mesh_texture_space).
    auto texspace = get<float>(a, "mesh_texspace", 'f', {6}, true);
    if (texspace.data && texspace.rows != M) bad("mesh_texspace differs in length from the meshes");
    for (size_t m = 0; m < M; ++m) {
        const bool given = texspace.data && finite3(texspace.data + 6 * m) && finite3(texspace.data + 6 * m + 3);
        vec3 location = given ? v3(texspace.data + 6 * m) : (g.mesh_lo[m] + g.mesh_hi[m]) * 0.5f;
        vec3 size = given ? v3(texspace.data + 6 * m + 3) : (g.mesh_hi[m] - g.mesh_lo[m]) * 0.5f;
        if (!finite3(&location.x) || !finite3(&size.x)) location = {0, 0, 0}, size = {1, 1, 1};  // an empty mesh
        vec3 scale{size.x != 0 ? 0.5f / size.x : 1.0f, size.y != 0 ? 0.5f / size.y : 1.0f, size.z != 0 ? 0.5f / size.z : 1.0f};
        g.meshes[m].texspace_scale = scale;
        g.meshes[m].texspace_offset = {0.5f - location.x * scale.x, 0.5f - location.y * scale.y, 0.5f - location.z * scale.z};
    }
    for (uint k : g.triangle_material) g.materials_needed = std::max(g.materials_needed, k + 1);
    return out;
}

// Materials and textures; the triangles' material indices must stay in range.
// A node program (types.h NODE_*) from word `start`: known operations, registers written
// before they are read, finite constants, textures that exist, and NODE_END before the end.
// Returns the FEATURE_NODE_* groups of the operations it uses.
uint check_node_program(const std::vector<uint>& words, uint32_t start, size_t textures, uint32_t attribute_slots,
                        const std::string& id) {
    const std::string where = id + ": node program at word " + std::to_string(start);
    uint64_t written = 0;  // registers set so far, a bit each
    uint features = 0;
    auto reg = [&](uint r) {
        if (r >= NODE_REGISTERS || !(written >> r & 1u)) bad(where + " reads register " + std::to_string(r) + " before it is set");
    };
    auto finite_words = [&](size_t at, size_t n) {
        for (size_t k = at; k < at + n; ++k) {
            float f;
            std::memcpy(&f, &words[k], 4);
            if (!std::isfinite(f)) bad(where + " holds a NaN or infinite constant");
        }
    };
    for (size_t pc = start;;) {
        if (pc >= words.size()) bad(where + " runs past the end of material_node_programs");
        const uint word = words[pc], op = word & 0xffu, dst = (word >> 8) & 0xffu, a = (word >> 16) & 0xffu, b = word >> 24;
        if (op == NODE_END) return features;
        if (op >= NODE_OPS) bad(where + ": unknown operation " + std::to_string(op));
        size_t size = 2;  // the instruction and its word
        if (op == NODE_CONST) size = 5;
        if (op == NODE_AFFINE) size = 13;
        if (op == NODE_MAP_RANGE || op == NODE_VORONOI || op == NODE_WAVE || op == NODE_BUMP) size = 3;
        if (op == NODE_BRICK) size = 6;
        if (op == NODE_RAMP && pc + 1 < words.size()) size = 2 + 4 * size_t(words[pc + 1] & 0xffffu);
        if (op == NODE_CURVES && pc + 1 < words.size()) size = 4 + size_t(words[pc + 1] >> 24) * (words[pc + 1] & 0xffffu);
        if (pc + size >= words.size()) bad(where + " runs past the end of material_node_programs");
        const uint arg = words[pc + 1];
        if (op == NODE_NOISE || op == NODE_VORONOI || op == NODE_WAVE || op == NODE_BRICK) features |= FEATURE_NODE_TEXTURES;
        if (op == NODE_GEOMETRY || op == NODE_ATTRIBUTE || op == NODE_BUMP || op == NODE_NORMAL_MAP || op == NODE_FRESNEL ||
            ((op == NODE_UV || op == NODE_GENERATED) && (arg >> 8 & 0xffu) != 0))
            features |= FEATURE_NODE_SURFACE;
        if (op == NODE_VECTOR_MATH || op == NODE_CURVES || op == NODE_HSV) features |= FEATURE_NODE_COLOR;
        switch (op) {
            case NODE_CONST: finite_words(pc + 1, 4); break;
            case NODE_UV:
            case NODE_GENERATED:
            case NODE_GEOMETRY:
            case NODE_ATTRIBUTE:
                if ((arg >> 8 & 0xffu) > 2) bad(where + ": unknown bump offset " + std::to_string(arg >> 8 & 0xffu));
                if (op == NODE_GEOMETRY && (arg & 0xffu) >= NODE_GEOMETRY_KINDS)
                    bad(where + ": unknown geometry output " + std::to_string(arg & 0xffu));
                if (op == NODE_ATTRIBUTE && (arg & 0xffu) >= attribute_slots)
                    bad(where + " reads attribute slot " + std::to_string(arg & 0xffu) + " of " + std::to_string(attribute_slots));
                break;
            case NODE_BUMP: reg(a), reg(b); for (int k = 0; k < 4; ++k) reg((arg >> (8 * k)) & 0xffu); break;
            case NODE_NORMAL_MAP:
                reg(a), reg(b);
                if (arg > NODE_NORMAL_MAP_BLENDER_WORLD) bad(where + ": unknown normal map space " + std::to_string(arg));
                break;
            case NODE_FRESNEL: reg(a), reg(b); if (arg > 2) bad(where + ": unknown Fresnel kind " + std::to_string(arg)); break;
            case NODE_TEXTURE:
                reg(a);
                if (arg >= textures) bad(where + " samples texture " + std::to_string(arg) + " of " + std::to_string(textures));
                break;
            case NODE_AFFINE: reg(a); finite_words(pc + 1, 12); break;
            case NODE_MATH:
                reg(a), reg(b), reg(arg >> 16);
                if ((arg & 0xffu) >= NODE_MATH_OPS) bad(where + ": unknown math operation " + std::to_string(arg & 0xffu));
                break;
            case NODE_MIX:
                reg(a), reg(b), reg((arg >> 8) & 0xffu);
                if ((arg & 0xffu) >= NODE_BLEND_MODES) bad(where + ": unknown blend mode " + std::to_string(arg & 0xffu));
                break;
            case NODE_INVERT: reg(a), reg(b); break;
            case NODE_MAP_RANGE:
                reg(a), reg((words[pc + 2] >> 16) & 0xffu);
                for (int k = 0; k < 4; ++k) reg((arg >> (8 * k)) & 0xffu);
                if (((words[pc + 2] >> 8) & 0xffu) >= NODE_MAP_RANGE_TYPES) bad(where + ": unknown map range type");
                break;
            case NODE_VECTOR_MATH:
                reg(a), reg(b), reg((arg >> 8) & 0xffu), reg(arg >> 16);
                if ((arg & 0xffu) >= NODE_VECTOR_MATH_OPS) bad(where + ": unknown vector math operation " + std::to_string(arg & 0xffu));
                break;
            case NODE_CURVES:
                reg(a), reg(b);
                if ((arg & 0xffffu) < 2 || ((arg >> 24) != 1 && (arg >> 24) != 3)) bad(where + ": a curve needs 2 rows and 1 or 3 channels");
                finite_words(pc + 2, size - 2);
                break;
            case NODE_HSV: reg(a), reg(b), reg(arg & 0xffu), reg((arg >> 8) & 0xffu), reg((arg >> 16) & 0xffu); break;
            case NODE_RAMP:
                reg(a);
                if ((arg & 0xffffu) < 2) bad(where + ": a ramp needs 2 rows at least");
                finite_words(pc + 2, size - 2);
                break;
            case NODE_SEPARATE: reg(a); if (arg > 3) bad(where + ": component " + std::to_string(arg)); break;
            case NODE_COMBINE: reg(a), reg(b), reg(arg); break;
            case NODE_STORE: reg(a); if (arg >= NODE_FIELDS) bad(where + ": unknown field " + std::to_string(arg)); break;
            case NODE_CONVERT: reg(a); if (arg > 2) bad(where + ": unknown conversion " + std::to_string(arg)); break;
            case NODE_NOISE: reg(a), reg(arg & 0xffu), reg((arg >> 8) & 0xffu), reg((arg >> 16) & 0xffu); break;
            case NODE_VORONOI:  // modes: feature < 3, output < 3
            case NODE_WAVE:     // modes: profile < 3
            case NODE_BRICK: {
                const uint more = words[pc + 2];
                reg(a), reg(b);
                for (int k = 0; k < 4; ++k) reg((arg >> (8 * k)) & 0xffu);
                for (int k = 0; k < (op == NODE_WAVE ? 1 : op == NODE_VORONOI ? 2 : 4); ++k) reg((more >> (8 * k)) & 0xffu);
                const uint modes = op == NODE_VORONOI ? more >> 16 : more >> 8;
                if ((op == NODE_VORONOI && ((modes & 3u) > 2u || (modes >> 5) > 2u)) || (op == NODE_WAVE && (modes >> 3) > 2u))
                    bad(where + ": unknown texture mode " + std::to_string(modes));
                if (op == NODE_BRICK) finite_words(pc + 3, 2);
                break;
            }
        }
        if (op != NODE_STORE) {
            if (dst >= NODE_REGISTERS) bad(where + " writes register " + std::to_string(dst));
            written |= uint64_t(1) << dst;
        }
        pc += size;
    }
}

std::shared_ptr<const SceneMaterials> prepare_materials(const SceneArrays& a, const SceneGeometry& g) {
    auto out = std::make_shared<SceneMaterials>();
    SceneMaterials& s = *out;
    auto materials_type = get<uint32_t>(a, "material_type", 'u', {});
    const size_t K = materials_type.rows;
    if (K < g.materials_needed)
        bad("triangle_material refers to material " + std::to_string(g.materials_needed - 1) + " but there are " +
            std::to_string(K) + " materials");
    auto base_color = get<float>(a, "material_base_color", 'f', {3});
    auto roughness = get<float>(a, "material_roughness", 'f', {});
    auto ior = get<float>(a, "material_ior", 'f', {});
    auto emission = get<float>(a, "material_emission", 'f', {3});
    auto texture = get<int32_t>(a, "material_texture", 'i', {});
    // Optional (files written before mix chains): absent means no mixes.
    auto mix_next = get<int32_t>(a, "material_mix_next", 'i', {}, true);
    auto mix_weight = get<float>(a, "material_mix_weight", 'f', {}, true);
    auto multiscatter = get<uint32_t>(a, "material_multiscatter", 'u', {}, true);  // optional: off
    // Principled inputs (Material from specular_tint on, in struct order); optional: none.
    auto principled = get<float>(a, "material_principled", 'f', {17}, true);
    // Node programs (optional: none): each material's first word or -1, and the words.
    auto program = get<int32_t>(a, "material_node_program", 'i', {}, true);
    auto program_words = get<uint32_t>(a, "material_node_programs", 'u', {}, true);
    if (program.data && program.rows != K) bad("material_node_program differs in length from material_type");
    s.node_programs.assign(program_words.data, program_words.data + program_words.rows);
    auto texels = get<uint8_t>(a, "texture_texels", 'u', {4});
    auto tex_info = get<uint32_t>(a, "texture_info", 'u', {3});
    auto tex_flags = get<uint32_t>(a, "texture_flags", 'u', {}, true);                  // optional: 0
    auto half_texels = get<uint16_t>(a, "texture_half_texels", 'u', {4}, true);        // optional: none
    if (base_color.rows != K || roughness.rows != K || ior.rows != K || emission.rows != K || texture.rows != K)
        bad("material_* arrays differ in length");
    if ((mix_next.data && mix_next.rows != K) || (mix_weight.data && mix_weight.rows != K))
        bad("material_mix_* arrays differ in length from material_type");
    if (multiscatter.data && multiscatter.rows != K) bad("material_multiscatter differs in length from material_type");
    if (principled.data && principled.rows != K) bad("material_principled differs in length from material_type");
    if (!mix_next.data != !mix_weight.data) bad("material_mix_next and material_mix_weight must be given together");
    if (tex_flags.data && tex_flags.rows != tex_info.rows) bad("texture_flags and texture_info differ in length");
    // One word buffer: the byte texels (one word each), then the half texels (two words each).
    if (uint64_t(texels.rows) + 2 * uint64_t(half_texels.rows) > 0xffffffffull) bad("textures exceed 2^32 texel words");
    for (size_t x = 0; x < tex_info.rows; ++x) {
        const uint32_t* ti = tex_info.data + 3 * x;
        const uint32_t flags = tex_flags.data ? tex_flags.data[x] : 0u;
        const std::string id = "texture " + std::to_string(x);
        if (flags & ~(TEXTURE_FLAG_CLOSEST | TEXTURE_FLAG_HALF)) bad(id + " has unknown texture_flags bits");
        const bool half = (flags & TEXTURE_FLAG_HALF) != 0;
        if (ti[1] == 0 || ti[2] == 0) bad(id + " has zero size");
        if (uint64_t(ti[0]) + uint64_t(ti[1]) * ti[2] > (half ? half_texels.rows : texels.rows))
            bad(id + " extends past the end of " + (half ? "texture_half_texels" : "texture_texels"));
        const uint32_t offset = half ? uint32_t(texels.rows + 2 * uint64_t(ti[0])) : ti[0];
        s.textures.push_back({offset, ti[1], ti[2], flags});
    }
    s.texels.resize(texels.rows + 2 * half_texels.rows);
    for (size_t i = 0; i < texels.rows; ++i) {
        const uint8_t* c = texels.data + 4 * i;
        s.texels[i] = uint(c[0]) | uint(c[1]) << 8 | uint(c[2]) << 16 | uint(c[3]) << 24;
    }
    for (size_t i = 0; i < 2 * half_texels.rows; ++i)  // RG, BA: as GLSL's unpackHalf2x16 reads them
        s.texels[texels.rows + i] = uint(half_texels.data[2 * i]) | uint(half_texels.data[2 * i + 1]) << 16;
    s.materials.resize(K);
    for (size_t k = 0; k < K; ++k) {
        Material& m = s.materials[k];
        std::string id = "material " + std::to_string(k);
        if (materials_type.data[k] > MATERIAL_PRINCIPLED) bad(id + ": unknown type " + std::to_string(materials_type.data[k]));
        if (!finite3(base_color.data + 3 * k) || !finite3(emission.data + 3 * k) || !std::isfinite(roughness.data[k]) ||
            !std::isfinite(ior.data[k]))
            bad(id + ": NaN or infinite value");
        if (!(ior.data[k] >= SceneLimits::ior_min && ior.data[k] <= SceneLimits::ior_max))
            bad(id + ": ior must be positive, in " + num(SceneLimits::ior_min) + ".." + num(SceneLimits::ior_max) +
                " (got " + num(ior.data[k]) + ")");
        if (max3(base_color.data + 3 * k) > SceneLimits::albedo)
            bad(id + ": base_color " + num(max3(base_color.data + 3 * k)) + " exceeds the limit of " +
                num(SceneLimits::albedo));
        if (max3(emission.data + 3 * k) > SceneLimits::radiance)
            bad(id + ": emission " + num(max3(emission.data + 3 * k)) + " exceeds the radiance limit of " +
                num(SceneLimits::radiance));
        if (texture.data[k] >= int32_t(s.textures.size()))
            bad(id + ": texture " + std::to_string(texture.data[k]) + " out of range (" + std::to_string(s.textures.size()) + " textures)");
        m.type = materials_type.data[k];
        m.base_color = vmax(v3(base_color.data + 3 * k), {0, 0, 0});
        m.roughness = std::min(std::max(roughness.data[k], 0.0f), 1.0f);
        m.ior = ior.data[k];
        m.emission = vmax(v3(emission.data + 3 * k), {0, 0, 0});
        m.base_color_texture = std::max(texture.data[k], -1);
        m.mix_next = -1;
        m.mix_weight = 1.0f;
        m.program = NO_INDEX;
        s.program_features.push_back(0);
        if (program.data && program.data[k] >= 0) {
            s.program_features.back() =
                check_node_program(s.node_programs, uint32_t(program.data[k]), s.textures.size(), g.attribute_slots, id);
            m.program = uint32_t(program.data[k]);
        }
        m.flags = (multiscatter.data && multiscatter.data[k] != 0) ? MATERIAL_FLAG_MULTISCATTER : 0u;
        if (m.type == MATERIAL_PRINCIPLED && !principled.data) bad(id + ": principled material without material_principled");
        if (principled.data) {
            const float* p = principled.data + 17 * k;
            for (int j = 0; j < 17; ++j)
                if (!std::isfinite(p[j])) bad(id + ": NaN or infinite principled input");
            auto clamp01 = [](float x) { return std::min(std::max(x, 0.0f), 1.0f); };
            m.specular_tint = vmax(v3(p), {0, 0, 0});
            m.metallic = clamp01(p[3]);
            m.coat_tint = vmax(v3(p + 4), {0, 0, 0});
            m.coat_weight = std::max(p[7], 0.0f);
            m.sheen_tint = vmax(v3(p + 8), {0, 0, 0});
            m.sheen_weight = std::max(p[11], 0.0f);
            m.transmission = clamp01(p[12]);
            m.specular_ior_level = std::max(p[13], 0.0f);
            m.coat_roughness = clamp01(p[14]);
            m.coat_ior = std::min(std::max(p[15], 1.0f), float(SceneLimits::ior_max));
            m.sheen_roughness = clamp01(p[16]);
        }
        if (mix_next.data) {
            int32_t next = mix_next.data[k];
            float w = mix_weight.data[k];
            if (next < -1 || next >= int64_t(K))
                bad(id + ": mix_next " + std::to_string(next) + " out of range (" + std::to_string(K) + " materials)");
            if (!std::isfinite(w)) bad(id + ": mix_weight is NaN or infinite");
            if (next >= 0) {
                m.mix_next = next;
                m.mix_weight = std::min(std::max(w, 0.0f), 1.0f);
            }
        }
    }
    // Mix chains must end (no cycle) within MIX_CHAIN_MAX materials: the shader walks at
    // most that many links.
    std::vector<uint8_t> state(K, 0);  // 0 unvisited, 1 on the current walk, 2 known good
    std::vector<uint32_t> length(K, 1);  // materials in the chain starting here
    for (size_t k = 0; k < K; ++k) {
        std::vector<size_t> walk;
        size_t j = k;
        while (state[j] == 0) {
            state[j] = 1;
            walk.push_back(j);
            if (s.materials[j].mix_next < 0) break;
            j = size_t(s.materials[j].mix_next);
            if (state[j] == 1)
                bad("material " + std::to_string(j) + ": mix chain has a cycle (material " + std::to_string(j) +
                    " is reached again through mix_next)");
        }
        for (auto it = walk.rbegin(); it != walk.rend(); ++it) {
            const Material& m = s.materials[*it];
            length[*it] = m.mix_next < 0 ? 1u : 1u + length[size_t(m.mix_next)];
            state[*it] = 2;
            if (length[*it] > MIX_CHAIN_MAX)
                bad("material " + std::to_string(*it) + ": mix chain of " + std::to_string(length[*it]) +
                    " materials is longer than the limit of " + std::to_string(MIX_CHAIN_MAX));
        }
    }
    return out;
}

// Instances in TLAS order (bvh_order of their bounds) and the scene's bounding sphere.
std::shared_ptr<const ScenePlacement> prepare_instances(const SceneArrays& a, bool spatial_order,
                                                        const SceneGeometry& g) {
    auto out = std::make_shared<ScenePlacement>();
    const size_t M = g.meshes.size();
    auto inst_xf = get<float>(a, "instance_transform", 'f', {3, 4});
    auto inst_mesh = get<uint32_t>(a, "instance_mesh", 'u', {});
    if (inst_mesh.rows != inst_xf.rows) bad("instance_transform and instance_mesh differ in length");
    std::vector<InstanceInfo> instances;
    std::vector<vec3> inst_lo, inst_hi;  // world bounds (BVH order)
    vec3 scene_lo{INFINITY, INFINITY, INFINITY}, scene_hi{-INFINITY, -INFINITY, -INFINITY};
    size_t skipped = 0;
    for (size_t i = 0; i < inst_xf.rows; ++i) {
        const float* x = inst_xf.data + 12 * i;
        for (int k = 0; k < 12; ++k)
            if (!std::isfinite(x[k])) bad("instance_transform[" + std::to_string(i) + "] is NaN or infinite");
        uint mesh = inst_mesh.data[i];
        if (mesh >= M) bad("instance_mesh[" + std::to_string(i) + "] = " + std::to_string(mesh) + " but there are " + std::to_string(M) + " meshes");
        if (g.meshes[mesh].triangle_count == 0) { ++skipped; continue; }
        InstanceInfo inst{};
        for (int r = 0; r < 3; ++r) inst.object_to_world[r] = {x[4 * r], x[4 * r + 1], x[4 * r + 2], x[4 * r + 3]};
        // Normal matrix: inverse transpose of the 3x3 part A. With rows r0, r1, r2 of A, the
        // cofactors c0 = r1 x r2, c1 = r2 x r0, c2 = r0 x r1 are the rows of det(A) A^-T.
        // Shaders normalise the normals, so the rows are scaled to a largest entry of 1 (not
        // divided by det, which overflows or underflows float32 at large or small scales).
        // Computed in double; singular (flat) means |det| is tiny next to the rows' lengths.
        dvec3 r0 = d3(x), r1 = d3(x + 4), r2 = d3(x + 8);
        dvec3 c0 = dcross(r1, r2), c1 = dcross(r2, r0), c2 = dcross(r0, r1);
        double det = ddot(r0, c0);
        if (!(std::fabs(det) > 1e-12 * dlength(r0) * dlength(r1) * dlength(r2))) { ++skipped; continue; }
        double m = 0;
        for (const dvec3& c : {c0, c1, c2}) m = std::max({m, std::fabs(c.x), std::fabs(c.y), std::fabs(c.z)});
        const double inv = (det > 0 ? 1.0 : -1.0) / m;
        inst.normal_to_world[0] = {float(c0.x * inv), float(c0.y * inv), float(c0.z * inv), 0};
        inst.normal_to_world[1] = {float(c1.x * inv), float(c1.y * inv), float(c1.z * inv), 0};
        inst.normal_to_world[2] = {float(c2.x * inv), float(c2.y * inv), float(c2.z * inv), 0};
        inst.mesh = mesh;
        inst.light_offset = NO_INDEX;
        // World bounds of the mesh's object bounds, in double (checked before float32 holds them).
        double dlo[3] = {INFINITY, INFINITY, INFINITY}, dhi[3] = {-INFINITY, -INFINITY, -INFINITY};
        for (int c = 0; c < 8; ++c) {
            const float corner[3] = {(c & 1) ? g.mesh_hi[mesh].x : g.mesh_lo[mesh].x,
                                     (c & 2) ? g.mesh_hi[mesh].y : g.mesh_lo[mesh].y,
                                     (c & 4) ? g.mesh_hi[mesh].z : g.mesh_lo[mesh].z};
            for (int r = 0; r < 3; ++r) {
                double w = double(x[4 * r]) * corner[0] + double(x[4 * r + 1]) * corner[1] +
                           double(x[4 * r + 2]) * corner[2] + x[4 * r + 3];
                dlo[r] = std::min(dlo[r], w), dhi[r] = std::max(dhi[r], w);
            }
        }
        double reach = 0;
        for (int r = 0; r < 3; ++r) reach = std::max({reach, std::fabs(dlo[r]), std::fabs(dhi[r])});
        if (reach > SceneLimits::coordinate)
            bad("instance_transform[" + std::to_string(i) + "] places mesh " + std::to_string(mesh) + " " + num(reach) +
                " m from the origin, beyond the coordinate limit of " + num(SceneLimits::coordinate) + " m");
        out->reach = std::max(out->reach, reach);
        vec3 lo{float(dlo[0]), float(dlo[1]), float(dlo[2])}, hi{float(dhi[0]), float(dhi[1]), float(dhi[2])};
        scene_lo = vmin(scene_lo, lo), scene_hi = vmax(scene_hi, hi);
        inst_lo.push_back(lo), inst_hi.push_back(hi);
        instances.push_back(inst);
    }
    if (skipped) out->warnings.push_back(std::to_string(skipped) + " instance(s) of empty meshes or with singular transforms skipped");
    std::vector<uint32_t> order(instances.size());
    std::iota(order.begin(), order.end(), 0u);
    if (spatial_order && instances.size() > 1) order = bvh_order(inst_lo, inst_hi);
    out->instances.reserve(instances.size());
    for (uint32_t i : order) {
        out->instances.push_back(instances[i]);
        out->world_lo.push_back(inst_lo[i]), out->world_hi.push_back(inst_hi[i]);
    }
    bool has_geometry = !out->instances.empty();
    out->center = has_geometry ? (scene_lo + scene_hi) * 0.5f : vec3{0, 0, 0};
    out->radius = has_geometry ? std::max(length(scene_hi - scene_lo) * 0.5f, 1e-3f) : 1.0f;
    return out;
}

// The world map's texels (negative ones zeroed, those above the radiance limit clamped to
// it with a warning; a non-finite one is an error) and its sampling tables.
std::shared_ptr<const SceneEnvironment> prepare_environment(const SceneArrays& a) {
    auto out = std::make_shared<SceneEnvironment>();
    SceneEnvironment& e = *out;
    if (!a.count("world_map")) bad("missing array 'world_map'");
    const ArrayView& wm = a.at("world_map");
    if (wm.kind != 'f' || wm.itemsize != 4 || wm.shape.size() != 3 || wm.shape[2] != 3)
        bad("array 'world_map' must be float32 (H, W, 3)");
    size_t H = wm.shape[0], W = wm.shape[1];
    if ((H == 0) != (W == 0)) bad("world_map has zero size " + shape_str(wm.shape));
    if (H == 0) return out;
    const float* px_ = static_cast<const float*>(wm.data);
    e.texels.resize(H * W);
    e.conditional.assign(H * (W + 1), 0.0f);
    e.marginal.assign(H + 1, 0.0f);
    double total = 0, lum_sum = 0, sin_sum = 0;
    std::vector<double> row_sum(H, 0.0);
    size_t clamped = 0;
    const float limit = float(SceneLimits::radiance);
    for (size_t r = 0; r < H; ++r) {
        float sin_theta = std::sin(kPi * (r + 0.5f) / H);
        float* cdf = &e.conditional[r * (W + 1)];
        double acc = 0;
        for (size_t c = 0; c < W; ++c) {
            const float* p = px_ + 3 * (r * W + c);
            if (!finite3(p))
                bad("world_map pixel (row " + std::to_string(r) + ", column " + std::to_string(c) + ") is NaN or infinite");
            if (max3(p) > limit) ++clamped;
            vec3 t = vmin(vmax(v3(p), {0, 0, 0}), {limit, limit, limit});
            e.texels[r * W + c] = t;
            double w = luminance(t) * sin_theta;
            acc += w;
            cdf[c + 1] = float(acc);
            lum_sum += luminance(t) * sin_theta;
            sin_sum += sin_theta;
        }
        for (size_t c = 1; c <= W; ++c) cdf[c] = acc > 0 ? float(cdf[c] / acc) : float(c) / W;
        cdf[W] = 1.0f;
        row_sum[r] = acc;
        total += acc;
    }
    for (size_t r = 0; r < H; ++r)
        e.marginal[r + 1] = total > 0 ? float(e.marginal[r] + row_sum[r] / total) : float(r + 1) / H;
    e.marginal[H] = 1.0f;
    e.width = uint(W);
    e.height = uint(H);
    e.total = float(total);
    e.mean_luminance = total > 0 ? float(lum_sum / sin_sum) : 0.0f;
    if (clamped)
        e.warnings.push_back("world_map: " + std::to_string(clamped) + " texel(s) above the radiance limit of " +
                             num(SceneLimits::radiance) + " clamped to it");
    return out;
}

// The light table: emissive triangles, analytic lights (Cycles units -> radiance), the
// environment and the selection CDF by emitted power. Needs s.geometry, s.materials and
// s.placement; sets s.lights, the light fields of s.info and (when `new_environment` or
// there is none yet) s.environment. Weights are summed in double and are finite by the
// limits checked, so no light can poison the CDF; a light that emits nothing is left out.
// `light_tree`: local lights are picked through a light tree (Cycles' Light Tree option),
// else from the power CDF like the distant ones.
void prepare_lights(const SceneArrays& a, bool new_environment, bool light_tree, SceneHost& s) {
    const SceneGeometry& g = *s.geometry;
    const std::vector<Material>& materials = s.materials->materials;
    auto out = std::make_shared<SceneLights>();
    out->instances = s.placement->instances;
    std::vector<Light>& lights = out->lights;
    const double radius = s.placement->radius;
    std::vector<double> power;  // selection weight of each light
    for (auto& inst : out->instances) {
        const MeshInfo& mesh = g.meshes[inst.mesh];
        bool emissive = false;
        for (uint t = mesh.first_triangle; t < mesh.first_triangle + mesh.triangle_count && !emissive; ++t)
            emissive = luminance(materials[g.triangle_material[t]].emission) > 0;
        if (!emissive) continue;
        inst.light_offset = uint(lights.size());
        for (uint t = mesh.first_triangle; t < mesh.first_triangle + mesh.triangle_count; ++t) {
            Light l{};
            l.type = LIGHT_TRIANGLE;
            vec3 p0 = transform_point(inst.object_to_world, g.positions[g.indices[t].x]);
            vec3 p1 = transform_point(inst.object_to_world, g.positions[g.indices[t].y]);
            vec3 p2 = transform_point(inst.object_to_world, g.positions[g.indices[t].z]);
            l.position = p0;
            l.axis_u = p1 - p0;
            l.axis_v = p2 - p0;
            const double area = 0.5 * dlength(dcross(d3(&l.axis_u.x), d3(&l.axis_v.x)));
            l.area = float(area);
            l.radiance = materials[g.triangle_material[t]].emission;
            l.direction = normalize(cross(l.axis_u, l.axis_v));
            lights.push_back(l);
            power.push_back(double(luminance(l.radiance)) * area * 2.0 * kPi);  // emits from both sides
        }
    }
    LightArrays la{get<uint32_t>(a, "light_type", 'u', {}),      get<float>(a, "light_position", 'f', {3}),
                   get<float>(a, "light_direction", 'f', {3}),   get<float>(a, "light_axis_u", 'f', {3}),
                   get<float>(a, "light_axis_v", 'f', {3}),      get<float>(a, "light_radius", 'f', {}),
                   get<float>(a, "light_color", 'f', {3}),       get<float>(a, "light_spot_size", 'f', {}),
                   get<float>(a, "light_spot_blend", 'f', {}),   get<float>(a, "light_sun_angle", 'f', {})};
    const size_t L = la.type.rows;
    std::vector<uint32_t> camera_visible(L, 1u);  // optional: every light is visible by default
    if (a.count("light_camera_visible")) {
        auto lcam = get<uint32_t>(a, "light_camera_visible", 'u', {});
        if (lcam.rows != L) bad("light_camera_visible and light_type differ in length");
        camera_visible.assign(lcam.data, lcam.data + L);
    }
    std::vector<uint32_t> soft_falloff(L, 0u);  // optional: true spheres by default
    if (a.count("light_soft_falloff")) {
        auto lsoft = get<uint32_t>(a, "light_soft_falloff", 'u', {});
        if (lsoft.rows != L) bad("light_soft_falloff and light_type differ in length");
        soft_falloff.assign(lsoft.data, lsoft.data + L);
    }
    s.info.analytic_first = uint(lights.size());
    for (size_t n : {la.position.rows, la.direction.rows, la.axis_u.rows, la.axis_v.rows, la.radius.rows, la.color.rows,
                     la.spot_size.rows, la.spot_blend.rows, la.sun_angle.rows})
        if (n != L) bad("light_* arrays differ in length");
    // Two passes: lights visible to the camera first, so camera rays test only a prefix.
    s.info.analytic_camera_count = 0;
    std::vector<size_t> dark;
    for (int pass = 0; pass < 2; ++pass)
    for (size_t i = 0; i < L; ++i) {
        if ((camera_visible[i] != 0) != (pass == 0)) continue;
        double weight = 0;
        Light l = analytic_light(la, i, radius, weight);
        if (soft_falloff[i] != 0 && (l.type == LIGHT_SPHERE || l.type == LIGHT_SPOT) && l.radius > 0)
            l.flags |= LIGHT_FLAG_SOFT_FALLOFF;
        if (!(weight > 0)) {  // black, zero size or a dark spot: contributes nothing
            dark.push_back(i);
            continue;
        }
        if (l.type != LIGHT_SUN) {
            const double extent = std::max(max_abs3(la.axis_u.data + 3 * i), max_abs3(la.axis_v.data + 3 * i)) + l.radius;
            out->reach = std::max(out->reach, max_abs3(la.position.data + 3 * i) + extent);
        }
        lights.push_back(l);
        power.push_back(weight);
        if (pass == 0) ++s.info.analytic_camera_count;
    }
    if (!dark.empty()) {
        std::sort(dark.begin(), dark.end());
        std::string list;
        for (size_t i : dark) list += (list.empty() ? "" : ", ") + std::to_string(i);
        out->warnings.push_back((dark.size() > 1 ? "lights " + list + " emit" : "light " + list + " emits") +
                                " no light (black or zero size): skipped");
    }

    s.info.analytic_count = uint(lights.size()) - s.info.analytic_first;
    auto world_color = get<float>(a, "world_color", 'f', {}, false);
    if (world_color.rows != 3 || !finite3(world_color.data)) bad("world_color must be 3 finite floats");
    if (max3(world_color.data) > SceneLimits::radiance)
        bad("world_color " + num(max3(world_color.data)) + " exceeds the radiance limit of " + num(SceneLimits::radiance));
    s.info.env_color = vmax(v3(world_color.data), {0, 0, 0});
    if (new_environment || !s.environment) s.environment = prepare_environment(a);
    const SceneEnvironment& env = *s.environment;
    s.info.env_width = env.width;
    s.info.env_height = env.height;
    s.info.env_total = env.total;
    s.info.env_light = NO_INDEX;
    const double env_lum = env.width ? env.mean_luminance : luminance(s.info.env_color);
    if (env_lum > 0) {
        Light l{};
        l.type = LIGHT_ENV;
        s.info.env_light = uint(lights.size());
        lights.push_back(l);
        power.push_back(env_lum * kPi * 4 * kPi * radius * radius);
    }
    // Many local lights: a light tree picks among them by their importance at the shading
    // point, with probability light_tree_prob = their share of the power; the CDF then holds
    // the distant lights (sun, env) alone.
    for (Light& l : lights) l.tree_node = NO_INDEX;
    std::vector<uint32_t> local;
    double local_power = 0;
    for (uint32_t i = 0; i < uint32_t(lights.size()); ++i)
        if (lights[i].type != LIGHT_SUN && lights[i].type != LIGHT_ENV && power[i] > 0) {
            local.push_back(i);
            local_power += power[i];
        }
    s.info.light_tree_nodes = 0;
    s.info.light_tree_prob = 0;
    if (light_tree && local.size() >= light_tree_min_lights() && local_power > 0) {
        out->light_tree = build_light_tree(lights, local, power);
        s.info.light_tree_nodes = uint(out->light_tree.size());
        s.info.light_tree_prob = float(local_power / std::accumulate(power.begin(), power.end(), 0.0));
        for (uint32_t i : local) power[i] = 0;
    }
    if (out->light_tree.empty()) out->light_tree.resize(1);  // a buffer needs an element
    // Every weight is finite and >= 0; with a total of 0 (zero-area emitters only) every
    // selection probability is 0, and NEE samples nothing.
    const double power_total = std::accumulate(power.begin(), power.end(), 0.0);
    out->light_cdf.assign(power.size() + 1, 0.0f);
    if (power_total > 0) {
        double acc = 0;
        for (size_t i = 0; i < power.size(); ++i) {
            acc += power[i];
            out->light_cdf[i + 1] = float(acc / power_total);
        }
        out->light_cdf.back() = 1.0f;
    }
    s.info.light_count = uint(lights.size());
    mark_transmission_contacts(g, materials, *s.placement, out->instances, s.info);
    s.lights = std::move(out);
}

// The thin lens and the panorama (optional arrays; without them a pinhole and an equirectangular
// panorama of the whole sphere), checked as Blender's ranges allow.
void prepare_lens(const SceneArrays& a, SceneInfo& info) {
    auto aperture = get<float>(a, "camera_aperture", 'f', {}, true);
    auto panorama_type = get<uint32_t>(a, "camera_panorama_type", 'u', {}, true);
    auto range = get<float>(a, "camera_panorama_range", 'f', {}, true);
    auto fisheye = get<float>(a, "camera_fisheye", 'f', {}, true);
    if ((aperture.data && aperture.rows != 5) || (panorama_type.data && panorama_type.rows != 1) ||
        (range.data && range.rows != 4) || (fisheye.data && fisheye.rows != 9))
        bad("camera lens arrays have wrong sizes (camera_aperture 5, camera_panorama_type 1, "
            "camera_panorama_range 4, camera_fisheye 9)");
    const float pi = 3.14159265358979f;
    const float no_aperture[5] = {0.0f, 10.0f, 0.0f, 0.0f, 1.0f};
    const float whole_sphere[4] = {-pi, pi, -0.5f * pi, 0.5f * pi};
    const float fisheye_default[9] = {pi, 10.5f, 36.0f, 24.0f, 0.0f, 0.0f, 0.0f, 0.0f, 0.0f};
    const float* ap = aperture.data ? aperture.data : no_aperture;
    const float* r = range.data ? range.data : whole_sphere;
    const float* f = fisheye.data ? fisheye.data : fisheye_default;
    for (int k = 0; k < 5; ++k)
        if (!std::isfinite(ap[k])) bad("camera_aperture holds NaN or infinity");
    for (int k = 0; k < 4; ++k)
        if (!std::isfinite(r[k])) bad("camera_panorama_range holds NaN or infinity");
    for (int k = 0; k < 9; ++k)
        if (!std::isfinite(f[k])) bad("camera_fisheye holds NaN or infinity");
    if (!(ap[0] >= 0 && ap[0] <= SceneLimits::camera_scale))
        bad("camera aperture radius " + num(ap[0]) + " must be in 0.." + num(SceneLimits::camera_scale));
    if (!(ap[1] >= 0 && ap[1] <= SceneLimits::coordinate)) bad("camera focus distance " + num(ap[1]) + " is negative or absurd");
    if (!(ap[2] >= 0 && ap[2] <= 1000)) bad("camera aperture blades " + num(ap[2]) + " must be in 0..1000");
    if (!(ap[4] >= 1e-3f && ap[4] <= 1e3f)) bad("camera aperture ratio " + num(ap[4]) + " must be in 0.001..1000");
    const uint32_t pano = panorama_type.data ? panorama_type.data[0] : PANORAMA_EQUIRECTANGULAR;
    if (pano > PANORAMA_CENTRAL_CYLINDRICAL) bad("unknown camera_panorama_type " + std::to_string(pano));
    if (!(f[0] > 0) || !(f[1] > 0) || !(f[2] > 0) || !(f[3] > 0))
        bad("camera_fisheye: field of view, lens and sensor size must be positive");
    info.aperture_radius = ap[0];
    info.focus_distance = std::max(ap[1], 1e-5f);  // as Cycles: a zero distance focuses just ahead
    info.aperture_blades = ap[2] < 3 ? 0.0f : std::floor(ap[2]);
    info.aperture_rotation = ap[3];
    info.aperture_ratio = ap[4];
    info.panorama_type = pano;
    info.panorama_range = {r[0], r[1], r[2], r[3]};
    info.fisheye = {f[0], f[1], f[2], f[3]};
    for (int k = 0; k < 5; ++k) info.fisheye_polynomial[k] = f[4 + k];
}

// The camera: a finite, non-singular basis of sensible scale, a window within
// SceneLimits::camera_scale and a clip range 0 <= start < end.
void prepare_camera(const SceneArrays& a, SceneInfo& info) {
    auto cam = get<float>(a, "camera_to_world", 'f', {4});
    auto cam_type = get<uint32_t>(a, "camera_type", 'u', {});
    auto window = get<float>(a, "camera_window", 'f', {});
    auto clip = get<float>(a, "camera_clip", 'f', {});
    if (cam.rows != 3 || cam_type.rows != 1 || window.rows != 4 || clip.rows != 2) bad("camera arrays have wrong sizes");
    for (int k = 0; k < 12; ++k)
        if (!std::isfinite(cam.data[k])) bad("camera_to_world is NaN or infinite");
    if (cam_type.data[0] > CAMERA_PANORAMA) bad("unknown camera_type " + std::to_string(cam_type.data[0]));
    // The columns of the 3x3 part are the camera's right, up and backward axes.
    const float* m = cam.data;
    dvec3 axes[3];
    for (int c = 0; c < 3; ++c) axes[c] = {m[c], m[4 + c], m[8 + c]};
    const double scale = SceneLimits::camera_scale;
    for (const dvec3& axis : axes)
        if (!(dlength(axis) >= 1 / scale && dlength(axis) <= scale))
            bad("camera_to_world: an axis has length " + num(dlength(axis)) + ", outside " + num(1 / scale) + ".." +
                num(scale) + " (a zero, degenerate or absurdly scaled camera)");
    const double det = ddot(axes[0], dcross(axes[1], axes[2]));
    if (!(std::fabs(det) > 1e-6 * dlength(axes[0]) * dlength(axes[1]) * dlength(axes[2])))
        bad("camera_to_world is singular (its axes are parallel)");
    if (std::max({std::fabs(double(m[3])), std::fabs(double(m[7])), std::fabs(double(m[11]))}) > SceneLimits::coordinate)
        bad("camera position is beyond the coordinate limit of " + num(SceneLimits::coordinate) + " m");
    for (int k = 0; k < 4; ++k)
        if (!(std::fabs(window.data[k]) <= scale))
            bad("camera_window (" + num(window.data[0]) + ", " + num(window.data[1]) + ", " + num(window.data[2]) + ", " +
                num(window.data[3]) + ") must be finite and within +-" + num(scale));
    if (!(window.data[1] > window.data[0]) || !(window.data[3] > window.data[2])) bad("camera_window is empty or NaN");
    if (!(std::isfinite(clip.data[0]) && std::isfinite(clip.data[1]) && clip.data[0] >= 0 && clip.data[1] > clip.data[0]))
        bad("camera_clip (" + num(clip.data[0]) + ", " + num(clip.data[1]) + ") must be finite with 0 <= start < end");
    for (int r = 0; r < 3; ++r) info.camera_to_world[r] = {m[4 * r], m[4 * r + 1], m[4 * r + 2], m[4 * r + 3]};
    info.camera_type = cam_type.data[0];
    info.camera_window = {window.data[0], window.data[1], window.data[2], window.data[3]};
    info.clip = {clip.data[0], clip.data[1]};
    prepare_lens(a, info);
}

}  // namespace

namespace {
struct OrderItem {
    vec3 lo, hi;  // the primitive's box
    uint32_t index;
    float centre(int axis) const { return (&lo.x)[axis] + (&hi.x)[axis]; }  // doubled
};

float half_area(vec3 lo, vec3 hi) {
    vec3 d{std::max(hi.x - lo.x, 0.0f), std::max(hi.y - lo.y, 0.0f), std::max(hi.z - lo.z, 0.0f)};
    return d.x * d.y + d.y * d.z + d.z * d.x;
}

// Orders items[first..last] (inclusive) as lavapipe's builder splits them: at (first + last) / 2,
// the left half first .. split, the right half after it, one primitive per leaf. The builder
// fixes the split's position, not its axis: each split partitions at the median along the axis
// whose median partition has the lowest surface-area cost, area(L) n_L + area(R) n_R
// (MacDonald & Booth 1990). The medians that judge the axes come from up to 255 of the range's
// primitives (all of them in smaller ranges), the costs from one pass over the range.
void median_split_order(std::vector<OrderItem>& items, size_t first, size_t last) {
    std::vector<float> sample;
    while (first < last) {
        size_t n = last - first + 1, split = (first + last) / 2, m = std::min<size_t>(n, 255);
        float median[3];
        for (int axis = 0; axis < 3; ++axis) {
            sample.resize(m);
            for (size_t j = 0; j < m; ++j) sample[j] = items[first + j * n / m].centre(axis);
            std::nth_element(sample.begin(), sample.begin() + m / 2, sample.end());
            median[axis] = sample[m / 2];
        }
        vec3 lo[2][3], hi[2][3];
        size_t count_left[3] = {0, 0, 0};
        for (int axis = 0; axis < 3; ++axis)
            for (int side = 0; side < 2; ++side) lo[side][axis] = {INFINITY, INFINITY, INFINITY}, hi[side][axis] = {-INFINITY, -INFINITY, -INFINITY};
        for (size_t k = first; k <= last; ++k) {
            const OrderItem& it = items[k];
            for (int axis = 0; axis < 3; ++axis) {
                int side = it.centre(axis) < median[axis] ? 0 : 1;
                count_left[axis] += side == 0;
                lo[side][axis] = vmin(lo[side][axis], it.lo), hi[side][axis] = vmax(hi[side][axis], it.hi);
            }
        }
        int best = 0;
        float best_cost = INFINITY;
        for (int axis = 0; axis < 3; ++axis) {
            float cost = half_area(lo[0][axis], hi[0][axis]) * float(count_left[axis]) +
                         half_area(lo[1][axis], hi[1][axis]) * float(n - count_left[axis]);
            if (cost < best_cost) best_cost = cost, best = axis;
        }
        std::nth_element(items.begin() + first, items.begin() + split, items.begin() + last + 1,
                         [best](const OrderItem& a, const OrderItem& b) { return a.centre(best) < b.centre(best); });
        median_split_order(items, first, split);
        first = split + 1;
    }
}
}  // namespace

std::vector<uint32_t> bvh_order(const std::vector<vec3>& lo, const std::vector<vec3>& hi) {
    std::vector<OrderItem> items(lo.size());
    for (size_t i = 0; i < lo.size(); ++i) items[i] = {lo[i], hi[i], uint32_t(i)};
    if (!items.empty()) median_split_order(items, 0, items.size() - 1);
    std::vector<uint32_t> order(items.size());
    for (size_t i = 0; i < items.size(); ++i) order[i] = items[i].index;
    return order;
}

OwnedArray::OwnedArray(const ArrayView& v) : shape(v.shape), kind(v.kind), itemsize(v.itemsize) {
    const auto* p = static_cast<const uint8_t*>(v.data);
    if (p) bytes.assign(p, p + v.size() * v.itemsize);
}

ArrayView OwnedArray::view() const {
    ArrayView v;
    v.data = bytes.data();
    v.shape = shape;
    v.kind = kind;
    v.itemsize = itemsize;
    return v;
}

namespace {
const std::pair<const char*, uint32_t> kPartNames[] = {
    {"geometry", PART_GEOMETRY}, {"instances", PART_INSTANCES}, {"materials", PART_MATERIALS},
    {"lights", PART_LIGHTS},     {"camera", PART_CAMERA},
};
}  // namespace

uint32_t parse_scene_parts(const std::vector<std::string>& names) {
    if (names.empty()) return PART_ALL;
    uint32_t mask = 0;
    for (const auto& name : names) {
        uint32_t bit = 0;
        for (const auto& [n, b] : kPartNames)
            if (name == n) bit = b;
        if (!bit) throw std::invalid_argument("unknown scene part '" + name + "' (parts: geometry, instances, materials, lights, camera)");
        mask |= bit;
    }
    return mask;
}

std::string scene_part_name(uint32_t part) {
    for (const auto& [n, b] : kPartNames)
        if (part == b) return n;
    return "?";
}

uint32_t scene_part_of_array(const std::string& name) {
    auto starts = [&](const char* prefix) { return name.rfind(prefix, 0) == 0; };
    if (starts("instance_")) return PART_INSTANCES;
    if (starts("material_") || starts("texture_")) return PART_MATERIALS;
    if (starts("light_") || starts("world_")) return PART_LIGHTS;
    if (starts("camera_")) return PART_CAMERA;
    if (starts("mesh_") || name == "positions" || name == "indices" || name == "triangle_material" ||
        name == "corner_normals" || name == "corner_uvs" || name == "corner_tangents" || name == "corner_attributes")
        return PART_GEOMETRY;
    return 0;
}

std::vector<std::string> SceneHost::warnings() const {
    std::vector<std::string> out;
    for (const auto* part : {placement ? &placement->warnings : nullptr, lights ? &lights->warnings : nullptr,
                             environment ? &environment->warnings : nullptr})
        if (part) out.insert(out.end(), part->begin(), part->end());
    // Float32 precision: the geometry's, the lights' and the camera's distance from the origin.
    double reach = std::max(placement ? placement->reach : 0.0, lights ? lights->reach : 0.0);
    for (int r = 0; r < 3; ++r) reach = std::max(reach, std::fabs(double(info.camera_to_world[r].w)));
    if (reach > SceneLimits::precision)
        out.push_back("the scene reaches " + num(reach) + " m from the origin; beyond " + num(SceneLimits::precision) +
                      " m float32 precision fails (from about 2.5e7 m rays miss surfaces): move it to the origin "
                      "or scale it down");
    return out;
}

SceneHost update_scene(const SceneHost& previous, const SceneArrays& a, bool spatial_order, uint32_t parts,
                       bool light_tree) {
    // Every other part refers to the geometry (mesh and triangle indices): it redoes all.
    if ((parts & PART_GEOMETRY) || !previous.geometry) parts = PART_ALL;
    SceneHost s = parts == PART_ALL ? SceneHost{} : previous;  // shares the parts kept
    if (parts & PART_GEOMETRY) {
        s.geometry = prepare_geometry(a, spatial_order);
        s.info.attribute_slots = s.geometry->attribute_slots;
        s.info.attribute_stride = uint(3 * s.geometry->indices.size());
    }
    if (parts & PART_MATERIALS) s.materials = prepare_materials(a, *s.geometry);
    if (parts & PART_INSTANCES) {
        s.placement = prepare_instances(a, spatial_order, *s.geometry);
        s.info.scene_center = s.placement->center;
        s.info.scene_radius = s.placement->radius;
    }
    if (parts & PART_CAMERA) {
        prepare_camera(a, s.info);
        s.features = (s.features & ~FEATURE_LENS) | (camera_has_lens(s.info) ? FEATURE_LENS : 0u);
    }
    // The light table holds the emissive instances' triangles (with their materials'
    // emission) as well as the analytic lights and the world.
    if (parts & (PART_INSTANCES | PART_MATERIALS | PART_LIGHTS)) {
        prepare_lights(a, (parts & PART_LIGHTS) != 0, light_tree, s);
        s.features = scene_features(s);
    }
    return s;
}

SceneHost prepare_scene(const SceneArrays& a, bool spatial_order, bool light_tree) {
    return update_scene({}, a, spatial_order, PART_ALL, light_tree);
}

SceneHost relight_scene(const SceneHost& previous, const SceneArrays& a, bool light_tree) {
    SceneHost s = previous;
    prepare_lights(a, false, light_tree, s);
    return s;
}

Scene::Scene(Context& ctx, SceneHost host, const Scene* previous) : host_(std::move(host)) {
    const SceneHost* old = previous ? &previous->host_ : nullptr;
    auto put = [&](uint32_t binding, const auto& vec, VkBufferUsageFlags usage = kStorageUsage) {
        buffers_[binding] = std::make_shared<const Buffer>(Buffer::with_vector(ctx, vec, usage));
    };
    auto reuse = [&](std::initializer_list<uint32_t> bindings) {
        for (uint32_t b : bindings) buffers_[b] = previous->buffers_.at(b);
    };
    // Each part's buffers: reused when `previous` has the same host object, else uploaded.
    const SceneGeometry& g = *host_.geometry;
    const bool same_geometry = old && old->geometry == host_.geometry;
    if (same_geometry) {
        reuse({BINDING_POSITIONS, BINDING_INDICES, BINDING_CORNER_NORMALS, BINDING_CORNER_UVS,
               BINDING_CORNER_TANGENTS, BINDING_CORNER_ATTRIBUTES, BINDING_TRIANGLE_MATERIAL, BINDING_MESHES});
    } else {
        const VkBufferUsageFlags as_input = kStorageUsage | VK_BUFFER_USAGE_ACCELERATION_STRUCTURE_BUILD_INPUT_READ_ONLY_BIT_KHR;
        put(BINDING_POSITIONS, g.positions, as_input);
        put(BINDING_INDICES, g.indices, as_input);
        put(BINDING_CORNER_NORMALS, g.corner_normals);
        put(BINDING_CORNER_UVS, g.corner_uvs);
        put(BINDING_CORNER_TANGENTS, g.corner_tangents);
        put(BINDING_CORNER_ATTRIBUTES, g.corner_attributes);
        put(BINDING_TRIANGLE_MATERIAL, g.triangle_material);
        put(BINDING_MESHES, g.meshes);
    }
    if (old && old->materials == host_.materials) {
        reuse({BINDING_MATERIALS, BINDING_TEXTURE_INFO, BINDING_TEXELS, BINDING_NODE_PROGRAMS});
    } else {
        put(BINDING_MATERIALS, host_.materials->materials);
        put(BINDING_TEXTURE_INFO, host_.materials->textures);
        put(BINDING_TEXELS, host_.materials->texels);
        put(BINDING_NODE_PROGRAMS, host_.materials->node_programs);
    }
    if (old && old->lights == host_.lights) {
        reuse({BINDING_INSTANCES, BINDING_LIGHTS, BINDING_LIGHT_CDF, BINDING_LIGHT_TREE});
    } else {
        put(BINDING_INSTANCES, host_.lights->instances);
        put(BINDING_LIGHTS, host_.lights->lights);
        put(BINDING_LIGHT_CDF, host_.lights->light_cdf);
        put(BINDING_LIGHT_TREE, host_.lights->light_tree);
    }
    if (old && old->environment == host_.environment) {
        reuse({BINDING_ENV_TEXELS, BINDING_ENV_MARGINAL, BINDING_ENV_CONDITIONAL});
    } else {
        put(BINDING_ENV_TEXELS, host_.environment->texels);
        put(BINDING_ENV_MARGINAL, host_.environment->marginal);
        put(BINDING_ENV_CONDITIONAL, host_.environment->conditional);
    }
    put(BINDING_SCENE, std::vector<SceneInfo>{host_.info});

    // One BLAS per mesh that some instance uses. A BLAS is self-contained once built, so the
    // same geometry keeps its BLASes; an instance edit builds only those of newly used meshes.
    const auto& instances = host_.placement->instances;
    if (same_geometry) mesh_blas_ = previous->mesh_blas_;
    mesh_blas_.resize(g.meshes.size());
    std::vector<uint32_t> new_meshes;
    std::vector<TriangleRange> ranges;
    std::vector<bool> queued(g.meshes.size(), false);
    for (const auto& inst : instances)
        if (!mesh_blas_[inst.mesh] && !queued[inst.mesh]) {
            queued[inst.mesh] = true;
            new_meshes.push_back(inst.mesh);
            ranges.push_back({g.meshes[inst.mesh].first_triangle, g.meshes[inst.mesh].triangle_count});
        }
    if (!ranges.empty()) {
        auto built = build_triangle_blases(ctx, *buffers_.at(BINDING_POSITIONS), uint32_t(g.positions.size()),
                                           *buffers_.at(BINDING_INDICES), ranges);
        for (size_t i = 0; i < built.size(); ++i) mesh_blas_[new_meshes[i]] = std::move(built[i]);
        blases_built_ = uint32_t(built.size());
    }
    if (same_geometry && old->placement == host_.placement) {
        tlas_ = previous->tlas_;
        return;
    }
    std::vector<TlasInstance> tlas_instances;
    tlas_instances.reserve(instances.size());
    for (size_t i = 0; i < instances.size(); ++i) {
        const auto& inst = instances[i];
        TlasInstance t{};
        for (int r = 0; r < 3; ++r) {
            t.transform[4 * r] = inst.object_to_world[r].x;
            t.transform[4 * r + 1] = inst.object_to_world[r].y;
            t.transform[4 * r + 2] = inst.object_to_world[r].z;
            t.transform[4 * r + 3] = inst.object_to_world[r].w;
        }
        t.custom_index = uint32_t(i);
        t.mask = 0xff;
        t.sbt_offset = HIT_GROUP_TRIANGLES;
        t.blas = mesh_blas_[inst.mesh]->address();
        tlas_instances.push_back(t);
    }
    tlas_ = build_tlas(ctx, tlas_instances);
}

void Scene::bind(DescriptorSet& set) const {
    for (const auto& [binding, buffer] : buffers_) set.bind_buffer(binding, *buffer);
    set.bind_tlas(BINDING_TLAS, tlas_->handle());
}

// World AABB of the placed geometry: the 8 transformed corners of each instance's mesh
// bounds (the bounding sphere where there are no instances).
void scene_bounds(const SceneHost& scene, float lo[3], float hi[3]) {
    for (int a = 0; a < 3; ++a) {
        lo[a] = INFINITY;
        hi[a] = -INFINITY;
    }
    if (scene.placement && scene.geometry) {
        const auto& g = *scene.geometry;
        for (const InstanceInfo& inst : scene.placement->instances) {
            if (inst.mesh >= g.mesh_lo.size()) continue;
            const vec3 b[2] = {g.mesh_lo[inst.mesh], g.mesh_hi[inst.mesh]};
            for (int c = 0; c < 8; ++c) {
                const float p[3] = {b[c & 1].x, b[(c >> 1) & 1].y, b[(c >> 2) & 1].z};
                for (int a = 0; a < 3; ++a) {
                    const vec4& row = inst.object_to_world[a];
                    const float w = row.x * p[0] + row.y * p[1] + row.z * p[2] + row.w;
                    lo[a] = std::min(lo[a], w);
                    hi[a] = std::max(hi[a], w);
                }
            }
        }
    }
    for (int a = 0; a < 3; ++a) {
        if (std::isfinite(lo[a]) && std::isfinite(hi[a])) continue;
        const vec3& c = scene.info.scene_center;
        const float r = std::max(scene.info.scene_radius, 1e-3f);
        for (int k = 0; k < 3; ++k) {
            const float ck = k == 0 ? c.x : k == 1 ? c.y : c.z;
            lo[k] = ck - r;
            hi[k] = ck + r;
        }
        break;
    }
}

}  // namespace px
