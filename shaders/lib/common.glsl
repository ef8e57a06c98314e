// Bindings and math shared by every entry point. Include after #version.
#extension GL_EXT_scalar_block_layout : require
#include "../shared/types.h"

const float PI = 3.14159265358979;
const float INV_PI = 0.31830988618379;
const float INFINITY_F = 1.0e30;

layout(set = 0, binding = BINDING_FILM, scalar) buffer FilmBuffer { vec4 film[]; };
layout(set = 0, binding = BINDING_RAY_COUNT, scalar) buffer RayCountBuffer { uint ray_count[]; };
layout(set = 0, binding = BINDING_ADAPTIVE_AUX, scalar) buffer AdaptiveAuxBuffer { vec4 adaptive_aux[]; };
layout(set = 0, binding = BINDING_ADAPTIVE_PIXELS, scalar) buffer AdaptivePixelBuffer { uint adaptive_pixels[]; };
layout(set = 0, binding = BINDING_POSITIONS, scalar) readonly buffer PositionBuffer { vec3 positions[]; };
layout(set = 0, binding = BINDING_INDICES, scalar) readonly buffer IndexBuffer { uvec3 indices[]; };
layout(set = 0, binding = BINDING_CORNER_NORMALS, scalar) readonly buffer NormalBuffer { vec3 corner_normals[]; };
layout(set = 0, binding = BINDING_CORNER_UVS, scalar) readonly buffer UvBuffer { vec2 corner_uvs[]; };
layout(set = 0, binding = BINDING_CORNER_TANGENTS, scalar) readonly buffer TangentBuffer { vec4 corner_tangents[]; };
layout(set = 0, binding = BINDING_CORNER_ATTRIBUTES, scalar) readonly buffer AttributeBuffer { vec4 corner_attributes[]; };
layout(set = 0, binding = BINDING_TRIANGLE_MATERIAL, scalar) readonly buffer TriMaterialBuffer { uint triangle_material[]; };
layout(set = 0, binding = BINDING_MESHES, scalar) readonly buffer MeshBuffer { MeshInfo meshes[]; };
layout(set = 0, binding = BINDING_INSTANCES, scalar) readonly buffer InstanceBuffer { InstanceInfo instances[]; };
layout(set = 0, binding = BINDING_MATERIALS, scalar) readonly buffer MaterialBuffer { Material materials[]; };
layout(set = 0, binding = BINDING_TEXTURE_INFO, scalar) readonly buffer TextureInfoBuffer { TextureInfo textures[]; };
layout(set = 0, binding = BINDING_TEXELS, scalar) readonly buffer TexelBuffer { uint texels[]; };
layout(set = 0, binding = BINDING_LIGHTS, scalar) readonly buffer LightBuffer { Light lights[]; };
layout(set = 0, binding = BINDING_LIGHT_CDF, scalar) readonly buffer LightCdfBuffer { float light_cdf[]; };
layout(set = 0, binding = BINDING_LIGHT_TREE, scalar) readonly buffer LightTreeBuffer { LightTreeNode light_tree[]; };
layout(set = 0, binding = BINDING_ENV_TEXELS, scalar) readonly buffer EnvTexelBuffer { vec3 env_texels[]; };
layout(set = 0, binding = BINDING_ENV_MARGINAL, scalar) readonly buffer EnvMarginalBuffer { float env_marginal[]; };
layout(set = 0, binding = BINDING_ENV_CONDITIONAL, scalar) readonly buffer EnvConditionalBuffer { float env_conditional[]; };
layout(set = 0, binding = BINDING_SCENE, scalar) readonly buffer SceneBuffer { SceneInfo scene; };
layout(set = 0, binding = BINDING_GGX_TABLES, scalar) readonly buffer GgxTableBuffer { uint ggx_table_words[]; };
layout(set = 0, binding = BINDING_PIXEL_FILTER, scalar) readonly buffer PixelFilterBuffer { float pixel_filter_table[]; };

layout(push_constant, scalar) uniform PushConstants { FrameParams params; };

// The pipeline's specialisation constants (METHOD, MIS_HEURISTIC, SCENE_FEATURES, TECHNIQUES,
// EMPTY_SHADOW_CALLS) and the HAS / USES conditions: code for what they leave out folds away.
#include "../shared/specialization.h"

