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


def test_cell_and_brick_hashes_over_arrays_are_the_hashes_per_element():
    cells = np.concatenate([RNG.integers(-2**40, 2**40, (20, 3)), [[-1, -7, 3], [0, 0, 0], [2**31, -2**31, 2**32 - 1]]])
    got = nodes.hash_pcg3d(cells[:, 0], cells[:, 1], cells[:, 2])
    assert [tuple(int(h[k]) for h in got) for k in range(len(cells))] == [nodes.hash_pcg3d(*map(int, c)) for c in cells]
    np.testing.assert_array_equal(nodes.hash_cell(cells.astype(np.float64)), [nodes.hash_cell(c) for c in cells])
    words = np.concatenate([RNG.integers(0, 2**32, 30), [0, 2**32 - 1]])
    np.testing.assert_array_equal(nodes.brick_noise(words), [nodes.brick_noise(int(n)) for n in words])


def _per_point(reference, arrays, *args):
    """reference at each point (the k-th element of each array in ``arrays``), then ``args``."""
    outs = [reference(*(a[k] for a in arrays), *args) for k in range(len(arrays[0]))]
    return [np.array(o) for o in zip(*outs)] if isinstance(outs[0], tuple) else np.array(outs)


@pytest.mark.parametrize("metric", nodes.VORONOI_METRICS)
@pytest.mark.parametrize("feature", nodes.VORONOI_FEATURES)
def test_voronoi_over_arrays_is_voronoi_per_point(feature, metric):
    p = RNG.uniform(-12, 12, (12, 3))
    for detail, normalize in ((0.0, False), (0.0, True), (2.5, False), (2.5, True)):
        args = (1.7, detail, 0.6, 2.1, 0.8, 1.5, 0.85)
        got = nodes.voronoi_reference(p, *args, feature, metric, normalize)
        want = _per_point(lambda q: nodes.voronoi_reference(q, *args, feature, metric, normalize), [p])
        for g, w in zip(got, want):
            np.testing.assert_array_equal(g, w)
    # Every parameter per point: randomness, a fractional detail, Smooth F1's smoothness 0 (F1
    # there), the exponents numpy raises to by its own paths (0.5, 1, 2).
    params = [RNG.uniform(0.5, 3.0, 12), RNG.choice([0.0, 0.4, 1.0, 2.5], 12), RNG.choice([0.0, 0.5, 1.0], 12),
              RNG.uniform(1.5, 3.0, 12), RNG.choice([0.0, 0.5, 2.0], 12), RNG.choice([0.5, 1.0, 1.3, 2.0], 12),
              RNG.uniform(0.0, 1.0, 12)]
    got = nodes.voronoi_reference(p, *params, feature, metric, True)
    want = _per_point(nodes.voronoi_reference, [p, *params], feature, metric, True)
    for g, w in zip(got, want):
        np.testing.assert_array_equal(g, w)
    grid = nodes.voronoi_reference(p.reshape(3, 4, 3), 1.7, 1.0, 0.6, 2.1, 0.8, 1.5, 0.85, feature, metric, True)
    flat = nodes.voronoi_reference(p, 1.7, 1.0, 0.6, 2.1, 0.8, 1.5, 0.85, feature, metric, True)
    assert grid[0].shape == (3, 4) and grid[1].shape == grid[2].shape == (3, 4, 3)
    for g, w in zip(grid, flat):
        np.testing.assert_array_equal(g.reshape(w.shape), w)


@pytest.mark.parametrize("feature", nodes.VORONOI_FEATURES)
def test_voronoi_in_chunks_and_blocks_is_voronoi_per_point(monkeypatch, feature):
    """Points in chunks of 7, their neighbour cells in blocks of 5 (40 // 7; 20 for the last 2
    points): the same as all 27 (125) neighbours of each point at once."""
    monkeypatch.setattr(nodes, "_VORONOI_CHUNK", 7)
    monkeypatch.setattr(nodes, "_VORONOI_BLOCK", 40)
    p = RNG.uniform(-5, 5, (30, 3))
    randomness = RNG.uniform(0, 1, 30)
    got = nodes.voronoi_reference(p, 2.0, 1.5, 0.5, 2.0, 1.0, 1.0, randomness, feature, "EUCLIDEAN", True)
    monkeypatch.undo()
    want = _per_point(lambda q, r: nodes.voronoi_reference(q, 2.0, 1.5, 0.5, 2.0, 1.0, 1.0, r, feature, "EUCLIDEAN",
                                                           True), [p, randomness])
    for g, w in zip(got, want):
        np.testing.assert_array_equal(g, w)


@pytest.mark.parametrize("wave_type, directions", [("BANDS", nodes.WAVE_BANDS_DIRECTIONS),
                                                   ("RINGS", nodes.WAVE_RINGS_DIRECTIONS)])
def test_wave_over_arrays_is_wave_per_point(wave_type, directions):
    p = RNG.uniform(-6, 6, (12, 3))
    params = [RNG.choice([0.0, 2.0, -1.5], 12), RNG.uniform(0, 4, 12), RNG.uniform(0.2, 3, 12), RNG.uniform(0, 1, 12),
              RNG.uniform(-2, 2, 12)]  # distortion (0 at some points), detail, its scale and roughness, phase
    for direction in directions:
        for profile in nodes.WAVE_PROFILES:
            for distortion in (0.0, 2.0):
                args = (wave_type, direction, profile, distortion, 2.5, 1.7, 0.55, 0.4)
                np.testing.assert_array_equal(nodes.wave_reference(p, *args),
                                              _per_point(nodes.wave_reference, [p], *args))
            got = nodes.wave_reference(p, wave_type, direction, profile, *params)
            want = _per_point(lambda q, *x: nodes.wave_reference(q, wave_type, direction, profile, *x), [p, *params])
            np.testing.assert_array_equal(got, want)


