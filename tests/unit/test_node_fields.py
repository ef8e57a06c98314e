"""parallax_core.node_fields: node graphs evaluated on the host at many points. The numpy
references evaluate arrays exactly as they evaluate each element (the device's operations
are checked against the elementwise use in tests/render/test_node_programs.py), and a
FieldProgram agrees with a Program folding each point's constants."""
import numpy as np
import pytest

from parallax_core import node_fields, nodes

RNG = np.random.default_rng(7)
A, B, C = (RNG.uniform(-3, 3, 40) for _ in range(3))
A[:4], B[:4] = 0.0, (0.0, 2.0, -1.0, 0.0)  # zeros, integers: the safe branches


@pytest.mark.parametrize("op", nodes.MATH_OPS)
def test_math_over_arrays_is_math_per_element(op):
    want = [nodes.math_reference(op, a, b, c) for a, b, c in zip(A, B, C)]
    np.testing.assert_array_equal(nodes.math_reference(op, A, B, C), want)


@pytest.mark.parametrize("op", nodes.VECTOR_MATH_OPS)
def test_vector_math_over_arrays_is_vector_math_per_element(op):
    a, b, c = (RNG.uniform(-2, 2, (30, 3)) for _ in range(3))
    b[0] = 0.0
    s = RNG.uniform(0.5, 2.0, 30)
    want = np.array([nodes.vector_math_reference(op, *x) for x in zip(a, b, c, s)])
    np.testing.assert_allclose(nodes.vector_math_reference(op, a, b, c, s), want, rtol=1e-12, atol=1e-12)


def test_colour_and_range_operations_over_arrays():
    t = RNG.uniform(0, 1, 25)
    c1, c2 = RNG.uniform(0, 1.5, (25, 4)), RNG.uniform(0, 1.5, (25, 4))
    for mode in nodes.BLEND_MODES:
        want = [nodes.blend_reference(mode, *x) for x in zip(t, c1, c2)]
        np.testing.assert_allclose(nodes.blend_reference(mode, t, c1, c2), want, rtol=1e-12)
    x = RNG.uniform(-1, 2, 25)
    for kind in nodes.MAP_RANGE_TYPES:
        for lo, hi in ((0.2, 0.7), (0.7, 0.2), (0.5, 0.5)):
            for vector in (False, True):
                want = [nodes.map_range_reference(v, lo, hi, 1.0, -1.0, True, kind, 3.0, vector) for v in x]
                np.testing.assert_allclose(nodes.map_range_reference(x, lo, hi, 1.0, -1.0, True, kind, 3.0, vector),
                                           want, rtol=1e-12)
    table = RNG.uniform(0, 1, (nodes.NODE_RAMP_SIZE, 4))
    for interpolate in (False, True):
        want = [nodes.ramp_reference(table, f, interpolate) for f in x]
        np.testing.assert_allclose(nodes.ramp_reference(table, x, interpolate), want)
    rgb = RNG.uniform(0, 1, (64, 3))
    for extrapolate in (False, True):
        want = [nodes.curves_reference(rgb, -0.5, 1.5, extrapolate, f, c) for f, c in zip(t, c1)]
        np.testing.assert_allclose(nodes.curves_reference(rgb, -0.5, 1.5, extrapolate, t, c1), want)
        want = [nodes.curves_reference(rgb[:, :1], -0.5, 1.5, extrapolate, 0.8, v) for v in x]
        np.testing.assert_allclose(nodes.curves_reference(rgb[:, :1], -0.5, 1.5, extrapolate, 0.8, x), want)
    hue, sat, val = RNG.uniform(0, 1, 25), RNG.uniform(0, 2, 25), RNG.uniform(0, 2, 25)
    want = [nodes.hsv_reference(*args, 0.7) for args in zip(c1, hue, sat, val)]
    np.testing.assert_allclose(nodes.hsv_reference(c1, hue, sat, val, 0.7), want, rtol=1e-12, atol=1e-15)


