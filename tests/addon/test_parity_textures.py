"""Voronoi, Wave and Brick Textures (and Noise's Factor) pixel by pixel: Cycles (bpy 5.0.1) and Parallax against
parallax_core.nodes' references, so both engines compute the same pattern (same hash, same
formulas), not merely the same mean.

A 2 x 2 quad fills an orthographic view of W x W pixels; the texture's Vector is built from
the UV snapped to the pixel's centre (Math nodes), so every sample of a pixel computes the same
value. Cycles shows it as an Emission colour (Combined), Parallax as a Diffuse colour read
back through its Denoising Albedo pass (the add-on compiles the graph: node_graph.py)."""
import math

import numpy as np
from blender_helpers import pin_denoising_off, render

W = 32
CENTRES = (np.arange(W) + 0.5) / W


def _snapped_point(nodes, links):
    """(2 u + 0.3, 1.5 v + 0.2, 0.45) at the pixel's centre UV."""
    coords = nodes.new("ShaderNodeTexCoord")
    separate = nodes.new("ShaderNodeSeparateXYZ")
    links.new(coords.outputs["UV"], separate.inputs[0])
    combine = nodes.new("ShaderNodeCombineXYZ")
    combine.inputs[2].default_value = 0.45
    for k, (scale, offset) in enumerate(((2.0, 0.3), (1.5, 0.2))):
        last = separate.outputs[k]
        for op, value in (("MULTIPLY", W), ("FLOOR", None), ("ADD", 0.5), ("DIVIDE", W)):
            math_node = nodes.new("ShaderNodeMath")
            math_node.operation = op
            if value is not None:
                math_node.inputs[1].default_value = value
            links.new(last, math_node.inputs[0])
            last = math_node.outputs[0]
        affine = nodes.new("ShaderNodeMath")
        affine.operation = "MULTIPLY_ADD"
        affine.inputs[1].default_value, affine.inputs[2].default_value = scale, offset
        links.new(last, affine.inputs[0])
        links.new(affine.outputs[0], combine.inputs[k])
    return combine.outputs[0]


def _socket(sockets, identifier):
    """A node's socket by identifier, hidden ones too (Voronoi's Smoothness outside Smooth F1)."""
    return next(s for s in sockets if s.identifier == identifier)


def _points():
    u, v = np.meshgrid(CENTRES, CENTRES)  # row 0 at the bottom
    return np.stack([2 * u + 0.3, 1.5 * v + 0.2, np.full_like(u, 0.45)], -1).reshape(-1, 3)


def _voronoi(feature, metric, output, detail=0.0, normalize=False):
    settings = dict(Scale=2.5, Detail=detail, Roughness=0.6, Lacunarity=2.2, Smoothness=0.8, Exponent=1.5,
                    Randomness=0.85)

    def build(nodes, links, vector):
        node = nodes.new("ShaderNodeTexVoronoi")
        node.feature, node.distance, node.normalize = feature, metric, normalize
        for name, value in settings.items():
            _socket(node.inputs, name).default_value = value
        links.new(vector, node.inputs["Vector"])
        return node.outputs[output]

    def reference(p, nodes):
        out = nodes.voronoi_reference(p, *settings.values(), feature, metric, normalize)
        return out[nodes.VORONOI_OUTPUTS.index(output)]
    return build, reference


def _wave(wave_type, direction, profile, distortion):
    settings = {"Scale": 1.3, "Distortion": distortion, "Detail": 2.5, "Detail Scale": 1.7,
                "Detail Roughness": 0.55, "Phase Offset": 0.4}

    def build(nodes, links, vector):
        node = nodes.new("ShaderNodeTexWave")
        node.wave_type, node.wave_profile = wave_type, profile
        setattr(node, "rings_direction" if wave_type == "RINGS" else "bands_direction", direction)
        for name, value in settings.items():
            node.inputs[name].default_value = value
        links.new(vector, node.inputs["Vector"])
        return node.outputs["Color"]

    def reference(p, nodes):
        return nodes.wave_reference(p * 1.3, wave_type, direction, profile, *list(settings.values())[1:])
    return build, reference


def _brick(output, squash, squash_frequency, mortar_smooth):
    colors = {"Color1": (0.8, 0.2, 0.1), "Color2": (0.2, 0.7, 0.3), "Mortar": (0.9, 0.9, 0.8)}
    settings = {"Scale": 1.5, "Mortar Size": 0.06, "Mortar Smooth": mortar_smooth, "Bias": 0.1,
                "Brick Width": 0.5, "Row Height": 0.25}

    def build(nodes, links, vector):
        node = nodes.new("ShaderNodeTexBrick")
        node.offset, node.offset_frequency, node.squash, node.squash_frequency = 0.4, 3, squash, squash_frequency
        for name, value in {**colors, **settings}.items():
            node.inputs[name].default_value = (*value, 1.0) if name in colors else value
        links.new(vector, node.inputs["Vector"])
        return _socket(node.outputs, output)

    def reference(p, nodes):
        out = nodes.brick_reference(p * 1.5, *colors.values(), *list(settings.values())[1:], 0.4, 3, squash,
                                    squash_frequency)
        return out[output == "Fac"]
    return build, reference


