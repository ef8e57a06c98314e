"""The node program machine (shaders/lib/nodes.glsl) against its numpy reference
(parallax_core/nodes.py): every Math and Vector Math operation, blend mode, Map Range type,
ColorRamp, RGB and Float Curves, Hue/Saturation/Value, Invert, the socket conversions, Mapping,
Separate/Combine, Image Texture, the procedural textures (Noise, Voronoi, Wave, Brick), the
geometry, Bump, Normal Map, Fresnel and Layer Weight, run on the device at each pixel of a quad
and read back through the Albedo pass (the stored Base Color) or the Normal pass.

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


def run_plain(device, build, field="base_color", pass_name="albedo"):
    """As run(), without snapping: ``build(program)`` returns the register stored in ``field``;
    the pass is read as averaged over each pixel's samples."""
    session, scene, _ = device
    p = nodes.Program()
    p.store(field, build(p))
    scene.materials = [Material("diffuse", (1.0, 1.0, 1.0), node_program=tuple(p.finish()))]
    session.update(scene)
    session.render(4)
    return session.read(pass_name)[::-1]


def test_geometry_outputs(device):
    """Cycles' Geometry and Texture Coordinate outputs on the quad (z = 0, facing the camera on
    +z): positions (world = object here) mapped to 0..1, the normals and the incoming direction."""
    u, v = grid()
    half = lambda p, x: p.mix("MULTIPLY", 1.0, p.mix("ADD", 1.0, x, 1.0), 0.5)  # -1..1 -> 0..1
    for kind in ("position", "object"):
        got = run_plain(device, lambda p: half(p, p.geometry(kind)))
        np.testing.assert_allclose(got[..., 0], u, atol=2e-3)
        np.testing.assert_allclose(got[..., 1], v, atol=2e-3)
        np.testing.assert_allclose(got[..., 2], 0.5, atol=1e-5)
    for kind in ("normal", "true_normal", "incoming", "object_normal"):
        got = run_plain(device, lambda p: half(p, p.geometry(kind)))
        np.testing.assert_allclose(got, np.broadcast_to([0.5, 0.5, 1.0], got.shape), atol=1e-5, err_msg=kind)
    got = run_plain(device, lambda p: p.to_color(p.math("ADD", p.separate(p.geometry("backfacing"), 0), 0.25)))
    np.testing.assert_allclose(got, 0.25, atol=1e-6)


def test_fresnel_and_layer_weight(device):
    """Fresnel and Layer Weight against Cycles' formulas (fresnel_dielectric_cos), the normal
    tilted by theta = u across the image (the view along -z: cos = cos theta)."""
    # Each pixel averages its samples: the references are averaged over 64 points across it.
    fine = (np.arange(W * 64) + 0.5) / (W * 64)
    theta = np.pi / 2 * 0.98 * fine
    pixel_mean = lambda x: np.broadcast_to(x.reshape(W, 64).mean(axis=1), (W, W))

    def tilted(p):
        t = p.math("MULTIPLY", p.separate(p.geometry("position"), 0), 0.5 * np.pi / 2 * 0.98)
        t = p.math("ADD", t, 0.5 * np.pi / 2 * 0.98)  # x = -1..1 -> theta = 0..0.98 pi/2
        return p.combine(p.math("SINE", t), 0.0, p.math("COSINE", t))

    def fresnel(cos_i, eta):
        g = np.sqrt(np.maximum(eta * eta - 1 + cos_i * cos_i, 0))
        a, b = (g - cos_i) / (g + cos_i), (cos_i * (g + cos_i) - 1) / (cos_i * (g - cos_i) + 1)
        return 0.5 * a * a * (1 + b * b)

    cases = {("fresnel", 1.45): fresnel(np.cos(theta), 1.45),
             ("layer_fresnel", 0.3): fresnel(np.cos(theta), 1 / 0.7),
             ("layer_facing", 0.5): 1 - np.cos(theta),
             ("layer_facing", 0.8): 1 - np.cos(theta) ** (0.5 / 0.2)}
    for (kind, value), want in cases.items():
        got = run_plain(device, lambda p: p.to_color(p.fresnel(kind, value, tilted(p))))
        want = pixel_mean(want)
        np.testing.assert_allclose(got[..., 0], want, rtol=0.03, atol=2e-3, err_msg=kind)  # 8 samples of a curve
        assert np.ptp(want) > 0.2


@pytest.mark.parametrize("strength,invert", [(1.0, False), (0.5, False), (1.0, True)])
def test_bump_tilts_the_normal_by_the_height_gradient(device, strength, invert):
    """Cycles' Bump: normal = normalize(N - distance grad h), mixed with N by the strength. The
    heights come from the program run at the two offsets (UV and Generated moved with them):
    h = 2 u + sin(3 v) on the quad (u = (x + 1) / 2, v = (y + 1) / 2), so grad h = (1,
    1.5 cos(3 v), 0) in world units."""
    u, v = grid()
    distance = 0.4

    def height(p, offset):
        uv = p.uv((offset, 0.1))
        gen = p.generated((offset, 0.1))  # 0..1 across the quad as the uvs are
        return p.math("ADD", p.math("MULTIPLY", p.separate(uv, 0), 2.0), p.math("SINE", p.math("MULTIPLY", p.separate(gen, 1), 3.0)))

    def build(p):
        return p.bump(strength, distance, [height(p, k) for k in range(3)], p.geometry("normal"), invert, 0.1)

    got = run_plain(device, build, field="normal", pass_name="normal")
    sign = -1.0 if invert else 1.0
    bumped = np.stack([-sign * distance * np.ones_like(u), -sign * distance * 1.5 * np.cos(3 * v), np.ones_like(u)], -1)
    bumped /= np.linalg.norm(bumped, axis=-1, keepdims=True)
    want = strength * bumped + (1 - strength) * np.array([0.0, 0.0, 1.0])
    want /= np.linalg.norm(want, axis=-1, keepdims=True)
    got = got[..., :3] / np.linalg.norm(got[..., :3], axis=-1, keepdims=True)
    # Within 0.01: each pixel averages 8 jittered samples of a curving normal.
    np.testing.assert_allclose(got, want, atol=0.01)
    assert np.abs(want[..., 0]).min() > 0.15  # tilted everywhere


