"""Material node programs: Cycles shader node graphs compiled to a small register machine that
the shaders run at every hit (shaders/lib/nodes.glsl; Cycles evaluates its graphs with an
interpreter too, the SVM in intern/cycles/kernel/svm/).

A program is a list of uint32 words: instructions ``op | dst << 8 | a << 16 | b << 24`` (a
register each; registers hold vec4) followed by their own words (constants as float bits).
It ends with NODE_END. ``Program`` builds one, folding every operation whose inputs are
constants on the host: an operand is a ``Register`` or a constant (a number or a sequence of
up to 4 floats). The ``*_reference`` functions are the operations in numpy, as the shaders do
them (tests compare the two).
"""
from __future__ import annotations

import heapq
import itertools
import math

import numpy as np

# shaders/shared/types.h NODE_* (tests/unit/test_nodes.py checks they agree).
NODE_END, NODE_CONST, NODE_UV, NODE_TEXTURE, NODE_AFFINE, NODE_MATH, NODE_MIX = 0, 1, 2, 3, 4, 5, 6
NODE_INVERT, NODE_MAP_RANGE, NODE_RAMP, NODE_SEPARATE, NODE_COMBINE, NODE_STORE, NODE_CONVERT = 7, 8, 9, 10, 11, 12, 13
NODE_GENERATED, NODE_NOISE = 14, 15
NODE_VORONOI, NODE_WAVE, NODE_BRICK = 16, 17, 18
NODE_VECTOR_MATH, NODE_CURVES, NODE_HSV = 19, 20, 21
NODE_GEOMETRY, NODE_BUMP, NODE_FRESNEL, NODE_NORMAL_MAP, NODE_ATTRIBUTE = 22, 23, 24, 25, 26
NODE_ATTRIBUTE_SLOTS = 8  # parallax_core.scene.ATTRIBUTE_SLOTS
# NODE_NORMAL_MAP's spaces: Blender's Normal Map space enum, in types.h's order.
NORMAL_MAP_SPACES = ("TANGENT", "OBJECT", "WORLD", "BLENDER_OBJECT", "BLENDER_WORLD")
# NODE_GEOMETRY's outputs (types.h NODE_GEOMETRY_*), in order.
GEOMETRY_KINDS = ("position", "normal", "true_normal", "incoming", "object", "object_normal", "backfacing")
NODE_REGISTERS = 32
NODE_RAMP_SIZE = 256  # Cycles' RAMP_TABLE_SIZE: a ColorRamp is a table of its colours

# Blender's Math node operations (the enum names) -> NODE_MATH's operation ids.
MATH_OPS = ("ADD", "SUBTRACT", "MULTIPLY", "DIVIDE", "POWER", "MINIMUM", "MAXIMUM", "LESS_THAN",
            "GREATER_THAN", "ABSOLUTE", "SQRT", "MULTIPLY_ADD", "FLOOR", "CEIL", "FRACT", "MODULO",
            "SINE", "COSINE", "ROUND", "SIGN", "EXPONENT", "CLAMP", "LOGARITHM", "INVERSE_SQRT", "TRUNC",
            "SNAP", "WRAP", "PINGPONG", "SMOOTH_MIN", "SMOOTH_MAX", "COMPARE", "TANGENT", "ARCSINE",
            "ARCCOSINE", "ARCTANGENT", "ARCTAN2", "SINH", "COSH", "TANH", "RADIANS", "DEGREES",
            "FLOORED_MODULO")
_TERNARY_MATH = {"MULTIPLY_ADD", "CLAMP", "WRAP", "SMOOTH_MIN", "SMOOTH_MAX", "COMPARE"}
_BINARY_MATH = {"ADD", "SUBTRACT", "MULTIPLY", "DIVIDE", "POWER", "MINIMUM", "MAXIMUM", "LESS_THAN",
                "GREATER_THAN", "MODULO", "LOGARITHM", "SNAP", "PINGPONG", "ARCTAN2",
                "FLOORED_MODULO"} | _TERNARY_MATH
# Blender's Vector Math operations (the enum names, in Blender's order) -> NODE_VECTOR_MATH's
# operation ids; GAMMA (Cycles' svm_math_gamma_color, the Gamma node) is the machine's own.
VECTOR_MATH_OPS = ("ADD", "SUBTRACT", "MULTIPLY", "DIVIDE", "MULTIPLY_ADD", "CROSS_PRODUCT", "PROJECT",
                   "REFLECT", "REFRACT", "FACEFORWARD", "DOT_PRODUCT", "DISTANCE", "LENGTH", "SCALE",
                   "NORMALIZE", "ABSOLUTE", "POWER", "SIGN", "MINIMUM", "MAXIMUM", "FLOOR", "CEIL",
                   "FRACTION", "MODULO", "WRAP", "SNAP", "SINE", "COSINE", "TANGENT", "GAMMA")
VECTOR_MATH_FLOAT_OPS = ("DOT_PRODUCT", "DISTANCE", "LENGTH")  # a Value, not a Vector
# The operands each operation reads (a, b and c are vectors, s the Scale float).
VECTOR_MATH_OPERANDS = {**{op: "ab" for op in VECTOR_MATH_OPS},
                        **{op: "a" for op in ("LENGTH", "NORMALIZE", "ABSOLUTE", "SIGN", "FLOOR", "CEIL",
                                              "FRACTION", "SINE", "COSINE", "TANGENT")},
                        "MULTIPLY_ADD": "abc", "FACEFORWARD": "abc", "WRAP": "abc", "REFRACT": "abs",
                        "SCALE": "as", "GAMMA": "as"}
# Map Range's interpolation types (NODE_MAP_RANGE's flags, bits 8..15).
MAP_RANGE_TYPES = ("LINEAR", "STEPPED", "SMOOTHSTEP", "SMOOTHERSTEP")
# Blender's Mix node blend types (MixRGB's blend_type, Mix's blend_type for colours).
BLEND_MODES = ("MIX", "ADD", "MULTIPLY", "SUBTRACT", "SCREEN", "DIFFERENCE", "DARKEN", "LIGHTEN", "OVERLAY",
               "DIVIDE")
# Voronoi Texture features and distance metrics, Wave Texture types, directions and profiles
# (Blender's enum names) -> the ids NODE_VORONOI and NODE_WAVE take.
VORONOI_FEATURES = ("F1", "F2", "SMOOTH_F1")
VORONOI_METRICS = ("EUCLIDEAN", "MANHATTAN", "CHEBYCHEV", "MINKOWSKI")
VORONOI_OUTPUTS = ("Distance", "Color", "Position")
WAVE_TYPES = ("BANDS", "RINGS")
WAVE_BANDS_DIRECTIONS = ("X", "Y", "Z", "DIAGONAL")
WAVE_RINGS_DIRECTIONS = ("X", "Y", "Z", "SPHERICAL")
WAVE_PROFILES = ("SIN", "SAW", "TRI")
# Material fields a program may set (NODE_STORE), clamped as Cycles clamps the inputs.
FIELDS = ("base_color", "roughness", "metallic", "transmission", "coat_weight", "specular_ior_level",
          "mix_weight", "coat_roughness", "sheen_weight", "normal")


def _f32(x):
    return int(np.float32(x).view(np.uint32))


def _result(x):
    """A reference's result: a numpy scalar for scalar inputs, else the array."""
    x = np.array(x, np.float64)
    return x[()] if x.ndim == 0 else x


def _where_nonzero(b):
    """b with its zeros replaced by 1 (a divisor for np.where's other branch)."""
    return np.where(b != 0, b, 1.0)


def _safe_divide(a, b):
    return np.where(b != 0, a / _where_nonzero(b), 0.0)


def _fract(x):
    return x - np.floor(x)


def _wrap(value, high, low):
    """Cycles' wrapf(value, max, min)."""
    span = high - low
    return np.where(span != 0, value - span * np.floor((value - low) / _where_nonzero(span)), low)


def _smooth_min(a, b, k):
    """Cycles' smoothminf."""
    h = np.maximum(k - np.abs(a - b), 0.0) / _where_nonzero(k)
    return np.where(k != 0, np.minimum(a, b) - h * h * h * k / 6.0, np.minimum(a, b))


def _safe_pow(a, b):
    """Cycles' safe_powf (compatible_powf): 0 for a negative base and a fractional exponent,
    x^0 = 1, 0^y = 0."""
    power = np.power(np.where(a == 0, 1.0, a), b)
    return np.where((a < 0) & (b != np.trunc(b)), 0.0, np.where(b == 0, 1.0, np.where(a == 0, 0.0, power)))


