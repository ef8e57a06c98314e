"""GraphCompiler (addon/sync/node_graph.py) on Blender node trees of the colour and vector
nodes: constant inputs fold on the host (through parallax_core.nodes' references, which
tests/render/test_node_programs.py runs against the device), and the folded values agree with
Blender's own evaluation (curves through CurveMapping.evaluate, colours through colorsys);
linked inputs compile to the machine's operations. Rendered parity: test_parity_nodes.py."""
import colorsys

import numpy as np
import pytest


def _tree(bpy, node_type):
    material = bpy.data.materials.new(node_type)
    tree = material.node_tree
    tree.nodes.clear()
    return tree, tree.nodes.new(node_type)


def _compile(tree, output, kind):
    """(value, program) of what ``output`` gives a Principled BSDF's Base Color (kind "color")
    or Roughness ("float"): a constant, or a register of the program."""
    from addon.sync.node_graph import GraphCompiler
    from parallax_core import nodes

    bsdf = tree.nodes.get("Target") or tree.nodes.new("ShaderNodeBsdfPrincipled")
    bsdf.name = "Target"
    socket = bsdf.inputs["Base Color" if kind == "color" else "Roughness"]
    tree.links.new(output, socket)
    program = nodes.Program()
    return GraphCompiler(program, None, "test").socket(socket, kind), program


def _ops(program):
    from parallax_core import nodes

    return [op for op, *_ in nodes.instructions(program.words + [nodes.NODE_END])]


def _inputs(node):
    return {s.identifier: s for s in node.inputs}


def _uv(tree, component=None):
    """The UV output, or one component of it (a Separate XYZ output)."""
    coords = tree.nodes.new("ShaderNodeTexCoord")
    if component is None:
        return coords.outputs["UV"]
    separate = tree.nodes.new("ShaderNodeSeparateXYZ")
    tree.links.new(coords.outputs["UV"], separate.inputs[0])
    return separate.outputs[component]


def _shape_curve(curve, points):
    """``curve`` through ``points`` (x, y), straight between them (vector handles)."""
    curve.points[0].location, curve.points[1].location = points[0], points[-1]
    for x, y in points[1:-1]:
        curve.points.new(x, y)
    for point in curve.points:
        point.handle_type = "VECTOR"


@pytest.mark.parametrize("extend", ["EXTRAPOLATED", "HORIZONTAL"])
def test_rgb_curves_fold_as_blender_evaluates(bpy, extend):
    from parallax_core import nodes

    tree, node = _tree(bpy, "ShaderNodeRGBCurve")
    mapping = node.mapping
    _shape_curve(mapping.curves[3], [(0.0, 0.1), (0.5, 0.7), (1.0, 0.9)])  # C, the combined curve
    _shape_curve(mapping.curves[0], [(-0.2, 0.0), (0.6, 0.3), (1.0, 1.0)])  # R, from x = -0.2: the range
    _shape_curve(mapping.curves[2], [(0.0, 1.0), (1.0, 0.2)])  # B, falling
    mapping.extend = extend
    mapping.update()
    mapping.initialize()
    evaluate = lambda k, x: mapping.evaluate(mapping.curves[k], x)
    node.inputs["Fac"].default_value = 0.75
    for color in [(0.1, 0.45, 0.9), (0.3, 0.0, 0.65), (0.95, 0.22, 0.41), (0.02, 0.8, 0.05)]:
        node.inputs["Color"].default_value = (*color, 1.0)
        got, _ = _compile(tree, node.outputs[0], "color")
        want = [evaluate(k, evaluate(3, c)) for k, c in enumerate(color)]
        np.testing.assert_allclose(got[:3], 0.25 * np.array(color) + 0.75 * np.array(want), atol=3e-3)
    # Beyond the range (-0.2..1) Cycles continues the table's end segment (extrapolated) or
    # holds its end: C then B near x = 1 are straight, so that is Blender's curve either way.
    node.inputs["Color"].default_value = (0.5, 0.5, 1.3, 1.0)
    got, _ = _compile(tree, node.outputs[0], "color")
    blue = evaluate(2, evaluate(3, 1.3 if extend == "EXTRAPOLATED" else 1.0))
    assert blue == pytest.approx(1.0 - 0.8 * (0.9 + 0.4 * 0.3) if extend == "EXTRAPOLATED" else 0.28, abs=1e-3)
    assert got[2] == pytest.approx(0.25 * 1.3 + 0.75 * blue, abs=2e-3)
    # Linked: the table (256 rows of R, G, B) travels with the instruction.
    tree.links.new(_uv(tree), node.inputs["Color"])
    value, program = _compile(tree, node.outputs[0], "color")
    assert isinstance(value, nodes.Register) and _ops(program)[-1] == nodes.NODE_CURVES
    word = program.words[-(3 + 256 * 3)]  # the word after the instruction, then min x, max x, the table
    assert word & 0xFFFF == 256 and word >> 24 == 3 and bool(word & 0x10000) == (extend == "EXTRAPOLATED")