def test_noise_over_arrays_is_noise_per_point():
    p = RNG.uniform(-20, 20, (30, 3))
    for detail in (0.0, 2.5):
        want = [nodes.noise_reference(q, detail, 0.6, 2.1, True) for q in p]
        np.testing.assert_allclose(nodes.noise_reference(p, detail, 0.6, 2.1, True), want, rtol=1e-12)
    details = RNG.uniform(0, 4, 30)  # a detail per point
    want = [nodes.noise_reference(q, d, 0.5, 2.0, False) for q, d in zip(p, details)]
    np.testing.assert_allclose(nodes.noise_reference(p, details, 0.5, 2.0, False), want, rtol=1e-12)
    assert nodes.hash_uint(1, 2, 3) == int(nodes.hash_uint(np.array([1]), 2, 3)[0])


def _graph(p, position):
    """A gradient-like graph: Separate Z -> Map Range -> ColorRamp, x Noise, hue shift."""
    z = p.separate(position, 2)
    fac = p.map_range(z, -0.2, 1.0, 0.0, 1.0, True, "SMOOTHSTEP")
    table = np.linspace([0.1, 0.2, 0.4, 1.0], [0.9, 0.8, 0.3, 1.0], nodes.NODE_RAMP_SIZE)
    color = p.ramp(fac, table, True)
    noise = p.noise(p.mix("MULTIPLY", 1.0, position, (4.0, 4.0, 4.0)), 2.0, 0.5, 2.0, True)
    color = p.mix("MULTIPLY", p.math("MULTIPLY", noise, 0.5), color, (1.0, 0.9, 0.8))
    return p.hsv(p.affine(color, np.eye(3, 4)), 0.55, 1.2, 1.0, 1.0)


def test_a_field_program_is_a_program_folded_at_each_point():
    d = RNG.normal(size=(20, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    program = node_fields.FieldProgram(len(d), {"position": d})
    got = program.evaluate(_graph(program, program.geometry("position")), "color")[:, :3]
    for k, point in enumerate(d):
        np.testing.assert_allclose(got[k], _graph(nodes.Program(), point)[:3], rtol=1e-12)


def test_what_the_host_cannot_evaluate_says_so():
    program = node_fields.FieldProgram(3, {})
    with pytest.raises(node_fields.NotOnHost, match="uv"):
        program.uv()
    assert program.math("ADD", 1.0, 2.0) == 3.0  # constants fold as a Program's
    with pytest.raises(node_fields.NotOnHost, match="Voronoi"):
        field = node_fields.FieldProgram(3, {"generated": np.eye(3)})
        field.voronoi(field.generated(), 5.0, 0.0, 0.5, 2.0, 1.0, 1.0, 1.0, "F1", "EUCLIDEAN", False, "Distance")


def test_host_images_sample_as_the_device_does():
    pixels = np.arange(4 * 8 * 3, dtype=np.float64).reshape(4, 8, 3)  # row 0 at the top
    image = node_fields.HostImage(pixels)
    # Texel centres hit their texels; v = 0 is the bottom row; u repeats.
    np.testing.assert_allclose(image.sample(np.array([0.5 / 8, 1.0 + 2.5 / 8]), np.array([0.5 / 4, 3.5 / 4])),
                               [pixels[3, 0], pixels[0, 2]])
    mid = image.sample(np.array([1.0 / 8]), np.array([0.5 / 4]))  # between columns 0 and 1
    np.testing.assert_allclose(mid[0], 0.5 * (pixels[3, 0] + pixels[3, 1]))
    u, v = node_fields.equirectangular_uv(np.array([[1.0, 0, 0], [0, 1.0, 0], [0, 0, 1.0]]))
    np.testing.assert_allclose(u, [0.5, 0.25, 0.5])
    np.testing.assert_allclose(v, [0.5, 0.5, 1.0])
    # Blender's mirror ball: the ball's centre reflects -Y, its rim's points at 45 degrees +X, +Z.
    u, v = node_fields.mirror_ball_uv(np.array([[0, -2.0, 0], [1.0, 0, 0], [0, 0, 1.0]]))
    np.testing.assert_allclose(u, [0.5, 0.5 + 0.5 * np.sqrt(0.5), 0.5])
    np.testing.assert_allclose(v, [0.5, 0.5, 0.5 + 0.5 * np.sqrt(0.5)])
