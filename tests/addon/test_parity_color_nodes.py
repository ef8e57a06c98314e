"""Parity with Cycles for the colour and vector nodes of node programs: Vector Math, RGB Curves,
Float Curve, Hue/Saturation/Value, Bright/Contrast, Gamma, Map Range (stepped, smooth and
vector) and the further Math operations, each patch of a 4 x 2 grid driving a material input.
Rendered by both engines with two seeds and compared as test_parity_nodes.py does (R < 3, means
within 3%, each patch's mean within 3%)."""
import math

import numpy as np
import pytest
from blender_helpers import build_scene, parity_ratio, render_seed_pairs
from test_parity_nodes import _image, _material, _uv_fraction

WIDTH, HEIGHT, BLOCK = 128, 64, 4
SAMPLES = 128


def _uv(nodes):
    return nodes.new("ShaderNodeTexCoord").outputs["UV"]


def _shape_curve(curve, points):
    curve.points[0].location, curve.points[1].location = points[0], points[-1]
    for x, y in points[1:-1]:
        curve.points.new(x, y)


def materials(bpy):
    image = _image(bpy, "Pattern")

    def diffuse(nodes, links, surface, color):
        bsdf = nodes.new("ShaderNodeBsdfDiffuse")
        links.new(color, bsdf.inputs["Color"])
        links.new(bsdf.outputs[0], surface)

    def texture(nodes):
        tex = nodes.new("ShaderNodeTexImage")
        tex.image = image
        return tex.outputs["Color"]

    def vector_math(nodes, links, surface):  # |UV * 1.7 - (0.4, -0.1, 0.6)| as the colour, a Dot Product as roughness
        bsdf = nodes.new("ShaderNodeBsdfPrincipled")
        bsdf.inputs["Metallic"].default_value = 0.5
        scale = nodes.new("ShaderNodeVectorMath")
        scale.operation, scale.inputs["Scale"].default_value = "SCALE", 1.7
        links.new(_uv(nodes), scale.inputs[0])
        shift = nodes.new("ShaderNodeVectorMath")
        shift.operation, shift.inputs[1].default_value = "SUBTRACT", (0.4, -0.1, 0.6)
        links.new(scale.outputs["Vector"], shift.inputs[0])
        absolute = nodes.new("ShaderNodeVectorMath")
        absolute.operation = "ABSOLUTE"
        links.new(shift.outputs["Vector"], absolute.inputs[0])
        links.new(absolute.outputs["Vector"], bsdf.inputs["Base Color"])
        dot = nodes.new("ShaderNodeVectorMath")
        dot.operation, dot.inputs[1].default_value = "DOT_PRODUCT", (0.5, 0.3, 0.0)
        links.new(_uv(nodes), dot.inputs[0])
        links.new(dot.outputs["Value"], bsdf.inputs["Roughness"])
        links.new(bsdf.outputs[0], surface)

    def rgb_curves(nodes, links, surface):  # RGB Curves (an S on C, red lifted) of the image
        curves = nodes.new("ShaderNodeRGBCurve")
        _shape_curve(curves.mapping.curves[3], [(0.0, 0.0), (0.3, 0.15), (0.7, 0.85), (1.0, 1.0)])
        _shape_curve(curves.mapping.curves[0], [(0.0, 0.2), (1.0, 0.9)])
        curves.mapping.update()
        curves.inputs["Fac"].default_value = 0.9
        links.new(texture(nodes), curves.inputs["Color"])
        diffuse(nodes, links, surface, curves.outputs[0])

    def float_curve(nodes, links, surface):  # Float Curve of fract(2 u) into metallic
        bsdf = nodes.new("ShaderNodeBsdfPrincipled")
        bsdf.inputs["Base Color"].default_value = (0.9, 0.6, 0.3, 1.0)
        bsdf.inputs["Roughness"].default_value = 0.35
        curve = nodes.new("ShaderNodeFloatCurve")
        _shape_curve(curve.mapping.curves[0], [(0.0, 0.0), (0.4, 0.9), (1.0, 0.3)])
        curve.mapping.update()
        links.new(_uv_fraction(nodes, links, 2.0), curve.inputs["Value"])
        links.new(curve.outputs[0], bsdf.inputs["Metallic"])
        links.new(bsdf.outputs[0], surface)

    def hue_saturation(nodes, links, surface):  # Hue/Saturation/Value of the image
        hsv = nodes.new("ShaderNodeHueSaturation")
        hsv.inputs["Hue"].default_value, hsv.inputs["Saturation"].default_value = 0.8, 1.6
        hsv.inputs["Value"].default_value = 0.9
        links.new(texture(nodes), hsv.inputs["Color"])
        diffuse(nodes, links, surface, hsv.outputs[0])

    def bright_gamma(nodes, links, surface):  # Gamma of Bright/Contrast of the image, contrast from u
        bc = nodes.new("ShaderNodeBrightContrast")
        bc.inputs["Bright"].default_value = 0.05
        links.new(texture(nodes), bc.inputs["Color"])
        links.new(_uv_fraction(nodes, links, 1.0), bc.inputs["Contrast"])
        gamma = nodes.new("ShaderNodeGamma")
        gamma.inputs["Gamma"].default_value = 1.8
        links.new(bc.outputs[0], gamma.inputs["Color"])
        diffuse(nodes, links, surface, gamma.outputs[0])

    def map_range_types(nodes, links, surface):  # stepped (red), smoother step (green) of fract(1.5 u); metallic smooth step
        bsdf = nodes.new("ShaderNodeBsdfPrincipled")
        bsdf.inputs["Roughness"].default_value = 0.3
        value = _uv_fraction(nodes, links, 1.5)
        combine = nodes.new("ShaderNodeCombineColor")
        combine.inputs[2].default_value = 0.3
        for k, kind in enumerate(("STEPPED", "SMOOTHERSTEP", "SMOOTHSTEP")):
            remap = nodes.new("ShaderNodeMapRange")
            remap.interpolation_type = kind
            remap.inputs["From Min"].default_value, remap.inputs["From Max"].default_value = 0.8, 0.1  # reversed
            remap.inputs["To Min"].default_value, remap.inputs["To Max"].default_value = 0.05, 0.95
            {s.identifier: s for s in remap.inputs}["Steps"].default_value = 3.0
            links.new(value, remap.inputs["Value"])
            links.new(remap.outputs["Result"], combine.inputs[k] if k < 2 else bsdf.inputs["Metallic"])
        links.new(combine.outputs[0], bsdf.inputs["Base Color"])
        links.new(bsdf.outputs[0], surface)

    def map_range_vector(nodes, links, surface):  # vector Map Range (smooth step) of the UVs as the colour
        remap = nodes.new("ShaderNodeMapRange")
        remap.data_type, remap.interpolation_type = "FLOAT_VECTOR", "SMOOTHSTEP"
        sockets = {s.identifier: s for s in remap.inputs}
        sockets["From_Min_FLOAT3"].default_value = (-0.4, 0.5, 0.0)
        sockets["From_Max_FLOAT3"].default_value = (0.4, -0.5, 1.0)
        sockets["To_Min_FLOAT3"].default_value = (0.1, 0.05, 0.6)
        sockets["To_Max_FLOAT3"].default_value = (0.9, 0.8, 0.2)
        links.new(_uv(nodes), sockets["Vector"])
        diffuse(nodes, links, surface, remap.outputs["Vector"])

    def more_math(nodes, links, surface):  # Ping-Pong, Smooth Min and Arctan2 of u and v as the colour
        separate = nodes.new("ShaderNodeSeparateXYZ")
        links.new(_uv(nodes), separate.inputs[0])
        combine = nodes.new("ShaderNodeCombineColor")
        for k, (op, b, c) in enumerate((("PINGPONG", 0.3, 0.0), ("SMOOTH_MIN", 0.1, 0.4), ("ARCTAN2", 0.0, 0.0))):
            node = nodes.new("ShaderNodeMath")
            node.operation = op
            links.new(separate.outputs[k % 2], node.inputs[0])
            if op == "ARCTAN2":
                links.new(separate.outputs[1], node.inputs[0])
                links.new(separate.outputs[0], node.inputs[1])
            else:
                node.inputs[1].default_value, node.inputs[2].default_value = b, c
            post = nodes.new("ShaderNodeMath")
            post.operation, post.inputs[1].default_value, post.inputs[2].default_value = "MULTIPLY_ADD", 0.3, 0.5
            links.new(node.outputs[0], post.inputs[0])
            links.new(post.outputs[0], combine.inputs[k])
        diffuse(nodes, links, surface, combine.outputs[0])

    builders = [vector_math, rgb_curves, float_curve, hue_saturation, bright_gamma, map_range_types, map_range_vector,
                more_math]
    return [_material(bpy, b.__name__, b) for b in builders]


