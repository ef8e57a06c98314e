"""Node graphs evaluated on the host at many points at once, for what the device does not
shade per hit: the world's background (baked into an environment map) and a light's
emission graph.

``FieldProgram`` has ``nodes.Program``'s builder interface, so the add-on's GraphCompiler
drives either. Where a Program records an instruction for the device, a FieldProgram
computes the operation at every point at once with the same numpy references that define
the device's operations (``nodes.*_reference``). A value that varies over the points is a
``Field``: (N, 4) lanes, a float in the first, as the machine's registers hold them; one that
does not is folded as a Program folds it.
"""
from __future__ import annotations

import functools

import numpy as np

from . import nodes


class NotOnHost(ValueError):
    """An operation the host does not evaluate over points (its message names it)."""


class Field:
    """A value at each of N points: ``lanes`` (N, 4) float64."""

    __slots__ = ("lanes",)

    def __init__(self, lanes):
        self.lanes = lanes


def _field(values, kind):
    """A Field of (N,) floats (kind "float") or (N, 3|4) vectors."""
    values = np.asarray(values, np.float64)
    lanes = np.zeros(values.shape[:1] + (4,))
    if kind == "float":
        lanes[:, 0] = values
    else:
        lanes[:, :values.shape[1]] = values
    return Field(lanes)


class HostImage:
    """An image the host samples: linear float (H, W, C) pixels, row 0 at the top, or 8-bit
    sRGB values (0..1, decoded after interpolation, as the device's textures are)."""

    def __init__(self, pixels, srgb=False, interpolation="linear"):
        self.pixels = np.asarray(pixels)  # float32 stays float32: an 8K HDRI is 400 MB already
        self.srgb = srgb
        self.interpolation = interpolation

    def sample(self, u, v, wrap_v=True):
        """Cycles' image lookup at (u, v) (v = 0 at the bottom row): bilinear over texel centres
        (or the closest texel), repeating in u, and in v when ``wrap_v`` (else clamped)."""
        h, w = self.pixels.shape[:2]
        x, y = u * w - 0.5, (1.0 - v) * h - 0.5  # row 0 at the top
        if self.interpolation == "closest":
            x, y = np.floor(x + 0.5), np.floor(y + 0.5)
        x0, y0 = np.floor(x), np.floor(y)
        fx, fy = (x - x0)[:, None], (y - y0)[:, None]
        cols = np.mod(np.stack([x0, x0 + 1]).astype(np.int64), w)
        rows = np.stack([y0, y0 + 1]).astype(np.int64)
        rows = np.mod(rows, h) if wrap_v else np.clip(rows, 0, h - 1)
        p = self.pixels
        out = ((1 - fy) * ((1 - fx) * p[rows[0], cols[0]] + fx * p[rows[0], cols[1]]) +
               fy * ((1 - fx) * p[rows[1], cols[0]] + fx * p[rows[1], cols[1]]))
        return np.where(out <= 0.04045, out / 12.92, ((out + 0.055) / 1.055) ** 2.4) if self.srgb else out


def equirectangular_uv(directions):
    """Blender's direction_to_equirectangular: u = -atan2(y, x) / 2 pi + 0.5,
    v = atan2(z, hypot(x, y)) / pi + 0.5."""
    d = np.asarray(directions, np.float64)
    return (-np.arctan2(d[:, 1], d[:, 0]) / (2 * np.pi) + 0.5,
            np.arctan2(d[:, 2], np.hypot(d[:, 0], d[:, 1])) / np.pi + 0.5)


@functools.lru_cache(maxsize=4)
def sky_model(params):
    """The sky.Sky of ``params`` (its tables are computed once per setting)."""
    from . import sky

    return sky.Sky(params)


def mirror_ball_uv(directions):
    """Blender's direction_to_mirrorball: the point of a mirror ball seen along -Y that
    reflects ``directions`` (the ball's image spans u, v in 0..1 over x, z)."""
    d = np.asarray(directions, np.float64)
    d = d / np.maximum(np.linalg.norm(d, axis=1, keepdims=True), 1e-30)
    d[:, 1] -= 1.0
    div = 2.0 * np.sqrt(np.maximum(-0.5 * d[:, 1], 0.0))
    d /= np.where(div > 0.0, div, 1.0)[:, None]
    return 0.5 * (d[:, 0] + 1.0), 0.5 * (d[:, 2] + 1.0)


