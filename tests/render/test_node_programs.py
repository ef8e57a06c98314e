"""The node program machine (shaders/lib/nodes.glsl) against its numpy reference
(parallax_core/nodes.py): every Math and Vector Math operation, blend mode, Map Range type,
ColorRamp, RGB and Float Curves, Hue/Saturation/Value, Invert,
the socket conversions, Mapping, Separate/Combine and Image Texture, run on the device at
each pixel of a quad and read back through the Albedo pass (the stored Base Color).

The quad fills the image (orthographic, box filter), and each program first snaps its UVs to
the pixel's centre, so every sample of a pixel computes the same value and the Albedo is that
value exactly (up to float rounding)."""
import math

import numpy as np
import pytest

import parallax_core as pc
from parallax_core import nodes
from parallax_core.scene import Camera, Material, Mesh, SceneData, Texture, World

W = 16
CENTRES = (np.arange(W) + 0.5) / W


@pytest.fixture(scope="module")
def device():
    p = np.array([[-1, -1, 0], [1, -1, 0], [1, 1, 0], [-1, 1, 0]], float)
    uv = np.array([[0, 0], [1, 0], [1, 1], [0, 1]], float)
    tris = np.array([[0, 1, 2], [0, 2, 3]])
    m = np.eye(4)
    m[:3, 3] = (0, 0, 5)
    texels = np.random.default_rng(3).random((4, 4, 3)).astype(np.float32)
    scene = SceneData([Mesh(p, tris, uvs=uv[tris])], [], [Material("diffuse")], [Texture(texels)], [],
                      World((1, 1, 1), 1.0), Camera.from_blender(m, W, W, type="ORTHO", ortho_scale=2.0), W, W)
    session = pc.Session(W, W)
    session.set_params(method="mis", samples_per_frame=2, pixel_filter_type="BOX", filter_width=1.0)
    return session, scene, texels


def run(device, build):
    """The Base Color a program stores at each pixel: ``build(program, u, v)`` gets the
    pixel's centre UV in registers and returns a register."""
    session, scene, _ = device
    p = nodes.Program()
    uv = p.uv()

    def snap(x):  # (floor(x W) + 0.5) / W: the pixel's centre
        return p.math("DIVIDE", p.math("ADD", p.math("FLOOR", p.math("MULTIPLY", x, W)), 0.5), W)

    out = build(p, snap(p.separate(uv, 0)), snap(p.separate(uv, 1)))
    p.store("base_color", out)
    scene.materials = [Material("diffuse", (1.0, 1.0, 1.0), node_program=tuple(p.finish()))]
    session.update(scene)
    session.render(1)
    return session.read("albedo")[::-1]  # row 0 at the bottom: v grows with the row


def grid():
    """(u, v) of each pixel, v along rows from the bottom."""
    return np.meshgrid(CENTRES, CENTRES)


@pytest.mark.parametrize("op", nodes.MATH_OPS)
def test_math(device, op):
    got = run(device, lambda p, u, v: p.to_color(p.math(op, p.math("MULTIPLY_ADD", u, 6.0, -3.0),
                                                         p.math("MULTIPLY_ADD", v, 4.0, -1.5), 0.8)))
    u, v = grid()
    want = np.vectorize(lambda a, b: nodes.math_reference(op, a, b, 0.8))(6 * u - 3, 4 * v - 1.5)
    np.testing.assert_allclose(got[..., 0], np.clip(want, 0.0, None), rtol=2e-5, atol=2e-5)


@pytest.mark.parametrize("mode", nodes.BLEND_MODES)
def test_blend(device, mode):
    got = run(device, lambda p, u, v: p.mix(mode, v, p.combine(u, 0.3, p.math("SUBTRACT", 1.0, u)),
                                            p.combine(0.6, u, 0.0), clamp_result=mode == "ADD"))
    u, v = grid()
    want = np.array([[nodes.blend_reference(mode, v[i, j], (u[i, j], 0.3, 1 - u[i, j]), (0.6, u[i, j], 0.0))
                      for j in range(W)] for i in range(W)])
    if mode == "ADD":
        want = np.clip(want, 0.0, 1.0)
    np.testing.assert_allclose(got, np.clip(want, 0.0, None), rtol=2e-5, atol=2e-5)