def test_float_curve_folds_as_blender_evaluates(bpy):
    tree, node = _tree(bpy, "ShaderNodeFloatCurve")
    mapping = node.mapping
    _shape_curve(mapping.curves[0], [(0.0, 0.2), (0.3, 0.9), (2.0, 0.4)])
    mapping.update()
    mapping.initialize()
    node.inputs["Factor"].default_value = 0.6
    for x in (0.1, 0.7, 1.9, 2.5, -0.5):  # beyond 0..2: extrapolated along the end segments
        node.inputs["Value"].default_value = x
        got, _ = _compile(tree, node.outputs[0], "float")
        assert got == pytest.approx(0.4 * x + 0.6 * mapping.evaluate(mapping.curves[0], x), abs=3e-3)


def test_hue_saturation_value_folds_as_colorsys(bpy):
    tree, node = _tree(bpy, "ShaderNodeHueSaturation")
    for color, hue, saturation, value, fac in [((0.8, 0.3, 0.1), 0.6, 1.4, 0.9, 1.0), ((0.2, 0.5, 0.9), 0.25, 0.5, 1.5, 0.7),
                                               ((0.4, 0.4, 0.4), 0.9, 3.0, 0.5, 0.8), ((1.5, 0.2, 0.6), 0.5, 1.0, 1.0, 1.0)]:
        for name, x in (("Hue", hue), ("Saturation", saturation), ("Value", value), ("Fac", fac)):
            _inputs(node)[name].default_value = x
        node.inputs["Color"].default_value = (*color, 1.0)
        got, _ = _compile(tree, node.outputs[0], "color")
        h, s, v = colorsys.rgb_to_hsv(*color)
        shifted = colorsys.hsv_to_rgb((h + hue + 0.5) % 1.0, min(max(s * saturation, 0.0), 1.0), v * value)
        np.testing.assert_allclose(got[:3], np.maximum(fac * np.array(shifted) + (1 - fac) * np.array(color), 0), atol=1e-6)
    tree.links.new(_uv(tree, "X"), _inputs(node)["Hue"])
    _, program = _compile(tree, node.outputs[0], "color")
    from parallax_core import nodes

    assert _ops(program)[-1] == nodes.NODE_HSV


