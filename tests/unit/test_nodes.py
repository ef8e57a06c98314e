"""parallax_core.nodes (the node program builder) against shaders/shared/types.h, and its
constant folding against the references."""
import math
import os
import re

import numpy as np
import pytest

from parallax_core import nodes

TYPES_H = os.path.join(os.path.dirname(__file__), "..", "..", "shaders", "shared", "types.h")


def header_constants():
    text = open(TYPES_H).read()
    return {name: int(value) for name, value in re.findall(r"PX_CONST uint (NODE_\w+) = (\d+);", text)}


def test_the_python_mirror_matches_the_header():
    header = header_constants()
    for name, value in header.items():
        if hasattr(nodes, name):
            assert getattr(nodes, name) == value, name
    assert header["NODE_MATH_OPS"] == len(nodes.MATH_OPS)
    assert header["NODE_BLEND_MODES"] == len(nodes.BLEND_MODES)
    assert header["NODE_FIELDS"] == len(nodes.FIELDS)
    assert header["NODE_VECTOR_MATH_OPS"] == len(nodes.VECTOR_MATH_OPS)
    assert header["NODE_MAP_RANGE_TYPES"] == len(nodes.MAP_RANGE_TYPES)
    assert header["NODE_OPS"] == 1 + max(v for k, v in header.items() if k.startswith("NODE_") and
                                         k not in ("NODE_OPS", "NODE_REGISTERS", "NODE_MATH_OPS",
                                                   "NODE_BLEND_MODES", "NODE_FIELDS", "NODE_VECTOR_MATH_OPS",
                                                   "NODE_MAP_RANGE_TYPES"))


def test_constants_fold_on_the_host_and_load_once():
    p = nodes.Program()
    assert p.math("MULTIPLY", 3.0, 2.0) == 6.0 and p.words == []  # nothing to run at a hit
    np.testing.assert_allclose(p.mix("SCREEN", 0.5, (0.2, 0.4, 0.6), (0.5, 0.5, 0.5)),
                               nodes.blend_reference("SCREEN", 0.5, (0.2, 0.4, 0.6), (0.5, 0.5, 0.5)))
    u = p.separate(p.uv(), 0)
    a, b = p.math("ADD", u, 0.25), p.math("MULTIPLY", u, 0.25)
    assert isinstance(a, nodes.Register) and isinstance(b, nodes.Register)
    loads = [w for w in p.words if w & 0xFF == nodes.NODE_CONST and w >> 16 == 0]
    assert len(loads) == 1  # 0.25 once
    with pytest.raises(ValueError, match="register"):
        p.store("roughness", 0.5)


def test_registers_are_reused_and_too_many_live_values_say_so():
    p = nodes.Program()
    value = p.separate(p.uv(), 0)
    for k in range(100):  # a long chain: two or three values live at a time
        value = p.math("ADD", value, float(k + 1))
    p.store("roughness", value)
    words = p.finish()
    used = {dst for op, dst, _, _, _ in nodes.instructions(words) if op != nodes.NODE_STORE}
    assert max(used) < 4
    p = nodes.Program()
    u = p.separate(p.uv(), 0)
    values = [p.math("ADD", u, float(k)) for k in range(nodes.NODE_REGISTERS + 8)]  # all live at once
    total = values[0]
    for v in values[1:]:
        total = p.math("ADD", total, v)
    p.store("roughness", total)
    with pytest.raises(nodes.ProgramTooLong):
        p.finish()