def test_map_range_ramp_invert_and_conversions(device):
    u, v = grid()
    got = run(device, lambda p, u, v: p.to_color(p.map_range(u, 0.2, 0.7, 1.0, -1.0, True)))
    want = np.vectorize(lambda x: nodes.map_range_reference(x, 0.2, 0.7, 1.0, -1.0, True))(u)
    np.testing.assert_allclose(got[..., 0], np.clip(want, 0.0, None), atol=2e-5)
    table = np.random.default_rng(5).random((7, 4))
    for interpolate in (True, False):
        got = run(device, lambda p, u, v: p.ramp(p.math("MULTIPLY_ADD", u, 1.2, -0.1), table, interpolate))
        want = np.array([[nodes.ramp_reference(table, 1.2 * x - 0.1, interpolate)[:3] for x in row] for row in u])
        np.testing.assert_allclose(got, want, atol=2e-5)
    got = run(device, lambda p, u, v: p.invert(v, p.combine(u, 0.2, 0.9)))
    np.testing.assert_allclose(got, np.stack([u + v * (1 - 2 * u), 0.2 + 0.6 * v, 0.9 - 0.8 * v], -1), atol=2e-5)
    got = run(device, lambda p, u, v: p.to_color(p.to_float(p.combine(u, v, 0.5), "color")))
    np.testing.assert_allclose(got[..., 1], 0.2126 * u + 0.7152 * v + 0.0722 * 0.5, atol=2e-5)
    got = run(device, lambda p, u, v: p.to_color(p.to_float(p.combine(u, v, 0.5), "vector")))
    np.testing.assert_allclose(got[..., 2], (u + v + 0.5) / 3, atol=2e-5)


def test_mapping_separate_and_texture(device):
    _, _, texels = device
    u, v = grid()
    angle = math.radians(30.0)
    matrix = np.array([[2 * math.cos(angle), -3 * math.sin(angle), 0, 0.1],
                       [2 * math.sin(angle), 3 * math.cos(angle), 0, 0.2], [0, 0, 1, 0]])
    got = run(device, lambda p, u, v: p.combine(*(p.separate(p.affine(p.combine(u, v, 0.0), matrix), k)
                                                  for k in (1, 0, 2))))
    np.testing.assert_allclose(got[..., 0], np.clip(matrix[1, 0] * u + matrix[1, 1] * v + 0.2, 0, None), atol=2e-5)
    np.testing.assert_allclose(got[..., 1], np.clip(matrix[0, 0] * u + matrix[0, 1] * v + 0.1, 0, None), atol=2e-5)
    # The texture at the texel centres (4 x 4 texels, one per 4 x 4 pixels: the samples at
    # u = (k + 0.5) / 4 hit texel centres exactly when snapped to them).
    got = run(device, lambda p, u, v: p.texture(p.combine(p.math("DIVIDE", p.math("ADD", p.math(
        "FLOOR", p.math("MULTIPLY", u, 4.0)), 0.5), 4.0), p.math("DIVIDE", p.math("ADD", p.math(
            "FLOOR", p.math("MULTIPLY", v, 4.0)), 0.5), 4.0), 0.0), 0))
    want = np.repeat(np.repeat(texels[::-1], 4, axis=0), 4, axis=1)  # image row 0 is the top
    np.testing.assert_allclose(got, want, atol=2e-3)