// The film holds the enabled passes only (FrameParams.film_passes), in PASS_* order.
uint film_slot(uint pass) { return bitCount(params.film_passes & ((1u << pass) - 1u)); }
// Adds to pixel `pixel_index`'s sums of `pass`; nothing if the pass is not enabled.
void film_add(uint pass, uint pixel_index, vec4 value) {
    if ((params.film_passes & (1u << pass)) == 0u) return;
    film[film_slot(pass) * (params.width * params.height) + pixel_index] += value;
}

// Adaptive sampling's mode this frame (ADAPTIVE_*): off in pipelines built without it, whose
// code for it folds away (a frame parameter's branch costs the H200 3-4% of its PT frames).
uint adaptive_mode() {
    return ADAPTIVE_SAMPLING == 0u ? ADAPTIVE_OFF : params.adaptive;
}

// The image pixel of a dispatch's launch position `launch` (gl_LaunchIDEXT.xy): its place in
// the dispatch's image rectangle (col_offset, row_offset), or with adaptive sampling's active
// list (ADAPTIVE_LIST) the pixel that entry of the list names, the list read as a virtual image
// of `width` columns (the session's row bands and cursor run over it as over the image). false:
// a lane past the list's end, which traces nothing.
bool dispatch_pixel(uvec2 launch, out uvec2 pixel) {
    pixel = launch + uvec2(params.col_offset, params.row_offset);
    if (adaptive_mode() != ADAPTIVE_LIST) return true;
    uint entry = pixel.y * params.width + pixel.x;
    if (entry >= params.active_pixels) return false;
    uint index = adaptive_pixels[entry];
    pixel = uvec2(index % params.width, index / params.width);
    return true;
}

float max3(vec3 v) { return max(v.x, max(v.y, v.z)); }
float luminance(vec3 c) { return dot(c, vec3(0.2126, 0.7152, 0.0722)); }
float sqr(float x) { return x * x; }

vec3 transform_point(vec4 rows[3], vec3 p) {
    vec4 h = vec4(p, 1.0);
    return vec3(dot(rows[0], h), dot(rows[1], h), dot(rows[2], h));
}
vec3 transform_vector(vec4 rows[3], vec3 v) {
    return vec3(dot(rows[0].xyz, v), dot(rows[1].xyz, v), dot(rows[2].xyz, v));
}

// Orthonormal basis around n (Duff et al. 2017, "Building an Orthonormal Basis, Revisited").
void make_basis(vec3 n, out vec3 t, out vec3 b) {
    float s = n.z >= 0.0 ? 1.0 : -1.0;
    float a = -1.0 / (s + n.z);
    float c = n.x * n.y * a;
    t = vec3(1.0 + s * n.x * n.x * a, s * c, -s * n.x);
    b = vec3(c, s + n.y * n.y * a, -n.y);
}

// Moves a ray origin off a surface along the geometric normal, robust at any scale
// (Wächter & Binder, Ray Tracing Gems ch. 6); `scale` 1 is their offset (256 ulps).
vec3 offset_ray_scaled(vec3 p, vec3 n, float scale) {
    const float origin = 1.0 / 32.0;
    float float_scale = scale / 65536.0, int_scale = scale * 256.0;
    ivec3 of_i = ivec3(int_scale * n);
    vec3 p_i = vec3(intBitsToFloat(floatBitsToInt(p.x) + ((p.x < 0.0) ? -of_i.x : of_i.x)),
                    intBitsToFloat(floatBitsToInt(p.y) + ((p.y < 0.0) ? -of_i.y : of_i.y)),
                    intBitsToFloat(floatBitsToInt(p.z) + ((p.z < 0.0) ? -of_i.z : of_i.z)));
    return vec3(abs(p.x) < origin ? p.x + float_scale * n.x : p_i.x,
                abs(p.y) < origin ? p.y + float_scale * n.y : p_i.y,
                abs(p.z) < origin ? p.z + float_scale * n.z : p_i.z);
}

vec3 offset_ray(vec3 p, vec3 n) { return offset_ray_scaled(p, n, 1.0); }

// Exact unpolarised Fresnel reflectance; eta = n_t / n_i, |cos_i| is used (Cycles'
// fresnel_dielectric_cos).
float fresnel_dielectric(float cos_i, float eta) {
    float c = abs(cos_i);
    float g2 = eta * eta - 1.0 + c * c;
    if (g2 <= 0.0) return 1.0;  // total internal reflection
    float g = sqrt(g2);
    float a = (g - c) / (g + c);
    float b = (c * (g + c) - 1.0) / (c * (g - c) + 1.0);
    return 0.5 * a * a * (1.0 + b * b);
}