@pytest.mark.parametrize("offset_frequency, squash, squash_frequency, mortar_smooth", [
    (2, 1.0, 2, 0.0), (3, 0.6, 2, 0.4), (1, 1.3, 3, 1.0), (0, 0.5, 2, 0.2)])
def test_brick_over_arrays_is_brick_per_point(offset_frequency, squash, squash_frequency, mortar_smooth):
    p = RNG.uniform(-3, 3, (40, 3))  # negative rows and bricks too
    frequencies = (0.4, offset_frequency, squash, squash_frequency)
    colors = ((0.8, 0.2, 0.1), 0.3, (0.9, 0.9, 0.8, 1.0))  # a colour, a float (grey), an RGBA colour
    floats = (0.06, mortar_smooth, 0.1, 0.5, 0.25)
    got = nodes.brick_reference(p, *colors, *floats, *frequencies)
    want = _per_point(nodes.brick_reference, [p], *colors, *floats, *frequencies)
    for g, w in zip(got, want):
        np.testing.assert_array_equal(g, w)
    # Colours and floats per point.
    colors = [RNG.uniform(0, 1, (40, 3)), RNG.uniform(0, 1, (40, 4)), RNG.uniform(0, 1, (40, 3))]
    floats = [RNG.choice([0.0, 0.03, 0.1], 40), RNG.choice([0.0, mortar_smooth], 40), RNG.uniform(-1, 1, 40),
              RNG.uniform(0.3, 1.0, 40), RNG.uniform(0.2, 0.5, 40)]
    got = nodes.brick_reference(p, *colors, *floats, *frequencies)
    want = _per_point(nodes.brick_reference, [p, *colors, *floats], *frequencies)
    for g, w in zip(got, want):
        np.testing.assert_array_equal(g, w)


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


def _texture_graph(p, position):
    """Voronoi (each feature and output; a linked scale and randomness), Wave (each type; a
    linked distortion and phase) and Brick (linked colours, mortar size, scale and bias) mixed
    together."""
    u = p.math("ADD", p.separate(position, 0), 1.5)
    v = p.math("MULTIPLY_ADD", p.separate(position, 1), 0.4, 0.5)
    color = p.voronoi(position, 3.0, 2.5, 0.6, 2.2, 0.8, 1.5, 0.85, "SMOOTH_F1", "EUCLIDEAN", True, "Color")
    for feature, metric, output in (("F1", "MANHATTAN", "Position"), ("F2", "MINKOWSKI", "Distance"),
                                    ("F1", "CHEBYCHEV", "Color")):
        value = p.voronoi(position, u, 1.0, 0.5, 2.0, 1.0, 0.7, v, feature, metric, output == "Distance", output)
        color = p.mix("ADD", 0.5, color, p.to_color(value) if output == "Distance" else value)
    for wave_type, direction, profile in (("BANDS", "DIAGONAL", "SAW"), ("RINGS", "SPHERICAL", "SIN")):
        color = p.mix("MULTIPLY", p.wave(position, 2.3, wave_type, direction, profile, u, 2.0, 1.5, 0.5, v), color,
                      (1.0, 0.8, 0.6))
    brick = p.brick(position, 4.0, p.combine(u, 0.2, 0.1), (0.1, 0.7, 0.3), position, p.math("MULTIPLY", v, 0.1),
                    0.3, 0.1, 0.5, 0.25, 0.4, 2, 0.7, 3, "Color")
    fac = p.brick(position, u, (0.8, 0.2, 0.1), 0.4, (0.9, 0.9, 0.8), 0.04, 0.0, v, 0.5, 0.25, 0.5, 2, 1.0, 2, "Fac")
    return p.mix("MIX", fac, p.mix("ADD", 1.0, color, brick), (0.2, 0.2, 0.2))


def test_a_field_program_with_textures_is_a_program_folded_at_each_point():
    points = RNG.uniform(-1.5, 1.5, (24, 3))
    program = node_fields.FieldProgram(len(points), {"generated": points})
    got = program.evaluate(_texture_graph(program, program.generated()), "color")[:, :3]
    assert got.std(axis=0).min() > 0.01  # a pattern
    for k, point in enumerate(points):
        np.testing.assert_array_equal(got[k], nodes._vec4(_texture_graph(nodes.Program(), point))[:3])
    # Constant inputs fold as a Program folds them.
    assert isinstance(program.wave((0.1, 0.2, 0.3), 2.0, "BANDS", "X", "SIN", 1.0, 2.0, 1.0, 0.5, 0.0), np.floating)


def test_what_the_host_cannot_evaluate_says_so():
    program = node_fields.FieldProgram(3, {})
    with pytest.raises(node_fields.NotOnHost, match="uv"):
        program.uv()
    assert program.math("ADD", 1.0, 2.0) == 3.0  # constants fold as a Program's
    field = node_fields.FieldProgram(3, {"generated": np.eye(3)})
    with pytest.raises(node_fields.NotOnHost, match="normal map"):
        field.normal_map(field.generated(), 1.0, "TANGENT")
    with pytest.raises(node_fields.NotOnHost, match="attributes"):
        field.attribute(0)


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