def test_procedural_textures_fold_and_read_their_registers():
    p = nodes.Program()
    point = (0.3, 0.7, 0.2)
    args = (5.0, 1.5, 0.6, 2.0, 1.0, 0.5, 0.9, "F2", "MANHATTAN", True)
    for k, output in enumerate(nodes.VORONOI_OUTPUTS):
        want = nodes.voronoi_reference(point, *args)[k]
        np.testing.assert_allclose(p.voronoi(point, *args, output), want)
    wave = ("RINGS", "SPHERICAL", "SAW", 2.0, 3.0, 1.5, 0.5, 0.25)
    assert p.wave(point, 2.0, *wave) == nodes.wave_reference(np.multiply(point, 2.0), *wave)
    brick = ((0.8, 0.1, 0.1), (0.1, 0.8, 0.1), (0.5, 0.5, 0.5), 0.02, 0.1, 0.0, 0.5, 0.25, 0.5, 2, 1.0, 2)
    color, fac = nodes.brick_reference(np.multiply(point, 4.0), *brick)
    np.testing.assert_allclose(p.brick(point, 4.0, *brick, "Color"), color)
    assert p.brick(point, 4.0, *brick, "Fac") == fac
    assert p.words == []  # all folded
    # Linked: every socket input is a register the allocator maps (the programs' operands).
    u = p.separate(p.uv(), 0)
    vector = p.combine(u, 0.5, 0.25)
    values = [p.voronoi(vector, u, 1.0, 0.5, 2.0, 1.0, 0.5, u, "F1", "EUCLIDEAN", False, "Color"),
              p.wave(vector, 3.0, "BANDS", "DIAGONAL", "TRI", u, 2.0, 1.0, 0.5, u),
              p.brick(vector, 5.0, vector, (0, 1, 0), vector, 0.02, 0.0, u, 0.5, 0.25, 0.5, 2, 1.0, 2, "Fac")]
    total = p.mix("ADD", 1.0, p.mix("ADD", 1.0, values[0], values[1]), values[2])
    p.store("base_color", total)
    steps = list(nodes.instructions(p.finish()))
    ops = [op for op, *_ in steps]
    assert ops.count(nodes.NODE_VORONOI) == ops.count(nodes.NODE_WAVE) == ops.count(nodes.NODE_BRICK) == 1
    assert [len(words) for op, _, _, _, words in steps if op in (nodes.NODE_VORONOI, nodes.NODE_WAVE, nodes.NODE_BRICK)] == [2, 2, 5]
    assert steps[-1][0] == nodes.NODE_STORE


def test_brick_noise_and_cell_hash_are_cycles_integer_arithmetic():
    # brick_noise wraps on 32 bits and keeps 31; hash_pcg3d works on signed ints (negative cells).
    assert 0.0 <= nodes.brick_noise(0xFFFFFFFF) < 1.0 and nodes.brick_noise(5) != nodes.brick_noise(6)
    h = nodes.hash_cell((-1, -7, 3))
    assert h.shape == (3,) and ((0 <= h) & (h <= 1)).all() and len(set(h)) == 3
    assert nodes.hash_pcg3d(-1, -2, 0) == nodes.hash_pcg3d(0xFFFFFFFF, 0xFFFFFFFE, 0)  # two's complement
def test_new_operations_fold_and_their_registers_are_tracked():
    """Vector Math, Curves, HSV and the Map Range types fold constants through their references
    and, on registers, read exactly the registers _READS names (the allocator keeps them)."""
    p = nodes.Program()
    np.testing.assert_allclose(p.vector_math("CROSS_PRODUCT", (1, 0, 0), (0, 1, 0)), (0, 0, 1))
    assert p.vector_math("DISTANCE", (1, 2, 3), (1, 2, 0)) == pytest.approx(3.0)
    np.testing.assert_allclose(p.vector_math("GAMMA", (0.25, -1.0, 0.0), scale=0.5), (0.5, -1.0, 0.0))
    np.testing.assert_allclose(p.hsv((0.2, 0.4, 0.6), 0.5, 1.0, 1.0, 1.0), (0.2, 0.4, 0.6), atol=1e-12)
    assert p.map_range(0.3, 0.0, 1.0, 0.0, 1.0, False, "STEPPED", 4.0) == pytest.approx(0.25)
    assert p.curves(np.linspace(0.0, 2.0, 5), 0.0, 1.0, True, 1.0, 1.5) == pytest.approx(3.0)  # extrapolated
    assert p.words == []
    u, v = p.separate(p.uv(), 0), p.separate(p.uv(), 1)
    w = p.combine(u, v, 0.5)
    size = len(p.words)
    assert p.curves(np.zeros((4, 3)), 0.0, 1.0, True, 0.0, w) == w and len(p.words) == size  # Fac 0: no table
    values = [p.vector_math("FACEFORWARD", w, (0.0, 0.0, 1.0), p.combine(v, u, 0.0)),
              p.vector_math("SCALE", w, scale=u),
              p.curves(np.random.default_rng(1).random((8, 3)), -0.5, 1.5, False, v, w),
              p.hsv(w, u, v, 0.7, 0.9), p.to_color(p.map_range(u, 0.0, 1.0, v, 2.0, True, "STEPPED", v))]
    total = values[0]
    for value in values[1:]:
        total = p.mix("ADD", 1.0, total, value)
    p.store("base_color", total)
    words = p.finish()
    ops = [op for op, *_ in nodes.instructions(words)]
    for op in (nodes.NODE_VECTOR_MATH, nodes.NODE_CURVES, nodes.NODE_HSV, nodes.NODE_MAP_RANGE):
        assert op in ops
    # Every register an instruction reads was written before (the machine's own check, here).
    written = set()
    for op, dst, a, b, extra in nodes.instructions(words):
        instruction = (op | dst << 8 | a << 16 | b << 24,) + extra
        for off, shift in nodes._READS.get(op, []):
            assert (instruction[off] >> shift) & 0xFF in written, (op, off, shift)
        if op != nodes.NODE_STORE:
            written.add(dst)