def test_programs_are_checked_before_they_run(device):
    session, scene, _ = device
    bad = {"reads register 3 before it is set": [nodes.NODE_STORE | 3 << 16, 0, nodes.NODE_END],
           "unknown operation": [99, 0, nodes.NODE_END],
           "samples texture 5": [nodes.NODE_UV, 0, nodes.NODE_TEXTURE | 1 << 8, 5, nodes.NODE_END],
           "runs past the end": [nodes.NODE_UV, 0]}
    for message, words in bad.items():
        scene.materials = [Material("diffuse", node_program=tuple(words))]
        with pytest.raises(ValueError, match=message):
            session.update(scene)


def test_noise_and_generated_coordinates(device):
    u, v = grid()
    got = run(device, lambda p, u, v: p.to_color(p.noise(p.combine(p.math("MULTIPLY", u, 7.0), p.math(
        "MULTIPLY", v, 7.0), 0.3), 2.5, 0.6, 2.1, True)))
    want = np.vectorize(lambda a, b: nodes.noise_reference((7 * a, 7 * b, 0.3), 2.5, 0.6, 2.1, True))(u, v)
    np.testing.assert_allclose(got[..., 0], want, atol=1e-4)
    assert want.std() > 0.05  # a pattern, not a constant
    # The quad spans -1..1 in x and y and is flat in z: Generated maps its bounds to 0..1 (as
    # its UVs do, sample by sample), the flat axis to 0.5 (Cycles keeps scale 1 there).
    got = run(device, lambda p, u, v: p.mix("ADD", 1.0, p.mix("SUBTRACT", 1.0, p.generated(), p.uv()), 0.25))
    np.testing.assert_allclose(got, np.broadcast_to([0.25, 0.25, 0.75], got.shape), atol=1e-5)


OFFSET = 64.0  # added before the store (Base Color clamps at 0): negative results come back too


def run_signed(device, build):
    """As run, for a result that may be negative: (what comes back) - OFFSET."""
    return run(device, lambda p, u, v: p.mix("ADD", 1.0, build(p, u, v), OFFSET)) - OFFSET


def vector_operands(p, u, v):
    """Operands of the Vector Math tests (registers) and their values at the grid."""
    mad = lambda x, m, c: p.math("MULTIPLY_ADD", x, m, c)
    return (p.combine(mad(u, 6.0, -3.0), mad(v, 4.0, -1.5), 0.7), p.combine(mad(v, -2.0, 0.8625), mad(u, 2.0, -0.6123), -0.9),
            p.combine(u, -0.35, mad(v, 3.0, -1.5)), mad(u, 1.3, -0.2))


def vector_operand_values(u, v, nudge=1.0):
    return ((nudge * (6 * u - 3), nudge * (4 * v - 1.5), 0.7), (-2 * v + 0.8625, 2 * u - 0.6123, -0.9), (u, -0.35, 3 * v - 1.5),
            1.3 * u - 0.2)


@pytest.mark.parametrize("op", nodes.VECTOR_MATH_OPS)
def test_vector_math(device, op):
    def build(p, u, v):
        a, b, c, s = vector_operands(p, u, v)
        return p.vector_math(op, a, b, c, s)

    got = run_signed(device, build)
    u, v = grid()
    reference = lambda nudge: np.array([[np.broadcast_to(nodes.vector_math_reference(
        op, *vector_operand_values(u[i, j], v[i, j], nudge)), 3) for j in range(W)] for i in range(W)])
    want = reference(1.0)
    assert np.isfinite(want).all() and np.abs(want).max() < OFFSET - 1.0
    # Where a floor's argument lands within float rounding of an integer (Modulo, Wrap, Snap),
    # either side of the step matches: the reference with a moved by 1e-5 decides.
    close = lambda w: np.abs(got - w) <= 3e-5 + 2e-5 * np.abs(w)
    ok = close(want) | close(reference(1.0 + 1e-5)) | close(reference(1.0 - 1e-5))
    np.testing.assert_allclose(got[~ok], want[~ok], rtol=2e-5, atol=3e-5)
    assert (~close(want)).sum() <= 3  # those are rare
    assert np.abs(want).max() > 0.1


