"""Parity with Cycles for node graphs driving shader inputs (issue 37, the node evaluator): a
grid of patches, each a material whose colour, roughness, metallic, normal or Mix Shader factor
comes from texture and maths nodes (shaders/lib/nodes.glsl runs them per hit), rendered by both
engines at 160 x 120 with 256 samples. The issue's goal: 8 x 8-block relMSE below 0.005, and
each patch's mean within 2%."""
import math

import numpy as np
import pytest
from blender_helpers import block_means, build_scene, render_engine

WIDTH, HEIGHT, BLOCK = 160, 120, 8
SAMPLES = 256
COLUMNS, ROWS = 5, 4


def _image(bpy, name, size=16):
    """A float, non-colour image: a smooth ramp along u times bands along v (values 0.05..0.95)."""
    u, v = np.meshgrid((np.arange(size) + 0.5) / size, (np.arange(size) + 0.5) / size)
    value = 0.05 + 0.9 * u * (0.5 + 0.5 * (np.floor(v * 4) % 2))
    rgba = np.ones((size, size, 4), np.float32)
    rgba[..., 0], rgba[..., 1], rgba[..., 2] = value, value[::-1], 1.0 - value
    image = bpy.data.images.new(name, size, size, alpha=False, float_buffer=True)
    image.colorspace_settings.name = "Non-Color"
    image.pixels.foreach_set(rgba.ravel())
    return image


def _material(bpy, name, build):
    """A material whose node tree ``build(nodes, links, output_socket)`` fills."""
    material = bpy.data.materials.new(name)
    if bpy.app.version < (5, 0, 0):
        material.use_nodes = True
    tree = material.node_tree
    tree.nodes.clear()
    output = tree.nodes.new("ShaderNodeOutputMaterial")
    build(tree.nodes, tree.links, output.inputs["Surface"])
    return material


def _uv_fraction(nodes, links, scale):
    """fract(u * scale): a ramp that repeats `scale` times across a patch."""
    coords = nodes.new("ShaderNodeTexCoord")
    separate = nodes.new("ShaderNodeSeparateXYZ")
    links.new(coords.outputs["UV"], separate.inputs[0])
    times = nodes.new("ShaderNodeMath")
    times.operation, times.inputs[1].default_value = "MULTIPLY", scale
    links.new(separate.outputs["X"], times.inputs[0])
    fraction = nodes.new("ShaderNodeMath")
    fraction.operation = "FRACT"
    links.new(times.outputs[0], fraction.inputs[0])
    return fraction.outputs[0]