# Blender's Math node as Cycles computes it (svm_math_float), elementwise over numpy arrays.
_MATH = {
    "ADD": lambda a, b, c: a + b, "SUBTRACT": lambda a, b, c: a - b, "MULTIPLY": lambda a, b, c: a * b,
    "DIVIDE": lambda a, b, c: _safe_divide(a, b),
    "POWER": lambda a, b, c: np.where((a < 0) & (b != np.floor(b)), 0.0, np.power(a, b)),
    "MINIMUM": lambda a, b, c: np.minimum(a, b), "MAXIMUM": lambda a, b, c: np.maximum(a, b),
    "LESS_THAN": lambda a, b, c: (a < b) * 1.0, "GREATER_THAN": lambda a, b, c: (a > b) * 1.0,
    "ABSOLUTE": lambda a, b, c: np.abs(a), "SQRT": lambda a, b, c: np.where(a > 0, np.sqrt(np.abs(a)), 0.0),
    "MULTIPLY_ADD": lambda a, b, c: a * b + c, "FLOOR": lambda a, b, c: np.floor(a),
    "CEIL": lambda a, b, c: np.ceil(a), "FRACT": lambda a, b, c: _fract(a),
    "MODULO": lambda a, b, c: np.where(b != 0, np.fmod(a, _where_nonzero(b)), 0.0),
    "SINE": lambda a, b, c: np.sin(a), "COSINE": lambda a, b, c: np.cos(a),
    "ROUND": lambda a, b, c: np.floor(a + 0.5), "SIGN": lambda a, b, c: np.sign(a),
    "EXPONENT": lambda a, b, c: np.exp(a), "CLAMP": lambda a, b, c: np.minimum(np.maximum(a, b), c),
    "LOGARITHM": lambda a, b, c: np.where((a <= 0) | (b <= 0), 0.0, _safe_divide(np.log(np.abs(a)), np.log(np.abs(b)))),
    "INVERSE_SQRT": lambda a, b, c: np.where(a > 0, 1.0 / np.sqrt(np.abs(a)), 0.0),
    "TRUNC": lambda a, b, c: np.trunc(a), "SNAP": lambda a, b, c: np.floor(_safe_divide(a, b)) * b,
    "WRAP": lambda a, b, c: _wrap(a, b, c),
    "PINGPONG": lambda a, b, c: np.where(b != 0, np.abs(_fract((a - b) / _where_nonzero(b * 2.0)) * b * 2.0 - b), 0.0),
    "SMOOTH_MIN": lambda a, b, c: _smooth_min(a, b, c), "SMOOTH_MAX": lambda a, b, c: -_smooth_min(-a, -b, c),
    "COMPARE": lambda a, b, c: ((a == b) | (np.abs(a - b) <= np.maximum(c, float(np.finfo(np.float32).eps)))) * 1.0,
    "TANGENT": lambda a, b, c: np.tan(a), "ARCSINE": lambda a, b, c: np.arcsin(np.clip(a, -1.0, 1.0)),
    "ARCCOSINE": lambda a, b, c: np.arccos(np.clip(a, -1.0, 1.0)), "ARCTANGENT": lambda a, b, c: np.arctan(a),
    "ARCTAN2": lambda a, b, c: np.where((a == 0) & (b == 0), 0.0, np.arctan2(a, b)),
    "SINH": lambda a, b, c: np.sinh(a), "COSH": lambda a, b, c: np.cosh(a), "TANH": lambda a, b, c: np.tanh(a),
    "RADIANS": lambda a, b, c: a * (math.pi / 180.0), "DEGREES": lambda a, b, c: a * (180.0 / math.pi),
    "FLOORED_MODULO": lambda a, b, c: np.where(b != 0, a - np.floor(a / _where_nonzero(b)) * b, 0.0),
}


def math_reference(op, a, b=0.0, c=0.0):
    """Blender's Math node as Cycles computes it (svm_math_float: safe division, power, ...),
    on floats or elementwise on arrays."""
    a, b, c = (np.asarray(x, np.float64) for x in (a, b, c))
    with np.errstate(all="ignore"):
        out = _MATH[op](a, b, c)
    return _result(np.broadcast_to(out, np.broadcast(a, b, c).shape))


def _dot(a, b):
    return np.sum(a * b, axis=-1)


def _safe_normalize(v):
    length = np.sqrt(_dot(v, v))[..., None]
    return np.where(length != 0, v / np.where(length != 0, length, 1.0), v)


def vector_math_reference(op, a, b=(0.0, 0.0, 0.0), c=(0.0, 0.0, 0.0), scale=1.0):
    """Blender's Vector Math node as Cycles computes it (svm_vector_math): a vector, or a float
    for VECTOR_MATH_FLOAT_OPS; GAMMA is Cycles' svm_math_gamma_color of a by scale. Vectors
    are (..., 3+) arrays (the first three components are used), scale a float or (...)."""
    a, b, c = (np.asarray(x, np.float64)[..., :3] for x in (a, b, c))
    s = np.asarray(scale, np.float64)[..., None]
    with np.errstate(all="ignore"):
        out = _vector_math(op, a, b, c, s)
    shape = np.broadcast(a, b, c, s).shape
    return _result(np.broadcast_to(out, shape[:-1] if op in VECTOR_MATH_FLOAT_OPS else shape))


def _vector_math(op, a, b, c, s):
    simple = {"ADD": lambda: a + b, "SUBTRACT": lambda: a - b, "MULTIPLY": lambda: a * b,
              "DIVIDE": lambda: _safe_divide(a, b), "MULTIPLY_ADD": lambda: a * b + c,
              "CROSS_PRODUCT": lambda: np.cross(a, b), "DOT_PRODUCT": lambda: _dot(a, b),
              "DISTANCE": lambda: np.sqrt(_dot(a - b, a - b)), "LENGTH": lambda: np.sqrt(_dot(a, a)),
              "SCALE": lambda: a * s, "NORMALIZE": lambda: _safe_normalize(a), "ABSOLUTE": lambda: np.abs(a),
              "POWER": lambda: _safe_pow(a, b), "SIGN": lambda: np.sign(a), "MINIMUM": lambda: np.minimum(a, b),
              "MAXIMUM": lambda: np.maximum(a, b), "FLOOR": lambda: np.floor(a), "CEIL": lambda: np.ceil(a),
              "FRACTION": lambda: _fract(a), "MODULO": lambda: np.where(b != 0, np.fmod(a, _where_nonzero(b)), 0.0),
              "WRAP": lambda: _wrap(a, b, c), "SNAP": lambda: np.floor(_safe_divide(a, b)) * b,
              "SINE": lambda: np.sin(a), "COSINE": lambda: np.cos(a), "TANGENT": lambda: np.tan(a)}
    if op in simple:
        return simple[op]()
    if op == "PROJECT":
        bb = _dot(b, b)[..., None]
        return np.where(bb != 0, _dot(a, b)[..., None] / np.where(bb != 0, bb, 1.0) * b, 0.0)
    if op == "REFLECT":
        n = _safe_normalize(b)
        return a - 2.0 * n * _dot(a, n)[..., None]
    if op == "REFRACT":
        n = _safe_normalize(b)
        na = _dot(n, a)[..., None]
        k = 1.0 - s * s * (1.0 - na * na)
        return np.where(k < 0, 0.0, s * a - (s * na + np.sqrt(np.maximum(k, 0.0))) * n)
    if op == "FACEFORWARD":
        return np.where(_dot(c, b)[..., None] < 0, a, -a)
    if op == "GAMMA":
        return np.where(s == 0, 1.0, np.where(a > 0, np.power(np.where(a > 0, a, 1.0), s), a))
    raise ValueError(f"unknown vector math operation {op!r}")


def rgb_to_hsv(rgb):
    """Cycles' rgb_to_hsv, of (..., 3+) colours."""
    rgb = np.asarray(rgb, np.float64)
    r, g, b = rgb[..., 0], rgb[..., 1], rgb[..., 2]
    cmax, cmin = np.maximum(np.maximum(r, g), b), np.minimum(np.minimum(r, g), b)
    delta = cmax - cmin
    s = _safe_divide(delta, cmax)
    with np.errstate(all="ignore"):
        cr, cg, cb = ((cmax - x) / np.where(delta != 0, delta, 1.0) for x in (r, g, b))
    h = np.where(r == cmax, cb - cg, np.where(g == cmax, 2.0 + cr - cb, 4.0 + cg - cr)) / 6.0
    h = np.where(s != 0, np.where(h < 0, h + 1.0, h), 0.0)
    return np.stack([h, s, cmax], -1)


def hsv_to_rgb(hsv):
    """Cycles' hsv_to_rgb, of (..., 3) values."""
    hsv = np.asarray(hsv, np.float64)
    h, s, v = hsv[..., 0], hsv[..., 1], hsv[..., 2]
    h = np.where(h == 1.0, 0.0, h * 6.0)
    i = np.floor(h)
    f = h - i
    p, q, t = v * (1 - s), v * (1 - s * f), v * (1 - s * (1 - f))
    sextants = [(v, t, p), (q, v, p), (p, v, t), (p, q, v), (t, p, v)]
    out = np.stack([v, p, q], -1)  # i = 5 and beyond
    for k in reversed(range(5)):
        out = np.where((i == k)[..., None], np.stack(sextants[k], -1), out)
    return np.where((s == 0)[..., None], np.stack([v, v, v], -1), out)


def hsv_reference(color, hue, saturation, value, fac):
    """Blender's Hue/Saturation/Value node as Cycles' svm_node_hsv: hue shifted (0.5: none),
    saturation scaled and clamped to 0..1, value scaled, mixed by fac, clamped to >= 0."""
    color = np.asarray(color, np.float64)[..., :3]
    hue, saturation, value, fac = (np.asarray(x, np.float64) for x in (hue, saturation, value, fac))
    h, s, v = np.moveaxis(rgb_to_hsv(color), -1, 0)
    out = hsv_to_rgb(np.stack(np.broadcast_arrays(_fract(h + hue + 0.5), np.clip(s * saturation, 0.0, 1.0),
                                                  v * value), -1))
    return np.maximum(fac[..., None] * out + (1.0 - fac[..., None]) * color, 0.0)