def color_grid(b):
    """Eight 1 m patches (UVs -0.5..0.5 each) in a 4 x 2 grid facing the camera, lit by an area
    light from the front and a grey world (as test_parity_nodes.node_grid)."""
    import bpy

    for k, material in enumerate(materials(bpy)):
        x, z = (k % 4 - 1.5) * 1.1, 1.65 - (k // 4) * 1.1
        patch = b.add_rect(f"Patch{k}", 1.0, 1.0, material, (x, 0.0, z), (math.pi / 2, 0.0, 0.0))
        b.box_project_uvs(patch.data)
    light = bpy.data.lights.new("Key", "AREA")
    light.energy, light.size = 400.0, 2.0
    b.add_object("Key", light, (1.5, -3.0, 2.5), (math.radians(55), 0.0, math.radians(25)))
    b.add_camera((0.0, -5.5, 1.1), (0.0, 0.0, 1.1), 45.0)
    b.set_world((0.2, 0.2, 0.2), 1.0)


def test_color_and_vector_nodes_match_cycles(bpy, tmp_path):
    from addon.sync import export_scene

    scene = build_scene(bpy, color_grid, WIDTH, HEIGHT)
    _, warnings = export_scene(bpy.context.evaluated_depsgraph_get(), WIDTH, HEIGHT)
    assert not [w for w in warnings if "not supported" in w], warnings
    p0, p1, c0, c1 = render_seed_pairs(bpy, tmp_path, scene, SAMPLES)
    np.save(tmp_path / "color_nodes.npy", np.stack([p0 + p1, c0 + c1]) / 2)
    ratio, rel_mse = parity_ratio(p0, p1, c0, c1, BLOCK)
    ours, theirs = float((p0 + p1).mean() / 2), float((c0 + c1).mean() / 2)
    print(f"color_grid: mean {ours:.4f} vs Cycles {theirs:.4f}, block relMSE {rel_mse:.5f}, "
          f"difference / noise {ratio:.2f}")
    cells = lambda img: img.reshape(2, HEIGHT // 2, 4, WIDTH // 4, -1).mean(axis=(1, 3, 4))
    print("patches (ours / Cycles):", (cells(p0 + p1) / cells(c0 + c1)).round(3).tolist())
    assert ours == pytest.approx(theirs, rel=0.03)
    assert ratio < 3.0
    np.testing.assert_allclose(cells(p0 + p1), cells(c0 + c1), rtol=0.03)
