// Scene: validated SceneData arrays uploaded as GPU buffers, one BLAS per mesh, one TLAS.
//
// The host side is split into parts that can be prepared on their own (SceneHost), so an
// interactive edit re-prepares and re-uploads only what it changed: see update_scene.
#pragma once
#include "../../../shaders/shared/types.h"
#include "vk/accel.h"

#include <cstdint>
#include <map>
#include <memory>
#include <string>
#include <vector>

namespace px {

// Limits on scene values (README "Limits"; parallax_core.LIMITS). Parallax computes in
// float32: beyond these, products and sums in the shaders overflow or lose every digit.
struct SceneLimits {
    // Emission, world colour and a light's radiance (Cycles' units converted): above it is an
    // error; world-map texels are clamped to it with a warning. A frame's film sums stay finite.
    static constexpr double radiance = 1e20;
    // Base colour: above it is an error (an Add shader may legitimately exceed 1).
    static constexpr double albedo = 1e3;
    static constexpr double ior_min = 1e-3, ior_max = 1e3;
    // Object- and world-space coordinates: beyond it squared distances overflow (error).
    static constexpr double coordinate = 1e18;
    // World-space reach (geometry, lights, camera) beyond which float32 spacing exceeds
    // 6 cm: a warning. From about 2.5e7 m on, rays miss metre-sized surfaces outright.
    static constexpr double precision = 1e6;
    // Camera: the window's coordinates and the lengths of its axes (1/camera_scale..camera_scale).
    static constexpr double camera_scale = 1e6;
};

// A borrowed n-dimensional array from the binding layer (C-contiguous).
struct ArrayView {
    const void* data = nullptr;
    std::vector<size_t> shape;
    char kind = 'f';  // 'f' float, 'u' unsigned, 'i' signed
    size_t itemsize = 4;
    size_t size() const {
        size_t n = 1;
        for (size_t s : shape) n *= s;
        return n;
    }
};
using SceneArrays = std::map<std::string, ArrayView>;

// An owned copy of an ArrayView (what a Session keeps of the last arrays it was given).
struct OwnedArray {
    std::vector<uint8_t> bytes;
    std::vector<size_t> shape;
    char kind = 'f';
    size_t itemsize = 4;
    explicit OwnedArray(const ArrayView& v);
    ArrayView view() const;
};

// The parts of a scene an update can replace (bit mask). Each flat array belongs to one
// part (parallax_core.scene.PART_KEYS): "geometry" positions, indices, triangle_material,
// corner_*, mesh_*; "instances" instance_*; "materials" material_*, texture_*; "lights"
// light_*, world_*; "camera" camera_*.
enum ScenePart : uint32_t {
    PART_GEOMETRY = 1u << 0,
    PART_INSTANCES = 1u << 1,
    PART_MATERIALS = 1u << 2,
    PART_LIGHTS = 1u << 3,  // analytic lights and the world (both live in the light table)
    PART_CAMERA = 1u << 4,
    PART_ALL = (1u << 5) - 1,
};
// Part names -> mask; an empty list means PART_ALL. Throws std::invalid_argument on an
// unknown name.
uint32_t parse_scene_parts(const std::vector<std::string>& names);
// The part an array name belongs to, or 0 for a name the core does not read.
uint32_t scene_part_of_array(const std::string& name);
// The name of one part bit ("geometry", ...).
std::string scene_part_name(uint32_t part);

// Host-side parts of a scene after validation and ordering; no Vulkan. Each part is shared
// and immutable once prepared, so a partial update copies only the pointers of the parts it
// keeps (and the Scene reuses their GPU buffers).
struct SceneGeometry {  // "geometry"
    std::vector<vec3> positions;
    std::vector<uvec3> indices;        // triangles in bvh_order within each mesh
    std::vector<vec3> corner_normals;  // 3 per triangle, or empty
    std::vector<vec2> corner_uvs;      // 3 per triangle, or empty
    std::vector<vec4> corner_tangents;  // 3 per triangle (tangent, bitangent sign), or empty
    std::vector<vec4> corner_attributes;  // attribute_slots blocks of 3 per triangle (NODE_ATTRIBUTE)
    uint32_t attribute_slots = 0;
    std::vector<uint> triangle_material;
    std::vector<MeshInfo> meshes;
    std::vector<vec3> mesh_lo, mesh_hi;  // object-space bounds per mesh
    uint32_t materials_needed = 0;       // 1 + the largest triangle_material (0 if none)
};
struct SceneMaterials {  // "materials"
    std::vector<Material> materials;
    std::vector<TextureInfo> textures;
    std::vector<uint> texels;
    std::vector<uint> node_programs;  // the materials' node programs (Material.program)
    std::vector<uint> program_features;  // per material: the FEATURE_NODE_* groups its program uses
};
struct ScenePlacement {  // "instances": the TLAS contents
    std::vector<InstanceInfo> instances;  // in TLAS order; light_offset = NO_INDEX
    std::vector<vec3> world_lo, world_hi; // each instance's world bounds (of its mesh's box)
    vec3 center{0, 0, 0};                 // bounding sphere of the placed geometry
    float radius = 1.0f;
    double reach = 0;                     // largest |world coordinate| of the placed geometry
    std::vector<std::string> warnings;
};
struct SceneEnvironment {  // the world map's texels and sampling tables ("lights")
    std::vector<vec3> texels;
    std::vector<float> marginal, conditional;
    uint width = 0, height = 0;
    float total = 0;           // sum of luminance * sin(theta) weights
    float mean_luminance = 0;  // sin(theta)-weighted mean texel luminance (0 if total is 0)
    std::vector<std::string> warnings;  // clamped texels
};
struct SceneLights {  // depends on geometry, instances, materials and lights
    std::vector<InstanceInfo> instances;  // the placement with light offsets: the INSTANCES buffer
    std::vector<Light> lights;
    std::vector<float> light_cdf;         // by power; with a tree, over the distant lights alone
    std::vector<LightTreeNode> light_tree; // over the local lights (light_tree.h); one unused node if none
    double reach = 0;  // largest |world coordinate| of an analytic light
    std::vector<std::string> warnings;  // skipped lights
};

struct SceneHost {
    std::shared_ptr<const SceneGeometry> geometry;
    std::shared_ptr<const SceneMaterials> materials;
    std::shared_ptr<const ScenePlacement> placement;
    std::shared_ptr<const SceneEnvironment> environment;
    std::shared_ptr<const SceneLights> lights;
    SceneInfo info{};
    uint features = 0;  // FEATURE_* bits of what this scene uses
    std::vector<std::string> warnings() const;  // skipped or clamped items, precision
};

// Validates and converts the arrays (see parallax_core.scene.SceneData.flatten for the
// format). Throws std::invalid_argument naming the offending array and element.
// `spatial_order` puts triangles and instances in bvh_order (lavapipe's BVH builder splits
// in input order, so this decides its trace speed; the Python binding asks for it only where
// DeviceReport::builds_in_input_order).
// `light_tree`: pick local lights through a light tree (else by power; light_tree.h).
SceneHost prepare_scene(const SceneArrays& arrays, bool spatial_order, bool light_tree = true);

// World AABB of the placed geometry: the 8 transformed corners of each instance's mesh bounds
// (the bounding sphere's box where there are no instances).
void scene_bounds(const SceneHost& scene, float lo[3], float hi[3]);

// `previous` with the `parts` re-prepared from `arrays` (which must hold every array, the
// unchanged ones included) and whatever depends on them; the other parts are shared with
// `previous`. PART_GEOMETRY re-prepares everything. Throws like prepare_scene; `previous`
// is never modified.
SceneHost update_scene(const SceneHost& previous, const SceneArrays& arrays, bool spatial_order, uint32_t parts,
                       bool light_tree = true);

// `previous` with its light table (and light sampling tables) remade from `arrays` for
// another `light_tree` setting; everything else, the environment included, is shared.
SceneHost relight_scene(const SceneHost& previous, const SceneArrays& arrays, bool light_tree);

// The order to hand primitives with boxes [lo, hi] to a BVH builder that splits its input in
// halves without sorting (lavapipe's): a median split per node along the axis of lowest
// surface-area cost. Without it a shuffled mesh traces hundreds of times slower there; against
// a Morton order it traces 20-25% faster in rooms of walls (README "Performance").
std::vector<uint32_t> bvh_order(const std::vector<vec3>& lo, const std::vector<vec3>& hi);

class Scene {
public:
    // Uploads `host`. GPU data of the parts `previous` shares with `host` (the same host
    // objects) is reused from `previous` rather than uploaded again; BLASes are reused while
    // the geometry is, so only a geometry change rebuilds them.
    Scene(Context& ctx, SceneHost host, const Scene* previous = nullptr);
    // Binds every scene buffer and the TLAS into `set`.
    void bind(class DescriptorSet& set) const;
    const SceneHost& host() const { return host_; }
    size_t triangle_count() const { return host_.geometry->indices.size(); }
    uint32_t blases_built() const { return blases_built_; }  // by this Scene, not reused

private:
    SceneHost host_;
    std::map<uint32_t, std::shared_ptr<const Buffer>> buffers_;  // binding -> buffer
    std::vector<std::shared_ptr<const AccelerationStructure>> mesh_blas_;  // per mesh; null if unused
    std::shared_ptr<const AccelerationStructure> tlas_;
    uint32_t blases_built_ = 0;
};

}  // namespace px