def materials(bpy):
    image = _image(bpy, "Pattern")

    def textured_roughness(nodes, links, surface):  # a roughness map (colour -> float: luminance)
        bsdf = nodes.new("ShaderNodeBsdfPrincipled")
        bsdf.inputs["Base Color"].default_value = (0.8, 0.5, 0.3, 1.0)
        bsdf.inputs["Metallic"].default_value = 1.0
        tex = nodes.new("ShaderNodeTexImage")
        tex.image = image
        links.new(tex.outputs["Color"], bsdf.inputs["Roughness"])
        links.new(bsdf.outputs[0], surface)

    def color_ramp(nodes, links, surface):  # a ColorRamp (B-spline) of fract(3 u)
        bsdf = nodes.new("ShaderNodeBsdfDiffuse")
        ramp = nodes.new("ShaderNodeValToRGB")
        ramp.color_ramp.interpolation = "B_SPLINE"
        ramp.color_ramp.elements[0].color = (0.9, 0.1, 0.1, 1.0)
        ramp.color_ramp.elements[1].color = (0.1, 0.2, 0.9, 1.0)
        ramp.color_ramp.elements.new(0.5).color = (0.1, 0.9, 0.2, 1.0)
        links.new(_uv_fraction(nodes, links, 3.0), ramp.inputs["Fac"])
        links.new(ramp.outputs["Color"], bsdf.inputs["Color"])
        links.new(bsdf.outputs[0], surface)

    def mix_by_texture(nodes, links, surface):  # a Mix Shader whose factor is the image's red
        diffuse = nodes.new("ShaderNodeBsdfDiffuse")
        diffuse.inputs["Color"].default_value = (0.8, 0.2, 0.1, 1.0)
        glossy = nodes.new("ShaderNodeBsdfGlossy")
        glossy.inputs["Roughness"].default_value = 0.2
        mix = nodes.new("ShaderNodeMixShader")
        tex = nodes.new("ShaderNodeTexImage")
        tex.image = image
        separate = nodes.new("ShaderNodeSeparateColor")
        links.new(tex.outputs["Color"], separate.inputs[0])
        links.new(separate.outputs[0], mix.inputs["Fac"])
        links.new(diffuse.outputs[0], mix.inputs[1])
        links.new(glossy.outputs[0], mix.inputs[2])
        links.new(mix.outputs[0], surface)

    def mix_multiply_mapping(nodes, links, surface):  # Mapping (scaled, turned) into the image, Mix multiply
        bsdf = nodes.new("ShaderNodeBsdfDiffuse")
        coords = nodes.new("ShaderNodeTexCoord")
        mapping = nodes.new("ShaderNodeMapping")
        mapping.inputs["Scale"].default_value = (2.0, 3.0, 1.0)
        mapping.inputs["Rotation"].default_value = (0.0, 0.0, math.radians(30.0))
        mapping.inputs["Location"].default_value = (0.1, 0.2, 0.0)
        links.new(coords.outputs["UV"], mapping.inputs["Vector"])
        tex = nodes.new("ShaderNodeTexImage")
        tex.image = image
        links.new(mapping.outputs[0], tex.inputs["Vector"])
        mix = nodes.new("ShaderNodeMix")
        mix.data_type, mix.blend_type = "RGBA", "MULTIPLY"
        mix.inputs["Factor"].default_value = 0.8
        mix.inputs[7].default_value = (0.9, 0.8, 0.3, 1.0)
        links.new(tex.outputs["Color"], mix.inputs[6])
        links.new(mix.outputs[2], bsdf.inputs["Color"])
        links.new(bsdf.outputs[0], surface)

    def map_range_metallic(nodes, links, surface):  # Map Range (clamped) of fract(2 u) into metallic
        bsdf = nodes.new("ShaderNodeBsdfPrincipled")
        bsdf.inputs["Base Color"].default_value = (0.3, 0.6, 0.8, 1.0)
        bsdf.inputs["Roughness"].default_value = 0.3
        remap = nodes.new("ShaderNodeMapRange")
        remap.inputs["From Min"].default_value, remap.inputs["From Max"].default_value = 0.2, 0.8
        remap.clamp = True
        links.new(_uv_fraction(nodes, links, 2.0), remap.inputs["Value"])
        links.new(remap.outputs[0], bsdf.inputs["Metallic"])
        links.new(bsdf.outputs[0], surface)

    def group_invert(nodes, links, surface):  # a node group (Invert, Combine/Separate) into a colour
        group = bpy.data.node_groups.new("InvertRamp", "ShaderNodeTree")
        group.interface.new_socket("Fac", in_out="INPUT", socket_type="NodeSocketFloat")
        group.interface.new_socket("Color", in_out="OUTPUT", socket_type="NodeSocketColor")
        inside, outside = group.nodes.new("NodeGroupInput"), group.nodes.new("NodeGroupOutput")
        combine = group.nodes.new("ShaderNodeCombineColor")
        combine.inputs[1].default_value, combine.inputs[2].default_value = 0.4, 0.1
        invert = group.nodes.new("ShaderNodeInvert")
        invert.inputs["Fac"].default_value = 0.7
        group.links.new(inside.outputs[0], combine.inputs[0])
        group.links.new(combine.outputs[0], invert.inputs["Color"])
        group.links.new(invert.outputs[0], outside.inputs[0])
        node = nodes.new("ShaderNodeGroup")
        node.node_tree = group
        links.new(_uv_fraction(nodes, links, 1.5), node.inputs[0])
        bsdf = nodes.new("ShaderNodeBsdfDiffuse")
        links.new(node.outputs[0], bsdf.inputs["Color"])
        links.new(bsdf.outputs[0], surface)

    def noise(nodes, links, surface):  # Noise Texture (3D fBm, Generated coordinates) colour and factor
        bsdf = nodes.new("ShaderNodeBsdfPrincipled")
        noise = nodes.new("ShaderNodeTexNoise")
        noise.inputs["Scale"].default_value, noise.inputs["Detail"].default_value = 5.0, 3.5
        noise.inputs["Distortion"].default_value = 0.4
        links.new(noise.outputs["Color"], bsdf.inputs["Base Color"])
        links.new(noise.outputs["Fac"], bsdf.inputs["Metallic"])
        links.new(bsdf.outputs[0], surface)

    def checker_gradient(nodes, links, surface):  # Checker (Generated) colour, an easing Gradient's roughness
        bsdf = nodes.new("ShaderNodeBsdfPrincipled")
        bsdf.inputs["Metallic"].default_value = 0.6
        checker = nodes.new("ShaderNodeTexChecker")
        checker.inputs["Scale"].default_value = 4.0
        checker.inputs["Color1"].default_value = (0.9, 0.7, 0.2, 1.0)
        checker.inputs["Color2"].default_value = (0.1, 0.3, 0.6, 1.0)
        gradient = nodes.new("ShaderNodeTexGradient")
        gradient.gradient_type = "EASING"
        links.new(checker.outputs["Color"], bsdf.inputs["Base Color"])
        links.new(gradient.outputs["Fac"], bsdf.inputs["Roughness"])
        links.new(bsdf.outputs[0], surface)

    def bump_noise(nodes, links, surface):  # Bump of a Noise height into a Principled BSDF's Normal
        bsdf = nodes.new("ShaderNodeBsdfPrincipled")
        bsdf.inputs["Base Color"].default_value = (0.7, 0.5, 0.3, 1.0)
        bsdf.inputs["Roughness"].default_value = 0.35
        bsdf.inputs["Metallic"].default_value = 0.5
        noise = nodes.new("ShaderNodeTexNoise")
        noise.inputs["Scale"].default_value, noise.inputs["Detail"].default_value = 6.0, 2.0
        bump = nodes.new("ShaderNodeBump")
        bump.inputs["Distance"].default_value = 0.05
        links.new(noise.outputs["Fac"], bump.inputs["Height"])
        links.new(bump.outputs["Normal"], bsdf.inputs["Normal"])
        links.new(bsdf.outputs[0], surface)

    def normal_map_image(nodes, links, surface):  # a tangent-space normal map image (Non-Color)
        bsdf = nodes.new("ShaderNodeBsdfGlossy")
        bsdf.inputs["Color"].default_value = (0.8, 0.8, 0.6, 1.0)
        bsdf.inputs["Roughness"].default_value = 0.3
        tex = nodes.new("ShaderNodeTexImage")
        tex.image = _normal_map_image(bpy, "Ripples")
        normal_map = nodes.new("ShaderNodeNormalMap")
        normal_map.inputs["Strength"].default_value = 0.8
        links.new(tex.outputs["Color"], normal_map.inputs["Color"])
        links.new(normal_map.outputs["Normal"], bsdf.inputs["Normal"])
        diffuse = nodes.new("ShaderNodeBsdfDiffuse")
        diffuse.inputs["Color"].default_value = (0.3, 0.5, 0.7, 1.0)
        links.new(normal_map.outputs["Normal"], diffuse.inputs["Normal"])
        mix = nodes.new("ShaderNodeMixShader")
        mix.inputs["Fac"].default_value = 0.5
        links.new(diffuse.outputs[0], mix.inputs[1])
        links.new(bsdf.outputs[0], mix.inputs[2])
        links.new(mix.outputs[0], surface)

    def layer_weight_mix(nodes, links, surface):  # Layer Weight's Facing as a Mix Shader factor
        diffuse = nodes.new("ShaderNodeBsdfDiffuse")
        diffuse.inputs["Color"].default_value = (0.8, 0.3, 0.1, 1.0)
        glossy = nodes.new("ShaderNodeBsdfGlossy")
        glossy.inputs["Roughness"].default_value = 0.15
        weight = nodes.new("ShaderNodeLayerWeight")
        weight.inputs["Blend"].default_value = 0.7
        mix = nodes.new("ShaderNodeMixShader")
        links.new(weight.outputs["Facing"], mix.inputs["Fac"])
        links.new(diffuse.outputs[0], mix.inputs[1])
        links.new(glossy.outputs[0], mix.inputs[2])
        links.new(mix.outputs[0], surface)

    def fresnel_bumped(nodes, links, surface):  # Fresnel at a bumped normal (a Bump of the image) into a colour
        bsdf = nodes.new("ShaderNodeBsdfDiffuse")
        tex = nodes.new("ShaderNodeTexImage")
        tex.image = image
        bump = nodes.new("ShaderNodeBump")
        bump.inputs["Distance"].default_value = 0.3
        links.new(tex.outputs["Color"], bump.inputs["Height"])
        fresnel = nodes.new("ShaderNodeFresnel")
        fresnel.inputs["IOR"].default_value = 4.0
        links.new(bump.outputs["Normal"], fresnel.inputs["Normal"])
        mix = nodes.new("ShaderNodeMix")
        mix.data_type = "RGBA"
        mix.inputs[6].default_value, mix.inputs[7].default_value = (0.1, 0.2, 0.8, 1.0), (0.9, 0.9, 0.2, 1.0)
        links.new(fresnel.outputs[0], mix.inputs["Factor"])
        links.new(mix.outputs[2], bsdf.inputs["Color"])
        links.new(bsdf.outputs[0], surface)

    def object_noise(nodes, links, surface):  # Noise of Object coordinates into a colour
        bsdf = nodes.new("ShaderNodeBsdfDiffuse")
        coords = nodes.new("ShaderNodeTexCoord")
        noise = nodes.new("ShaderNodeTexNoise")
        noise.inputs["Scale"].default_value = 3.0
        links.new(coords.outputs["Object"], noise.inputs["Vector"])
        links.new(noise.outputs["Color"], bsdf.inputs["Color"])
        links.new(bsdf.outputs[0], surface)

    def attribute_color(nodes, links, surface):  # a colour attribute (node_grid adds it) times an Attribute's factor
        bsdf = nodes.new("ShaderNodeBsdfDiffuse")
        color = nodes.new("ShaderNodeVertexColor")
        color.layer_name = "Paint"
        factor = nodes.new("ShaderNodeAttribute")
        factor.attribute_name = "Paint"
        mix = nodes.new("ShaderNodeMix")
        mix.data_type, mix.blend_type = "RGBA", "MULTIPLY"
        mix.inputs["Factor"].default_value = 1.0
        links.new(color.outputs["Color"], mix.inputs[6])
        links.new(next(s for s in factor.outputs if s.identifier == "Fac"), mix.inputs[7])
        links.new(mix.outputs[2], bsdf.inputs["Color"])
        links.new(bsdf.outputs[0], surface)

    def second_uv_map(nodes, links, surface):  # the image through a second UV map (node_grid adds it), named
        bsdf = nodes.new("ShaderNodeBsdfDiffuse")
        uv = nodes.new("ShaderNodeUVMap")
        uv.uv_map = "Turned"
        tex = nodes.new("ShaderNodeTexImage")
        tex.image = image
        links.new(uv.outputs["UV"], tex.inputs["Vector"])
        links.new(tex.outputs["Color"], bsdf.inputs["Color"])
        links.new(bsdf.outputs[0], surface)

    builders = [textured_roughness, color_ramp, mix_by_texture, mix_multiply_mapping, map_range_metallic,
                group_invert, noise, checker_gradient, bump_noise, normal_map_image, layer_weight_mix,
                fresnel_bumped, object_noise, attribute_color, second_uv_map]
    return [_material(bpy, b.__name__, b) for b in builders]