@pytest.mark.parametrize("space,strength,sign", [("TANGENT", 1.0, 1.0), ("TANGENT", 0.5, -1.0), ("WORLD", 1.0, 1.0),
                                                 ("WORLD", 0.5, 1.0), ("BLENDER_WORLD", 1.0, 1.0)])
def test_normal_map(device, space, strength, sign):
    """Cycles' Normal Map of a colour that varies across the quad, read back through the Normal
    pass: tangent space with the mesh's tangents (+x, the bitangent sign flipping y), world space
    as the colour itself, Blender's world space with y and z negated."""
    session, scene, _ = device
    mesh = scene.meshes[0]
    tangents = np.zeros((len(mesh.indices), 3, 4))
    tangents[..., :] = (1.0, 0.0, 0.0, sign)
    scene.meshes = [Mesh(mesh.positions, mesh.indices, uvs=mesh.uvs, tangents=tangents)]
    try:
        p = nodes.Program()
        uv = p.uv()
        snap = lambda x: p.math("DIVIDE", p.math("ADD", p.math("FLOOR", p.math("MULTIPLY", x, W)), 0.5), W)
        u, v = snap(p.separate(uv, 0)), snap(p.separate(uv, 1))
        color = p.combine(p.math("ADD", p.math("MULTIPLY", u, 0.6), 0.2), p.math("ADD", p.math("MULTIPLY", v, -0.5), 0.75), 0.85)
        p.store("normal", p.normal_map(color, strength, space))
        scene.materials = [Material("diffuse", (1.0, 1.0, 1.0), node_program=tuple(p.finish()))]
        session.update(scene)
        session.render(1)
        got = session.read("normal")[::-1][..., :3]
    finally:
        scene.meshes = [mesh]
    uu, vv = grid()
    c = 2.0 * (np.stack([0.6 * uu + 0.2, -0.5 * vv + 0.75, np.full_like(uu, 0.85)], -1) - 0.5)
    n_shading = np.array([0.0, 0.0, 1.0])
    if space == "TANGENT":  # x along the tangent, y along sign * (N x T) = sign * +y
        c[..., :2] *= strength
        c[..., 2] = 1.0 + (c[..., 2] - 1.0) * min(max(strength, 0.0), 1.0)
        want = c * np.array([1.0, sign, 1.0])
        want /= np.linalg.norm(want, axis=-1, keepdims=True)
    else:
        want = c * (np.array([1.0, -1.0, -1.0]) if space == "BLENDER_WORLD" else 1.0)
        want /= np.linalg.norm(want, axis=-1, keepdims=True)
        want = n_shading + (want - n_shading) * strength
        want /= np.linalg.norm(want, axis=-1, keepdims=True)
    if space == "BLENDER_WORLD":  # z negated: it faces away, and the Normal pass shows it flipped
        assert (want[..., 2] < 0).all()
        want = -want
    np.testing.assert_allclose(got / np.linalg.norm(got, axis=-1, keepdims=True), want, atol=2e-3)


def test_normal_map_without_tangents_keeps_the_normal(device):
    got = run_plain(device, lambda p: p.normal_map((0.9, 0.5, 0.6), 1.0, "TANGENT"), field="normal", pass_name="normal")
    np.testing.assert_allclose(got[..., :3], np.broadcast_to([0.0, 0.0, 1.0], got[..., :3].shape), atol=1e-5)


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


def test_attributes_interpolate_and_read_zero_where_missing(device):
    """NODE_ATTRIBUTE: a slot's corner values interpolated over the triangle (here, the quad's
    uv as (u, v, u v-free 0.25, 1) at its corners: linear, so the pixel centre's value), slot 1
    absent from the mesh reads 0, and a program reading past the scene's slots is refused."""
    session, scene, _ = device
    mesh = scene.meshes[0]
    corners = np.concatenate([mesh.uvs, np.full(mesh.uvs.shape[:2] + (1,), 0.25), np.ones(mesh.uvs.shape[:2] + (1,))], -1)
    other = Mesh(mesh.positions + (0.0, 0.0, -50.0), mesh.indices, uvs=mesh.uvs, attributes={1: corners})
    scene.meshes = [Mesh(mesh.positions, mesh.indices, uvs=mesh.uvs, attributes={0: corners}), other]
    try:
        got = run_plain(device, lambda p: p.attribute(0))
        u, v = grid()
        np.testing.assert_allclose(got, np.stack([u, v, np.full_like(u, 0.25)], -1), atol=2e-3)
        got = run_plain(device, lambda p: p.mix("ADD", 1.0, p.attribute(1), 0.5))
        np.testing.assert_allclose(got, 0.5, atol=1e-6)  # the quad lacks slot 1
        p = nodes.Program()
        p.store("base_color", p.attribute(2))
        scene.materials = [Material("diffuse", node_program=tuple(p.finish()))]
        with pytest.raises(ValueError, match="reads attribute slot 2 of 2"):
            session.update(scene)
    finally:
        scene.meshes = [mesh]