def curve_lookup_reference(table, f, extrapolate):
    """Cycles' float_ramp_lookup (rgb_ramp_lookup, one channel) of an interpolated table:
    beyond 0..1 continued along its end segments if extrapolate, else clamped."""
    table = np.asarray(table, np.float64)
    f = np.asarray(f, np.float64)
    n = len(table)
    inside = ramp_reference(table, f, True)
    if not extrapolate:
        return inside
    below = table[0] + (table[0] - table[1]) * -f * (n - 1)
    above = table[-1] + (table[-1] - table[-2]) * (f - 1.0) * (n - 1)
    return _result(np.where(f < 0.0, below, np.where(f > 1.0, above, inside)))


def curves_reference(tables, min_x, max_x, extrapolate, fac, value):
    """Blender's RGB Curves (tables: 3 columns, R G B after C) or Float Curve (1 column) as
    Cycles' svm_node_curves / svm_node_curve: each channel's table over min_x..max_x, mixed
    with the input by fac. value: a float or (..., 3+) colour; fac a float or (...)."""
    tables = np.asarray(tables, np.float64).reshape(len(tables), -1)
    channels = tables.shape[1]
    value = np.asarray(value, np.float64)
    x = value[..., None] if channels == 1 else value[..., :channels]  # Float Curve: a float
    with np.errstate(all="ignore"):
        rel = (x - min_x) / (max_x - min_x)
    y = np.stack([curve_lookup_reference(tables[:, k], rel[..., k], extrapolate) for k in range(channels)], -1)
    fac = np.asarray(fac, np.float64)[..., None]
    out = (1.0 - fac) * x + fac * y
    return _result(out[..., 0]) if channels == 1 else out


def blend_reference(mode, t, c1, c2):
    """Blender's Mix (colour) blend types as Cycles computes them (svm_mix), factor t (a float
    or (...)), colours (..., 3+)."""
    c1, c2 = np.asarray(c1, np.float64)[..., :3], np.asarray(c2, np.float64)[..., :3]
    t = np.asarray(t, np.float64)[..., None]
    tm = 1.0 - t
    if mode == "MIX":
        return tm * c1 + t * c2
    if mode == "ADD":
        return c1 + t * c2
    if mode == "MULTIPLY":
        return c1 * (tm + t * c2)
    if mode == "SUBTRACT":
        return c1 - t * c2
    if mode == "SCREEN":
        return 1.0 - (tm + t * (1.0 - c2)) * (1.0 - c1)
    if mode == "DIFFERENCE":
        return tm * c1 + t * np.abs(c1 - c2)
    if mode == "DARKEN":
        return tm * c1 + t * np.minimum(c1, c2)
    if mode == "LIGHTEN":
        return tm * c1 + t * np.maximum(c1, c2)
    if mode == "OVERLAY":
        return np.where(c1 < 0.5, c1 * (tm + 2.0 * t * c2), 1.0 - (tm + 2.0 * t * (1.0 - c2)) * (1.0 - c1))
    if mode == "DIVIDE":
        with np.errstate(all="ignore"):
            return np.where(c2 != 0.0, tm * c1 + t * c1 / np.where(c2 != 0.0, c2, 1.0), c1)
    raise ValueError(f"unknown blend mode {mode!r}")


def map_range_reference(value, from_min, from_max, to_min, to_max, clamp, interpolation="LINEAR", steps=4.0,
                        vector=False):
    """Blender's Map Range as Cycles: svm_node_map_range (0 where the input range is empty;
    clamped by the Clamp node MapRangeNode::expand adds) or, for one component of a vector,
    svm_node_vector_map_range (safe division; the smooth types never clamp). Floats or arrays."""
    value, from_min, from_max, to_min, to_max, steps = (
        np.asarray(x, np.float64) for x in (value, from_min, from_max, to_min, to_max, steps))
    span = from_max - from_min
    with np.errstate(all="ignore"):
        factor = _safe_divide(value - from_min, span)
        if interpolation == "STEPPED":
            factor = np.where(steps > 0, np.floor(factor * (steps + 1.0)) / np.where(steps > 0, steps, 1.0), 0.0)
        elif interpolation in ("SMOOTHSTEP", "SMOOTHERSTEP"):
            flip = (from_min > from_max) & (not vector)  # smoothstep(from_max, from_min, value), flipped
            t = np.clip(np.where(flip, (value - from_max) / -_where_nonzero(span), factor), 0.0, 1.0)
            t = (3.0 - 2.0 * t) * t * t if interpolation == "SMOOTHSTEP" else t * t * t * (t * (t * 6.0 - 15.0) + 10.0)
            factor = np.where(flip, 1.0 - t, t)
            clamp = clamp and not vector
        out = to_min + factor * (to_max - to_min)
    if clamp:
        out = np.clip(out, np.minimum(to_min, to_max), np.maximum(to_min, to_max))
    if not vector:
        out = np.where(span == 0, 0.0, out)
    return _result(np.broadcast_to(out, np.broadcast(value, from_min, from_max, to_min, to_max, steps).shape))


def ramp_reference(table, fac, interpolate):
    """Cycles' rgb_ramp_lookup: the table (n, ...) at fac (clamped to 0..1; a float or an array),
    interpolated or not."""
    table = np.asarray(table, np.float64)
    f = np.clip(np.nan_to_num(np.asarray(fac, np.float64)), 0.0, 1.0) * (len(table) - 1)
    i = np.clip(f.astype(np.int64), 0, len(table) - 1)
    t = (f - i).reshape(f.shape + (1,) * (table.ndim - 1))
    out = table[i]
    if interpolate:
        out = np.where(t > 0.0, (1.0 - t) * out + t * table[np.minimum(i + 1, len(table) - 1)], out)
    return _result(out) if table.ndim == 1 else out


def _cie_lobe(wavelength, mean, below, above):
    width = np.where(wavelength < mean, below, above)
    return np.exp(-0.5 * ((wavelength - mean) / width) ** 2)


def cie_1931(wavelength):
    """The CIE 1931 2-degree colour matching functions (x, y, z) at ``wavelength`` nm (an
    array): Wyman, Sloan and Shirley's multi-lobe fit (JCGT 2(2), 2013, equation 2)."""
    l = np.asarray(wavelength, np.float64)
    return np.stack([1.056 * _cie_lobe(l, 599.8, 37.9, 31.0) + 0.362 * _cie_lobe(l, 442.0, 16.0, 26.7) -
                     0.065 * _cie_lobe(l, 501.1, 20.4, 26.2),
                     0.821 * _cie_lobe(l, 568.8, 46.9, 40.5) + 0.286 * _cie_lobe(l, 530.9, 16.3, 31.1),
                     1.217 * _cie_lobe(l, 437.0, 11.8, 36.0) + 0.681 * _cie_lobe(l, 459.0, 26.0, 13.8)], -1)


# CIE XYZ -> linear Rec.709 (sRGB primaries, D65; IEC 61966-2-1).
XYZ_TO_REC709 = np.array([[3.2404542, -1.5371385, -0.4985314],
                          [-0.9692660, 1.8760108, 0.0415560],
                          [0.0556434, -0.2040259, 1.0572252]])


def blackbody_reference(temperature):
    """Blender's Blackbody node: the colour of Planck's spectrum at ``temperature`` K (a float
    or an array) in linear Rec.709, scaled to luminance 1 and clamped to >= 0, as Cycles'
    svm_math_blackbody_color_rec709 (which holds the colour of 800 K below 800 K and of
    12000 K above). Integrated here from 360 to 830 nm (Cycles uses a fit of the same)."""
    t = np.clip(np.asarray(temperature, np.float64), 800.0, 12000.0)
    wavelength = np.arange(360.0, 831.0, 2.0)
    metres = wavelength * 1e-9
    second_radiation_constant = 6.62607015e-34 * 2.99792458e8 / 1.380649e-23  # h c / k (m K)
    planck = 1.0 / (metres ** 5 * np.expm1(second_radiation_constant / (metres * t[..., None])))
    rgb = (planck @ cie_1931(wavelength)) @ XYZ_TO_REC709.T
    return np.maximum(rgb / (rgb @ (0.2126, 0.7152, 0.0722))[..., None], 0.0)


def _rotate(x, k):
    return (x << np.uint32(k)) | (x >> np.uint32(32 - k))