def texture_materials(bpy):
    """Voronoi, Wave and Brick Textures (their default Vector: Generated, 0..1 across a patch) at
    scales where a patch holds many cells, bands or bricks."""
    def texture(nodes, kind, **settings):
        node = nodes.new(kind)
        for name, value in settings.items():
            if name.isupper() or name[0].isupper():
                next(s for s in node.inputs if s.identifier == name).default_value = value
            else:
                setattr(node, name, value)
        return node

    def factor(node):
        return next(s for s in node.outputs if s.identifier == "Fac")

    def voronoi_color(nodes, links, surface):  # F1 cell colours into a base colour
        bsdf = nodes.new("ShaderNodeBsdfPrincipled")
        bsdf.inputs["Roughness"].default_value = 0.6
        voronoi = texture(nodes, "ShaderNodeTexVoronoi", Scale=6.0)
        links.new(voronoi.outputs["Color"], bsdf.inputs["Base Color"])
        links.new(bsdf.outputs[0], surface)

    def voronoi_fractal_roughness(nodes, links, surface):  # F2 Manhattan, fractal, normalized, into roughness
        bsdf = nodes.new("ShaderNodeBsdfPrincipled")
        bsdf.inputs["Base Color"].default_value = (0.8, 0.6, 0.3, 1.0)
        bsdf.inputs["Metallic"].default_value = 1.0
        voronoi = texture(nodes, "ShaderNodeTexVoronoi", feature="F2", distance="MANHATTAN", normalize=True,
                          Scale=4.0, Detail=2.0, Roughness=0.6)
        links.new(voronoi.outputs["Distance"], bsdf.inputs["Roughness"])
        links.new(bsdf.outputs[0], surface)

    def wave_bands(nodes, links, surface):  # sine bands, distorted, as a grey colour
        bsdf = nodes.new("ShaderNodeBsdfDiffuse")
        wave = texture(nodes, "ShaderNodeTexWave", bands_direction="DIAGONAL", Scale=2.0, Distortion=3.0, Detail=2.0)
        links.new(wave.outputs["Color"], bsdf.inputs["Color"])
        links.new(bsdf.outputs[0], surface)

    def brick_color(nodes, links, surface):  # bricks (squashed rows, tints) as the colour
        bsdf = nodes.new("ShaderNodeBsdfDiffuse")
        brick = texture(nodes, "ShaderNodeTexBrick", squash=0.7, offset_frequency=2, squash_frequency=3,
                        Scale=4.0, Bias=0.2, Color1=(0.8, 0.3, 0.1, 1.0), Color2=(0.5, 0.6, 0.2, 1.0),
                        Mortar=(0.9, 0.9, 0.85, 1.0))
        links.new(brick.outputs["Color"], bsdf.inputs["Color"])
        links.new(bsdf.outputs[0], surface)

    def brick_mortar_mix(nodes, links, surface):  # the smooth mortar's factor mixing two shaders
        diffuse = nodes.new("ShaderNodeBsdfDiffuse")
        diffuse.inputs["Color"].default_value = (0.8, 0.2, 0.1, 1.0)
        glossy = nodes.new("ShaderNodeBsdfGlossy")
        glossy.inputs["Roughness"].default_value = 0.25
        brick = texture(nodes, "ShaderNodeTexBrick", Scale=3.0, **{"Mortar Size": 0.05, "Mortar Smooth": 0.5})
        mix = nodes.new("ShaderNodeMixShader")
        links.new(factor(brick), mix.inputs["Fac"])
        links.new(diffuse.outputs[0], mix.inputs[1])
        links.new(glossy.outputs[0], mix.inputs[2])
        links.new(mix.outputs[0], surface)

    # Smooth F1, Minkowski and rings are checked pixel by pixel in test_parity_textures.py.
    builders = [voronoi_color, voronoi_fractal_roughness, wave_bands, brick_color, brick_mortar_mix]
    return [_material(bpy, b.__name__, b) for b in builders]


