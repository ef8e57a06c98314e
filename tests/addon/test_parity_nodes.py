"""Parity with Cycles for node graphs driving shader inputs (issue 37, the node evaluator): a
grid of patches, each a material whose colour, roughness, metallic or Mix Shader factor comes
from texture and maths nodes (shaders/lib/nodes.glsl runs them per hit); a second grid of the
procedural Voronoi, Wave and Brick Textures. Rendered by both
engines with two seeds, compared as test_parity_features.py does (R < 3, means within 3%),
and patch by patch (each patch's mean within 3%)."""
import math

import numpy as np
import pytest
from blender_helpers import build_scene, parity_ratio, render_seed_pairs

WIDTH, HEIGHT, BLOCK = 128, 64, 4
SAMPLES = 128


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

    builders = [textured_roughness, color_ramp, mix_by_texture, mix_multiply_mapping, map_range_metallic,
                group_invert, noise, checker_gradient]
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

    def voronoi_smooth_position(nodes, links, surface):  # Smooth F1 Chebychev cell positions as a colour
        bsdf = nodes.new("ShaderNodeBsdfDiffuse")
        voronoi = texture(nodes, "ShaderNodeTexVoronoi", feature="SMOOTH_F1", distance="CHEBYCHEV", Scale=5.0,
                          Smoothness=0.7)
        links.new(voronoi.outputs["Position"], bsdf.inputs["Color"])
        links.new(bsdf.outputs[0], surface)

    def voronoi_minkowski_mix(nodes, links, surface):  # Minkowski distance mixing two colours
        bsdf = nodes.new("ShaderNodeBsdfDiffuse")
        voronoi = texture(nodes, "ShaderNodeTexVoronoi", distance="MINKOWSKI", Scale=7.0, Exponent=1.3,
                          Randomness=0.7)
        mix = nodes.new("ShaderNodeMix")
        mix.data_type = "RGBA"
        mix.inputs[6].default_value, mix.inputs[7].default_value = (0.9, 0.2, 0.1, 1.0), (0.1, 0.3, 0.9, 1.0)
        links.new(voronoi.outputs["Distance"], mix.inputs["Factor"])
        links.new(mix.outputs[2], bsdf.inputs["Color"])
        links.new(bsdf.outputs[0], surface)

    def wave_bands(nodes, links, surface):  # sine bands, distorted, as a grey colour
        bsdf = nodes.new("ShaderNodeBsdfDiffuse")
        wave = texture(nodes, "ShaderNodeTexWave", bands_direction="DIAGONAL", Scale=2.0, Distortion=3.0, Detail=2.0)
        links.new(wave.outputs["Color"], bsdf.inputs["Color"])
        links.new(bsdf.outputs[0], surface)

    def wave_rings_metallic(nodes, links, surface):  # saw rings' factor into metallic
        bsdf = nodes.new("ShaderNodeBsdfPrincipled")
        bsdf.inputs["Base Color"].default_value = (0.3, 0.7, 0.5, 1.0)
        bsdf.inputs["Roughness"].default_value = 0.35
        wave = texture(nodes, "ShaderNodeTexWave", wave_type="RINGS", rings_direction="Z", wave_profile="SAW",
                       Scale=1.5)
        links.new(factor(wave), bsdf.inputs["Metallic"])
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

    builders = [voronoi_color, voronoi_fractal_roughness, voronoi_smooth_position, voronoi_minkowski_mix,
                wave_bands, wave_rings_metallic, brick_color, brick_mortar_mix]
    return [_material(bpy, b.__name__, b) for b in builders]


def node_grid(b, make_materials=materials):
    """Eight 1 m patches (UVs -0.5..0.5 each) in a 4 x 2 grid facing the camera, lit by an area light
    from the front and a grey world."""
    import bpy

    for k, material in enumerate(make_materials(bpy)):
        x, z = (k % 4 - 1.5) * 1.1, 1.65 - (k // 4) * 1.1
        patch = b.add_rect(f"Patch{k}", 1.0, 1.0, material, (x, 0.0, z), (math.pi / 2, 0.0, 0.0))
        b.box_project_uvs(patch.data)  # u, v = the quad's own x, y: -0.5..0.5
    light = bpy.data.lights.new("Key", "AREA")
    light.energy, light.size = 400.0, 2.0
    b.add_object("Key", light, (1.5, -3.0, 2.5), (math.radians(55), 0.0, math.radians(25)))
    b.add_camera((0.0, -5.5, 1.1), (0.0, 0.0, 1.1), 45.0)
    b.set_world((0.2, 0.2, 0.2), 1.0)


@pytest.mark.parametrize("grid", ["nodes", "textures"])
def test_node_graphs_match_cycles(bpy, tmp_path, grid):
    from addon.sync import export_scene

    make = materials if grid == "nodes" else texture_materials
    scene = build_scene(bpy, lambda b: node_grid(b, make), WIDTH, HEIGHT)
    _, warnings = export_scene(bpy.context.evaluated_depsgraph_get(), WIDTH, HEIGHT)
    assert not [w for w in warnings if "not supported" in w], warnings
    p0, p1, c0, c1 = render_seed_pairs(bpy, tmp_path, scene, SAMPLES)
    np.save(tmp_path / f"{grid}.npy", np.stack([p0 + p1, c0 + c1]) / 2)
    ratio, rel_mse = parity_ratio(p0, p1, c0, c1, BLOCK)
    ours, theirs = float((p0 + p1).mean() / 2), float((c0 + c1).mean() / 2)
    print(f"{grid} grid: mean {ours:.4f} vs Cycles {theirs:.4f}, block relMSE {rel_mse:.5f}, "
          f"difference / noise {ratio:.2f}")
    assert ours == pytest.approx(theirs, rel=0.03)
    assert ratio < 3.0
    # Patch by patch: the image's 4 x 2 cells, each round one patch.
    cells = lambda img: img.reshape(2, HEIGHT // 2, 4, WIDTH // 4, -1).mean(axis=(1, 3, 4))
    np.testing.assert_allclose(cells(p0 + p1), cells(c0 + c1), rtol=0.03)