class FieldProgram(nodes.Program):
    """A Program evaluated at N points. ``coordinates`` maps the coordinate sources a graph
    may read ("uv", "generated" and nodes.GEOMETRY_KINDS) to (N, 3) arrays; a source it lacks
    raises NotOnHost (a light's graph, for one, has no points to vary over)."""

    def __init__(self, count, coordinates):
        super().__init__()
        self.count = count
        self.coordinates = coordinates
        self.skies = []  # (node name, SkyParams) of each Sky Texture evaluated

    @staticmethod
    def is_constant(value):
        return not isinstance(value, (nodes.Register, Field))

    @staticmethod
    def _varies(*values):
        return any(isinstance(v, Field) for v in values)

    def _float(self, value):
        return value.lanes[:, 0] if isinstance(value, Field) else float(nodes._vec4(value)[0])

    def _lanes(self, value):
        return value.lanes if isinstance(value, Field) else np.broadcast_to(nodes._vec4(value), (self.count, 4))

    def _vector(self, value):
        return self._lanes(value)[:, :3]

    def _coordinate(self, kind):
        if kind not in self.coordinates:
            raise NotOnHost(f"its {kind.replace('_', ' ')} coordinates")
        return _field(self.coordinates[kind], "vector")

    def evaluate(self, value, kind):
        """(N, 4) lanes of a value (a constant broadcast); kind "float" gives (N,)."""
        lanes = self._lanes(value)
        return lanes[:, 0] if kind == "float" else lanes

    # -- coordinates --

    def uv(self, bump_offset=(0, 0.0)):
        return self._coordinate("uv")

    def generated(self, bump_offset=(0, 0.0)):
        return self._coordinate("generated")

    def geometry(self, kind, bump_offset=(0, 0.0)):
        if kind == "backfacing" and "backfacing" not in self.coordinates:
            return 0.0
        return self._coordinate(kind)

    def attribute(self, slot, bump_offset=(0, 0.0)):
        raise NotOnHost("mesh attributes")

    def bump(self, strength, distance, heights, normal, invert, width):
        if self._varies(strength, distance, normal, *heights):
            raise NotOnHost("a bumped normal")
        return super().bump(strength, distance, heights, normal, invert, width)

    def normal_map(self, color, strength, space):
        raise NotOnHost("a normal map")

    def fresnel(self, kind, value, normal):
        raise NotOnHost("a surface's Fresnel")

    # -- textures --

    def noise(self, vector, detail, roughness, lacunarity, normalize):
        if not self._varies(vector, detail, roughness, lacunarity):
            return super().noise(vector, detail, roughness, lacunarity, normalize)
        value = nodes.noise_reference(self._vector(vector), *(self._float(x) for x in (detail, roughness, lacunarity)),
                                      normalize)
        return _field(np.broadcast_to(value, (self.count,)), "float")

    def voronoi(self, vector, scale, detail, roughness, lacunarity, smoothness, exponent, randomness, feature,
                metric, normalize, output):
        args = (scale, detail, roughness, lacunarity, smoothness, exponent, randomness)
        if not self._varies(vector, *args):
            return super().voronoi(vector, *args, feature, metric, normalize, output)
        k = nodes.VORONOI_OUTPUTS.index(output)
        value = nodes.voronoi_reference(self._vector(vector), *(self._float(x) for x in args), feature, metric,
                                        normalize)[k]
        return _field(np.broadcast_to(value, (self.count,) if k == 0 else (self.count, 3)),
                      ("float", "color", "vector")[k])

    def wave(self, vector, scale, wave_type, direction, profile, distortion, detail, detail_scale, detail_roughness,
             phase):
        floats = (distortion, detail, detail_scale, detail_roughness, phase)
        if not self._varies(vector, scale, *floats):
            return super().wave(vector, scale, wave_type, direction, profile, *floats)
        point = self._vector(vector) * np.asarray(self._float(scale))[..., None]
        value = nodes.wave_reference(point, wave_type, direction, profile, *(self._float(x) for x in floats))
        return _field(np.broadcast_to(value, (self.count,)), "float")

    def brick(self, vector, scale, color1, color2, mortar, mortar_size, mortar_smooth, bias, brick_width, row_height,
              offset_amount, offset_frequency, squash_amount, squash_frequency, output):
        colors, floats = (color1, color2, mortar), (mortar_size, mortar_smooth, bias, brick_width, row_height)
        frequencies = (offset_amount, offset_frequency, squash_amount, squash_frequency)
        if not self._varies(vector, scale, *colors, *floats):
            return super().brick(vector, scale, *colors, *floats, *frequencies, output)
        if not (0 <= offset_frequency <= 255 and 0 <= squash_frequency <= 255):
            raise ValueError("brick frequencies are 0..255")
        point = self._vector(vector) * np.asarray(self._float(scale))[..., None]
        color, fac = nodes.brick_reference(point, *(self._vector(c) for c in colors), *(self._float(x) for x in floats),
                                           *frequencies)
        if output == "Fac":
            return _field(np.broadcast_to(fac, (self.count,)), "float")
        return _field(np.broadcast_to(color, (self.count, 3)), "color")

    def texture(self, vector, texture):
        """An Image Texture (a HostImage, flat and repeating) at vector.xy."""
        v = self._vector(vector)
        return _field(texture.sample(v[:, 0], v[:, 1]), "color")

    def environment(self, vector, image, projection="EQUIRECTANGULAR"):
        """Cycles' Environment Texture in direction ``vector``: equirectangular or mirror ball."""
        mapping = equirectangular_uv if projection == "EQUIRECTANGULAR" else mirror_ball_uv
        u, v = mapping(self._vector(vector))
        return _field(image.sample(u, v, wrap_v=False), "color")

    def sky(self, vector, params, name=""):
        """Sky Texture ``name`` (parallax_core.sky.SkyParams) in direction ``vector``, its sun
        disc left out (listed in ``skies``: the world's export makes it a sun light)."""
        self.skies.append((name, params))
        return _field(sky_model(params).radiance(self._vector(vector)), "color")

    def blackbody(self, temperature):
        """Blender's Blackbody at each point's temperature."""
        return _field(nodes.blackbody_reference(np.broadcast_to(self._float(temperature), (self.count,))), "color")

    # -- maths --

    def to_float(self, value, kind):
        if not self._varies(value):
            return super().to_float(value, kind)
        v = value.lanes[:, :3]
        return _field(v @ (0.2126, 0.7152, 0.0722) if kind == "color" else v.mean(axis=1), "float")

    def to_color(self, value):
        if not self._varies(value):
            return super().to_color(value)
        return Field(np.repeat(value.lanes[:, :1], 4, axis=1))

    def affine(self, vector, matrix):
        if not self._varies(vector):
            return super().affine(vector, matrix)
        m = np.asarray(matrix, np.float64).reshape(3, 4)
        return _field(self._vector(vector) @ m[:, :3].T + m[:, 3], "vector")

    def math(self, op, a, b=0.0, c=0.0):
        if not self._varies(a, b, c):
            return super().math(op, a, b, c)
        value = nodes.math_reference(op, *(self._float(x) for x in (a, b, c)))
        return _field(np.broadcast_to(value, (self.count,)), "float")

    def mix(self, mode, fac, a, b, clamp_result=False):
        if not self._varies(fac, a, b):
            return super().mix(mode, fac, a, b, clamp_result)
        out = nodes.blend_reference(mode, self._float(fac), self._lanes(a), self._lanes(b))
        return _field(np.clip(out, 0.0, 1.0) if clamp_result else np.broadcast_to(out, (self.count, 3)), "color")

    def invert(self, fac, color):
        if not self._varies(fac, color):
            return super().invert(fac, color)
        f, c = np.asarray(self._float(fac))[..., None], self._vector(color)
        return _field((1.0 - f) * c + f * (1.0 - c), "color")

    def map_range(self, value, from_min, from_max, to_min, to_max, clamp, interpolation="LINEAR", steps=4.0,
                  vector=False):
        args = (value, from_min, from_max, to_min, to_max, steps)
        if not self._varies(*args):
            return super().map_range(*args[:5], clamp, interpolation, steps, vector)
        out = nodes.map_range_reference(*(self._float(x) for x in args[:5]), clamp, interpolation,
                                        self._float(steps), vector)
        return _field(np.broadcast_to(out, (self.count,)), "float")

    def ramp(self, fac, table, interpolate):
        if not self._varies(fac):
            return super().ramp(fac, table, interpolate)
        return Field(nodes.ramp_reference(np.asarray(table, np.float64).reshape(-1, 4), self._float(fac), interpolate))

    def vector_math(self, op, a, b=(0.0, 0.0, 0.0), c=(0.0, 0.0, 0.0), scale=1.0):
        if not self._varies(a, b, c, scale):
            return super().vector_math(op, a, b, c, scale)
        out = nodes.vector_math_reference(op, self._vector(a), self._vector(b), self._vector(c), self._float(scale))
        kind = "float" if op in nodes.VECTOR_MATH_FLOAT_OPS else "vector"
        return _field(out, kind)

    def curves(self, tables, min_x, max_x, extrapolate, fac, value):
        if not self._varies(fac, value):
            return super().curves(tables, min_x, max_x, extrapolate, fac, value)
        single = np.asarray(tables).reshape(len(tables), -1).shape[1] == 1
        x = self._lanes(value)[:, 0] if single else self._vector(value)
        out = nodes.curves_reference(tables, min_x, max_x, extrapolate, self._float(fac), x)
        return _field(np.broadcast_to(out, (self.count,) if single else (self.count, 3)), "float" if single else "color")

    def hsv(self, color, hue, saturation, value, fac):
        if not self._varies(color, hue, saturation, value, fac):
            return super().hsv(color, hue, saturation, value, fac)
        out = nodes.hsv_reference(self._vector(color), *(self._float(x) for x in (hue, saturation, value, fac)))
        return _field(out, "color")

    def separate(self, value, component):
        if not self._varies(value):
            return super().separate(value, component)
        return _field(value.lanes[:, component], "float")

    def combine(self, x, y, z):
        if not self._varies(x, y, z):
            return super().combine(x, y, z)
        out = np.stack([np.broadcast_to(self._float(v), (self.count,)) for v in (x, y, z)] + [np.ones(self.count)], 1)
        return Field(out)

    def store(self, field, register):
        raise NotOnHost("a material field")
