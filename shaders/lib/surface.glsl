// Reconstructs the surface at a hit: position, normals, uv, material, texture.

struct SurfaceHit {
    vec3 p;
    vec3 generated;  // Generated texture coordinates (node programs only: FEATURE_NODES)
    vec3 ng;  // geometric normal, unit, world space (winding order side)
    vec3 ns;  // shading normal, unit, on the same side as ng
    vec3 ns_smooth;  // the interpolated one, before a node program bumps ns (FEATURE_NODES)
    vec2 bary;       // barycentrics of vertices 1 and 2 (FEATURE_NODES)
    vec2 uv;
    uint material;
    uint instance;
    uint primitive;
};

SurfaceHit fetch_surface(uint instance_index, uint primitive, vec2 bary) {
    SurfaceHit h;
    InstanceInfo inst = instances[instance_index];
    MeshInfo mesh = meshes[inst.mesh];
    uint tri = mesh.first_triangle + primitive;
    uvec3 idx = indices[tri];
    vec3 p0 = positions[idx.x], p1 = positions[idx.y], p2 = positions[idx.z];
    vec3 b = vec3(1.0 - bary.x - bary.y, bary.x, bary.y);
    vec3 p_object = b.x * p0 + b.y * p1 + b.z * p2;
    h.p = transform_point(inst.object_to_world, p_object);
    h.generated = HAS(FEATURE_NODES) ? p_object * mesh.texspace_scale + mesh.texspace_offset : vec3(0.0);
    vec3 ng_obj = cross(p1 - p0, p2 - p0);
    h.ng = normalize(transform_vector(inst.normal_to_world, ng_obj));
    h.ns = h.ng;
    if (HAS(FEATURE_SHADING_NORMALS) && mesh.has_normals != 0u) {
        vec3 n = b.x * corner_normals[3u * tri] + b.y * corner_normals[3u * tri + 1u] + b.z * corner_normals[3u * tri + 2u];
        n = transform_vector(inst.normal_to_world, n);
        if (dot(n, n) > 1e-12) {
            n = normalize(n);
            h.ns = dot(n, h.ng) >= 0.0 ? n : -n;
        }
    }
    h.uv = vec2(0.0);
    if (HAS(FEATURE_UVS) && mesh.has_uvs != 0u)
        h.uv = b.x * corner_uvs[3u * tri] + b.y * corner_uvs[3u * tri + 1u] + b.z * corner_uvs[3u * tri + 2u];
    h.ns_smooth = h.ns;
    h.bary = bary;
    h.material = triangle_material[tri];
    h.instance = instance_index;
    h.primitive = primitive;
    return h;
}

vec3 srgb_to_linear(vec3 c) {
    return mix(c / 12.92, pow((c + 0.055) / 1.055, vec3(2.4)), step(vec3(0.04045), c));
}

// One texel: sRGB-encoded for byte textures, linear for half-float ones (TEXTURE_FLAG_HALF).
vec3 texel_value(TextureInfo t, uint x, uint y) {
    uint i = y * t.width + x;
    if ((t.flags & TEXTURE_FLAG_HALF) != 0u) {
        uint w = t.offset + 2u * i;
        return vec3(unpackHalf2x16(texels[w]), unpackHalf2x16(texels[w + 1u]).x);
    }
    return unpackUnorm4x8(texels[t.offset + i]).rgb;
}

// Lookup with repeat wrapping; v = 1 is the top row (row 0), as in Blender. Closest takes the
// texel the point falls in (Cycles' INTERPOLATION_CLOSEST: floor(u * width)); Linear is
// bilinear. As Cycles does for 8-bit sRGB images (svm_image_texture,
// NODE_IMAGE_COMPRESS_AS_SRGB), the stored sRGB values are interpolated and the result decoded:
// decoding first would brighten every blend of a light and a dark texel (the decode is
// convex), most where the texture is magnified. Half-float texels are linear already and are
// interpolated as they are, like Cycles' float images.
vec3 sample_texture(int index, vec2 uv) {
    TextureInfo t = textures[index];
    vec3 c;
    if ((t.flags & TEXTURE_FLAG_CLOSEST) != 0u) {
        uint x = min(uint(fract(uv.x) * float(t.width)), t.width - 1u);
        uint y = t.height - 1u - min(uint(fract(uv.y) * float(t.height)), t.height - 1u);
        c = texel_value(t, x, y);
    } else {
        float x = fract(uv.x) * float(t.width) - 0.5;
        float y = (1.0 - fract(uv.y)) * float(t.height) - 0.5;
        float fx = floor(x), fy = floor(y);
        vec2 f = vec2(x - fx, y - fy);
        uint x0 = uint(int(fx) + int(t.width)) % t.width, x1 = (x0 + 1u) % t.width;
        uint y0 = uint(int(fy) + int(t.height)) % t.height, y1 = (y0 + 1u) % t.height;
        c = mix(mix(texel_value(t, x0, y0), texel_value(t, x1, y0), f.x),
                mix(texel_value(t, x0, y1), texel_value(t, x1, y1), f.x), f.y);
    }
    return (t.flags & TEXTURE_FLAG_HALF) != 0u ? c : srgb_to_linear(c);
}

vec3 material_albedo(Material m, vec2 uv) {
    vec3 c = m.base_color;
    if (HAS(FEATURE_TEXTURES) && m.base_color_texture >= 0) c *= sample_texture(m.base_color_texture, uv);
    return c;
}