def test_vector_math_sockets_and_outputs(bpy):
    """Each operation reads the sockets Blender shows for it (Scale for Scale and Refract's
    IOR, the third vector for Multiply Add, Faceforward, Wrap); Value carries Dot Product,
    Distance and Length, Vector the others."""
    from parallax_core import nodes

    tree, node = _tree(bpy, "ShaderNodeVectorMath")
    sockets = _inputs(node)
    a, b, c = np.array([0.3, -1.2, 2.0]), np.array([0.5, 0.25, -1.0]), np.array([-0.4, 0.9, 0.1])
    for key, value in (("Vector", a), ("Vector_001", b), ("Vector_002", c)):
        sockets[key].default_value = value
    sockets["Scale"].default_value = 1.45
    vector, value = node.outputs[0], node.outputs[1]  # by index: Blender hides the unavailable one's name
    for op in nodes.VECTOR_MATH_OPS[:-1]:  # GAMMA is the Gamma node's
        node.operation = op
        is_float = op in nodes.VECTOR_MATH_FLOAT_OPS
        got, _ = _compile(tree, value if is_float else vector, "float" if is_float else "color")
        want = nodes.vector_math_reference(op, a, b, c, 1.45)
        np.testing.assert_allclose(np.ravel(got)[:1] if is_float else got[:3], np.ravel(want)[:1] if is_float else want,
                                   rtol=1e-6, atol=1e-6)  # the sockets hold float32
        other, _ = _compile(tree, vector if is_float else value, "color" if is_float else "float")
        np.testing.assert_array_equal(other, 0.0)
    node.operation = "CROSS_PRODUCT"
    np.testing.assert_allclose(_compile(tree, vector, "color")[0], np.cross(a, b), rtol=1e-6)
    node.operation = "SCALE"
    np.testing.assert_allclose(_compile(tree, vector, "color")[0], 1.45 * a, rtol=1e-6)
    node.operation = "FACEFORWARD"  # a where dot(c, b) < 0
    np.testing.assert_allclose(_compile(tree, vector, "color")[0], a if c @ b < 0 else -a)
    node.operation = "DISTANCE"
    assert _compile(tree, value, "float")[0] == pytest.approx(np.linalg.norm(a - b))
    tree.links.new(_uv(tree), sockets["Vector_001"])
    value, program = _compile(tree, value, "float")
    assert isinstance(value, nodes.Register) and _ops(program)[-1] == nodes.NODE_VECTOR_MATH


def test_gamma_bright_contrast_and_map_range(bpy):
    from parallax_core import nodes

    tree, gamma = _tree(bpy, "ShaderNodeGamma")
    gamma.inputs["Color"].default_value = (0.5, 0.25, 0.0, 1.0)
    gamma.inputs["Gamma"].default_value = 2.0
    np.testing.assert_allclose(_compile(tree, gamma.outputs[0], "color")[0], (0.25, 0.0625, 0.0))
    gamma.inputs["Gamma"].default_value = 0.0  # svm_math_gamma_color: white
    np.testing.assert_allclose(_compile(tree, gamma.outputs[0], "color")[0], (1.0, 1.0, 1.0))
    tree, bc = _tree(bpy, "ShaderNodeBrightContrast")
    bc.inputs["Color"].default_value = (0.2, 0.5, 0.9, 1.0)
    bc.inputs["Bright"].default_value, bc.inputs["Contrast"].default_value = 0.1, 0.5
    np.testing.assert_allclose(_compile(tree, bc.outputs[0], "color")[0], (0.15, 0.6, 1.2))
    bc.inputs["Bright"].default_value = -0.5
    np.testing.assert_allclose(_compile(tree, bc.outputs[0], "color")[0], (0.0, 0.0, 0.6), atol=1e-12)
    tree.links.new(_uv(tree, "Y"), bc.inputs["Contrast"])
    assert nodes.NODE_VECTOR_MATH in _ops(_compile(tree, bc.outputs[0], "color")[1])

    tree, remap = _tree(bpy, "ShaderNodeMapRange")
    sockets = _inputs(remap)
    remap.interpolation_type = "STEPPED"
    sockets["Value"].default_value, sockets["Steps"].default_value = 0.3, 4.0
    assert _compile(tree, remap.outputs["Result"], "float")[0] == pytest.approx(0.25)  # floor(0.3 * 5) / 4
    remap.interpolation_type, remap.data_type = "SMOOTHSTEP", "FLOAT_VECTOR"
    sockets["Vector"].default_value = (0.25, 0.5, 1.5)
    sockets["To_Max_FLOAT3"].default_value = (2.0, 2.0, 2.0)
    np.testing.assert_allclose(_compile(tree, remap.outputs["Vector"], "color")[0][:3], (2 * 0.15625, 1.0, 2.0))
    tree.links.new(_uv(tree), sockets["Vector"])
    ops = _ops(_compile(tree, remap.outputs["Vector"], "color")[1])
    assert ops.count(nodes.NODE_MAP_RANGE) == 3 and ops[-1] == nodes.NODE_COMBINE