def _noise_factor():
    """The Noise Texture's Factor output (the compiler once took it for Color: its name)."""
    def build(nodes, links, vector):
        node = nodes.new("ShaderNodeTexNoise")
        node.inputs["Scale"].default_value, node.inputs["Detail"].default_value = 3.0, 2.5
        links.new(vector, node.inputs["Vector"])
        return _socket(node.outputs, "Fac")

    def reference(p, nodes):
        return nodes.noise_reference(p * 3.0, 2.5, 0.5, 2.0, True)
    return build, reference


CASES = {
    "noise_factor": _noise_factor(),
    "voronoi_f1_color": _voronoi("F1", "EUCLIDEAN", "Color"),
    "voronoi_f1_minkowski_distance": _voronoi("F1", "MINKOWSKI", "Distance", detail=1.0, normalize=True),
    "voronoi_f2_manhattan_fractal_distance": _voronoi("F2", "MANHATTAN", "Distance", detail=2.5, normalize=True),
    "voronoi_smooth_f1_position": _voronoi("SMOOTH_F1", "CHEBYCHEV", "Position"),
    "voronoi_smooth_f1_fractal_color": _voronoi("SMOOTH_F1", "EUCLIDEAN", "Color", detail=1.5),
    "wave_bands_saw": _wave("BANDS", "DIAGONAL", "SAW", 0.0),
    "wave_rings_sine_distorted": _wave("RINGS", "SPHERICAL", "SIN", 2.0),
    "wave_bands_triangle_distorted": _wave("BANDS", "Y", "TRI", 3.0),
    "brick_color": _brick("Color", 0.6, 2, 0.0),
    "brick_smooth_fac": _brick("Fac", 1.3, 2, 0.5),
}


def _scene(bpy):
    bpy.ops.wm.read_factory_settings(use_empty=True)
    scene = bpy.context.scene
    scene.render.resolution_x = scene.render.resolution_y = W
    scene.render.resolution_percentage = 100
    scene.cycles.pixel_filter_type, scene.cycles.filter_width = "BOX", 1.0
    scene.cycles.samples, scene.cycles.max_bounces = 2, 0
    scene.parallax.samples = 2
    pin_denoising_off(scene)
    scene.view_layers[0].parallax.use_pass_denoising_data = True
    world = bpy.data.worlds.new("Black")
    world.color = (0.0, 0.0, 0.0)
    scene.world = world
    mesh = bpy.data.meshes.new("Quad")
    mesh.from_pydata([(-1, -1, 0), (1, -1, 0), (1, 1, 0), (-1, 1, 0)], [], [(0, 1, 2, 3)])
    uv = mesh.uv_layers.new(name="UVMap")
    for loop, (x, y) in zip(uv.data, ((0, 0), (1, 0), (1, 1), (0, 1))):
        loop.uv = (x, y)
    quad = bpy.data.objects.new("Quad", mesh)
    scene.collection.objects.link(quad)
    camera_data = bpy.data.cameras.new("Camera")
    camera_data.type, camera_data.ortho_scale = "ORTHO", 2.0
    camera = bpy.data.objects.new("Camera", camera_data)
    camera.location = (0.0, 0.0, 5.0)
    scene.collection.objects.link(camera)
    scene.camera = camera
    return scene, quad


def _material(bpy, name, build, shader):
    material = bpy.data.materials.new(name)
    if bpy.app.version < (5, 0, 0):
        material.use_nodes = True
    tree = material.node_tree
    tree.nodes.clear()
    out = tree.nodes.new("ShaderNodeOutputMaterial")
    node = tree.nodes.new(shader)
    tree.links.new(build(tree.nodes, tree.links, _snapped_point(tree.nodes, tree.links)), node.inputs["Color"])
    tree.links.new(node.outputs[0], out.inputs["Surface"])
    return material


def test_textures_match_cycles_pixel_by_pixel(bpy, tmp_path):
    from addon.engine import final
    from parallax_core import nodes

    scene, quad = _scene(bpy)
    points = _points()
    failures = []
    for name, (build, reference) in CASES.items():
        want = np.array([np.broadcast_to(reference(p, nodes), 3) for p in points]).reshape(W, W, 3)
        assert want.std() > 0.01, name  # a pattern, not a constant
        quad.data.materials.clear()
        quad.data.materials.append(_material(bpy, name + "_emission", build, "ShaderNodeEmission"))
        scene.render.engine = "CYCLES"
        cycles = render(bpy, tmp_path / f"{name}_cycles.exr")["Combined"][::-1, :, :3]
        quad.data.materials.clear()
        quad.data.materials.append(_material(bpy, name + "_diffuse", build, "ShaderNodeBsdfDiffuse"))
        scene.render.engine = "PARALLAX"
        ours = render(bpy, tmp_path / f"{name}_parallax.exr")["Denoising Albedo"][::-1]
        assert not [w for w in final.last_report.warnings if "not supported" in w], final.last_report.warnings
        for engine, got in (("Cycles", cycles), ("Parallax", ours)):
            # Within 1e-4 but where a cell, band or brick edge passes within float rounding of
            # the pixel's point (float32 there, float64 in the reference): at most 1%.
            bad = (np.abs(got - np.clip(want, 0.0, None)) > 1e-4).any(axis=-1)
            print(f"{name}: {engine} differs at {bad.sum()} of {bad.size} pixels")
            if bad.mean() > 0.01:
                failures.append(f"{name}: {engine} differs from the reference at {bad.sum()} of {bad.size} pixels")
    assert not failures, failures