@pytest.mark.parametrize("extrapolate", [True, False])
def test_curves(device, extrapolate):
    """RGB Curves (3 tables) and Float Curve (1) over -0.5..1.5, with inputs beyond that range."""
    rng = np.random.default_rng(11)
    rgb, single = rng.random((9, 3)), rng.random(6) * 2.0 - 0.5
    u, v = grid()
    got = run_signed(device, lambda p, u, v: p.curves(rgb, -0.5, 1.5, extrapolate, v, p.combine(
        p.math("MULTIPLY_ADD", u, 3.0, -1.0), p.math("MULTIPLY_ADD", v, -2.6, 2.1), 0.3)))
    want = np.array([[nodes.curves_reference(rgb, -0.5, 1.5, extrapolate, v[i, j], (3 * u[i, j] - 1, 2.1 - 2.6 * v[i, j], 0.3))
                      for j in range(W)] for i in range(W)])
    np.testing.assert_allclose(got, want, rtol=2e-5, atol=3e-5)
    got = run_signed(device, lambda p, u, v: p.to_color(p.curves(single, -0.5, 1.5, extrapolate, 0.8, p.math(
        "MULTIPLY_ADD", u, 3.0, -1.0))))
    want = np.vectorize(lambda x: nodes.curves_reference(single, -0.5, 1.5, extrapolate, 0.8, x))(3 * u - 1)
    np.testing.assert_allclose(got[..., 0], want, rtol=2e-5, atol=3e-5)
    assert (np.abs(want - 0.2 * (3 * u - 1)) > 1e-3).any()  # the curve changes the value


def test_hue_saturation_value(device):
    u, v = grid()
    got = run(device, lambda p, u, v: p.hsv(p.combine(u, p.math("MULTIPLY", v, 0.8), p.math("SUBTRACT", 1.0, u)),
                                            p.math("MULTIPLY_ADD", u, 0.9, 0.05), p.math("MULTIPLY", v, 2.0),
                                            p.math("ADD", u, 0.5), 0.8))
    want = np.array([[nodes.hsv_reference((u[i, j], 0.8 * v[i, j], 1 - u[i, j]), 0.9 * u[i, j] + 0.05, 2 * v[i, j],
                                          u[i, j] + 0.5, 0.8) for j in range(W)] for i in range(W)])
    np.testing.assert_allclose(got, want, rtol=2e-5, atol=3e-5)


@pytest.mark.parametrize("interpolation", nodes.MAP_RANGE_TYPES)
@pytest.mark.parametrize("reverse", [False, True])
def test_map_range_types(device, interpolation, reverse):
    """The float node (red) and a vector component (green), clamped, from min and max
    registers (reversed: from 0.9 to 0.1), steps a register."""
    lo, hi = (0.9, 0.1) if reverse else (0.1, 0.9)

    def build(p, u, v):
        x = p.math("MULTIPLY_ADD", u, 2.4, -0.7)
        fmin, fmax = p.math("ADD", p.math("MULTIPLY", v, 0.0), lo), p.math("ADD", p.math("MULTIPLY", v, 0.0), hi)
        steps = p.math("ADD", p.math("MULTIPLY", v, 0.0), 3.0)
        args = (x, fmin, fmax, p.math("MULTIPLY", v, 0.5), 1.5, True, interpolation, steps)
        return p.combine(p.map_range(*args), p.map_range(*args, vector=True), 0.0)

    got = run_signed(device, build)
    u, v = grid()
    for k, vector in enumerate((False, True)):
        want = np.vectorize(lambda a, b: nodes.map_range_reference(2.4 * a - 0.7, lo, hi, 0.5 * b, 1.5, True, interpolation,
                                                                   3.0, vector))(u, v)
        np.testing.assert_allclose(got[..., k], want, rtol=2e-5, atol=3e-5)