@pytest.mark.parametrize("interpolation", nodes.MAP_RANGE_TYPES)
def test_map_range_reference_as_cycles(interpolation):
    ref = lambda x, *args, **kw: nodes.map_range_reference(x, *args, interpolation=interpolation, steps=3.0, **kw)
    # The float node: 0 for an empty range; the reversed range of the smooth types is flipped.
    assert ref(0.5, 1.0, 1.0, 2.0, 3.0, False) == 0.0
    assert ref(0.5, 1.0, 1.0, 2.0, 3.0, False, vector=True) == 2.0  # the vector node: factor 0
    for x in np.linspace(-0.5, 1.5, 17):
        forward, backward = ref(x, 0.0, 1.0, 0.0, 1.0, False), ref(1.0 - x, 1.0, 0.0, 0.0, 1.0, False)
        if interpolation in ("SMOOTHSTEP", "SMOOTHERSTEP"):
            assert forward == pytest.approx(backward, abs=1e-12) and 0.0 <= forward <= 1.0
        t = min(max(x, 0.0), 1.0)
        want = {"LINEAR": x, "STEPPED": math.floor(x * 4.0) / 3.0, "SMOOTHSTEP": t * t * (3 - 2 * t),
                "SMOOTHERSTEP": t ** 3 * (t * (6 * t - 15) + 10)}[interpolation]
        assert forward == pytest.approx(want, abs=1e-12)
        assert ref(x, 0.0, 1.0, 0.2, 0.6, True) == pytest.approx(min(max(0.2 + 0.4 * want, 0.2), 0.6), abs=1e-12)


def test_hsv_round_trip_and_cycles_edge_cases():
    rng = np.random.default_rng(7)
    for rgb in rng.random((50, 3)) * 2.0:
        np.testing.assert_allclose(nodes.hsv_to_rgb(nodes.rgb_to_hsv(rgb)), rgb, atol=1e-12)
    np.testing.assert_allclose(nodes.rgb_to_hsv((1.0, 0.0, 0.0)), (0.0, 1.0, 1.0))
    np.testing.assert_allclose(nodes.rgb_to_hsv((0.0, 0.0, 1.0)), (2.0 / 3.0, 1.0, 1.0))
    np.testing.assert_allclose(nodes.hsv_to_rgb((1.0, 1.0, 1.0)), (1.0, 0.0, 0.0))  # h = 1 is red
    # Hue +0.5 turns red to cyan; saturation 0 is grey; fac 0 is the input.
    np.testing.assert_allclose(nodes.hsv_reference((1.0, 0.0, 0.0), 1.0, 1.0, 1.0, 1.0), (0.0, 1.0, 1.0))
    np.testing.assert_allclose(nodes.hsv_reference((0.8, 0.2, 0.4), 0.5, 0.0, 1.0, 1.0), (0.8, 0.8, 0.8))
    np.testing.assert_allclose(nodes.hsv_reference((0.8, 0.2, 0.4), 0.1, 2.0, 0.5, 0.0), (0.8, 0.2, 0.4))
