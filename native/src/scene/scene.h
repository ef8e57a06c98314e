// Scene: validated SceneData arrays uploaded as GPU buffers, one BLAS per mesh, one TLAS.
#pragma once
#include "../../../shaders/shared/types.h"
#include "vk/accel.h"

#include <map>
#include <memory>
#include <string>
#include <vector>

namespace px {

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

// Host-side scene after validation, ordering and light-table construction; no Vulkan.
struct SceneHost {
    std::vector<vec3> positions;
    std::vector<uvec3> indices;
    std::vector<vec3> corner_normals;  // 3 per triangle, or empty
    std::vector<vec2> corner_uvs;      // 3 per triangle, or empty
    std::vector<uint> triangle_material;
    std::vector<MeshInfo> meshes;
    std::vector<InstanceInfo> instances;  // in TLAS order; custom index = position here
    std::vector<Material> materials;
    std::vector<TextureInfo> textures;
    std::vector<uint> texels;
    std::vector<Light> lights;
    std::vector<float> light_cdf;
    std::vector<vec3> env_texels;
    std::vector<float> env_marginal, env_conditional;
    SceneInfo info{};
    uint features = 0;  // FEATURE_* bits of what this scene uses
    std::vector<std::string> warnings;
};

// Validates and converts the arrays (see parallax_core.scene.SceneData.flatten for the
// format). Throws std::invalid_argument naming the offending array and element.
// `spatial_order` sorts triangles and instances along a Morton curve (lavapipe's BVH
// builder splits in input order, so this decides its trace speed).
SceneHost prepare_scene(const SceneArrays& arrays, bool spatial_order);

class Scene {
public:
    Scene(Context& ctx, SceneHost host);
    // Binds every scene buffer and the TLAS into `set`.
    void bind(class DescriptorSet& set) const;
    const SceneHost& host() const { return host_; }
    size_t triangle_count() const { return host_.indices.size(); }

private:
    SceneHost host_;
    std::map<uint32_t, Buffer> buffers_;  // binding -> buffer
    std::vector<std::unique_ptr<AccelerationStructure>> blases_;
    std::unique_ptr<AccelerationStructure> tlas_;
};

}  // namespace px