def hash_uint(*keys):
    """Bob Jenkins' lookup3 hash of 1 to 3 words, as Cycles' hash_uint, hash_uint2, hash_uint3:
    ints or arrays of them (uint32 arithmetic)."""
    keys = [np.asarray(np.asarray(k, np.int64) & 0xFFFFFFFF, np.uint32) for k in keys]
    start = np.uint32((0xDEADBEEF + (len(keys) << 2) + 13) & 0xFFFFFFFF)
    shape = np.broadcast(*keys).shape
    keys = [np.broadcast_to(k, shape).reshape(-1) for k in keys]  # arrays: uint32 wraps silently
    regs = {name: np.full(keys[0].shape, start, np.uint32) for name in "abc"}
    for name, key in zip("abc", keys):
        regs[name] = regs[name] + key
    for x, y, k in (("c", "b", 14), ("a", "c", 11), ("b", "a", 25), ("c", "b", 16), ("a", "c", 4),
                    ("b", "a", 14), ("c", "b", 24)):
        regs[x] = (regs[x] ^ regs[y]) - _rotate(regs[y], k)
    c = regs["c"].reshape(shape)
    return int(c) if c.ndim == 0 else c.astype(np.int64)


def random_offset(seed, k):
    """Cycles' random_float3_offset component k: 100 + 100 hash(seed, k), the noise's seeds."""
    bits = lambda f: int(np.float32(f).view(np.uint32))
    return 100.0 + 100.0 * float(np.float32(hash_uint(bits(seed), bits(k)) * (1.0 / 0xFFFFFFFF)))


def perlin_reference(p):
    """Cycles' perlin_3d at point p ((..., 3) floats)."""
    p = np.asarray(p, np.float64)
    cell = np.floor(p)
    f = p - cell
    w = f * f * f * (f * (f * 6.0 - 15.0) + 10.0)
    cell = cell.astype(np.int64)
    corners = []
    for k in range(8):
        o = np.array([k & 1, (k >> 1) & 1, k >> 2])
        h = hash_uint(*(cell[..., j] + o[j] for j in range(3))) & 15
        q = f - o
        u = np.where(h < 8, q[..., 0], q[..., 1])
        v = np.where(h < 4, q[..., 1], np.where((h == 12) | (h == 14), q[..., 0], q[..., 2]))
        corners.append(np.where(h & 1, -u, u) + np.where(h & 2, -v, v))
    lerp = lambda a, b, t: a * (1 - t) + b * t
    x = [lerp(corners[2 * j], corners[2 * j + 1], w[..., 0]) for j in range(4)]
    return _result(lerp(lerp(x[0], x[1], w[..., 1]), lerp(x[2], x[3], w[..., 1]), w[..., 2]))


def noise_reference(p, detail, roughness, lacunarity, normalize):
    """Cycles' 3D fBm noise_fbm (detail clamped to 0..15, roughness to >= 0) at p ((..., 3));
    detail, roughness and lacunarity floats or (...) arrays."""
    detail = np.clip(np.asarray(detail, np.float64), 0.0, 15.0)
    roughness, lacunarity = np.maximum(np.asarray(roughness, np.float64), 0.0), np.asarray(lacunarity, np.float64)
    p = np.asarray(p, np.float64)

    def signed(scale):
        q = scale[..., None] * p
        q = np.fmod(q, 100000.0) + 0.5 * (np.abs(q) >= 1000000.0)
        return 0.9820 * perlin_reference(q)

    octaves = np.floor(detail)
    scale, amplitude, max_amplitude, total = (np.ones(np.broadcast(detail, roughness, lacunarity, p[..., 0]).shape),
                                              1.0, 0.0, 0.0)
    for i in range(int(np.max(octaves)) + 1):
        active = i <= octaves
        total = total + np.where(active, signed(scale) * amplitude, 0.0)
        max_amplitude = max_amplitude + np.where(active, amplitude, 0.0)
        amplitude = np.where(active, amplitude * roughness, amplitude)
        scale = np.where(active, scale * lacunarity, scale)
    value = 0.5 * total / max_amplitude + 0.5 if normalize else total
    remainder = detail - octaves
    if np.any(remainder != 0.0):
        total2 = total + signed(scale) * amplitude
        value2 = 0.5 * total2 / (max_amplitude + amplitude) + 0.5 if normalize else total2
        value = np.where(remainder != 0.0, value * (1 - remainder) + value2 * remainder, value)
    return _result(value)


def _u32(x):
    """Integers modulo 2^32 as a uint32 array (at least 1-d): Python ints of any size, integer
    arrays, or float arrays of integers (truncated; exact at any magnitude, as int() is)."""
    if isinstance(x, int):
        x &= 0xFFFFFFFF
    x = np.asarray(x)
    if x.dtype.kind == "f":
        x = np.fmod(np.trunc(x), 4294967296.0)
    return np.atleast_1d(np.asarray(x, np.int64)).astype(np.uint32)  # int64 -> uint32 keeps the low bits


_PCG_A, _PCG_C = np.uint32(1664525), np.uint32(1013904223)


def _pcg3d(x, y, z):
    """hash_pcg3d_i on uint32 arrays whose first step (k * 1664525 + 1013904223) is done:
    uint32 arithmetic wraps as the signed ints do, v ^= v >> 16 shifts arithmetically."""
    for step in range(2):
        x = x + y * z
        y = y + z * x
        z = z + x * y
        if step == 0:
            x, y, z = (k ^ (k.view(np.int32) >> 16).view(np.uint32) for k in (x, y, z))
    m = np.uint32(0x7FFFFFFF)
    return x & m, y & m, z & m


def hash_pcg3d(x, y, z):
    """Cycles' hash_pcg3d_i (PCG 3D on signed 32-bit integers, results masked to 31 bits): of
    ints (a tuple of ints) or integer arrays (a tuple of int64 arrays)."""
    shape = np.broadcast_shapes(*(np.shape(k) for k in (x, y, z)))
    keys = (np.broadcast_to(_u32(k), shape or (1,)).reshape(-1) * _PCG_A + _PCG_C for k in (x, y, z))
    out = _pcg3d(*keys)
    return tuple(int(h[0]) for h in out) if shape == () else tuple(h.reshape(shape).astype(np.int64) for h in out)


def _hash_color(x, y, z, axis=-1):
    """hash_int3_to_float3 of hash_pcg3d_i's (N,) words: (N, 3) (axis -1) or (3, N) (axis 0),
    float32 as Cycles computes it."""
    h = np.stack([x, y, z], axis).view(np.int32)  # 31 bits
    return (h.astype(np.float32) * np.float32(1.0 / 2147483648.0)).astype(np.float64)


def hash_cell(cell):
    """Cycles' hash_int3_to_float3: a Voronoi cell's point offset and colour, float32 as it is
    computed there; of a cell (3 integers) or cells (..., 3)."""
    cell = np.asarray(cell)
    shape = cell.shape[:-1]
    keys = (_u32(cell[..., k]).reshape(-1) * _PCG_A + _PCG_C for k in range(3))
    return _hash_color(*_pcg3d(*keys)).reshape(shape + (3,))


def _dot3(a, b):
    """a . b over the last axis, (a0 b0 + a1 b1) + a2 b2 elementwise: the same bits for any
    stack of vectors. A matmul over the stack was not: on an AVX-512 machine a stack of 12
    points and one point alone rounded apart by an ulp (BLAS kernels differ by shape)."""
    a, b = np.asarray(a, np.float64), np.asarray(b, np.float64)
    return (a[..., 0] * b[..., 0] + a[..., 1] * b[..., 1]) + a[..., 2] * b[..., 2]


_FAST_POWERS = ((1.0, np.positive), (-1.0, np.reciprocal), (0.0, np.ones_like), (0.5, np.sqrt), (2.0, np.square))


def _scalar_power(x, e):
    """x ** e as numpy computes it for a float e (its fast paths for 1, -1, 0, 0.5 and 2, else
    np.power), also for e an array broadcastable to x."""
    e = np.asarray(e, np.float64)
    if e.ndim == 0:
        return x ** float(e)
    out = np.power(x, e)
    for value, op in _FAST_POWERS:
        hit = e == value
        if np.any(hit):
            out = np.where(hit, op(x), out)
    return out


def _float_pow(x, y):
    """x ** y as Python's floats compute it (the C library's pow; numpy's SIMD power may differ
    in the last bits), elementwise."""
    x, y = np.asarray(x, np.float64), np.asarray(y, np.float64)
    shape = np.broadcast_shapes(x.shape, y.shape)
    xs = np.broadcast_to(x, shape).ravel().tolist()
    ys = itertools.repeat(float(y)) if y.ndim == 0 else np.broadcast_to(y, shape).ravel().tolist()
    return np.fromiter(map(pow, xs, ys), np.float64, len(xs)).reshape(shape)


def _voronoi_bound(d, metric, exponent):
    """voronoi_distance_bound of d = a - b, its components first ((3, ...)): what the distance
    orders by."""
    if metric == "EUCLIDEAN":
        v = np.stack([d[0], d[1], d[2]], -1)
        return _dot3(v, v)
    d = np.abs(d)
    if metric == "MANHATTAN":
        return (d[0] + d[1]) + d[2]
    if metric == "CHEBYCHEV":
        return np.maximum(np.maximum(d[0], d[1]), d[2])
    t = _scalar_power(d, exponent)
    return (t[0] + t[1]) + t[2]


def _voronoi_unbound(bound, metric, exponent):
    """The distance of its bound."""
    if metric == "EUCLIDEAN":
        return np.sqrt(bound)
    if metric == "MINKOWSKI":
        return _float_pow(bound, 1.0 / np.asarray(exponent, np.float64))
    return bound


