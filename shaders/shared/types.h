// Every struct, binding index and constant that crosses the host/device boundary.
// Polyglot: compiled by C++17 (host) and by glslang (GLSL 460). All buffers use the
// scalar block layout (GL_EXT_scalar_block_layout), so a C++ struct of 4-byte scalars
// has exactly the layout the shaders see: no vec3 padding rules to remember.
#ifndef PARALLAX_SHARED_TYPES_H
#define PARALLAX_SHARED_TYPES_H

#ifdef __cplusplus
#include <cstdint>
namespace px {
using uint = uint32_t;
struct vec2 { float x, y; };
struct vec3 { float x, y, z; };
struct vec4 { float x, y, z, w; };
struct uvec3 { uint x, y, z; };
#define PX_CONST static constexpr
#else
#define PX_CONST const
#endif

// ---- descriptor set 0 bindings -------------------------------------------------------
PX_CONST uint BINDING_TLAS = 0;
PX_CONST uint BINDING_FILM = 1;            // vec4 film[passes][width*height] sums (FrameParams.film_passes)
PX_CONST uint BINDING_RAY_COUNT = 2;       // uint per pixel, rays traced (all frames)
PX_CONST uint BINDING_POSITIONS = 3;       // vec3 per vertex (all meshes)
PX_CONST uint BINDING_INDICES = 4;         // uvec3 per triangle, global vertex indices
PX_CONST uint BINDING_CORNER_NORMALS = 5;  // vec3 [3] per triangle (meshes with normals)
PX_CONST uint BINDING_CORNER_UVS = 6;      // vec2 [3] per triangle (meshes with UVs)
PX_CONST uint BINDING_TRIANGLE_MATERIAL = 7;
PX_CONST uint BINDING_MESHES = 8;          // MeshInfo
PX_CONST uint BINDING_INSTANCES = 9;       // InstanceInfo, indexed by gl_InstanceCustomIndexEXT
PX_CONST uint BINDING_MATERIALS = 10;      // Material
PX_CONST uint BINDING_TEXTURE_INFO = 11;   // TextureInfo
PX_CONST uint BINDING_TEXELS = 12;         // uint words: RGBA8 sRGB texels, then RGBA half texels (2 words each)
PX_CONST uint BINDING_LIGHTS = 13;         // Light
PX_CONST uint BINDING_LIGHT_CDF = 14;      // float[light_count + 1], selection by power
PX_CONST uint BINDING_ENV_TEXELS = 15;     // vec3 linear radiance, row 0 = top (zenith)
PX_CONST uint BINDING_ENV_MARGINAL = 16;   // float[env_height + 1]
PX_CONST uint BINDING_ENV_CONDITIONAL = 17;// float[env_height * (env_width + 1)]
PX_CONST uint BINDING_SCENE = 18;          // SceneInfo (uniform-like, one element)
PX_CONST uint BINDING_TEST_IO = 19;        // sampling test shader: vec4 in/out
PX_CONST uint BINDING_TECH_PARAMS = 20;    // TechniqueParams (one element)
PX_CONST uint BINDING_IC_GRID = 21;        // irradiance cache lookup grid: uint start per bucket, + 1 (ic_lookup)
PX_CONST uint BINDING_IC_ENTRIES = 22;     // IcEntry[capacity]
PX_CONST uint BINDING_IC_GRID_ENTRIES = 23;  // IcCandidate per bucket place (BINDING_IC_GRID)
PX_CONST uint BINDING_IC_QUEUE = 24;       // uint count, 3 pad, IcRequest[]
PX_CONST uint BINDING_IC_JOBS = 25;        // IcJob[], written by the host
PX_CONST uint BINDING_IC_SAMPLES = 26;     // IcSample[jobs * IC_STRATA]
PX_CONST uint BINDING_ADRRS_ESTIMATE = 27; // vec4 per pixel: ADRRS' pixel estimate (rgb, a > 0: valid)
PX_CONST uint BINDING_ADRRS_QUEUE = 28;    // uint active count, 3 pad; per pixel of a dispatch: its
                                           // entries; then the list of active pixels
PX_CONST uint BINDING_ADRRS_SPLITS = 29;   // AdrrsSplit[pixel of a dispatch][adrrs.slots]
PX_CONST uint BINDING_GUIDING_TLAS = 30;    // guiding: TLAS over the regions' AABBs (spatial order)
PX_CONST uint BINDING_GUIDING_REGIONS = 31; // GuidingRegion[regions]
PX_CONST uint BINDING_GUIDING_LOBES = 32;   // GuidingLobe[regions * GUIDING_MAX_COMPONENTS]
PX_CONST uint BINDING_GUIDING_ORDER = 33;   // uint per region-BLAS primitive: its region
PX_CONST uint BINDING_GUIDING_SAMPLES = 34; // GuidingSample[recording paths * GUIDING_PATH_VERTICES]
PX_CONST uint BINDING_ADRRS_ADJOINT = 35;  // vec4 per grid cell and axis direction: mean E (rgb), entries
PX_CONST uint BINDING_GGX_TABLES = 36;     // uint unorm16 pairs: multiscatter GGX albedos (ggx_tables.h)
PX_CONST uint BINDING_LIGHT_TREE = 37;     // LightTreeNode[], root first (SceneInfo.light_tree_nodes)
PX_CONST uint BINDING_GUIDING_NODES = 38;  // GuidingNode[]: the region tree, walked by guiding_region_at
// Adaptive sampling (Cycles' adaptive_aux_buffer): per pixel, rgb = twice the radiance sums of
// every second sample (the half buffer A), w = 1 once the pixel converged (adaptive.comp).
PX_CONST uint BINDING_ADAPTIVE_AUX = 39;
// uint[2 * pixels]: the active pixels' indices in image order (FrameParams.active_pixels of
// them, dispatch_pixel), then per pixel 1 while it is still sampled (the filtered mask).
PX_CONST uint BINDING_ADAPTIVE_PIXELS = 40;
// float[PIXEL_FILTER_TABLE_SIZE]: the pixel filter's inverted CDF (render/pixel_filter.h)
PX_CONST uint BINDING_PIXEL_FILTER = 41;
// uint words: the materials' node programs (Material.program; shaders/lib/nodes.glsl)
PX_CONST uint BINDING_NODE_PROGRAMS = 42;
PX_CONST uint BINDING_CORNER_TANGENTS = 43;  // vec4 [3] per triangle: tangent, bitangent sign (Normal Map)
PX_CONST uint BINDING_CORNER_ATTRIBUTES = 44;  // vec4 [slots][3 per triangle] (SceneInfo.attribute_*)
// EARS: EarsCell[adrrs.ears_slots] (the iteration being learnt)
PX_CONST uint BINDING_EARS_CELLS = 45;
PX_CONST uint BINDING_EARS_FACTORS = 46;  // EarsFactor[adrrs.ears_slots] (the last iteration's)
PX_CONST uint BINDING_EARS_PIXELS = 47;   // EarsPixel per pixel (the iteration being learnt)
PX_CONST uint BINDING_IC_PATHS_ONLY = 48; // uint per pixel: 1 = consistent mode no longer asks the cache there
PX_CONST uint BINDING_EARS_RECORDS = 49;  // EarsRecord[EARS_PATH_VERTICES] per invocation (adrrs.ears_threads)
PX_CONST uint BINDING_IC_REUSE = 50;      // IcReuseRecord per pixel: consistent mode's last query there
PX_CONST uint BINDING_COUNT = 51;

// ---- shader binding table: miss shaders and hit groups (RayTracingPipeline group order) -
PX_CONST uint MISS_SCENE = 0;         // miss.rmiss: the world
PX_CONST uint MISS_SHADOW = 1;        // shadow.rmiss: the light is visible
PX_CONST uint MISS_GUIDING_QUERY = 2; // guiding_query.rmiss: no region
PX_CONST uint HIT_GROUP_TRIANGLES = 0;  // the scene TLAS' instances (closesthit.rchit)
PX_CONST uint HIT_GROUP_GUIDING = 1;    // the region TLAS' instance (guiding_query.rint + .rchit)
// A pipeline without guiding holds the next filled slot's group in guiding's slots (Session::
// pipeline_shaders), so these indices hold in every pipeline.

// ---- film passes ------------------------------------------------------------------------
PX_CONST uint PASS_COMBINED = 0;   // rgb radiance, a = 1
PX_CONST uint PASS_DEPTH = 1;      // x = z-depth along the camera axis (1e10 on a miss)
PX_CONST uint PASS_NORMAL = 2;     // xyz = world shading normal of the first hit
PX_CONST uint PASS_ALBEDO = 3;     // rgb = albedo at the first non-specular vertex
PX_CONST uint PASS_RAY_DEPTH = 4;  // x = number of path segments traced
PX_CONST uint PASS_IC_IRRADIANCE = 5;  // rgb = cached irradiance at the first diffuse vertex
PX_CONST uint PASS_IC_GRADIENTS = 6;   // r = |translational|, g = |rotational| / ic.gradient_max
PX_CONST uint PASS_ADRRS_ESTIMATE = 7;  // rgb = ADRRS' pixel estimate
PX_CONST uint PASS_ADRRS_SPLITS = 8;    // x = extra paths split off per pixel sample
PX_CONST uint PASS_GUIDING_REGIONS = 9;     // rgb = a colour per guiding region at the first hit
PX_CONST uint PASS_GUIDING_COMPONENTS = 10; // x = active lobes / guiding_max_components at the first hit
PX_CONST uint PASS_GUIDING_LOBES = 11;      // rgb = VMM pdf: probe inset (lat-long) + per-region spheres
PX_CONST uint PASS_NEE_VISIBILITY = 12;     // x = shadow rays that reached their light, y = shadow rays traced
PX_CONST uint PASS_RRS_FACTOR = 13;  // x = sum of EARS' factors q, y = decisions (x / y: the mean)
PX_CONST uint PASS_RRS_COST = 14;    // x = sum of the learnt relative cost at the first decision, y = count
PX_CONST uint PASS_IC_RESIDUAL = 15;  // rgb = sum of (cache estimate - path) per sample, a = sum of its squared norm
PX_CONST uint PASS_IC_RADIUS = 16;    // x = validity radius (accuracy * R) of the nearest entry at the first diffuse vertex
PX_CONST uint PASS_COUNT = 17;     // film slots
// Samples per pixel: no film slot of its own, Session::read takes Combined's w (the count).
PX_CONST uint PASS_SAMPLE_COUNT = PASS_COUNT;

// ---- enums ------------------------------------------------------------------------------
PX_CONST uint METHOD_PT = 0;   // BSDF sampling only
PX_CONST uint METHOD_NEE = 1;  // next event estimation, emission only via camera/specular
PX_CONST uint METHOD_MIS = 2;  // NEE + BSDF sampling combined by MIS (Veach 1997)

PX_CONST uint HEURISTIC_BALANCE = 0;
PX_CONST uint HEURISTIC_POWER = 1;

PX_CONST uint MATERIAL_DIFFUSE = 0;     // Lambert, two-sided
PX_CONST uint MATERIAL_CONDUCTOR = 1;   // GGX, colour = reflectance (Cycles Glossy BSDF)
PX_CONST uint MATERIAL_DIELECTRIC = 2;  // smooth or rough GGX glass (Cycles Glass BSDF)
PX_CONST uint MATERIAL_EMISSION = 3;    // emits only, no scattering (Cycles Emission)
PX_CONST uint MATERIAL_PRINCIPLED = 4;  // Cycles' Principled BSDF v2 (shaders/lib/principled.glsl)

PX_CONST uint LIGHT_TRIANGLE = 0;  // emissive mesh triangle, world-space vertices
PX_CONST uint LIGHT_SPHERE = 1;    // point light, radius 0 = delta
PX_CONST uint LIGHT_SPOT = 2;      // sphere light with cone falloff
PX_CONST uint LIGHT_SUN = 3;       // distant light, cone of half-angle sun_angle/2
PX_CONST uint LIGHT_RECT = 4;      // area light: position ± axis_u/2 ± axis_v/2
PX_CONST uint LIGHT_DISK = 5;      // area light: ellipse with half-axes axis_u/2, axis_v/2
PX_CONST uint LIGHT_ENV = 6;       // the world (constant or map), at most one

PX_CONST uint CAMERA_PERSPECTIVE = 0;
PX_CONST uint CAMERA_ORTHOGRAPHIC = 1;
PX_CONST uint CAMERA_PANORAMA = 2;  // SceneInfo.panorama_type picks the projection (camera.glsl)

// Blender's (and Cycles') panoramic projections, in Blender's enum order.
PX_CONST uint PANORAMA_EQUIRECTANGULAR = 0;
PX_CONST uint PANORAMA_EQUIANGULAR_CUBEMAP_FACE = 1;
PX_CONST uint PANORAMA_MIRRORBALL = 2;
PX_CONST uint PANORAMA_FISHEYE_EQUIDISTANT = 3;
PX_CONST uint PANORAMA_FISHEYE_EQUISOLID = 4;
PX_CONST uint PANORAMA_FISHEYE_LENS_POLYNOMIAL = 5;
PX_CONST uint PANORAMA_CENTRAL_CYLINDRICAL = 6;

PX_CONST uint NO_INDEX = 0xffffffffu;

// Most materials one mix chain may hold, its head included (Material.mix_next); the host
// rejects longer chains, so the shader's bounded walk always reaches the selected link.
PX_CONST uint MIX_CHAIN_MAX = 16;

// Scene features: a specialization constant (DESIGN: "Specialise, don't branch"), so a
// pipeline only carries the material, light and geometry code its scene uses.
PX_CONST uint FEATURE_CONDUCTOR = 1u << 0;
PX_CONST uint FEATURE_DIELECTRIC = 1u << 1;
PX_CONST uint FEATURE_TEXTURES = 1u << 2;
PX_CONST uint FEATURE_SHADING_NORMALS = 1u << 3;
PX_CONST uint FEATURE_UVS = 1u << 4;
PX_CONST uint FEATURE_TRIANGLE_LIGHTS = 1u << 5;
PX_CONST uint FEATURE_SPHERE_LIGHTS = 1u << 6;  // point and spot
PX_CONST uint FEATURE_AREA_LIGHTS = 1u << 7;    // rect and disk
PX_CONST uint FEATURE_SUN = 1u << 8;
PX_CONST uint FEATURE_ENV = 1u << 9;            // constant world or map
PX_CONST uint FEATURE_ENV_MAP = 1u << 10;
PX_CONST uint FEATURE_MIX = 1u << 11;           // some used material has mix_next >= 0
PX_CONST uint FEATURE_PRINCIPLED = 1u << 12;
// Some used material transmits (Glass, Principled with transmission): only then do rays leaving
// a surface skip their own triangle (self_skip.rahit) instead of starting past it, which costs
// lavapipe about a third of its speed (contact geometry; integrator.glsl surface_ray_flags).
PX_CONST uint FEATURE_TRANSMISSION = 1u << 13;
// The camera has depth of field or is a panorama (camera.glsl); without it the camera code
// is the pinhole's alone, which lavapipe runs 1.5-2% faster (bench/results/issue37_camera_nodes).
PX_CONST uint FEATURE_LENS = 1u << 14;
PX_CONST uint FEATURE_NODES = 1u << 15;  // some used material has a node program (nodes.glsl)
// The node programs' heavier operations, by group (scene.cpp node_program_features): a scene
// whose programs use none of a group runs an interpreter without its code, which the H200
// runs at about half the cost per hit (bench/results/issue37_camera_nodes).
PX_CONST uint FEATURE_NODE_TEXTURES = 1u << 16;  // Noise, Voronoi, Wave, Brick
PX_CONST uint FEATURE_NODE_SURFACE = 1u << 17;   // geometry, attributes, bump offsets, Bump, Normal Map, Fresnel
PX_CONST uint FEATURE_NODE_COLOR = 1u << 18;     // Vector Math, Curves, Hue/Saturation/Value
PX_CONST uint FEATURE_ALL = 0xffffffffu;
// The features a folded pipeline carries whatever the scene holds (PARALLAX_SCENE_FEATURES=folded,
// the test suite's setting): light types, vertex normals and UVs, conductors. Their code tests
// the scene data too (a light's type, a mesh's has_normals), so the images stay the same, and a
// cold make test compiles 75 variants instead of 164. Renders keep the scene's exact features:
// folded, lavapipe's frames took 4-10% longer (bench/results/lavapipe_folded_features).
PX_CONST uint FEATURES_FOLDED = FEATURE_CONDUCTOR | FEATURE_SHADING_NORMALS | FEATURE_UVS | FEATURE_TRIANGLE_LIGHTS |
                                FEATURE_SPHERE_LIGHTS | FEATURE_AREA_LIGHTS | FEATURE_SUN | FEATURE_ENV | FEATURE_ENV_MAP;

// The light-path limits a pipeline carries (LIGHT_PATH_LIMITS, tested by LIMITS()): only where
// the settings can bind them (light_path_limits in render/params.h). Carrying them costs the
// H200 7% of its rays on the soup (bench/results/regression_h200_lightpaths).
PX_CONST uint LIMIT_KIND_BOUNCES = 1u;  // Cycles' diffuse, glossy and transmission budgets
PX_CONST uint LIMIT_CLAMP = 2u;         // Cycles' direct and indirect sample clamps
PX_CONST uint LIMIT_BLUR_GLOSSY = 4u;   // Cycles' Filter Glossy
PX_CONST uint LIMIT_ALL = 7u;

// ---- scene records --------------------------------------------------------------------
struct MeshInfo {
    uint first_triangle;
    uint triangle_count;
    uint has_normals;  // corner normals at the same triangle index
    uint has_uvs;      // corner uvs at the same triangle index
    // Blender's Generated texture coordinates: object-space position * scale + offset maps the
    // mesh's texture space (its bounds by default) to 0..1.
    vec3 texspace_scale;
    vec3 texspace_offset;
    uint has_tangents;  // corner tangents at the same triangle index (tangent-space Normal Maps)
};

struct InstanceInfo {
    vec4 object_to_world[3];  // rows of a 3x4 matrix
    vec4 normal_to_world[3];  // rows of the inverse transpose (3x3 used)
    uint mesh;
    uint light_offset;  // index of this instance's first triangle light, or NO_INDEX
    uint flags;         // INSTANCE_FLAG_*
    uint pad0;
};
// Some material of the instance transmits light (glass, Principled transmission).
PX_CONST uint INSTANCE_FLAG_TRANSMITS = 1u;

struct Material {
    vec3 base_color;
    float roughness;  // Cycles roughness; alpha = roughness^2
    vec3 emission;    // radiance: colour * strength
    float ior;
    uint type;
    int base_color_texture;  // -1: none
    // Stochastic mix chain (Mix Shader): at a hit this material's BSDF is used with
    // probability mix_weight, otherwise the hit continues to materials[mix_next] (which may
    // chain further). -1: no mix (mix_weight ignored). Acyclic, validated on the host.
    int mix_next;
    float mix_weight;  // in [0,1]
    uint flags;        // MATERIAL_FLAG_*
    // MATERIAL_PRINCIPLED only (Blender's Principled BSDF inputs, clamped as Cycles does);
    // base_color, roughness and ior above are its Base Color, Roughness and IOR.
    vec3 specular_tint;  // dielectric F0 tint; the metal's F82 tint
    float metallic;
    vec3 coat_tint;
    float coat_weight;
    vec3 sheen_tint;
    float sheen_weight;
    float transmission;
    float specular_ior_level;  // 0.5: F0 of ior; scales F0 by 2x this
    float coat_roughness;
    float coat_ior;
    float sheen_roughness;
    uint program;  // first word of its node program in BINDING_NODE_PROGRAMS; NO_INDEX: none
    uint pad1, pad2;
};

// Node programs (parallax_core/nodes.py builds them; shaders/lib/nodes.glsl runs them at each
// hit): instructions op | dst << 8 | a << 16 | b << 24 over vec4 registers, each followed by
// one word or more of its own, up to NODE_END.
PX_CONST uint NODE_END = 0;
PX_CONST uint NODE_CONST = 1;      // dst = 4 float words
PX_CONST uint NODE_UV = 2;         // dst = (uv, 0, 0); word: bump offset (NODE_BUMP)
PX_CONST uint NODE_TEXTURE = 3;    // dst = texture[word] at a.xy (Image Texture, Linear/Closest, repeat)
PX_CONST uint NODE_AFFINE = 4;     // dst.xyz = 3x4 matrix (12 words) * (a.xyz, 1) (Mapping)
PX_CONST uint NODE_MATH = 5;       // dst.x = MATH op (word & 0xff) of a.x, b.x, c.x (c: word >> 16)
PX_CONST uint NODE_MIX = 6;        // dst = blend (word & 0xff) of b over a by reg (word >> 8 & 0xff).x;
                                   // word bit 16: clamp the result to 0..1
PX_CONST uint NODE_INVERT = 7;     // dst = mix(a, 1 - a, b.x); word unused
PX_CONST uint NODE_MAP_RANGE = 8;  // dst.x = a.x mapped; word: registers of from min, max, to min, max
                                   // (a byte each); next word: bit 0 clamp, bits 8-15 interpolation
                                   // (nodes.MAP_RANGE_TYPES), 16-23 steps register, bit 24 vector
PX_CONST uint NODE_RAMP = 9;       // dst = table of (word & 0xffff) rgba rows at a.x, interpolated
                                   // if word >> 16 (ColorRamp as Cycles' lookup table)
PX_CONST uint NODE_SEPARATE = 10;  // dst.x = a[word]
PX_CONST uint NODE_COMBINE = 11;   // dst = (a.x, b.x, reg[word].x, 1)
PX_CONST uint NODE_STORE = 12;     // Material field (word: parallax_core.nodes.FIELDS) = a
PX_CONST uint NODE_CONVERT = 13;   // word 0: dst.x = luminance of a.rgb; 1: mean of a.xyz; 2: dst = a.xxx
PX_CONST uint NODE_GENERATED = 14; // dst = Generated texture coordinates; word: bump offset
PX_CONST uint NODE_NOISE = 15;     // dst.x = Cycles' 3D fBm Perlin noise at a.xyz; word: registers of
                                   // detail, roughness, lacunarity (a byte each), bit 24: normalize
PX_CONST uint NODE_VORONOI = 16;   // dst = Cycles' 3D Voronoi of a.xyz * b.x; word: registers of detail,
                                   // roughness, lacunarity, smoothness; next: exponent, randomness, then
                                   // (bits 16..) feature | metric << 2 | normalize << 4 | output << 5
PX_CONST uint NODE_WAVE = 17;      // dst = Cycles' Wave of a.xyz * b.x; word: registers of distortion,
                                   // detail, detail scale, detail roughness; next: phase, then (bits 8..)
                                   // type | direction << 1 | profile << 3
PX_CONST uint NODE_BRICK = 18;     // dst = Cycles' Brick of a.xyz * b.x; word: registers of color1, color2,
                                   // mortar, mortar size; next: mortar smooth, bias, brick width, row
                                   // height; then offset, squash (floats); then offset frequency | squash
                                   // frequency << 8 | (Fac, not Color) << 16
PX_CONST uint NODE_VECTOR_MATH = 19; // dst.xyz = VECTOR_MATH op (word & 0xff) of a.xyz, b.xyz, reg (word >> 8
                                     // & 0xff).xyz, reg (word >> 16).x (Scale); a float result in all three
PX_CONST uint NODE_CURVES = 20;    // dst = a, each of its (word >> 24) channels through an interpolated
                                   // table of (word & 0xffff) rows over min x..max x (the next 2 words),
                                   // mixed by b.x; bit 16: extrapolate (RGB Curves, Float Curve)
PX_CONST uint NODE_HSV = 21;       // dst.rgb = Hue/Saturation/Value of a.rgb, fac b.x; word: registers
                                   // of hue, saturation, value (a byte each)
PX_CONST uint NODE_GEOMETRY = 22;  // dst = the hit's NODE_GEOMETRY_* (word & 0xff) at the bump offset
                                   // (word >> 8: see NODE_BUMP)
PX_CONST uint NODE_BUMP = 23;      // dst.xyz = Cycles' bumped normal: strength a.x, distance b.x; word:
                                   // registers of the heights at the centre, dx and dy offsets and of
                                   // the normal (a byte each); next word: invert | filter width << 16
PX_CONST uint NODE_FRESNEL = 24;   // dst.x = word 0: Fresnel of IOR a.x, 1: Layer Weight's Fresnel,
                                   // 2: its Facing, of blend a.x; b: the normal
PX_CONST uint NODE_NORMAL_MAP = 25;  // dst.xyz = Cycles' Normal Map of colour a.rgb, strength b.x; word:
                                     // space (NODE_NORMAL_MAP_*)
PX_CONST uint NODE_ATTRIBUTE = 26;  // dst = attribute slot (word & 0xff) at the hit, interpolated (0 where
                                    // the mesh lacks it); word >> 8: bump offset, as NODE_GEOMETRY
PX_CONST uint NODE_OPS = 27;
PX_CONST uint NODE_ATTRIBUTE_SLOTS = 8;
PX_CONST uint NODE_NORMAL_MAP_TANGENT = 0;
PX_CONST uint NODE_NORMAL_MAP_OBJECT = 1;
PX_CONST uint NODE_NORMAL_MAP_WORLD = 2;
PX_CONST uint NODE_NORMAL_MAP_BLENDER_OBJECT = 3;
PX_CONST uint NODE_NORMAL_MAP_BLENDER_WORLD = 4;
// A coordinate operation's bump offset (word >> 8 of NODE_GEOMETRY, word of NODE_UV and
// NODE_GENERATED): 0 the hit itself, 1 and 2 the points Cycles' Bump evaluates its height at,
// a filter width (half float, word >> 16) of a pixel's footprint along the triangle's edges.
PX_CONST uint NODE_GEOMETRY_POSITION = 0;     // world space
PX_CONST uint NODE_GEOMETRY_NORMAL = 1;       // the shading normal on the viewer's side (Cycles' N)
PX_CONST uint NODE_GEOMETRY_TRUE_NORMAL = 2;  // the geometric normal on the viewer's side
PX_CONST uint NODE_GEOMETRY_INCOMING = 3;     // towards the viewer
PX_CONST uint NODE_GEOMETRY_OBJECT = 4;       // object-space position (Texture Coordinate Object)
PX_CONST uint NODE_GEOMETRY_OBJECT_NORMAL = 5;  // object-space normal (Texture Coordinate Normal)
PX_CONST uint NODE_GEOMETRY_BACKFACING = 6;   // 1 where the ray hit the back
PX_CONST uint NODE_GEOMETRY_KINDS = 7;
PX_CONST uint NODE_REGISTERS = 32;
PX_CONST uint NODE_MATH_OPS = 42;   // parallax_core.nodes.MATH_OPS, in that order
PX_CONST uint NODE_VECTOR_MATH_OPS = 30;  // parallax_core.nodes.VECTOR_MATH_OPS
PX_CONST uint NODE_MAP_RANGE_TYPES = 4;   // parallax_core.nodes.MAP_RANGE_TYPES
PX_CONST uint NODE_BLEND_MODES = 10;  // parallax_core.nodes.BLEND_MODES
PX_CONST uint NODE_FIELDS = 10;     // parallax_core.nodes.FIELDS: base_color, roughness, metallic,
                                    // transmission, coat_weight, specular_ior_level, mix_weight,
                                    // coat_roughness, sheen_weight, normal (emission stays constant: the
                                    // light table samples emitters by it)

// Conductor/dielectric: Cycles' Multiscatter GGX, the single-scatter lobe scaled by
// 1/E(mu_o) (and the Fresnel-coloured multi-bounce term) from shaders/shared/ggx_tables.h.
PX_CONST uint MATERIAL_FLAG_MULTISCATTER = 1u;

// TextureInfo.flags (parallax_core.scene TEXTURE_FLAG_*).
PX_CONST uint TEXTURE_FLAG_CLOSEST = 1u;  // Blender's Closest interpolation: the nearest texel
PX_CONST uint TEXTURE_FLAG_HALF = 2u;     // linear RGBA half-float texels, 2 words each (float images)

struct TextureInfo {
    uint offset;  // first word of the texture in the texel buffer
    uint width;
    uint height;
    uint flags;   // TEXTURE_FLAG_*
};

// One light. Radiometric quantities are already converted from Cycles' units to radiance
// (sphere, spot, rect, disk, triangle, env) or irradiance-derived radiance (sun).
struct Light {
    vec3 position;   // sphere/spot/rect/disk centre; triangle vertex 0
    uint type;
    vec3 radiance;   // emitted radiance (sun: radiance of its disc)
    float radius;    // sphere/spot radius
    vec3 direction;  // spot axis / rect+disk normal (emitting side) / direction *to* the sun
    float cos_half_angle;  // spot: cos(spot_size/2); sun: cos(angle/2)
    vec3 axis_u;     // rect/disk full extent along u; triangle edge p1 - p0
    float spot_smooth;     // spot: (1 - cos_half_angle) * blend (Cycles' smoothstep width)
    vec3 axis_v;     // rect/disk full extent along v; triangle edge p2 - p0
    float area;      // rect/disk/triangle area; sphere/spot: pi radius^2
    uint flags;      // LIGHT_FLAG_*
    uint tree_node;  // its leaf in the light tree, or NO_INDEX (not in the tree)
};

// A node of the light tree (Conty Estevez & Kulla 2018): a binary BVH over the local lights
// (emissive triangles, sphere, spot, rect, disk) with, per node, the bounds of its lights'
// positions, of their emission directions (a cone of normals: axis, theta_o, plus the spread
// theta_e of emission around a normal) and their summed power. Children are adjacent. The
// angles are kept as cosines and sines: the shader's importance needs no inverse trigonometry.
struct LightTreeNode {
    vec3 bounds_min;
    uint child;      // interior: the first child (the second is child + 1); leaf: the light index
    vec3 bounds_max;
    uint parent;     // NO_INDEX at the root
    vec3 axis;       // normal cone axis
    float cos_o;     // normals within theta_o of the axis (-1: any direction)
    float sin_o;
    float cos_e;     // emission within theta_e of a normal (0: a diffuse emitter)
    float power;     // summed selection weight of the lights below
    uint flags;      // LIGHT_NODE_*
};
PX_CONST uint LIGHT_NODE_LEAF = 1u;
PX_CONST uint LIGHT_NODE_TWO_SIDED = 2u;  // the lights emit on both sides: the cone bounds the normals up to sign

// Point/spot with a radius: Cycles' Soft Falloff (Blender's default). The light is a disk of
// the sphere's radius and radiance centred on the light and facing the shading point (Cycles'
// is_sphere = false), so irradiance falls off as 1/(d^2 + r^2) near it instead of 1/d^2.
PX_CONST uint LIGHT_FLAG_SOFT_FALLOFF = 1u;

PX_CONST uint CONTACT_BOX_MAX = 8u;  // SceneInfo.contact_lo/hi

struct SceneInfo {
    vec4 camera_to_world[3];  // rows; camera looks down -Z with +Y up (Blender)
    vec4 camera_window;       // left, right, bottom, top at distance 1 (persp), in world units
                              // (ortho) or of the panorama's (u, v) square (panorama)
    vec2 clip;                // clip start, clip end
    uint camera_type;
    // Thin lens (Cycles' depth of field): aperture radius in world units (0: a pinhole), focus
    // distance, blades (below 3: a round aperture), blade rotation (radians), aspect ratio.
    float aperture_radius;
    float focus_distance;
    float aperture_blades;
    float aperture_rotation;
    float aperture_ratio;
    uint panorama_type;       // PANORAMA_*
    vec4 panorama_range;      // equirectangular: longitude min, max, latitude min, max;
                              // central cylindrical: angle min, max, height min, max / radius
    vec4 fisheye;             // field of view, lens (mm), sensor width, height (mm, as fitted)
    float fisheye_polynomial[5];  // k0..k4: theta = -(k0 + k1 r + ... + k4 r^4), r in mm
    uint light_count;         // entries in the light table (env included)
    vec3 env_color;           // constant world radiance (used when env_width == 0)
    uint env_light;           // index of the env entry in the light table, or NO_INDEX
    uint env_width;
    uint env_height;
    float env_total;          // sum of the env map luminance * sin(theta) weights
    uint analytic_first;      // analytic lights (sphere..disk) are contiguous in the table
    uint analytic_count;
    vec3 scene_center;        // bounding sphere of the geometry (sun/env sampling)
    float scene_radius;
    uint analytic_camera_count;  // the first ones of the analytic lights are visible to the camera
    uint light_tree_nodes;    // nodes in BINDING_LIGHT_TREE; 0: lights are picked from light_cdf alone
    float light_tree_prob;    // probability of picking a local light through the tree (the rest
                              // picks a distant light from light_cdf, which then holds them alone)
    // World boxes round the transmissive instances (a few slightly grown, or unions of nearby
    // ones): rays leaving a surface point inside one start contact-safe (integrator.glsl).
    uint contact_box_count;
    vec3 contact_lo[CONTACT_BOX_MAX];
    vec3 contact_hi[CONTACT_BOX_MAX];
    uint attribute_slots;   // node programs' attribute slots in BINDING_CORNER_ATTRIBUTES
    uint attribute_stride;  // corners per slot (3 x triangles)
};

// Per-frame parameters (push constants).
struct FrameParams {
    uint width;
    uint height;
    uint frame;             // frame index since the last reset
    uint seed;
    uint samples_per_frame; // of the whole frame
    uint max_depth;         // path segments after the camera ray that count towards the limit
    uint depth_leeway;      // extra segments allowed after discrete (specular) bounces
    uint rr_start_depth;    // Russian roulette from this depth on (0: off)
    uint light_samples;     // NEE light samples per vertex
    uint test_routine;      // sampling test shader only
    uint test_count;
    float test_param0;
    uint row_offset;        // first image row of this dispatch (frames may go in row bands)
    vec4 test_params;
    uint mode;              // FRAME_RENDER or FRAME_IC_PREPARE
    uint ic_job_count;      // hemisphere / finish dispatches: jobs in BINDING_IC_JOBS
    // A dispatch may trace part of a frame: columns from col_offset (and rows from
    // row_offset), samples sample_offset .. sample_offset + sample_count - 1 of each pixel.
    uint col_offset;
    uint sample_offset;
    uint sample_count;
    uint guiding_record;    // 1: camera paths record guiding training samples (GuidingSample)
    // The film's passes, bit PASS_* (PASS_COMBINED always): the film holds only these, in PASS_*
    // order (film_slot in lib/common.glsl, Session::film_offset).
    uint film_passes;
    // Adaptive sampling: ADAPTIVE_OFF, ADAPTIVE_IMAGE (the dispatch covers its image rectangle
    // and fills the half buffer) or ADAPTIVE_LIST (it covers a virtual image of `width` columns
    // over the first active_pixels entries of BINDING_ADAPTIVE_PIXELS). Render frames only.
    uint adaptive;
    uint active_pixels;
    float adaptive_threshold;  // adaptive.comp: Cycles' threshold (x5, as Cycles scales it)
    // Cycles' light paths: the bounce budgets of each kind of scattering (BOUNCE_*, counted as
    // Cycles' labels), the sample clamps (x3, as Cycles scales them; +inf: off) and Filter
    // Glossy's factor (1 / blur_glossy, as Cycles' kernel holds it).
    uint diffuse_bounces;
    uint glossy_bounces;
    uint transmission_bounces;
    float clamp_direct;
    float clamp_indirect;
    float filter_glossy;
};

// Pixel filters (RenderParams.pixel_filter_type, Cycles' order) and the size of the table that
// importance-samples them (BINDING_PIXEL_FILTER), Cycles' FILTER_TABLE_SIZE. Interpolating an
// inverted CDF spreads each tail cell's samples evenly: with 256 entries Blackman-Harris 1.5 px
// came out 0.8% wider than itself (standard deviation of the offsets) and 0.5% wider than
// Cycles', blurring the image more; with 1024 it is within 0.15% of both.
PX_CONST uint FILTER_BOX = 0;
PX_CONST uint FILTER_GAUSSIAN = 1;
PX_CONST uint FILTER_BLACKMAN_HARRIS = 2;
PX_CONST uint PIXEL_FILTER_TABLE_SIZE = 1024;

PX_CONST uint ADAPTIVE_OFF = 0;
PX_CONST uint ADAPTIVE_IMAGE = 1;
PX_CONST uint ADAPTIVE_LIST = 2;
// adaptive.comp's two dispatches (FrameParams.mode): the convergence check, then the filter.
PX_CONST uint ADAPTIVE_CHECK = 0;
PX_CONST uint ADAPTIVE_FILTER = 1;

// Sampling test routines (shaders/tests/sampling_test.comp).
PX_CONST uint TEST_DIFFUSE = 0;
PX_CONST uint TEST_CONDUCTOR = 1;
PX_CONST uint TEST_DIELECTRIC = 2;
PX_CONST uint TEST_LIGHT = 3;   // light sampling from a shading point (all lights)
PX_CONST uint TEST_IC_HEMISPHERE = 4;  // the cache's stratified cosine hemisphere (one ray per stratum)
// Guiding (shaders/techniques/guiding.glsl); lobes (3 vec4 each) follow the samples in the
// test buffer, test_params.xyz = query position, test_param0 = lobe count.
PX_CONST uint TEST_GUIDING_VMF = 5;   // lobe 0 alone: vmf_sample / vmf_pdf
PX_CONST uint TEST_GUIDING_VMM = 6;   // the mixture: guiding_vmm_sample / guiding_vmm_pdf
PX_CONST uint TEST_GUIDING_PACK = 7;  // guiding_pack_direction / guiding_unpack_direction
PX_CONST uint TEST_ADRRS = 8;         // ADRRS' weight window and expected-value split
PX_CONST uint TEST_CONDUCTOR_MS = 9;  // TEST_CONDUCTOR / TEST_DIELECTRIC with Multiscatter GGX
PX_CONST uint TEST_DIELECTRIC_MS = 10;
// Principled BSDF: the Material follows the samples in the test buffer (PRINCIPLED_TEST_VEC4S
// vec4s: base_color+roughness, specular_tint+metallic, coat_tint+coat_weight,
// sheen_tint+sheen_weight, (transmission, specular_ior_level, coat_roughness, coat_ior),
// (sheen_roughness, multiscatter, 0, 0)); test_param0 = ior, test_params = (wo, unused).
PX_CONST uint TEST_PRINCIPLED = 11;
PX_CONST uint PRINCIPLED_TEST_VEC4S = 6;
// The path sampler (shaders/lib/rng.glsl): sample i of pixel test_params.x in stream seed;
// out (rnd2, rnd) of slots test_param0 and test_param0 + 1, then (rnd2, rnd) of the next two.
PX_CONST uint TEST_RNG = 12;
// The camera's aperture (shaders/lib/sampling.glsl, aperture_sample): test_params = (blades,
// rotation, ratio, 0); out io[2i].xy, a point on the aperture of radius 1.
PX_CONST uint TEST_APERTURE = 13;

#include "techniques.h"

#ifdef __cplusplus
}  // namespace px
#endif
#endif
