"""The node program machine (shaders/lib/nodes.glsl) against its numpy reference
(parallax_core/nodes.py): every Math operation, blend mode, Map Range, ColorRamp, Invert,
the socket conversions, Mapping, Separate/Combine, Image Texture and the procedural textures
(Noise, Voronoi, Wave, Brick), run on the device at each pixel of a quad and read back
through the Albedo pass (the stored Base Color).

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
           "runs past the end": [nodes.NODE_UV, 0],
           "unknown texture mode 3": [nodes.NODE_UV, 0, nodes.NODE_VORONOI | 1 << 8, 0, 3 << 16, nodes.NODE_END],
           "reads register 5": [nodes.NODE_UV, 0, nodes.NODE_WAVE | 1 << 8, 5, 0, nodes.NODE_END],
           "NaN": [nodes.NODE_UV, 0, nodes.NODE_BRICK | 1 << 8, 0, 0, 0x7FC00000, 0, 0x202, nodes.NODE_END]}
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


def assert_mostly_close(got, want, atol=1e-4, allowed=0.01):
    """got == want (clamped at 0, as the Albedo stores it) within atol at all but a fraction
    ``allowed`` of the pixels (those where a cell, band or brick edge passes within float
    rounding of the pixel's point, where float32 and the float64 reference may pick different
    sides)."""
    bad = np.abs(np.asarray(got) - np.clip(want, 0.0, None)) > atol
    bad = bad.reshape(W * W, -1).any(axis=1)
    assert bad.mean() <= allowed, f"{bad.sum()} of {bad.size} pixels differ by more than {atol}"


def scaled_point(p, u, v, sx, sy, z):
    return p.combine(p.math("MULTIPLY_ADD", u, sx, 0.3), p.math("MULTIPLY_ADD", v, sy, 0.2), z)


@pytest.mark.parametrize("feature, metric, detail, output", [
    ("F1", "EUCLIDEAN", 0.0, "Distance"), ("F1", "EUCLIDEAN", 0.0, "Color"), ("F1", "MANHATTAN", 0.0, "Position"),
    ("F2", "CHEBYCHEV", 0.0, "Distance"), ("F2", "EUCLIDEAN", 2.5, "Color"), ("F1", "MINKOWSKI", 1.0, "Distance"),
    ("SMOOTH_F1", "EUCLIDEAN", 0.0, "Distance"), ("SMOOTH_F1", "MANHATTAN", 1.5, "Color"),
    ("SMOOTH_F1", "EUCLIDEAN", 0.0, "Position")])
def test_voronoi(device, feature, metric, detail, output):
    u, v = grid()
    # Scale 2.5 over points spanning 0.3..2.3 and 0.2..1.7: about 5 x 4 cells, then finer octaves.
    args = dict(scale=2.5, detail=detail, roughness=0.6, lacunarity=2.2, smoothness=0.8, exponent=1.5,
                randomness=0.85, feature=feature, metric=metric, normalize=detail > 0.0 or metric == "CHEBYCHEV")
    got = run(device, lambda p, u, v: p.voronoi(scaled_point(p, u, v, 2.0, 1.5, 0.45), output=output, **{
        k: (p.math("ADD", u, 1.5) if k == "scale" and output == "Position" else x) for k, x in args.items()}))
    want = []
    for a, b in zip(u.ravel(), v.ravel()):
        scale = a + 1.5 if output == "Position" else args["scale"]  # a linked scale too
        out = nodes.voronoi_reference((2 * a + 0.3, 1.5 * b + 0.2, 0.45), scale, *[args[k] for k in (
            "detail", "roughness", "lacunarity", "smoothness", "exponent", "randomness", "feature", "metric",
            "normalize")])[nodes.VORONOI_OUTPUTS.index(output)]
        want.append(np.broadcast_to(out, 3))
    want = np.array(want).reshape(W, W, 3)
    assert want[..., 0].std() > 0.03  # a pattern, not a constant
    assert_mostly_close(got, want)


@pytest.mark.parametrize("wave_type, direction, profile, distortion", [
    ("BANDS", "X", "SIN", 0.0), ("BANDS", "DIAGONAL", "SAW", 0.0), ("BANDS", "Z", "TRI", 3.0),
    ("RINGS", "SPHERICAL", "SIN", 2.0), ("RINGS", "Y", "TRI", 0.0), ("RINGS", "X", "SAW", 1.5)])
def test_wave(device, wave_type, direction, profile, distortion):
    u, v = grid()
    got = run(device, lambda p, u, v: p.to_color(p.wave(scaled_point(p, u, v, 0.5, 0.4, p.math("MULTIPLY", u, 0.3)),
                                                        1.3, wave_type, direction, profile, distortion, 2.5, 1.7,
                                                        0.55, 0.4)))
    want = np.vectorize(lambda a, b: nodes.wave_reference(1.3 * np.array([0.5 * a + 0.3, 0.4 * b + 0.2, 0.3 * a]),
                                                          wave_type, direction, profile, distortion, 2.5, 1.7,
                                                          0.55, 0.4))(u, v)
    assert want.std() > 0.05
    assert_mostly_close(got[..., 0], want)


@pytest.mark.parametrize("output", ["Color", "Fac"])
@pytest.mark.parametrize("offset_frequency, squash, squash_frequency, mortar_smooth", [
    (2, 1.0, 2, 0.0), (3, 0.6, 2, 0.4), (1, 1.3, 3, 1.0)])
def test_brick(device, output, offset_frequency, squash, squash_frequency, mortar_smooth):
    u, v = grid()
    colors = ((0.8, 0.2, 0.1), (0.2, 0.7, 0.3), (0.9, 0.9, 0.8))
    # Points spanning -1..1.6 and -0.6..1.2 at scale 1.5: negative rows and bricks too.
    got = run(device, lambda p, u, v: p.brick(
        p.combine(p.math("MULTIPLY_ADD", u, 2.6, -1.0), p.math("MULTIPLY_ADD", v, 1.8, -0.6), 0.0), 1.5,
        p.combine(u, 0.2, 0.1), *colors[1:], 0.06, mortar_smooth, p.math("MULTIPLY_ADD", v, 0.6, -0.3), 0.5, 0.25,
        0.4, offset_frequency, squash, squash_frequency, output))
    want = np.array([nodes.brick_reference(1.5 * np.array([2.6 * a - 1.0, 1.8 * b - 0.6, 0.0]), (a, 0.2, 0.1),
                                           *colors[1:], 0.06, mortar_smooth, 0.6 * b - 0.3, 0.5, 0.25, 0.4,
                                           offset_frequency, squash, squash_frequency)[output == "Fac"]
                     for a, b in zip(u.ravel(), v.ravel())])
    want = np.broadcast_to(want.reshape(W * W, -1), (W * W, 3)).reshape(W, W, 3)
    assert want.std() > 0.05
    assert_mostly_close(got, want)