def _voronoi_distance(d, metric, exponent, bound=False):
    """Cycles' voronoi_distance of d = a - b ((..., 3); voronoi_distance_bound if ``bound``);
    exponent a float or an array broadcastable to d[..., 0]."""
    value = _voronoi_bound(np.moveaxis(np.asarray(d, np.float64), -1, 0), metric, exponent)
    return _result(value if bound else _voronoi_unbound(value, metric, exponent))


def _cell_keys(cell, reach):
    """For each axis, the first PCG step of cell + o (floats, as the cell's neighbours are
    computed) for o in -reach..reach: {o: (N,) uint32}."""
    return [{o: np.fmod(cell[:, a] + o, 4294967296.0).astype(np.int64).astype(np.uint32) * _PCG_A + _PCG_C
             for o in range(-reach, reach + 1)} for a in range(3)]


# A Voronoi octave's neighbour cells in Cycles' order (x fastest), as (B, 3, 1) offsets.
_NEIGHBOURS = {reach: np.array([[[i], [j], [k]] for k in range(-reach, reach + 1) for j in range(-reach, reach + 1)
                                for i in range(-reach, reach + 1)], np.float64) for reach in (1, 2)}
_VORONOI_BLOCK = 1 << 15  # neighbours x points computed at once


def _voronoi_neighbours(cell, local, reach, metric, exponent, randomness, bound):
    """The neighbour cells of the points in blocks (all 3^3 or 5^3 at once for few points, one
    at a time for many): yields (first neighbour's index, (B, 6, N) colours and points (relative
    to the cell), (B, N) distances (or their bounds)), local being (3, N)."""
    n = len(cell)
    keys = _cell_keys(cell, reach)
    offsets = _NEIGHBOURS[reach]
    size = max(1, min(len(offsets), _VORONOI_BLOCK // max(n, 1)))
    for first in range(0, len(offsets), size):
        block = offsets[first:first + size]
        words = (np.stack([keys[a][int(o[a, 0])] for o in block]) for a in range(3))  # (B, N) each
        cells = np.empty((len(block), 6, n))
        cells[:, :3] = _hash_color(*_pcg3d(*words), axis=1)
        np.add(block, cells[:, :3] * randomness, out=cells[:, 3:])
        d = _voronoi_bound(np.moveaxis(cells[:, 3:] - local, 1, 0), metric, exponent)
        yield first, cells, (d if bound else _voronoi_unbound(d, metric, exponent))


def _voronoi_octave(coord, feature, metric, exponent, randomness, smoothness):
    """One octave of Cycles' 3D voronoi_f1 / voronoi_f2 / voronoi_smooth_f1 at coord ((N, 3)):
    (distance (N,), colour (N, 3), position (N, 3)). randomness and smoothness are (N,) (or
    broadcast to it), exponent a float or (N,); smoothness > 0 for SMOOTH_F1."""
    n = len(coord)
    cell = np.floor(coord)
    local = (coord - cell).T  # the neighbours' arrays are components first
    randomness = np.broadcast_to(np.asarray(randomness, np.float64), (n,))
    if feature == "SMOOTH_F1":  # blended over the 5^3 neighbours in order
        smoothness = np.broadcast_to(np.asarray(smoothness, np.float64), (n,))
        distance, blend = np.zeros(n), np.zeros((6, n))  # blend: colour, position
        for first, cells, ds in _voronoi_neighbours(cell, local, 2, metric, exponent, randomness, False):
            for b, d in enumerate(ds):
                if first + b == 0:
                    h = np.ones(n)
                else:
                    t = np.minimum(np.maximum(0.5 + 0.5 * (distance - d) / smoothness, 0.0), 1.0)
                    h = (3.0 - 2.0 * t) * t * t
                correction = smoothness * h * (1.0 - h)
                distance = distance * (1 - h) + d * h - correction
                correction = correction / (1.0 + 3.0 * smoothness)
                blend = blend * (1 - h) + cells[b] * h - correction
        return distance, blend[:3].T, cell + blend[3:].T
    # F1, F2: the closest two of the 3^3 neighbours (by the bound for F1, by the distance for
    # F2) as Cycles' loop keeps them: a strictly closer one replaces, so of equals the first
    # stays (the first two of a stable sort).
    second = feature == "F2"
    ar = np.arange(n)
    best, which = [np.full(n, np.inf), np.full(n, np.inf)], [np.zeros(n, np.int64), np.zeros(n, np.int64)]
    for first, _, ds in _voronoi_neighbours(cell, local, 1, metric, exponent, randomness, not second):
        if len(ds) == 1:
            c0, j0, c1, j1 = ds[0], first, np.inf, first
        else:  # the block's closest two
            i0 = np.argmin(ds, axis=0)
            c0, j0 = ds[i0, ar], first + i0
            if second:
                rest = ds.copy()
                rest[i0, ar] = np.inf
                i1 = np.argmin(rest, axis=0)
                c1, j1 = rest[i1, ar], first + i1
        closer = c0 < best[0]
        if second:  # the kept pair's first, then the block's; or the block's first, then the kept pair's
            kept, ahead = best[1] <= c0, best[0] <= c1
            best[1], which[1] = (np.where(closer, np.where(ahead, best[0], c1), np.where(kept, best[1], c0)),
                                 np.where(closer, np.where(ahead, which[0], j1), np.where(kept, which[1], j0)))
        best[0], which[0] = np.where(closer, c0, best[0]), np.where(closer, j0, which[0])
    d, m = (best[1], which[1]) if second else (_voronoi_unbound(best[0], metric, exponent), which[0])
    # The chosen neighbour's hash again (the same bits as in the loop).
    offset = _NEIGHBOURS[1][m, :, 0]
    cell_color = hash_cell(cell + offset)
    return d, cell_color, offset + cell_color * randomness[:, None] + cell


_VORONOI_CHUNK = 1 << 15  # points at a time (the temporaries stay in cache)


def voronoi_reference(p, scale, detail, roughness, lacunarity, smoothness, exponent, randomness, feature,
                      metric, normalize):
    """Cycles' 3D Voronoi Texture (svm_node_tex_voronoi, fractal_voronoi_x_fx) at point p
    ((..., 3)): (distance (...), colour (..., 3), position (..., 3)). The float parameters are
    floats or arrays broadcastable to the points (a detail per point too)."""
    p = np.asarray(p, np.float64)[..., :3]
    exponent = np.asarray(exponent, np.float64)
    params = [np.asarray(x, np.float64) for x in (scale, detail, roughness, lacunarity, smoothness, randomness)]
    shape = np.broadcast_shapes(p.shape[:-1], exponent.shape, *(x.shape for x in params))
    count = math.prod(shape)
    p = np.broadcast_to(p, shape + (3,)).reshape(-1, 3)
    params = [np.broadcast_to(x, shape).reshape(-1) for x in params]
    if exponent.ndim:
        exponent = np.broadcast_to(exponent, shape).reshape(-1)
    distance, color, position = np.empty(count), np.empty((count, 3)), np.empty((count, 3))
    with np.errstate(all="ignore"):
        for start in range(0, count, _VORONOI_CHUNK):
            part = slice(start, start + _VORONOI_CHUNK)
            distance[part], color[part], position[part] = _voronoi_points(
                p[part], *(x[part] for x in params), exponent[part] if exponent.ndim else exponent, feature, metric,
                normalize)
    return _result(distance.reshape(shape)), color.reshape(shape + (3,)), position.reshape(shape + (3,))


def _voronoi_points(p, scale, detail, roughness, lacunarity, smoothness, randomness, exponent, feature, metric,
                    normalize):
    """voronoi_reference at (N, 3) points, its parameters (N,) (exponent a float or (N,))."""
    clamp = lambda x, low, high: np.minimum(np.maximum(x, low), high)
    detail, roughness, randomness = clamp(detail, 0.0, 15.0), clamp(roughness, 0.0, 1.0), clamp(randomness, 0.0, 1.0)
    smoothness = clamp(smoothness / 2.0, 0.0, 0.5)
    take = lambda x, at: x if np.ndim(x) == 0 else x[at]

    def octave(coord, at):
        """The octave at coord of the points ``at`` (an index array): Smooth F1 falls back to F1
        where its smoothness is 0."""
        if feature != "SMOOTH_F1":
            return _voronoi_octave(coord, feature, metric, take(exponent, at), randomness[at], None)
        smooth = smoothness[at] != 0.0
        if smooth.all():
            return _voronoi_octave(coord, feature, metric, take(exponent, at), randomness[at], smoothness[at])
        d, c, q = np.empty(len(at)), np.empty((len(at), 3)), np.empty((len(at), 3))
        for mask, kind in ((smooth, "SMOOTH_F1"), (~smooth, "F1")):
            if mask.any():
                sub = at[mask]
                d[mask], c[mask], q[mask] = _voronoi_octave(coord[mask], kind, metric, take(exponent, sub),
                                                            randomness[sub], smoothness[sub])
        return d, c, q

    coord = p * scale[:, None]
    n = len(p)
    single = (detail == 0.0) | (roughness == 0.0)  # one octave, taken as it is
    octaves = np.where(single, 1, np.ceil(detail).astype(np.int64) + 1)
    amplitude, max_amplitude, octave_scale = np.ones(n), np.zeros(n), np.ones(n)
    distance, color, position = np.zeros(n), np.zeros((n, 3)), np.zeros((n, 3))
    for i in range(int(octaves.max(initial=0))):
        at = np.flatnonzero(octaves > i)
        sc, amp = octave_scale[at], amplitude[at]
        d, c, q = octave(coord[at] * sc[:, None], at)
        if i == 0 and single.any():
            s = single[at]
            max_amplitude[at[s]], distance[at[s]], color[at[s]], position[at[s]] = 1.0, d[s], c[s], q[s]
            keep = ~s
            at, sc, amp, d, c, q = at[keep], sc[keep], amp[keep], d[keep], c[keep], q[keep]
        full = i <= detail[at]
        r = detail[at] - np.floor(detail[at])  # the last, partial octave's weight
        w = np.where(full, amp, amp * r)
        max_amplitude[at] = max_amplitude[at] + w
        distance[at] = distance[at] + np.where(full, d * amp, d * amp * r)
        color[at] = color[at] + np.where(full[:, None], c * amp[:, None], c * amp[:, None] * r[:, None])
        pos = position[at]
        step = pos * (1 - amp[:, None]) + q / sc[:, None] * amp[:, None]
        position[at] = np.where(full[:, None], step, pos * (1 - r[:, None]) + step * r[:, None])
        octave_scale[at] = np.where(full, sc * lacunarity[at], sc)
        amplitude[at] = np.where(full, amp * roughness[at], amp)
    if normalize:
        max_distance = _voronoi_distance(np.repeat((0.5 + 0.5 * randomness)[:, None], 3, 1), metric, exponent)
        distance = distance / (max_amplitude * max_distance * (2.0 if feature == "F2" else 1.0))
        color = color / max_amplitude[:, None]
    position = np.where((scale != 0.0)[:, None], position / _where_nonzero(scale)[:, None], 0.0)
    return distance, color, position


def wave_reference(p, wave_type, direction, profile, distortion, detail, detail_scale, detail_roughness, phase):
    """Cycles' svm_wave at point p ((..., 3), already scaled); the float parameters floats or
    arrays broadcastable to the points."""
    p = (np.asarray(p, np.float64)[..., :3] + 0.000001) * 0.999999
    distortion, detail, detail_scale, detail_roughness, phase = (
        np.asarray(x, np.float64) for x in (distortion, detail, detail_scale, detail_roughness, phase))
    axis = {"X": 0, "Y": 1, "Z": 2}.get(direction)
    if wave_type == "BANDS":
        n = p[..., axis] * 20.0 if axis is not None else ((p[..., 0] + p[..., 1]) + p[..., 2]) * 10.0
    else:
        rp = p.copy()
        if axis is not None:
            rp[..., axis] = 0.0
        n = np.sqrt(_dot3(rp, rp)) * 20.0
    shape = np.broadcast_shapes(n.shape, *(x.shape for x in (distortion, detail, detail_scale, detail_roughness,
                                                              phase)))
    n = np.array(np.broadcast_to(n + phase, shape))
    distorted = np.broadcast_to(distortion != 0.0, shape)
    if distorted.any():
        points = np.broadcast_to(p, shape + (3,))[distorted]
        take = lambda x: np.broadcast_to(x, shape)[distorted]
        noise = noise_reference(points * take(detail_scale)[:, None], take(detail), take(detail_roughness), 2.0, True)
        n[distorted] = n[distorted] + take(distortion) * (noise * 2.0 - 1.0)
    if profile == "SIN":
        return _result(0.5 + 0.5 * np.sin(n - math.pi / 2))
    n = n / (2 * math.pi)
    return _result(n - np.floor(n) if profile == "SAW" else np.abs(n - np.floor(n + 0.5)) * 2.0)


def brick_noise(n):
    """Cycles' brick_noise: integer noise of a uint (a brick's row and number); of an int or an
    integer array."""
    shape = np.shape(n)
    n = _u32(n).reshape(-1)
    n = (n + np.uint32(1013)) & np.uint32(0x7FFFFFFF)
    n = (n >> np.uint32(13)) ^ n
    nn = (n * (n * n * np.uint32(60493) + np.uint32(19990303)) + np.uint32(1376312589)) & np.uint32(0x7FFFFFFF)
    return _result((0.5 * nn.astype(np.float32).astype(np.float64) / 1073741824.0).reshape(shape))


def _color3(value):
    """A colour input as (..., 3): a float (grey), a colour of 3 or 4, or colours (..., 3|4)."""
    value = np.asarray(value, np.float64)
    return _vec4(value)[:3] if value.ndim <= 1 else value[..., :3]


def brick_reference(p, color1, color2, mortar_color, mortar_size, mortar_smooth, bias, brick_width, row_height,
                    offset_amount, offset_frequency, squash_amount, squash_frequency):
    """Cycles' svm_brick and svm_node_tex_brick at point p ((..., 3), already scaled): (colour
    (..., 3), fac (...)). Colours and floats may vary over the points; the frequencies are ints."""
    p = np.asarray(p, np.float64)
    mortar_size, mortar_smooth, bias, brick_width, row_height, offset_amount, squash_amount = (
        np.asarray(x, np.float64) for x in (mortar_size, mortar_smooth, bias, brick_width, row_height,
                                            offset_amount, squash_amount))
    with np.errstate(all="ignore"):
        rownum = np.floor(p[..., 1] / row_height)
        offset = 0.0
        if offset_frequency and squash_frequency:
            brick_width = brick_width * np.where(np.fmod(rownum, squash_frequency) != 0, 1.0, squash_amount)
            offset = np.where(np.fmod(rownum, offset_frequency) != 0, 0.0, brick_width * offset_amount)
        bricknum = np.floor((p[..., 0] + offset) / brick_width)
        x, y = (p[..., 0] + offset) - brick_width * bricknum, p[..., 1] - row_height * rownum
        words = lambda v: np.asarray(np.fmod(v, 4294967296.0), np.int64)
        key = ((words(rownum) << 16) + (words(bricknum) & 0xFFFF)) & 0xFFFFFFFF
        tint = np.minimum(np.maximum(brick_noise(key) + bias, 0.0), 1.0)
        min_dist = np.minimum(np.minimum(np.minimum(x, y), brick_width - x), row_height - y)
        f = (1.0 - min_dist / mortar_size) / _where_nonzero(mortar_smooth)
        smooth = np.where(f <= 0.0, 0.0, np.where(f >= 1.0, 1.0, 3.0 * f * f - 2.0 * f * f * f))
        fac = np.where(min_dist >= mortar_size, 0.0, np.where(mortar_smooth == 0.0, 1.0, smooth))
    fac = np.broadcast_to(fac, np.broadcast_shapes(fac.shape, tint.shape))
    tint = np.broadcast_to(tint, fac.shape)[..., None]
    color = (1.0 - tint) * _color3(color1) + tint * _color3(color2)
    return color * (1.0 - fac[..., None]) + _color3(mortar_color) * fac[..., None], _result(fac)


def _vec4(value):
    v = np.zeros(4, np.float64)
    flat = np.atleast_1d(np.asarray(value, np.float64)).ravel()[:4]
    v[:len(flat)] = flat
    if len(flat) == 1:
        v[:3] = flat[0]  # a float into a colour: grey, as Blender converts it
    return v


def instructions(words):
    """(op, dst, a, b, its words) of each instruction of a finished program, NODE_END excluded."""
    starts = [pc for pc, _ in _instruction_starts(words)] + [None]
    for pc, end in zip(starts, starts[1:]):
        word = words[pc]
        end = end if end is not None else len(words) - 1
        yield word & 0xFF, (word >> 8) & 0xFF, (word >> 16) & 0xFF, word >> 24, tuple(words[pc + 1:end])


# The register fields each operation reads: (word after the instruction, 0 for the
# instruction itself; bit shift), a byte each (NODE_COMBINE's third: the whole word).
_READS = {NODE_TEXTURE: [(0, 16)], NODE_AFFINE: [(0, 16)], NODE_MATH: [(0, 16), (0, 24), (1, 16)],
          NODE_MIX: [(0, 16), (0, 24), (1, 8)], NODE_INVERT: [(0, 16), (0, 24)],
          NODE_MAP_RANGE: [(0, 16), (1, 0), (1, 8), (1, 16), (1, 24), (2, 16)], NODE_RAMP: [(0, 16)],
          NODE_SEPARATE: [(0, 16)], NODE_COMBINE: [(0, 16), (0, 24), (1, 0)], NODE_STORE: [(0, 16)],
          NODE_CONVERT: [(0, 16)], NODE_NOISE: [(0, 16), (1, 0), (1, 8), (1, 16)],
          NODE_VORONOI: [(0, 16), (0, 24), (1, 0), (1, 8), (1, 16), (1, 24), (2, 0), (2, 8)],
          NODE_WAVE: [(0, 16), (0, 24), (1, 0), (1, 8), (1, 16), (1, 24), (2, 0)],
          NODE_BRICK: [(0, 16), (0, 24), (1, 0), (1, 8), (1, 16), (1, 24), (2, 0), (2, 8), (2, 16), (2, 24)],
          NODE_BUMP: [(0, 16), (0, 24), (1, 0), (1, 8), (1, 16), (1, 24)], NODE_FRESNEL: [(0, 16), (0, 24)],
          NODE_NORMAL_MAP: [(0, 16), (0, 24)],
          NODE_VECTOR_MATH: [(0, 16), (0, 24), (1, 8), (1, 16)], NODE_CURVES: [(0, 16), (0, 24)],
          NODE_HSV: [(0, 16), (0, 24), (1, 0), (1, 8), (1, 16)]}

# Words after the instruction, where more than one.
_SIZES = {NODE_CONST: 4, NODE_AFFINE: 12, NODE_MAP_RANGE: 2, NODE_VORONOI: 2, NODE_WAVE: 2, NODE_BRICK: 5, NODE_BUMP: 2}


def allocate_registers(words):
    """``words`` (a finished program over up to 256 virtual registers, each written once) with
    NODE_REGISTERS machine registers: a register is reused once its value is read for the last
    time (the program is straight-line code). Raises ProgramTooLong if more are live at once."""
    steps = [(pc, op) for pc, op in _instruction_starts(words)]
    field = lambda pc, off, shift: (words[pc + off] >> shift) & 0xFF
    last_read = {}
    for k, (pc, op) in enumerate(steps):
        for off, shift in _READS.get(op, []):
            last_read[field(pc, off, shift)] = k
    out, free, machine = list(words), list(range(NODE_REGISTERS)), {}
    for k, (pc, op) in enumerate(steps):
        released = set()
        for off, shift in _READS.get(op, []):
            virtual = field(pc, off, shift)
            out[pc + off] = out[pc + off] & ~(0xFF << shift) | machine[virtual] << shift
            if last_read[virtual] == k and virtual not in released:
                released.add(virtual)
                heapq.heappush(free, machine[virtual])
        if op != NODE_STORE:  # writes dst (after reading: an operand's register may take it)
            virtual = field(pc, 0, 8)
            if not free:
                raise ProgramTooLong(f"the node graph needs more than {NODE_REGISTERS} registers at once")
            machine[virtual] = heapq.heappop(free)  # the lowest free one
            out[pc] = out[pc] & ~(0xFF << 8) | machine[virtual] << 8
            if virtual not in last_read:  # never read: free again
                heapq.heappush(free, machine[virtual])
    return out


def _instruction_starts(words):
    pc = 0
    while words[pc] & 0xFF != NODE_END:
        op = words[pc] & 0xFF
        yield pc, op
        size = _SIZES.get(op, 1)
        if op == NODE_RAMP:
            size = 1 + 4 * (words[pc + 1] & 0xFFFF)
        if op == NODE_CURVES:  # the word, min x, max x, the table
            size = 3 + (words[pc + 1] >> 24) * (words[pc + 1] & 0xFFFF)
        pc += 1 + size


class Register(int):
    """A register of a Program (an operand that is not a constant)."""


class ProgramTooLong(ValueError):
    """The graph needs more registers than NODE_REGISTERS at once (or 256 values)."""


class Program:
    """One material's node program. Operands: a Register or a constant (floats)."""

    def __init__(self):
        self.words = []
        self._next = 0
        self._constants = {}  # a constant's register: each is loaded once

    @staticmethod
    def is_constant(value):
        return not isinstance(value, Register)

    def _register(self):  # a virtual register, each written once (finish() allocates machine ones)
        if self._next >= 256:
            raise ProgramTooLong("the node graph computes more than 256 values")
        self._next += 1
        return Register(self._next - 1)

    def _in(self, value):
        """A register holding ``value`` (a constant is loaded into one)."""
        if not self.is_constant(value):
            return value
        words = tuple(_f32(x) for x in _vec4(value))
        if words not in self._constants:
            r = self._register()
            self.words += [NODE_CONST | r << 8, *words]
            self._constants[words] = r
        return self._constants[words]

    def _op(self, op, a=0, b=0, extra=(0,)):
        r = self._register()
        self.words += [op | r << 8 | a << 16 | b << 24, *extra]
        return r

    @staticmethod
    def _place(kind, bump_offset):
        """A coordinate operation's word: kind | offset << 8 | filter width (half) << 16, where
        ``bump_offset`` is (0, 0.0) at the hit or (1 or 2, filter width): one of the points
        Cycles' Bump evaluates its height at (nodes.glsl bump_step)."""
        offset, width = bump_offset
        return kind | offset << 8 | int(np.float16(width).view(np.uint16)) << 16

    def uv(self, bump_offset=(0, 0.0)):
        return self._op(NODE_UV, extra=[self._place(0, bump_offset)])

    def generated(self, bump_offset=(0, 0.0)):
        """Blender's Generated texture coordinates (the mesh's texture space as 0..1)."""
        return self._op(NODE_GENERATED, extra=[self._place(0, bump_offset)])

    def geometry(self, kind, bump_offset=(0, 0.0)):
        """The hit's GEOMETRY_KINDS ``kind`` (normals and the incoming direction face the
        viewer, as Cycles' N, Ng and I)."""
        return self._op(NODE_GEOMETRY, extra=[self._place(GEOMETRY_KINDS.index(kind), bump_offset)])

    def attribute(self, slot, bump_offset=(0, 0.0)):
        """The mesh's attribute ``slot`` (SceneData Mesh.attributes) at the hit, interpolated
        over the triangle: (rgb or xyz, alpha), 0 where the mesh lacks it."""
        return self._op(NODE_ATTRIBUTE, extra=[self._place(slot, bump_offset)])

    def bump(self, strength, distance, heights, normal, invert, width):
        """Cycles' Bump: ``normal`` tilted by the gradient of the height, given at the hit and
        at bump offsets 1 and 2 of filter width ``width`` (``heights``)."""
        if all(self.is_constant(h) for h in heights) and len({float(_vec4(h)[0]) for h in heights}) == 1:
            return normal  # a flat height: no tilt
        strength, distance, normal = self._in(strength), self._in(distance), self._in(normal)
        h = [self._in(x) for x in heights]
        flags = int(bool(invert)) | int(np.float16(width).view(np.uint16)) << 16
        return self._op(NODE_BUMP, strength, distance, [h[0] | h[1] << 8 | h[2] << 16 | normal << 24, flags])

    def normal_map(self, color, strength, space):
        """Cycles' Normal Map of ``color`` in NORMAL_MAP_SPACES ``space`` (tangent space: the
        mesh's tangents)."""
        return self._op(NODE_NORMAL_MAP, self._in(color), self._in(strength), [NORMAL_MAP_SPACES.index(space)])

    def fresnel(self, kind, value, normal):
        """Cycles' Fresnel (kind "fresnel", value: IOR) or Layer Weight ("layer_fresnel",
        "layer_facing"; value: Blend) at ``normal``."""
        kinds = ("fresnel", "layer_fresnel", "layer_facing")
        return self._op(NODE_FRESNEL, self._in(value), self._in(normal), [kinds.index(kind)])

    def noise(self, vector, detail, roughness, lacunarity, normalize):
        """Cycles' 3D fBm noise at ``vector`` (already scaled)."""
        args = (detail, roughness, lacunarity)
        if self.is_constant(vector) and all(self.is_constant(x) for x in args):
            return noise_reference(_vec4(vector)[:3], *(_vec4(x)[0] for x in args), normalize)
        vector, detail, roughness, lacunarity = (self._in(x) for x in (vector, *args))
        return self._op(NODE_NOISE, vector, 0, [detail | roughness << 8 | lacunarity << 16 | int(bool(normalize)) << 24])

    def voronoi(self, vector, scale, detail, roughness, lacunarity, smoothness, exponent, randomness,
                feature, metric, normalize, output):
        """Cycles' 3D Voronoi Texture at ``vector`` (scaled here): its ``output``
        (VORONOI_OUTPUTS; Distance as a float, Color and Position as vectors)."""
        args = (scale, detail, roughness, lacunarity, smoothness, exponent, randomness)
        if self.is_constant(vector) and all(self.is_constant(x) for x in args):
            out = voronoi_reference(_vec4(vector)[:3], *(_vec4(x)[0] for x in args), feature, metric, normalize)
            return out[VORONOI_OUTPUTS.index(output)]
        vector, scale, detail, roughness, lacunarity, smoothness, exponent, randomness = (
            self._in(x) for x in (vector, *args))
        modes = (VORONOI_FEATURES.index(feature) | VORONOI_METRICS.index(metric) << 2 | int(bool(normalize)) << 4 |
                 VORONOI_OUTPUTS.index(output) << 5)
        return self._op(NODE_VORONOI, vector, scale, [detail | roughness << 8 | lacunarity << 16 | smoothness << 24,
                                                      exponent | randomness << 8 | modes << 16])

    def wave(self, vector, scale, wave_type, direction, profile, distortion, detail, detail_scale,
             detail_roughness, phase):
        """Cycles' Wave Texture at ``vector`` (scaled here): its Fac (a float)."""
        args = (scale, distortion, detail, detail_scale, detail_roughness, phase)
        directions = WAVE_BANDS_DIRECTIONS if wave_type == "BANDS" else WAVE_RINGS_DIRECTIONS
        if self.is_constant(vector) and all(self.is_constant(x) for x in args):
            scale, *rest = (_vec4(x)[0] for x in args)
            return wave_reference(_vec4(vector)[:3] * scale, wave_type, direction, profile, *rest)
        vector, scale, distortion, detail, detail_scale, detail_roughness, phase = (self._in(x) for x in (vector, *args))
        modes = WAVE_TYPES.index(wave_type) | directions.index(direction) << 1 | WAVE_PROFILES.index(profile) << 3
        return self._op(NODE_WAVE, vector, scale, [distortion | detail << 8 | detail_scale << 16 | detail_roughness << 24,
                                                   phase | modes << 8])

    def brick(self, vector, scale, color1, color2, mortar, mortar_size, mortar_smooth, bias, brick_width,
              row_height, offset_amount, offset_frequency, squash_amount, squash_frequency, output):
        """Cycles' Brick Texture at ``vector`` (scaled here): its Color or Fac. The offset and
        squash settings are the node's own (constants)."""
        if not (0 <= offset_frequency <= 255 and 0 <= squash_frequency <= 255):
            raise ValueError("brick frequencies are 0..255")
        floats = (scale, mortar_size, mortar_smooth, bias, brick_width, row_height)
        if all(self.is_constant(x) for x in (vector, color1, color2, mortar, *floats)):
            scale, *rest = (_vec4(x)[0] for x in floats)
            color, fac = brick_reference(_vec4(vector)[:3] * scale, color1, color2, mortar, *rest, offset_amount,
                                         offset_frequency, squash_amount, squash_frequency)
            return fac if output == "Fac" else color
        vector, scale, color1, color2, mortar, mortar_size, mortar_smooth, bias, brick_width, row_height = (
            self._in(x) for x in (vector, scale, color1, color2, mortar, *floats[1:]))
        return self._op(NODE_BRICK, vector, scale, [
            color1 | color2 << 8 | mortar << 16 | mortar_size << 24, mortar_smooth | bias << 8 | brick_width << 16 |
            row_height << 24, _f32(offset_amount), _f32(squash_amount),
            int(offset_frequency) | int(squash_frequency) << 8 | int(output == "Fac") << 16])

    def to_float(self, value, kind):
        """A colour (its luminance, Rec. 709) or a vector (its mean) as a float, as Blender
        converts sockets."""
        if self.is_constant(value):
            v = _vec4(value)
            return float(v[:3] @ (0.2126, 0.7152, 0.0722)) if kind == "color" else float(v[:3].mean())
        return self._op(NODE_CONVERT, value, 0, [0 if kind == "color" else 1])

    def to_color(self, value):
        """A float as grey (x, x, x)."""
        if self.is_constant(value):
            return np.full(4, _vec4(value)[0])
        return self._op(NODE_CONVERT, value, 0, [2])

    def texture(self, vector, texture):
        return self._op(NODE_TEXTURE, self._in(vector), 0, [int(texture)])

    def affine(self, vector, matrix):
        """matrix (3, 4) applied to the point vector.xyz."""
        m = np.asarray(matrix, np.float64).reshape(3, 4)
        if self.is_constant(vector):
            return m @ np.append(_vec4(vector)[:3], 1.0)
        return self._op(NODE_AFFINE, vector, 0, [_f32(x) for x in m.ravel()])

    def math(self, op, a, b=0.0, c=0.0):
        if all(self.is_constant(x) for x in (a, b, c)):
            return math_reference(op, _vec4(a)[0], _vec4(b)[0], _vec4(c)[0])
        a = self._in(a)
        b = self._in(b) if op in _BINARY_MATH else a  # an operand the operation ignores: any register
        c = self._in(c) if op in _TERNARY_MATH else a
        return self._op(NODE_MATH, a, b, [MATH_OPS.index(op) | c << 16])

    def mix(self, mode, fac, a, b, clamp_result=False):
        """Blend ``b`` over ``a`` by ``fac`` (clamp it first where Blender does)."""
        if all(self.is_constant(x) for x in (fac, a, b)):
            out = blend_reference(mode, _vec4(fac)[0], _vec4(a), _vec4(b))
            return np.clip(out, 0.0, 1.0) if clamp_result else out
        fac, a, b = self._in(fac), self._in(a), self._in(b)
        return self._op(NODE_MIX, a, b, [BLEND_MODES.index(mode) | fac << 8 | int(bool(clamp_result)) << 16])

    def invert(self, fac, color):
        if self.is_constant(fac) and self.is_constant(color):
            c = _vec4(color)[:3]
            return (1.0 - _vec4(fac)[0]) * c + _vec4(fac)[0] * (1.0 - c)
        color, fac = self._in(color), self._in(fac)
        return self._op(NODE_INVERT, color, fac)

    def map_range(self, value, from_min, from_max, to_min, to_max, clamp, interpolation="LINEAR", steps=4.0,
                  vector=False):
        """Map Range (map_range_reference); ``vector``: one component of Cycles' vector Map Range."""
        args = (value, from_min, from_max, to_min, to_max, steps)
        if all(self.is_constant(x) for x in args):
            return map_range_reference(*(_vec4(x)[0] for x in args[:5]), clamp, interpolation, _vec4(steps)[0], vector)
        value, fmin, fmax, tmin, tmax = (self._in(x) for x in args[:5])
        steps = self._in(steps) if interpolation == "STEPPED" else value  # unread otherwise: any register
        kind = MAP_RANGE_TYPES.index(interpolation)
        clamp = clamp and not (vector and kind >= 2)  # the vector node's smooth types never clamp
        return self._op(NODE_MAP_RANGE, value, 0, [fmin | fmax << 8 | tmin << 16 | tmax << 24,
                                                   int(bool(clamp)) | kind << 8 | steps << 16 | int(bool(vector)) << 24])

    def ramp(self, fac, table, interpolate):
        table = np.asarray(table, np.float64).reshape(-1, 4)
        if self.is_constant(fac):
            return ramp_reference(table, _vec4(fac)[0], interpolate)
        return self._op(NODE_RAMP, fac, 0, [len(table) | int(bool(interpolate)) << 16] +
                        [_f32(x) for x in table.ravel()])

    def vector_math(self, op, a, b=(0.0, 0.0, 0.0), c=(0.0, 0.0, 0.0), scale=1.0):
        """Vector Math (vector_math_reference): a vector, or for VECTOR_MATH_FLOAT_OPS a float
        (the register's x)."""
        if all(self.is_constant(x) for x in (a, b, c, scale)):
            return vector_math_reference(op, _vec4(a)[:3], _vec4(b)[:3], _vec4(c)[:3], _vec4(scale)[0])
        used = VECTOR_MATH_OPERANDS[op]
        a = self._in(a)
        b, c, scale = (self._in(x) if k in used else a for x, k in ((b, "b"), (c, "c"), (scale, "s")))
        return self._op(NODE_VECTOR_MATH, a, b, [VECTOR_MATH_OPS.index(op) | c << 8 | scale << 16])

    def curves(self, tables, min_x, max_x, extrapolate, fac, value):
        """RGB Curves (tables: rows of R, G, B) or Float Curve (one column): curves_reference."""
        tables = np.asarray(tables, np.float64)
        tables = tables.reshape(len(tables), -1)
        if self.is_constant(fac) and self.is_constant(value):
            return curves_reference(tables, min_x, max_x, extrapolate, _vec4(fac)[0], value)
        if self.is_constant(fac) and _vec4(fac)[0] == 0.0:  # the input as it is (Cycles drops the node)
            return value
        value, fac = self._in(value), self._in(fac)
        return self._op(NODE_CURVES, value, fac, [len(tables) | int(bool(extrapolate)) << 16 | tables.shape[1] << 24,
                                                  _f32(min_x), _f32(max_x)] + [_f32(x) for x in tables.ravel()])

    def hsv(self, color, hue, saturation, value, fac):
        """Hue/Saturation/Value (hsv_reference)."""
        args = (color, hue, saturation, value, fac)
        if all(self.is_constant(x) for x in args):
            return hsv_reference(_vec4(color), *(_vec4(x)[0] for x in args[1:]))
        color, hue, saturation, value, fac = (self._in(x) for x in args)
        return self._op(NODE_HSV, color, fac, [hue | saturation << 8 | value << 16])

    def separate(self, value, component):
        if self.is_constant(value):
            return _vec4(value)[component]
        return self._op(NODE_SEPARATE, value, 0, [int(component)])

    def combine(self, x, y, z):
        if all(self.is_constant(v) for v in (x, y, z)):
            return np.array([_vec4(x)[0], _vec4(y)[0], _vec4(z)[0], 1.0])
        x, y, z = self._in(x), self._in(y), self._in(z)
        return self._op(NODE_COMBINE, x, y, [z])

    def store(self, field, register):
        """Sets a Material field (FIELDS) at the hit from a register (the host sets constant
        fields itself)."""
        if self.is_constant(register):
            raise ValueError("store takes a register; set a constant field on the Material")
        self.words += [NODE_STORE | register << 16, FIELDS.index(field)]

    def fork(self):
        """A copy to add one material's stores to (the computations are shared)."""
        other = Program()
        other.words, other._next, other._constants = list(self.words), self._next, dict(self._constants)
        return other

    def finish(self):
        """The words, NODE_END included, over machine registers."""
        return allocate_registers(self.words + [NODE_END])