def _normal_map_image(bpy, name, size=64):
    """A tangent-space normal map (Non-Color): the normals of ripples h = 0.08 sin(6 pi u) sin(4 pi v)."""
    u, v = np.meshgrid((np.arange(size) + 0.5) / size, (np.arange(size) + 0.5) / size)
    dh_du = 0.08 * 6 * np.pi * np.cos(6 * np.pi * u) * np.sin(4 * np.pi * v)
    dh_dv = 0.08 * 4 * np.pi * np.sin(6 * np.pi * u) * np.cos(4 * np.pi * v)
    n = np.stack([-dh_du, -dh_dv, np.ones_like(u)], -1)
    n /= np.linalg.norm(n, axis=-1, keepdims=True)
    rgba = np.ones((size, size, 4), np.float32)
    rgba[..., :3] = 0.5 * n + 0.5
    image = bpy.data.images.new(name, size, size, alpha=False, float_buffer=True)
    image.colorspace_settings.name = "Non-Color"
    image.pixels.foreach_set(rgba.ravel())
    return image


def node_grid(b):
    """The patches (1 m each, UVs -0.5..0.5) in a 5 x 4 grid facing the camera, lit by an area
    light from the front and a grey world."""
    import bpy

    for k, material in enumerate(materials(bpy) + texture_materials(bpy)):
        x, z = (k % COLUMNS - (COLUMNS - 1) / 2) * 1.1, 1.1 + ((ROWS - 1) / 2 - k // COLUMNS) * 1.1
        patch = b.add_rect(f"Patch{k}", 1.0, 1.0, material, (x, 0.0, z), (math.pi / 2, 0.0, 0.0))
        b.box_project_uvs(patch.data)  # u, v = the quad's own x, y: -0.5..0.5
        if material.name == "attribute_color":  # a colour per corner of the quad, interpolated
            paint = patch.data.color_attributes.new("Paint", "FLOAT_COLOR", "POINT")
            for vertex, color in zip(paint.data, [(0.9, 0.1, 0.1, 1), (0.1, 0.8, 0.2, 1), (0.2, 0.3, 0.9, 1), (0.9, 0.9, 0.2, 1)]):
                vertex.color = color
        if material.name == "second_uv_map":  # the first map turned by 90 degrees and doubled
            turned = patch.data.uv_layers.new(name="Turned")
            for corner, first in zip(turned.data, patch.data.uv_layers["UVMap"].data):
                turned_uv = (2.0 * first.uv[1], -2.0 * first.uv[0])
                corner.uv = turned_uv
    light = bpy.data.lights.new("Key", "AREA")
    light.energy, light.size = 500.0, 3.0
    b.add_object("Key", light, (2.0, -5.0, 3.5), (math.radians(55), 0.0, math.radians(25)))
    b.add_camera((0.0, -7.5, 1.1), (0.0, 0.0, 1.1), 45.0)
    b.set_world((0.2, 0.2, 0.2), 1.0)


def test_node_graphs_match_cycles(bpy, tmp_path):
    from addon.sync import export_scene

    scene = build_scene(bpy, node_grid, WIDTH, HEIGHT)
    _, warnings = export_scene(bpy.context.evaluated_depsgraph_get(), WIDTH, HEIGHT)
    assert not warnings
    ours, theirs = (render_engine(bpy, tmp_path, scene, engine, 0, SAMPLES) for engine in ("PARALLAX", "CYCLES"))
    np.save(tmp_path / "nodes.npy", np.stack([ours, theirs]))
    P, C = block_means(ours, BLOCK), block_means(theirs, BLOCK)
    rel_mse = float(((P - C) ** 2).sum() / max((C ** 2).sum(), 1e-30))
    # Patch by patch: the image's cells, each round one patch (a patch's central 80%).
    cells = lambda img: img.reshape(ROWS, HEIGHT // ROWS, COLUMNS, WIDTH // COLUMNS, -1)[
        :, 3:-3, :, 3:-3].mean(axis=(1, 3, 4)).ravel()
    patch_ratio = cells(ours) / cells(theirs)
    print(f"node_grid: 8x8-block relMSE {rel_mse:.5f}; patch means / Cycles' {np.round(patch_ratio, 3).tolist()}")
    assert rel_mse < 0.005
    np.testing.assert_allclose(patch_ratio, 1.0, atol=0.02)
