"""SceneData: the scene as numpy arrays and small dataclasses, in Cycles/Blender conventions.

Blender's world is Z-up and right-handed; cameras look down their local -Z with +Y up;
lights point along their local -Z. Units (light power, strength, roughness with
alpha = roughness^2, IOR) are Cycles'. ``SceneData.flatten()`` turns a scene into the flat
arrays the native core consumes; ``save``/``load`` store those arrays in one ``.npz``.
"""
from __future__ import annotations

import json
import math
import zipfile
import zlib
from dataclasses import dataclass, field

import numpy as np

__all__ = [
    "Mesh", "Instance", "Material", "Texture", "Light", "World", "Camera", "SceneData",
    "FLAT_KEYS", "PARTS", "PART_KEYS", "MATERIAL_TYPES", "LIGHT_TYPES", "MIX_CHAIN_MAX", "TEXTURE_INTERPOLATIONS",
    "direction_to_equirectangular", "equirectangular_to_direction",
]

MATERIAL_TYPES = {"diffuse": 0, "conductor": 1, "dielectric": 2, "emission": 3, "principled": 4}
LIGHT_TYPES = {"point": 1, "spot": 2, "sun": 3, "area": 4}
AREA_SHAPES = {"square": 4, "rectangle": 4, "disk": 5, "ellipse": 5}
CAMERA_TYPES = {"perspective": 0, "orthographic": 1, "panorama": 2}
# Camera.panorama_type (Blender's Camera.panorama_type) -> px PANORAMA_* (types.h).
PANORAMA_TYPES = {"EQUIRECTANGULAR": 0, "EQUIANGULAR_CUBEMAP_FACE": 1, "MIRRORBALL": 2,
                  "FISHEYE_EQUIDISTANT": 3, "FISHEYE_EQUISOLID": 4, "FISHEYE_LENS_POLYNOMIAL": 5,
                  "CENTRAL_CYLINDRICAL": 6}
# Texture.interpolation -> its texture_flags bit (Blender's Image Texture node: Linear, Closest).
TEXTURE_INTERPOLATIONS = {"linear": 0, "closest": 1}
# texture_flags bits (px TEXTURE_FLAG_* in shaders/shared/types.h).
TEXTURE_FLAG_CLOSEST = 1  # the nearest texel, no filtering
TEXTURE_FLAG_HALF = 2     # texels in texture_half_texels (linear), else texture_texels (sRGB bytes)
HALF_MAX = 65504.0        # largest finite half float: float texels are clamped to [0, HALF_MAX]

# Every key flatten() produces, with its dtype and shape (V vertices, T triangles, M meshes,
# I instances, K materials, N texels, X textures, L lights).
FLAT_KEYS = {
    "positions": (np.float32, "(V,3)"),
    "indices": (np.uint32, "(T,3)"),
    "triangle_material": (np.uint32, "(T,)"),
    "corner_normals": (np.float32, "(T,3,3) or (0,3,3)"),
    "corner_uvs": (np.float32, "(T,3,2) or (0,3,2)"),
    "corner_tangents": (np.float32, "(T,3,4) or (0,3,4)"),  # object-space tangent, bitangent sign
    "corner_attributes": (np.float32, "(S*T,3,4)"),  # S slots of T triangles' corner values (node programs)
    "mesh_first_triangle": (np.uint32, "(M,)"),
    "mesh_triangle_count": (np.uint32, "(M,)"),
    "mesh_has_normals": (np.uint32, "(M,)"),
    "mesh_has_uvs": (np.uint32, "(M,)"),
    "mesh_has_tangents": (np.uint32, "(M,)"),
    "mesh_attribute_mask": (np.uint32, "(M,)"),  # bit s: the mesh holds attribute slot s
    "mesh_texspace": (np.float32, "(M,6)"),        # Generated coordinates' space: location, half size
    "instance_transform": (np.float32, "(I,3,4)"),
    "instance_mesh": (np.uint32, "(I,)"),
    "material_type": (np.uint32, "(K,)"),
    "material_base_color": (np.float32, "(K,3)"),
    "material_roughness": (np.float32, "(K,)"),
    "material_ior": (np.float32, "(K,)"),
    "material_emission": (np.float32, "(K,3)"),
    "material_texture": (np.int32, "(K,)"),
    "material_mix_next": (np.int32, "(K,)"),
    "material_mix_weight": (np.float32, "(K,)"),
    "material_multiscatter": (np.uint32, "(K,)"),
    "material_principled": (np.float32, "(K,17)"),  # PRINCIPLED_FIELDS, in that order
    "material_node_program": (np.int32, "(K,)"),     # first word of its node program, -1: none
    "material_node_programs": (np.uint32, "(P,)"),   # the programs' words (parallax_core.nodes)
    "texture_texels": (np.uint8, "(N,4)"),
    "texture_info": (np.uint32, "(X,3)"),           # first texel, width, height
    "texture_flags": (np.uint32, "(X,)"),           # TEXTURE_FLAG_* bits
    "texture_half_texels": (np.uint16, "(N2,4)"),   # float textures: linear RGBA, IEEE half bits
    "light_type": (np.uint32, "(L,)"),
    "light_position": (np.float32, "(L,3)"),
    "light_direction": (np.float32, "(L,3)"),
    "light_axis_u": (np.float32, "(L,3)"),
    "light_axis_v": (np.float32, "(L,3)"),
    "light_radius": (np.float32, "(L,)"),
    "light_color": (np.float32, "(L,3)"),
    "light_spot_size": (np.float32, "(L,)"),
    "light_spot_blend": (np.float32, "(L,)"),
    "light_sun_angle": (np.float32, "(L,)"),
    "light_camera_visible": (np.uint32, "(L,)"),
    "light_soft_falloff": (np.uint32, "(L,)"),
    "world_color": (np.float32, "(3,)"),
    "world_map": (np.float32, "(H,W,3) or (0,0,3)"),
    "camera_to_world": (np.float32, "(3,4)"),
    "camera_type": (np.uint32, "(1,)"),
    "camera_window": (np.float32, "(4,)"),
    "camera_clip": (np.float32, "(2,)"),
    "camera_aperture": (np.float32, "(5,)"),        # radius, focus distance, blades, rotation, ratio
    "camera_panorama_type": (np.uint32, "(1,)"),
    "camera_panorama_range": (np.float32, "(4,)"),  # Camera.panorama_range
    "camera_fisheye": (np.float32, "(9,)"),         # fov, lens, sensor width, height, k0..k4
}

# The parts of a scene that an update can replace on its own (Session.update(parts=...)),
# and the flat keys of each: every FLAT_KEYS key is in exactly one part. "lights" covers the
# analytic lights and the world: both live in the native light table.
PARTS = ("geometry", "instances", "materials", "lights", "camera")


def _part_of_key(key):
    for prefixes, part in ((("instance_",), "instances"), (("material_", "texture_"), "materials"),
                           (("light_", "world_"), "lights"), (("camera_",), "camera")):
        if key.startswith(prefixes):
            return part
    return "geometry"  # positions, indices, triangle_material, corner_*, mesh_*


PART_KEYS = {part: tuple(k for k in FLAT_KEYS if _part_of_key(k) == part) for part in PARTS}


def parts_set(parts):
    """``parts`` (None, one part name or an iterable of them) as a frozenset of PARTS names
    (None: all). Raises ValueError for an unknown or empty selection."""
    if parts is None:
        return frozenset(PARTS)
    names = [parts] if isinstance(parts, str) else list(parts)
    unknown = [p for p in names if p not in PARTS]
    if unknown:
        raise ValueError(f"unknown scene part(s) {unknown} (parts: {', '.join(PARTS)})")
    if not names:
        raise ValueError("no scene parts given (parts=None means the whole scene)")
    return frozenset(names)


# Keys added after version 1 files were written, with the value a missing key stands for.
# Keys newer than some saved files, with their defaults (and the array they follow in length).
_OPTIONAL_KEY_DEFAULTS = {"material_mix_next": -1, "material_mix_weight": 1.0, "material_multiscatter": 0,
                          "material_principled": 0.0,
                          "material_node_program": -1, "material_node_programs": 0,
                          "light_camera_visible": 1, "light_soft_falloff": 0,
                          "texture_flags": 0, "texture_half_texels": 0}

# Principled material inputs (Blender's Principled BSDF), their sizes, and the clamps Cycles
# applies (low, high; None: open): the columns of material_principled in this order.
PRINCIPLED_FIELDS = (
    ("specular_tint", 3, 0.0, None), ("metallic", 1, 0.0, 1.0),
    ("coat_tint", 3, 0.0, None), ("coat_weight", 1, 0.0, None),
    ("sheen_tint", 3, 0.0, None), ("sheen_weight", 1, 0.0, None),
    ("transmission", 1, 0.0, 1.0), ("specular_ior_level", 1, 0.0, None),
    ("coat_roughness", 1, 0.0, 1.0), ("coat_ior", 1, 1.0, None), ("sheen_roughness", 1, 0.0, 1.0),
)

# Most materials one mix chain may hold, head included (MIX_CHAIN_MAX in shared/types.h).
MIX_CHAIN_MAX = 16
# Attribute slots a scene may hold (types.h NODE_ATTRIBUTE_SLOTS): Mesh.attributes' keys.
ATTRIBUTE_SLOTS = 8

_META_KEY = "__meta__"

# The IOR range the core accepts (px::SceneLimits, parallax_core.LIMITS; a test checks that
# they agree): outside it is an error in both, never a clamp in one.
IOR_RANGE = (1e-3, 1e3)


# ---- helpers ------------------------------------------------------------------------------

def _vec(v, n=3):
    return np.asarray(v, dtype=np.float64).reshape(n)


def _finite(*values):
    return all(np.all(np.isfinite(np.asarray(v, dtype=np.float64))) for v in values)


_F32_MAX = float(np.finfo(np.float32).max)


def _floats(value, what, shape=None):
    """``value`` as a float64 array; ValueError naming ``what`` if it is not numbers (of
    ``shape``, when given)."""
    try:
        if value is None:  # numpy would read it as NaN
            raise TypeError
        v = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError):
        raise ValueError(f"{what} must be numbers, got {value!r}") from None
    if shape is not None and v.shape != shape:
        raise ValueError(f"{what} has shape {v.shape}, expected {shape}")
    return v


def _index(value, what):
    """``value`` as an int; ValueError naming ``what`` if it is not an integer."""
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, (int, np.integer)):
        raise ValueError(f"{what} must be an integer index, got {value!r}")
    return int(value)


def _check_f32(value, what):
    """ValueError naming ``what`` if the finite float64 ``value`` overflows float32 (the core's
    type): a product such as colour x power can, although each factor fits."""
    peak = float(np.max(np.abs(value), initial=0.0))
    if peak > _F32_MAX:
        raise ValueError(f"{what} = {peak:g} does not fit in float32 (at most {_F32_MAX:.3g})")


def _normalized(v):
    """Unit vector in float64; leaves vectors already unit to float32 precision untouched,
    so flatten(from_flat(flatten(s))) reproduces the same bits."""
    v = np.asarray(v, dtype=np.float64).reshape(3)
    n = float(np.linalg.norm(v))
    if n == 0.0:
        return None
    return v if abs(n - 1.0) <= 1e-6 else v / n


def _basis(n):
    """Orthonormal u, v with u x v = n (Duff et al. 2017)."""
    sign = math.copysign(1.0, n[2])
    a = -1.0 / (sign + n[2])
    b = n[0] * n[1] * a
    u = np.array([1.0 + sign * n[0] * n[0] * a, sign * b, -sign * n[0]])
    v = np.array([b, sign + n[1] * n[1] * a, -n[1]])
    return u, v


def _transform_3x4(m):
    """(3,4) float64 from a (3,4) or (4,4) affine matrix; None if the shape is wrong."""
    m = np.asarray(m, dtype=np.float64)
    if m.shape == (4, 4):
        return m[:3].copy()
    if m.shape == (3, 4):
        return m.copy()
    return None


def _label(kind, index, name):
    return f"{kind} '{name}' ({kind} {index})" if name else f"{kind} {index}"


def direction_to_equirectangular(d):
    """Blender's ``direction_to_equirectangular``: world directions (...,3) -> (u, v) in [0,1].

    u = -atan2(y, x) / (2 pi) + 0.5,  v = atan2(z, hypot(x, y)) / pi + 0.5.
    In a World map, v = 1 is row 0 (the top, +Z); u = 0 is column 0.
    """
    d = np.asarray(d, dtype=np.float64)
    u = -np.arctan2(d[..., 1], d[..., 0]) / (2.0 * np.pi) + 0.5
    v = np.arctan2(d[..., 2], np.hypot(d[..., 0], d[..., 1])) / np.pi + 0.5
    return u, v


def equirectangular_to_direction(u, v):
    """Inverse of ``direction_to_equirectangular``: unit directions (...,3)."""
    phi = np.pi * (1.0 - 2.0 * np.asarray(u, dtype=np.float64))
    theta = np.pi * (1.0 - np.asarray(v, dtype=np.float64))  # from +Z
    phi, theta = np.broadcast_arrays(phi, theta)
    s = np.sin(theta)
    return np.stack([s * np.cos(phi), s * np.sin(phi), np.cos(theta)], axis=-1)


# ---- scene parts --------------------------------------------------------------------------

@dataclass
class Mesh:
    """Triangle mesh. ``normals``/``uvs`` are per corner; ``material_indices`` are global
    indices into ``SceneData.materials`` (default 0)."""
    positions: np.ndarray                  # (V,3) float
    indices: np.ndarray                    # (T,3) int
    normals: np.ndarray | None = None      # (T,3,3)
    uvs: np.ndarray | None = None          # (T,3,2), Blender UVs (v = 0 at the bottom)
    # (T,3,4): the UVs' tangent (object space, MikkTSpace as Blender computes it) and the
    # bitangent's sign per corner, for tangent-space Normal Maps.
    tangents: np.ndarray | None = None
    # Attribute slots (at most ATTRIBUTE_SLOTS) -> (T,3,4) corner values: colour attributes,
    # other UV maps, generic attributes, as the node programs' NODE_ATTRIBUTE reads them (a slot
    # a mesh lacks reads 0, as Cycles' Attribute node where the attribute is missing).
    attributes: dict = field(default_factory=dict)
    material_indices: np.ndarray | None = None  # (T,) int
    name: str = ""
    texspace: tuple | None = None          # Generated coordinates' space: location, half size (None: the bounds)


@dataclass
class Instance:
    """One placement of ``meshes[mesh]``; ``transform`` is object-to-world, (3,4) or (4,4)."""
    mesh: int
    transform: np.ndarray = field(default_factory=lambda: np.eye(4))


@dataclass
class Material:
    """Cycles-like material. Emitted radiance = emission * emission_strength; any type may emit.

    type: "diffuse" (Lambert), "conductor" (GGX, colour = reflectance), "dielectric" (glass),
    "emission" (emits only). roughness is clamped to [0,1] (alpha = roughness^2).

    Mixes (Blender's Mix Shader, Principled BSDF blends) are chains of materials:
    ``mix_next`` is the global index of another material and ``mix_weight`` (clamped to
    [0,1]) the probability of using THIS material's BSDF at a hit; with probability
    1 - mix_weight the hit continues to ``materials[mix_next]``, which may chain further. The
    surface's BSDF is f = w0 f0 + (1-w0) (w1 f1 + (1-w1) (...)). Emission comes from the
    HEAD material only (the one the triangle references): materials reached through the
    chain contribute only their BSDF, so put a mix's combined emission on its head. Chains
    must be acyclic and hold at most MIX_CHAIN_MAX materials; ``mix_next=None`` (no mix)
    ignores ``mix_weight``.

    multiscatter (conductor, dielectric, principled): Cycles' Multiscatter GGX, the
    single-scatter lobe scaled to conserve the energy lost to masking (Kulla & Conty 2017, as
    Cycles does it).

    "principled": Cycles' Principled BSDF v2 (shaders/lib/principled.glsl): base_color,
    roughness, ior and the fields from ``metallic`` on are the node's inputs of those names
    (transmission = Transmission Weight, coat_* = Coat *, sheen_* = Sheen *), clamped as
    Cycles clamps them; other types ignore them.

    node_program: the words of a node program (parallax_core.nodes.Program.finish()) that sets
    the fields a node graph drives at each hit; empty: none.
    """
    type: str = "diffuse"
    base_color: tuple = (0.8, 0.8, 0.8)
    roughness: float = 0.5
    ior: float = 1.45
    emission: tuple = (0.0, 0.0, 0.0)
    emission_strength: float = 1.0
    base_color_texture: int | None = None
    name: str = ""
    mix_next: int | None = None
    mix_weight: float = 1.0
    multiscatter: bool = False
    metallic: float = 0.0
    transmission: float = 0.0
    specular_ior_level: float = 0.5
    specular_tint: tuple = (1.0, 1.0, 1.0)
    coat_weight: float = 0.0
    coat_roughness: float = 0.03
    coat_ior: float = 1.5
    coat_tint: tuple = (1.0, 1.0, 1.0)
    sheen_weight: float = 0.0
    sheen_roughness: float = 0.5
    sheen_tint: tuple = (1.0, 1.0, 1.0)
    node_program: tuple = ()


@dataclass
class Texture:
    """An image, (H,W,3|4) or (H,W) grey; row 0 is the top of the image. ``pixels`` uint8:
    sRGB-encoded bytes, interpolated before decoding (as Cycles does 8-bit sRGB images); any
    float dtype: linear values (Cycles' float images: EXR, HDR, non-colour data), kept as half
    floats (clamped to 0..65504; values above 1 stay) and interpolated linearly.
    ``interpolation``: "linear" (bilinear) or "closest" (the nearest texel), as the Image
    Texture node's Linear and Closest."""
    pixels: np.ndarray
    name: str = ""
    interpolation: str = "linear"


@dataclass
class Light:
    """Blender light. power: W for point/spot/area, W/m^2 ("strength") for sun.

    direction: where the light points (the light object's local -Z). radius: point/spot
    soft size. spot_size: full cone angle. angle: sun angular diameter. Area lights have
    ``shape`` and ``size`` (and ``size_y`` for rectangle/ellipse) along ``axis_u``/``axis_v``
    (the light's local X and Y, unit); if those are None a basis with u x v = -direction is
    derived. camera_visible: whether camera rays see the light itself (Blender's Camera ray
    visibility; it lights the scene either way). soft_falloff (point/spot with a radius):
    Cycles' Soft Falloff, Blender's default, where the light is a disk of ``radius`` facing
    each shading point (irradiance ~ 1/(d^2 + r^2) near it); off: a true sphere.
    """
    type: str = "point"
    color: tuple = (1.0, 1.0, 1.0)
    power: float = 10.0
    position: tuple = (0.0, 0.0, 0.0)
    direction: tuple = (0.0, 0.0, -1.0)
    radius: float = 0.0
    spot_size: float = math.pi / 4
    spot_blend: float = 0.15
    angle: float = 0.0
    shape: str = "square"
    size: float = 1.0
    size_y: float = 1.0
    axis_u: tuple | None = None
    axis_v: tuple | None = None
    camera_visible: bool = True
    soft_falloff: bool = False
    name: str = ""


@dataclass
class World:
    """Background: ``color * strength``, or ``map * strength`` when a map is given.

    ``map`` is a linear float (H,W,3) equirectangular image with Blender's Environment
    Texture mapping (``direction_to_equirectangular``): u = -atan2(y,x)/(2 pi) + 0.5,
    v = atan2(z, hypot(x,y))/pi + 0.5, pixel (row, col) covers u = (col + 0.5)/W and
    v = 1 - (row + 0.5)/H. So row 0 is the top (+Z, zenith), the image centre looks along +X
    and u = 0.25 along +Y.
    """
    color: tuple = (0.05, 0.05, 0.05)
    strength: float = 1.0
    map: np.ndarray | None = None


@dataclass
class Camera:
    """Camera looking down its local -Z with +Y up (Blender).

    window = (left, right, bottom, top) of the image plane at distance 1 (perspective), in
    world units (orthographic), or of the panorama's (u, v) square (panorama: (0, 1, 0, 1) is
    the whole image, as Cycles maps it). Default: 50 mm lens on a 36 mm sensor, square image.
    Pixel (x, y) of a W x H image (row 0 at the top) has camera-space point
    sx = left + (x + 0.5) / W * (right - left), sy = top - (y + 0.5) / H * (top - bottom):
    perspective rays go from the origin along (sx, sy, -1); orthographic ones start at
    (sx, sy, 0) and go along (0, 0, -1); panoramas look along panorama_type's projection of
    (u, v) = (sx, sy).

    Depth of field (Cycles' thin lens): aperture_radius in world units (0: a pinhole), focused
    on the plane at focus_distance (along the view direction for panoramas); aperture_blades
    below 3 make a round aperture, else a polygon turned by aperture_rotation (radians);
    aperture_ratio squeezes it horizontally (anamorphic bokeh).

    Panoramas (Blender's and Cycles' definitions): panorama_range = (longitude min, max,
    latitude min, max) in radians for EQUIRECTANGULAR; (angle min, max, height min / radius,
    max / radius) for CENTRAL_CYLINDRICAL. Fisheyes: fisheye_fov (radians), fisheye_lens (mm),
    fisheye_sensor = (width, height) in mm as fitted to the image, and fisheye_polynomial =
    (k0..k4) for FISHEYE_LENS_POLYNOMIAL.
    """
    camera_to_world: np.ndarray = field(default_factory=lambda: np.eye(4)[:3].copy())
    type: str = "perspective"
    window: tuple = (-0.36, 0.36, -0.36, 0.36)
    clip_start: float = 0.1
    clip_end: float = 1000.0
    aperture_radius: float = 0.0
    focus_distance: float = 10.0
    aperture_blades: int = 0
    aperture_rotation: float = 0.0
    aperture_ratio: float = 1.0
    panorama_type: str = "EQUIRECTANGULAR"
    panorama_range: tuple = (-math.pi, math.pi, -math.pi / 2, math.pi / 2)
    fisheye_fov: float = math.pi
    fisheye_lens: float = 10.5
    fisheye_sensor: tuple = (36.0, 24.0)
    fisheye_polynomial: tuple = (0.0, 0.0, 0.0, 0.0, 0.0)

    @classmethod
    def from_blender(cls, matrix_world, width, height, type="PERSP", lens=50.0,
                     sensor_width=36.0, sensor_height=24.0, sensor_fit="AUTO",
                     ortho_scale=7.0, shift_x=0.0, shift_y=0.0, clip_start=0.1,
                     clip_end=1000.0, pixel_aspect=1.0, panorama_type="EQUIRECTANGULAR", **lens_settings):
        """Blender camera data -> Camera (``BKE_camera_params_compute_viewplane``; panoramas as
        Cycles' Blender sync maps them).

        AUTO fits sensor_width to the larger of width*pixel_aspect and height; HORIZONTAL
        fits sensor_width to the width; VERTICAL fits sensor_height to the height. Shift is
        in units of the fitted dimension (of the image square for panoramas). pixel_aspect =
        pixel_aspect_x / pixel_aspect_y. Scale in matrix_world is removed (as Cycles does).
        ``lens_settings``: the Camera fields of depth of field and of the panorama
        (aperture_radius, focus_distance, ..., panorama_range, fisheye_fov, fisheye_lens,
        fisheye_polynomial); fisheye_sensor is fitted here.
        """
        kind = {"PERSP": "perspective", "ORTHO": "orthographic", "PANO": "panorama"}.get(str(type).upper())
        if kind is None:
            raise ValueError(f"camera: unsupported Blender camera type '{type}'")
        fit = str(sensor_fit).upper()
        if fit not in ("AUTO", "HORIZONTAL", "VERTICAL"):
            raise ValueError(f"camera: unknown sensor_fit '{sensor_fit}'")
        unknown = set(lens_settings) - {"aperture_radius", "focus_distance", "aperture_blades", "aperture_rotation",
                                        "aperture_ratio", "panorama_range", "fisheye_fov", "fisheye_lens",
                                        "fisheye_polynomial"}
        if unknown:
            raise ValueError(f"camera: unknown settings {sorted(unknown)}")
        xratio, yratio = float(width) * float(pixel_aspect), float(height)
        if fit == "AUTO":
            fit = "HORIZONTAL" if xratio >= yratio else "VERTICAL"
            sensor = sensor_width
        else:
            sensor = sensor_width if fit == "HORIZONTAL" else sensor_height
        m = _transform_3x4(matrix_world)
        if m is None:
            raise ValueError("camera: matrix_world must be (4,4) or (3,4)")
        lengths = np.linalg.norm(m[:, :3], axis=0)
        m[:, :3] /= np.where(lengths > 0, lengths, 1.0)
        if kind == "panorama":
            # Cycles: the image is the (u, v) square, shifted; the fisheye sensor is fitted to the
            # image's aspect.
            fitted = (sensor, sensor * yratio / xratio) if fit == "HORIZONTAL" else (sensor * xratio / yratio, sensor)
            window = (shift_x, 1.0 + shift_x, shift_y, 1.0 + shift_y)
            return cls(m, kind, window, float(clip_start), float(clip_end), panorama_type=str(panorama_type).upper(),
                       fisheye_sensor=fitted, **lens_settings)
        # Extent of the fitted dimension: at distance 1 (perspective) or in world units.
        extent = ortho_scale if kind == "orthographic" else sensor / lens
        if fit == "HORIZONTAL":
            half_x, half_y = 0.5 * extent, 0.5 * extent * yratio / xratio
        else:
            half_x, half_y = 0.5 * extent * xratio / yratio, 0.5 * extent
        dx, dy = shift_x * extent, shift_y * extent
        return cls(m, kind, (dx - half_x, dx + half_x, dy - half_y, dy + half_y),
                   float(clip_start), float(clip_end), **lens_settings)

    @classmethod
    def look_at(cls, eye, target, up=(0.0, 0.0, 1.0), fov_y_degrees=40.0, width=1, height=1,
                clip_start=0.01, clip_end=1000.0):
        """Perspective camera at ``eye`` looking at ``target`` with vertical field of view."""
        eye, target, up = _vec(eye), _vec(target), _vec(up)
        forward = target - eye
        forward /= np.linalg.norm(forward)
        right = np.cross(forward, up)
        if np.linalg.norm(right) < 1e-9:  # looking along up: pick any perpendicular
            right = _basis(forward)[0]
        right /= np.linalg.norm(right)
        cam_up = np.cross(right, forward)
        m = np.column_stack([right, cam_up, -forward, eye])
        top = math.tan(math.radians(fov_y_degrees) / 2.0)
        half_x = top * width / height
        return cls(m, "perspective", (-half_x, half_x, -top, top), clip_start, clip_end)


@dataclass
class SceneData:
    """A whole scene. If ``instances`` is empty or None while meshes exist, every mesh gets
    one identity instance. If ``materials`` is empty, one default ``Material()`` is used.
    ``width``/``height`` are the intended resolution (None: unspecified)."""
    meshes: list = field(default_factory=list)
    instances: list | None = field(default_factory=list)
    materials: list = field(default_factory=list)
    textures: list = field(default_factory=list)
    lights: list = field(default_factory=list)
    world: World = field(default_factory=World)
    camera: Camera = field(default_factory=Camera)
    width: int | None = None
    height: int | None = None

    # -- derived lists --

    def effective_instances(self):
        if self.instances:
            return list(self.instances)
        return [Instance(i) for i in range(len(self.meshes))]

    def effective_materials(self):
        return list(self.materials) if self.materials else [Material()]

    # -- validation --

    def validate(self, parts=None):
        """Raise ValueError naming the first bad item; return a list of warning strings.
        ``parts`` (see PARTS; None: all) limits the checks to those parts of the scene."""
        return [w for ws in self._check(parts)[0].values() for w in ws]

    def _check(self, parts=None):
        """Checks the given parts (None: all). Returns (warnings by part, in PARTS order;
        per-mesh boolean masks of the triangles to keep (geometry); per-light keep flags
        (lights))."""
        parts = parts_set(parts)
        warnings = {p: [] for p in PARTS if p in parts}
        keeps, light_keep = [], []
        materials = self.effective_materials()
        K = len(materials)
        if "geometry" in parts:
            for i, mesh in enumerate(self.meshes):
                keep, n_bad = _check_mesh(mesh, i, K)
                keeps.append(keep)
                if n_bad:
                    warnings["geometry"].append(f"{_label('mesh', i, mesh.name)}: "
                                                f"{n_bad} degenerate triangles skipped")
        if "instances" in parts:
            warnings["instances"] += self._check_instances()
        if "materials" in parts:
            self._check_materials(materials)
        if "lights" in parts:
            for j, light in enumerate(self.lights):
                ok = _check_light(light, _label("light", j, light.name))
                if not ok:
                    warnings["lights"].append(f"{_label('light', j, light.name)}: "
                                              "zero-size area light skipped")
                light_keep.append(ok)
            self._check_world()
        if "camera" in parts:
            self._check_camera()
        return warnings, keeps, light_keep

    def _check_instances(self):
        warnings = []
        M = len(self.meshes)
        for i, inst in enumerate(self.effective_instances()):
            if not (0 <= _index(inst.mesh, f"instance {i}: mesh") < M):
                raise ValueError(f"instance {i}: mesh {inst.mesh} out of range ({M} meshes)")
            t = _floats(inst.transform, f"instance {i}: transform")
            if t.shape not in ((3, 4), (4, 4)):
                raise ValueError(f"instance {i}: transform has shape {t.shape}, "
                                 "expected (3,4) or (4,4)")
            if not _finite(t):
                raise ValueError(f"instance {i}: transform is NaN/Inf")
            if t.shape == (4, 4) and not np.allclose(t[3], (0, 0, 0, 1)):
                raise ValueError(f"instance {i}: transform is projective "
                                 f"(last row {t[3].tolist()})")
            _check_f32(t, f"instance {i}: transform")
            # Flat (the core skips it): |det| tiny next to the rows' lengths, as the core tests.
            if not abs(np.linalg.det(t[:3, :3])) > 1e-12 * np.prod(np.linalg.norm(t[:3, :3], axis=1)):
                warnings.append(f"instance {i}: transform is singular")
        return warnings

    def _check_materials(self, materials):
        K, X = len(materials), len(self.textures)
        for k, mat in enumerate(materials):
            lbl = _label("material", k, mat.name)
            if mat.type not in MATERIAL_TYPES:
                raise ValueError(f"{lbl}: unknown type '{mat.type}'")
            for attr in ("base_color", "roughness", "ior", "emission", "emission_strength"):
                v = _floats(getattr(mat, attr), f"{lbl}: {attr}")
                if v.shape != (() if attr in ("roughness", "ior", "emission_strength") else (3,)):
                    raise ValueError(f"{lbl}: {attr} has shape {v.shape}")
                if not _finite(v):
                    raise ValueError(f"{lbl}: {attr} is NaN/Inf")
                _check_f32(v, f"{lbl}: {attr}")
            for attr, size, _, _ in PRINCIPLED_FIELDS:
                v = _floats(getattr(mat, attr), f"{lbl}: {attr}")
                if v.shape != (() if size == 1 else (size,)):
                    raise ValueError(f"{lbl}: {attr} has shape {v.shape}")
                if not _finite(v):
                    raise ValueError(f"{lbl}: {attr} is NaN/Inf")
                _check_f32(v, f"{lbl}: {attr}")
            if not IOR_RANGE[0] <= float(mat.ior) <= IOR_RANGE[1]:
                raise ValueError(f"{lbl}: ior must be positive, in {IOR_RANGE[0]:g}.."
                                 f"{IOR_RANGE[1]:g} (got {float(mat.ior):g})")
            _check_f32(_vec(mat.emission) * float(mat.emission_strength),
                       f"{lbl}: emission x emission_strength")
            t = mat.base_color_texture
            if t is not None and not (0 <= _index(t, f"{lbl}: base_color_texture") < X):
                raise ValueError(f"{lbl}: base_color_texture {t} out of range ({X} textures)")
            if np.ndim(_floats(mat.mix_weight, f"{lbl}: mix_weight")) != 0 or not _finite(mat.mix_weight):
                raise ValueError(f"{lbl}: mix_weight is NaN/Inf or not a number")
            words = np.asarray(mat.node_program)
            if words.size and (words.ndim != 1 or words.dtype.kind not in "iu" or words.min() < 0 or words.max() >= 2**32):
                raise ValueError(f"{lbl}: node_program must be uint32 words (parallax_core.nodes.Program)")
            n = mat.mix_next
            if n is not None:
                if isinstance(n, (bool, np.bool_)) or not isinstance(n, (int, np.integer)):
                    raise ValueError(f"{lbl}: mix_next must be None or a material index, "
                                     f"got {n!r}")
                if not 0 <= int(n) < K:
                    raise ValueError(f"{lbl}: mix_next {n} out of range ({K} materials)")
        _check_mix_chains(materials)
        for x, tex in enumerate(self.textures):
            lbl = _label("texture", x, tex.name)
            _texture_rgba(tex.pixels, lbl)
            if not isinstance(tex.interpolation, str) or tex.interpolation not in TEXTURE_INTERPOLATIONS:
                raise ValueError(f"{lbl}: unknown interpolation {tex.interpolation!r} "
                                 f"(choose from {', '.join(TEXTURE_INTERPOLATIONS)})")

    def _check_world(self):
        w = self.world
        if not isinstance(w, World):
            raise ValueError(f"world: expected a World, got {w!r}")
        color, strength = _floats(w.color, "world: color"), _floats(w.strength, "world: strength")
        if not _finite(color, strength) or color.shape != (3,) or strength.shape != ():
            raise ValueError("world: color/strength must be finite, color 3 values")
        _check_f32(color * strength, "world: color x strength")
        if w.map is not None:
            m = _floats(w.map, "world map")
            if m.ndim != 3 or m.shape[2] not in (3, 4):
                raise ValueError(f"world map: shape {m.shape}, expected (H,W,3) or (H,W,4)")
            if m.shape[0] == 0 or m.shape[1] == 0:
                raise ValueError("world map: zero-size image")
            bad = ~np.isfinite(m[..., :3]).all(axis=2)
            if bad.any():
                r, c = np.argwhere(bad)[0]
                raise ValueError(f"world map: pixel (row {r}, column {c}) is NaN/Inf")
            _check_f32(m[..., :3] * strength, "world map: pixel x strength")

    def _check_camera(self):
        cam = self.camera
        if cam is None:
            raise ValueError("camera: scene has no camera")
        if cam.type not in CAMERA_TYPES:
            raise ValueError(f"camera: unknown type '{cam.type}'")
        m = _transform_3x4(_floats(cam.camera_to_world, "camera: camera_to_world"))
        if m is None or not _finite(m):
            raise ValueError("camera: camera_to_world must be a finite (3,4) or (4,4) matrix")
        _check_f32(m, "camera: camera_to_world")
        win = _floats(cam.window, "camera: window")
        if win.shape != (4,) or not _finite(win) or win[0] >= win[1] or win[2] >= win[3]:
            raise ValueError(f"camera: bad window {tuple(win.ravel().tolist())}, "
                             "expected left < right, bottom < top")
        _check_f32(win, "camera: window")
        clip = _floats((cam.clip_start, cam.clip_end), "camera: clip_start/clip_end", (2,))
        if not _finite(clip) or not 0 <= clip[0] < clip[1]:
            raise ValueError(f"camera: bad clip range ({cam.clip_start}, {cam.clip_end})")
        if cam.panorama_type not in PANORAMA_TYPES:
            raise ValueError(f"camera: unknown panorama_type {cam.panorama_type!r} "
                             f"(choose from {', '.join(PANORAMA_TYPES)})")
        aperture = _floats(_camera_aperture(cam), "camera: aperture settings", (5,))
        if not _finite(aperture) or aperture[0] < 0 or aperture[1] < 0 or aperture[2] < 0 or aperture[4] <= 0:
            raise ValueError("camera: aperture_radius, focus_distance and aperture_blades must be finite and "
                             f"not negative, aperture_ratio positive (got {tuple(aperture.tolist())})")
        fisheye = _floats(_camera_fisheye(cam), "camera: fisheye settings", (9,))
        rng = _floats(cam.panorama_range, "camera: panorama_range", (4,))
        if not _finite(fisheye, rng) or np.any(fisheye[:4] <= 0):
            raise ValueError("camera: panorama_range and fisheye settings must be finite, fisheye_fov, "
                             "fisheye_lens and fisheye_sensor positive")

    # -- flat arrays --

    def flatten(self, warnings=None, parts=None):
        """Validate and return the flat arrays (see FLAT_KEYS). Degenerate triangles and
        zero-size area lights are dropped; their warnings are appended to ``warnings``.
        ``parts`` (see PARTS; None: all) validates and returns only those parts' keys
        (PART_KEYS), for Session.update(scene, parts=...)."""
        flat, warns = self._flatten_parts(parts)
        if warnings is not None:
            warnings.extend(w for ws in warns.values() for w in ws)
        return flat

    def _flatten_parts(self, parts=None):
        """``(flat arrays of the parts, warnings by part)``: flatten() with the warnings
        kept apart per part (in PARTS order)."""
        parts = parts_set(parts)
        warns, keeps, light_keep = self._check(parts)
        out = {}
        if "geometry" in parts:
            self._flatten_meshes(keeps, out)
        if "instances" in parts:
            insts = self.effective_instances()
            out["instance_transform"] = np.array(
                [_transform_3x4(i.transform) for i in insts], dtype=np.float32).reshape(-1, 3, 4)
            out["instance_mesh"] = np.array([int(i.mesh) for i in insts], dtype=np.uint32)
        if "materials" in parts:
            self._flatten_materials(out)
        if "lights" in parts:
            self._flatten_lights(light_keep, out)
            w = self.world
            out["world_color"] = (_vec(w.color) * float(w.strength)).astype(np.float32)
            if w.map is None:
                out["world_map"] = np.zeros((0, 0, 3), np.float32)
            else:
                m = np.asarray(w.map, dtype=np.float64)[..., :3] * float(w.strength)
                out["world_map"] = m.astype(np.float32)
        if "camera" in parts:
            cam = self.camera
            out["camera_to_world"] = _transform_3x4(cam.camera_to_world).astype(np.float32)
            out["camera_type"] = np.array([CAMERA_TYPES[cam.type]], dtype=np.uint32)
            out["camera_window"] = np.array(cam.window, dtype=np.float32)
            out["camera_clip"] = np.array([cam.clip_start, cam.clip_end], dtype=np.float32)
            out["camera_aperture"] = np.array(_camera_aperture(cam), dtype=np.float32)
            out["camera_panorama_type"] = np.array([PANORAMA_TYPES[cam.panorama_type]], dtype=np.uint32)
            out["camera_panorama_range"] = np.array(cam.panorama_range, dtype=np.float32)
            out["camera_fisheye"] = np.array(_camera_fisheye(cam), dtype=np.float32)
        flat = {k: np.ascontiguousarray(out[k], dtype=FLAT_KEYS[k][0])
                for k in FLAT_KEYS if _part_of_key(k) in parts}
        return flat, warns

    def _flatten_meshes(self, keeps, out):
        pos, idx, mat, nrm, uvs, tangents = [], [], [], [], [], []
        first, count, has_n, has_uv, has_t, texspace = [], [], [], [], [], []
        any_n = any(m.normals is not None for m in self.meshes)
        any_uv = any(m.uvs is not None for m in self.meshes)
        any_t = any(m.tangents is not None for m in self.meshes)
        slots = 1 + max((s for m in self.meshes for s in m.attributes), default=-1)
        attributes, masks = [[] for _ in range(slots)], []
        v_off = t_off = 0
        for mesh, keep in zip(self.meshes, keeps):
            p = np.asarray(mesh.positions, dtype=np.float32).reshape(-1, 3)
            tri = np.asarray(mesh.indices).reshape(-1, 3)[keep].astype(np.int64)
            T = len(tri)
            pos.append(p)
            idx.append(tri + v_off)
            mi = mesh.material_indices
            mat.append(np.zeros(T, np.int64) if mi is None else np.asarray(mi).reshape(-1)[keep])
            if any_n:
                nrm.append(np.zeros((T, 3, 3), np.float32) if mesh.normals is None
                           else np.asarray(mesh.normals, dtype=np.float32)[keep])
            if any_uv:
                uvs.append(np.zeros((T, 3, 2), np.float32) if mesh.uvs is None
                           else np.asarray(mesh.uvs, dtype=np.float32)[keep])
            if any_t:
                tangents.append(np.zeros((T, 3, 4), np.float32) if mesh.tangents is None
                                else np.asarray(mesh.tangents, dtype=np.float32)[keep])
            first.append(t_off)
            count.append(T)
            has_n.append(mesh.normals is not None)
            has_uv.append(mesh.uvs is not None)
            has_t.append(mesh.tangents is not None)
            for slot in range(slots):
                values = mesh.attributes.get(slot)
                attributes[slot].append(np.zeros((T, 3, 4), np.float32) if values is None
                                        else np.asarray(values, dtype=np.float32)[keep])
            masks.append(sum(1 << slot for slot in mesh.attributes))
            texspace.append(_bounds_texspace(p) if mesh.texspace is None else np.asarray(mesh.texspace, np.float64).ravel())
            v_off += len(p)
            t_off += T
        if v_off >= 2**32 or t_off >= 2**32:
            raise ValueError(f"scene: too large ({v_off} vertices, {t_off} triangles)")
        cat = lambda parts, shape, dt: (np.concatenate(parts).astype(dt, copy=False)
                                        if parts else np.zeros(shape, dt))
        out["positions"] = cat(pos, (0, 3), np.float32)
        out["indices"] = cat(idx, (0, 3), np.uint32)
        out["triangle_material"] = cat(mat, (0,), np.uint32)
        out["corner_normals"] = cat(nrm, (0, 3, 3), np.float32)
        out["corner_uvs"] = cat(uvs, (0, 3, 2), np.float32)
        out["corner_tangents"] = cat(tangents, (0, 3, 4), np.float32)
        out["corner_attributes"] = cat([cat(a, (0, 3, 4), np.float32) for a in attributes], (0, 3, 4), np.float32)
        out["mesh_first_triangle"] = np.array(first, dtype=np.uint32)
        out["mesh_triangle_count"] = np.array(count, dtype=np.uint32)
        out["mesh_has_normals"] = np.array(has_n, dtype=np.uint32)
        out["mesh_has_uvs"] = np.array(has_uv, dtype=np.uint32)
        out["mesh_has_tangents"] = np.array(has_t, dtype=np.uint32)
        out["mesh_attribute_mask"] = np.array(masks, dtype=np.uint32)
        out["mesh_texspace"] = np.array(texspace, dtype=np.float32).reshape(-1, 6)

    def _flatten_materials(self, out):
        mats = self.effective_materials()
        out["material_type"] = np.array([MATERIAL_TYPES[m.type] for m in mats], np.uint32)
        out["material_base_color"] = np.array([_vec(m.base_color) for m in mats],
                                              np.float32).reshape(-1, 3)
        out["material_roughness"] = np.array(
            [min(max(float(m.roughness), 0.0), 1.0) for m in mats], np.float32)
        out["material_ior"] = np.array([float(m.ior) for m in mats], np.float32)
        out["material_emission"] = np.array(
            [_vec(m.emission) * float(m.emission_strength) for m in mats],
            np.float32).reshape(-1, 3)
        out["material_texture"] = np.array(
            [-1 if m.base_color_texture is None else int(m.base_color_texture) for m in mats],
            np.int32)
        out["material_mix_next"] = np.array(
            [-1 if m.mix_next is None else int(m.mix_next) for m in mats], np.int32)
        out["material_mix_weight"] = np.array(
            [1.0 if m.mix_next is None else min(max(float(m.mix_weight), 0.0), 1.0)
             for m in mats], np.float32)
        out["material_multiscatter"] = np.array([int(bool(m.multiscatter)) for m in mats], np.uint32)
        offsets, words = [], []
        for m in mats:
            offsets.append(len(words) if len(m.node_program) else -1)
            words.extend(int(w) for w in m.node_program)
        out["material_node_program"] = np.array(offsets, np.int32)
        out["material_node_programs"] = np.array(words, np.uint32)
        out["material_principled"] = np.array(
            [np.concatenate([np.clip(np.asarray(getattr(m, a), np.float64).reshape(n), lo, hi)
                             for a, n, lo, hi in PRINCIPLED_FIELDS]) for m in mats],
            np.float32).reshape(-1, 17)
        texels, halves, info, flags = [], [], [], []
        first = {False: 0, True: 0}  # next texel of the byte and of the half texel arrays
        for tex in self.textures:
            rgba = _texture_rgba(tex.pixels, "texture")
            h, w = rgba.shape[:2]
            is_float = rgba.dtype != np.uint8
            if is_float:
                halves.append(rgba.reshape(-1, 4).astype(np.float16).view(np.uint16))
            else:
                texels.append(rgba.reshape(-1, 4))
            info.append((first[is_float], w, h))
            flags.append(TEXTURE_INTERPOLATIONS[tex.interpolation] | (TEXTURE_FLAG_HALF if is_float else 0))
            first[is_float] += w * h
        out["texture_texels"] = (np.concatenate(texels) if texels
                                 else np.zeros((0, 4), np.uint8))
        out["texture_info"] = np.array(info, np.uint32).reshape(-1, 3)
        out["texture_flags"] = np.array(flags, np.uint32)
        out["texture_half_texels"] = (np.concatenate(halves) if halves
                                      else np.zeros((0, 4), np.uint16))

    def _flatten_lights(self, light_keep, out):
        rows = [_light_row(l) for l, ok in zip(self.lights, light_keep) if ok]
        cols = ("type", "position", "direction", "axis_u", "axis_v", "radius", "color",
                "spot_size", "spot_blend", "sun_angle", "camera_visible", "soft_falloff")
        shapes = {"position": 3, "direction": 3, "axis_u": 3, "axis_v": 3, "color": 3}
        for c in cols:
            dt = np.uint32 if c in ("type", "camera_visible", "soft_falloff") else np.float32
            shape = (-1, shapes[c]) if c in shapes else (-1,)
            out["light_" + c] = np.array([r[c] for r in rows], dtype=dt).reshape(shape)

    # -- resolution --

    def with_resolution(self, width, height):
        """Copy with another resolution; the camera window keeps its vertical extent and
        centre and widens/narrows horizontally so pixels stay square."""
        import copy
        s = copy.copy(self)
        cam = copy.copy(self.camera)
        if self.width and self.height and cam is not None:
            l, r, b, t = (float(x) for x in cam.window)
            scale = (width / height) / (self.width / self.height)
            cx, hx = 0.5 * (l + r), 0.5 * (r - l) * scale
            cam.window = (cx - hx, cx + hx, b, t)
        s.camera, s.width, s.height = cam, int(width), int(height)
        return s

    # -- files --

    def metadata(self):
        first_vertex, v = [], 0
        for m in self.meshes:
            first_vertex.append(v)
            v += len(np.asarray(m.positions).reshape(-1, 3))
        return {
            "version": 1, "width": self.width, "height": self.height,
            "mesh_names": [m.name for m in self.meshes],
            "mesh_first_vertex": first_vertex,
            "material_names": [m.name for m in self.effective_materials()],
            "texture_names": [t.name for t in self.textures],
            "light_names": [l.name for l in self.lights if _check_light(l, "light")],
        }

    def save(self, path):
        """Write the flat arrays and a JSON metadata string to one compressed ``.npz``."""
        flat = self.flatten()
        meta = np.array(json.dumps(self.metadata()))
        np.savez_compressed(path, **flat, **{_META_KEY: meta})

    @classmethod
    def load(cls, path):
        """Read a file written by ``save``. A file that is not a readable scene .npz (empty,
        truncated, wrong arrays or metadata) raises ValueError naming the file and the item."""
        try:
            data = np.load(path, allow_pickle=False)
            if not isinstance(data, np.lib.npyio.NpzFile):  # a plain .npy
                raise ValueError("a single array, not an archive of arrays")
            with data as f:
                flat = {k: f[k] for k in f.files}
        except (FileNotFoundError, IsADirectoryError, PermissionError):
            raise
        except (OSError, EOFError, ValueError, zipfile.BadZipFile, zlib.error) as e:
            raise ValueError(f"scene file {path}: not a readable .npz ({type(e).__name__}: {e})") from None
        try:
            meta = {}
            if _META_KEY in flat:
                try:
                    meta = json.loads(str(flat.pop(_META_KEY)))
                except ValueError as e:
                    raise ValueError(f"{_META_KEY} is not valid JSON ({e})") from None
            return cls.from_flat(flat, meta)
        except ValueError as e:
            raise ValueError(f"scene file {path}: {e}") from None

    @classmethod
    def from_flat(cls, flat, meta=None):
        """Rebuild a SceneData from flatten() output; flatten() of the result is identical.
        Arrays it cannot read (missing, wrong shape, lengths that disagree, unknown type ids,
        textures past the texels) or bad metadata raise ValueError naming the item."""
        meta = {} if meta is None else meta
        a = _check_flat(flat, meta)
        M = len(a["mesh_first_triangle"])
        first_vertex = meta.get("mesh_first_vertex")
        if first_vertex is None or len(first_vertex) != M:
            first_vertex = _infer_first_vertex(a)
        names = meta.get("mesh_names") or [""] * M
        V, T = len(a["positions"]), len(a["indices"])
        meshes = []
        for m in range(M):
            t0 = int(a["mesh_first_triangle"][m])
            t1 = t0 + int(a["mesh_triangle_count"][m])
            v0 = int(first_vertex[m])
            v1 = int(first_vertex[m + 1]) if m + 1 < M else V
            meshes.append(Mesh(
                positions=a["positions"][v0:v1].copy(),
                indices=a["indices"][t0:t1].astype(np.int64) - v0,
                normals=a["corner_normals"][t0:t1].copy() if a["mesh_has_normals"][m] else None,
                uvs=a["corner_uvs"][t0:t1].copy() if a["mesh_has_uvs"][m] else None,
                tangents=a["corner_tangents"][t0:t1].copy() if a["mesh_has_tangents"][m] else None,
                attributes={s: a["corner_attributes"][s * T + t0:s * T + t1].copy()
                            for s in range(ATTRIBUTE_SLOTS) if int(a["mesh_attribute_mask"][m]) >> s & 1},
                material_indices=a["triangle_material"][t0:t1].astype(np.int64),
                name=names[m],
                texspace=tuple(a["mesh_texspace"][m].tolist())))
        instances = [Instance(int(mi), t.astype(np.float64))
                     for mi, t in zip(a["instance_mesh"], a["instance_transform"])]
        types = {v: k for k, v in MATERIAL_TYPES.items()}
        mnames = meta.get("material_names") or [""] * len(a["material_type"])
        materials = [
            Material(type=types[int(a["material_type"][k])],
                     base_color=tuple(a["material_base_color"][k].tolist()),
                     roughness=float(a["material_roughness"][k]),
                     ior=float(a["material_ior"][k]),
                     emission=tuple(a["material_emission"][k].tolist()),
                     emission_strength=1.0,
                     base_color_texture=(None if a["material_texture"][k] < 0
                                         else int(a["material_texture"][k])),
                     name=mnames[k],
                     mix_next=(None if a["material_mix_next"][k] < 0
                               else int(a["material_mix_next"][k])),
                     mix_weight=float(a["material_mix_weight"][k]),
                     multiscatter=bool(a["material_multiscatter"][k]),
                     node_program=_node_program(a, k),
                     **_principled_fields(a["material_principled"][k]))
            for k in range(len(a["material_type"]))]
        tnames = meta.get("texture_names") or [""] * len(a["texture_info"])
        interpolations = {v: k for k, v in TEXTURE_INTERPOLATIONS.items()}
        textures = []
        for x, (o, w, h) in enumerate(a["texture_info"].astype(np.int64)):
            f = int(a["texture_flags"][x])
            src = a["texture_half_texels"].view(np.float16) if f & TEXTURE_FLAG_HALF else a["texture_texels"]
            textures.append(Texture(src[o:o + w * h].reshape(h, w, 4).copy(), tnames[x],
                                    interpolations[f & TEXTURE_FLAG_CLOSEST]))
        lnames = meta.get("light_names") or [""] * len(a["light_type"])
        lights = [_light_from_row(a, j, lnames[j]) for j in range(len(a["light_type"]))]
        wm = a["world_map"]
        world = World(color=tuple(a["world_color"].tolist()), strength=1.0,
                      map=wm.copy() if wm.size else None)
        ap, fish = a["camera_aperture"].tolist(), a["camera_fisheye"].tolist()
        camera = Camera(a["camera_to_world"].astype(np.float64),
                        {v: k for k, v in CAMERA_TYPES.items()}[int(a["camera_type"][0])],
                        tuple(a["camera_window"].tolist()),
                        float(a["camera_clip"][0]), float(a["camera_clip"][1]),
                        aperture_radius=ap[0], focus_distance=ap[1], aperture_blades=int(ap[2]),
                        aperture_rotation=ap[3], aperture_ratio=ap[4],
                        panorama_type={v: k for k, v in PANORAMA_TYPES.items()}[int(a["camera_panorama_type"][0])],
                        panorama_range=tuple(a["camera_panorama_range"].tolist()), fisheye_fov=fish[0],
                        fisheye_lens=fish[1], fisheye_sensor=tuple(fish[2:4]), fisheye_polynomial=tuple(fish[4:9]))
        return cls(meshes, instances, materials, textures, lights, world, camera,
                   meta.get("width"), meta.get("height"))


# ---- per-item checks and conversions -----------------------------------------------------

def _check_mesh(mesh, i, K):
    """Raise for bad data; return (mask of non-degenerate triangles, number degenerate)."""
    lbl = _label("mesh", i, mesh.name)
    p = np.asarray(mesh.positions)
    if p.ndim != 2 or p.shape[1] != 3:
        raise ValueError(f"{lbl}: positions has shape {p.shape}, expected (V,3)")
    if not np.issubdtype(p.dtype, np.number):
        raise ValueError(f"{lbl}: positions must be numeric, got {p.dtype}")
    bad = ~np.isfinite(p).all(axis=1)
    if bad.any():
        raise ValueError(f"{lbl}: vertex {int(np.argmax(bad))} is NaN/Inf")
    _check_f32(p, f"{lbl}: positions")
    if mesh.texspace is not None:
        texspace = _floats(mesh.texspace, f"{lbl}: texspace", (6,))
        if not _finite(texspace):
            raise ValueError(f"{lbl}: texspace (location, half size) must be 6 finite numbers")
    V = len(p)
    tri = np.asarray(mesh.indices)
    if tri.size == 0:
        tri = tri.reshape(0, 3).astype(np.int64)
    if tri.ndim != 2 or tri.shape[1] != 3:
        raise ValueError(f"{lbl}: indices has shape {tri.shape}, expected (T,3)")
    if not np.issubdtype(tri.dtype, np.integer):
        raise ValueError(f"{lbl}: indices must be integers, got {tri.dtype}")
    T = len(tri)
    if T and (tri.min() < 0 or tri.max() >= V):
        out = (tri < 0) | (tri >= V)
        if out.any():
            t, c = np.argwhere(out)[0]
            raise ValueError(f"{lbl}: triangle {t} index {tri[t, c]} out of range "
                             f"({V} vertices)")
    for slot in mesh.attributes:
        if isinstance(slot, bool) or not isinstance(slot, (int, np.integer)) or not 0 <= slot < ATTRIBUTE_SLOTS:
            raise ValueError(f"{lbl}: attribute slot {slot!r} is not an integer in 0..{ATTRIBUTE_SLOTS - 1}")
    per_corner = [("normals", mesh.normals, (3, 3)), ("uvs", mesh.uvs, (3, 2)), ("tangents", mesh.tangents, (3, 4))]
    per_corner += [(f"attribute slot {k}", v, (3, 4)) for k, v in mesh.attributes.items()]
    for attr, a, tail in per_corner:
        if a is None:
            continue
        a = np.asarray(a)
        if a.shape != (T,) + tail:
            raise ValueError(f"{lbl}: {attr} has shape {a.shape}, expected "
                             f"(T,{','.join(map(str, tail))}) with T={T}")
        bad = ~np.isfinite(a).reshape(T, -1).all(axis=1)
        if bad.any():
            raise ValueError(f"{lbl}: {attr} of triangle {int(np.argmax(bad))} is NaN/Inf")
    if mesh.material_indices is not None:
        mi = np.asarray(mesh.material_indices)
        if mi.shape != (T,) or (T and not np.issubdtype(mi.dtype, np.integer)):
            raise ValueError(f"{lbl}: material_indices has shape {mi.shape} ({mi.dtype}), "
                             f"expected integer (T,) with T={T}")
        out = (mi < 0) | (mi >= K)
        if out.any():
            t = int(np.argmax(out))
            raise ValueError(f"{lbl}: triangle {t} material {mi[t]} out of range "
                             f"({K} materials)")
    # Degenerate: zero area relative to the longest edge, on the float32 positions.
    x, y, z = np.ascontiguousarray(p.astype(np.float32).T, dtype=np.float64)
    i0, i1, i2 = np.ascontiguousarray(tri.T)
    ax, ay, az = x[i1] - x[i0], y[i1] - y[i0], z[i1] - z[i0]
    bx, by, bz = x[i2] - x[i0], y[i2] - y[i0], z[i2] - z[i0]
    area2 = (ay * bz - az * by) ** 2 + (az * bx - ax * bz) ** 2 + (ax * by - ay * bx) ** 2
    scale = np.maximum(ax * ax + ay * ay + az * az, bx * bx + by * by + bz * bz)
    keep = area2 > 1e-24 * scale * scale
    return keep, int(T - keep.sum())


def _check_flat(flat, meta):
    """The FLAT_KEYS arrays of ``flat`` (optional ones filled in) after checking what from_flat
    relies on: every array present and numeric with its shape, the lengths of each group
    equal, known type ids, textures inside texture_texels, and well-formed metadata."""
    if not isinstance(flat, dict):
        raise ValueError(f"scene arrays must be a dict, got {type(flat).__name__}")
    if not isinstance(meta, dict):
        raise ValueError(f"{_META_KEY} must be a JSON object, got {type(meta).__name__}")
    a = {}
    for k in FLAT_KEYS:
        if k in flat:
            v = np.asarray(flat[k])
            if v.dtype.kind not in "biuf":
                raise ValueError(f"array '{k}' must be numeric, got {v.dtype}")
            a[k] = v
    a = _with_optional_defaults(a)
    missing = [k for k in FLAT_KEYS if k not in a]
    if missing:
        raise ValueError(f"missing arrays {missing}")
    # Shapes: "(T,3,3) or (0,3,3)" -> trailing dimensions (3, 3); the rows are checked below.
    for k, (_, shape) in FLAT_KEYS.items():
        trailing = tuple(int(d) for d in shape.split(" or ")[0].strip("()").split(",")[1:] if d.strip().isdigit())
        if k == "world_map":
            trailing = (None, 3)
        v = a[k]
        ok = v.ndim == 1 + len(trailing) and all(t is None or d == t for d, t in zip(v.shape[1:], trailing))
        if not ok:
            raise ValueError(f"array '{k}' has shape {v.shape}, expected {shape}")
        if v.dtype.kind == "f" and np.dtype(FLAT_KEYS[k][0]).kind in "iu":
            raise ValueError(f"array '{k}' must hold integers, got {v.dtype}")
    groups = {"T": ("indices", "triangle_material"), "M": [k for k in FLAT_KEYS if k.startswith("mesh_")],
              "I": ("instance_transform", "instance_mesh"),
              "K": [k for k in FLAT_KEYS if k.startswith("material_") and k != "material_node_programs"],
              "L": [k for k in FLAT_KEYS if k.startswith("light_")]}
    for keys in groups.values():
        lengths = {k: len(a[k]) for k in keys}
        if len(set(lengths.values())) > 1:
            raise ValueError(f"arrays of one kind differ in length: {lengths}")
    T, M, V = len(a["indices"]), len(a["mesh_first_triangle"]), len(a["positions"])
    for k in ("corner_normals", "corner_uvs", "corner_tangents"):
        if len(a[k]) not in (0, T):
            raise ValueError(f"array '{k}' has {len(a[k])} rows, expected 0 or {T}")
    slots = len(a["corner_attributes"]) // max(T, 1)
    if len(a["corner_attributes"]) != slots * T or (T == 0 and len(a["corner_attributes"])) or slots > ATTRIBUTE_SLOTS:
        raise ValueError(f"array 'corner_attributes' has {len(a['corner_attributes'])} rows, expected a multiple "
                         f"of {T} (up to {ATTRIBUTE_SLOTS} slots)")
    if np.any(a["mesh_attribute_mask"] >> np.uint32(slots)):
        raise ValueError(f"mesh_attribute_mask names an attribute slot beyond the {slots} in corner_attributes")
    for k, n in (("world_color", 3), ("camera_to_world", 3), ("camera_type", 1), ("camera_window", 4),
                 ("camera_clip", 2), ("camera_aperture", 5), ("camera_panorama_type", 1),
                 ("camera_panorama_range", 4), ("camera_fisheye", 9)):
        if len(a[k]) != n:
            raise ValueError(f"array '{k}' has shape {a[k].shape}, expected {n} rows")

    def ids(key, known):
        bad = [int(x) for x in a[key] if int(x) not in known]
        if bad:
            raise ValueError(f"array '{key}' holds unknown type id {bad[0]} (known: {sorted(known)})")

    ids("material_type", set(MATERIAL_TYPES.values()))
    ids("light_type", set(LIGHT_TYPES.values()) | set(AREA_SHAPES.values()))
    ids("camera_type", set(CAMERA_TYPES.values()))
    ids("camera_panorama_type", set(PANORAMA_TYPES.values()))
    if np.any(a["indices"] < 0) or np.any(a["indices"] >= V):
        raise ValueError(f"array 'indices' refers to vertices outside 0..{V - 1}")
    first, count = a["mesh_first_triangle"].astype(np.int64), a["mesh_triangle_count"].astype(np.int64)
    if np.any(first < 0) or np.any(count < 0) or np.any(first + count > T):
        m = int(np.argmax((first < 0) | (count < 0) | (first + count > T)))
        raise ValueError(f"mesh {m} covers triangles {first[m]}..{first[m] + count[m]}, but there are {T}")
    if len(a["texture_flags"]) != len(a["texture_info"]):
        raise ValueError(f"array 'texture_flags' has {len(a['texture_flags'])} rows, expected "
                         f"{len(a['texture_info'])} (one per texture)")
    for x, (o, w, h) in enumerate(a["texture_info"].astype(np.int64)):
        f = int(a["texture_flags"][x])
        if f & ~(TEXTURE_FLAG_CLOSEST | TEXTURE_FLAG_HALF):
            raise ValueError(f"texture {x}: unknown texture_flags bits {f:#x}")
        key = "texture_half_texels" if f & TEXTURE_FLAG_HALF else "texture_texels"
        N = len(a[key])
        if w <= 0 or h <= 0 or o < 0 or o + w * h > N:
            raise ValueError(f"texture {x}: {w}x{h} texels at offset {o} do not fit in the {N} texels "
                             f"of '{key}'")
    for key in ("width", "height"):
        value = meta.get(key)
        if value is not None and (isinstance(value, bool) or not isinstance(value, int) or value < 1):
            raise ValueError(f"{_META_KEY} {key} must be a positive integer, got {value!r}")
    for key, n in (("mesh_names", M), ("material_names", len(a["material_type"])),
                   ("texture_names", len(a["texture_info"])), ("light_names", len(a["light_type"]))):
        names = meta.get(key)
        if names is not None and (not isinstance(names, list) or len(names) != n
                                  or not all(isinstance(x, str) for x in names)):
            raise ValueError(f"{_META_KEY} {key} must be a list of {n} strings, got {names!r}")
    fv = meta.get("mesh_first_vertex")
    if fv is not None and (not isinstance(fv, list) or len(fv) != M or not all(
            isinstance(x, int) and not isinstance(x, bool) and 0 <= x <= V for x in fv) or fv != sorted(fv)):
        raise ValueError(f"{_META_KEY} mesh_first_vertex must be {M} increasing vertex indices "
                         f"in 0..{V}, got {fv!r}")
    return a


def _node_program(a, k):
    """Material k's node program words: from its offset to the next program's (they are
    stored in material order)."""
    offsets = a["material_node_program"]
    if offsets[k] < 0:
        return ()
    later = [int(o) for o in offsets[k + 1:] if o >= 0]
    end = later[0] if later else len(a["material_node_programs"])
    return tuple(int(w) for w in a["material_node_programs"][int(offsets[k]):end])


def _camera_aperture(cam):
    """camera_aperture's row: radius, focus distance, blades, rotation, ratio."""
    return (cam.aperture_radius, cam.focus_distance, cam.aperture_blades, cam.aperture_rotation, cam.aperture_ratio)


def _camera_fisheye(cam):
    """camera_fisheye's row: fov, lens, sensor width, height, k0..k4."""
    return (cam.fisheye_fov, cam.fisheye_lens, *cam.fisheye_sensor, *cam.fisheye_polynomial)


def _bounds_texspace(positions):
    """Blender's automatic texture space of a mesh: (location, half size) of its bounds."""
    p = np.asarray(positions, np.float64).reshape(-1, 3)
    if not len(p):
        return np.array([0.0, 0.0, 0.0, 1.0, 1.0, 1.0])
    lo, hi = p.min(axis=0), p.max(axis=0)
    return np.concatenate([(lo + hi) / 2, (hi - lo) / 2])


def _with_optional_defaults(flat):
    """``flat`` with the keys newer than its file filled in (no mixes; a pinhole camera; the
    meshes' bounds as their texture spaces), as a new dict."""
    flat = dict(flat)
    if "mesh_texspace" not in flat and all(k in flat for k in ("positions", "indices", "mesh_first_triangle",
                                                                "mesh_triangle_count")):
        rows = []
        for first, count in zip(np.asarray(flat["mesh_first_triangle"], np.int64),
                                np.asarray(flat["mesh_triangle_count"], np.int64)):
            used = np.asarray(flat["indices"])[first:first + count].ravel().astype(np.int64)
            rows.append(_bounds_texspace(np.asarray(flat["positions"])[used]))
        flat["mesh_texspace"] = np.array(rows, np.float32).reshape(-1, 6)
    if "mesh_first_triangle" in flat:  # files before tangents and attributes
        M = len(flat["mesh_first_triangle"])
        for k in ("mesh_has_tangents", "mesh_attribute_mask"):
            flat.setdefault(k, np.zeros(M, np.uint32))
        for k in ("corner_tangents", "corner_attributes"):
            flat.setdefault(k, np.zeros((0, 3, 4), np.float32))
    pinhole = Camera()
    for k, row in (("camera_aperture", _camera_aperture(pinhole)), ("camera_panorama_type", (0,)),
                   ("camera_panorama_range", pinhole.panorama_range), ("camera_fisheye", _camera_fisheye(pinhole))):
        flat.setdefault(k, np.array(row, dtype=FLAT_KEYS[k][0]))
    for k, default in _OPTIONAL_KEY_DEFAULTS.items():
        if k not in flat:
            like = {"light": "light_type", "material": "material_type", "texture": "texture_info"}[k.split("_")[0]]
            n = len(flat[like]) if like in flat and np.ndim(flat[like]) >= 1 else 0
            if k in ("texture_half_texels", "material_node_programs"):
                n = 0  # files without float textures or node programs
            trailing = tuple(int(d) for d in FLAT_KEYS[k][1].strip("()").split(",")[1:] if d)
            flat[k] = np.full((n,) + trailing, default, dtype=FLAT_KEYS[k][0])
    return flat


def _principled_fields(row):
    """Material keyword arguments from one row of material_principled."""
    out, i = {}, 0
    for attr, n, _, _ in PRINCIPLED_FIELDS:
        out[attr] = float(row[i]) if n == 1 else tuple(float(x) for x in row[i:i + n])
        i += n
    return out


def _check_mix_chains(materials):
    """Raise ValueError naming a material whose mix chain loops or is longer than
    MIX_CHAIN_MAX (mix_next already checked to be None or in range)."""
    length = {}  # materials in the chain starting at k, for chains known to end
    for k in range(len(materials)):
        walk, j = [], k
        while j is not None and j not in length:
            if j in walk:
                lbl = _label("material", j, materials[j].name)
                cycle = " -> ".join(str(i) for i in walk[walk.index(j):] + [j])
                raise ValueError(f"{lbl}: mix chain has a cycle ({cycle})")
            walk.append(j)
            j = materials[j].mix_next
            j = None if j is None else int(j)
        n = 0 if j is None else length[j]
        for i in reversed(walk):
            n += 1
            length[i] = n
            if n > MIX_CHAIN_MAX:
                raise ValueError(f"{_label('material', i, materials[i].name)}: mix chain of "
                                 f"{n} materials is longer than the limit of {MIX_CHAIN_MAX}")


def _texture_rgba(pixels, lbl):
    px = np.asarray(pixels)
    if px.ndim == 2:
        px = px[:, :, None]
    if px.ndim != 3 or px.shape[2] not in (1, 3, 4):
        raise ValueError(f"{lbl}: pixels has shape {px.shape}, expected (H,W,3) or (H,W,4)")
    if px.shape[0] == 0 or px.shape[1] == 0:
        raise ValueError(f"{lbl}: zero-size image")
    if px.dtype.kind == "f":  # linear float texels
        px = px.astype(np.float32)
        if not np.isfinite(px).all():
            raise ValueError(f"{lbl}: float pixels must be finite (NaN or infinite texel)")
        px = np.clip(px, 0.0, HALF_MAX)
        opaque = 1.0
    elif px.dtype == np.uint8:
        opaque = 255
    else:
        raise ValueError(f"{lbl}: pixels must be uint8 sRGB or float linear, got {px.dtype}")
    if px.shape[2] == 1:
        px = np.repeat(px, 3, axis=2)
    if px.shape[2] == 3:
        px = np.concatenate([px, np.full(px.shape[:2] + (1,), opaque, px.dtype)], axis=2)
    return np.ascontiguousarray(px)


def _check_light(light, lbl):
    """Raise for bad data; return False for a zero-size area light (skipped)."""
    if light.type not in LIGHT_TYPES:
        raise ValueError(f"{lbl}: unknown type '{light.type}'")
    if light.type == "area" and light.shape not in AREA_SHAPES:
        raise ValueError(f"{lbl}: unknown area shape '{light.shape}'")
    for attr in ("color", "position", "direction"):
        v = _floats(getattr(light, attr), f"{lbl}: {attr}")
        if v.shape != (3,) or not _finite(v):
            raise ValueError(f"{lbl}: {attr} must be 3 finite numbers, got {getattr(light, attr)}")
        _check_f32(v, f"{lbl}: {attr}")
    for attr in ("power", "radius", "spot_size", "spot_blend", "angle", "size", "size_y"):
        v = _floats(getattr(light, attr), f"{lbl}: {attr}")
        if not _finite(v) or v.ndim != 0:
            raise ValueError(f"{lbl}: {attr} is NaN/Inf or not a number")
        _check_f32(v, f"{lbl}: {attr}")
    _check_f32(_vec(light.color) * float(light.power), f"{lbl}: color x power")
    if _normalized(light.direction) is None:
        raise ValueError(f"{lbl}: direction has zero length")
    for attr in ("axis_u", "axis_v"):
        v = getattr(light, attr)
        if v is not None:
            v = _floats(v, f"{lbl}: {attr}")
            if v.shape != (3,) or not _finite(v) or _normalized(v) is None:
                raise ValueError(f"{lbl}: {attr} must be a finite non-zero 3-vector")
    if light.type == "area":
        sy = light.size if light.shape in ("square", "disk") else light.size_y
        return light.size != 0 and sy != 0
    return True


def _light_row(light):
    d = _normalized(light.direction)
    if light.axis_u is None or light.axis_v is None:
        u, v = _basis(-d)
    else:
        u, v = _normalized(light.axis_u), _normalized(light.axis_v)
    if light.type == "area":
        t = AREA_SHAPES[light.shape]
        sy = light.size if light.shape in ("square", "disk") else light.size_y
        u, v = u * abs(float(light.size)), v * abs(float(sy))
    else:
        t = LIGHT_TYPES[light.type]
    return {
        "type": t,
        "position": _vec(light.position),
        "direction": d,
        "axis_u": u,
        "axis_v": v,
        "radius": max(float(light.radius), 0.0),
        "color": _vec(light.color) * float(light.power),
        "spot_size": min(max(float(light.spot_size), 0.0), math.pi),
        "spot_blend": min(max(float(light.spot_blend), 0.0), 1.0),
        "sun_angle": min(max(float(light.angle), 0.0), math.pi),
        "camera_visible": int(bool(light.camera_visible)),
        "soft_falloff": int(bool(light.soft_falloff) and light.type in ("point", "spot")),
    }


def _light_from_row(a, j, name):
    t = int(a["light_type"][j])
    u = a["light_axis_u"][j].astype(np.float64)
    v = a["light_axis_v"][j].astype(np.float64)
    kw = {}
    if t in (4, 5):
        su, sv = float(np.linalg.norm(u)), float(np.linalg.norm(v))
        kw = dict(type="area", shape="rectangle" if t == 4 else "ellipse", size=su, size_y=sv,
                  axis_u=tuple(u / su) if su > 0 else None,  # zero size: skipped, with a warning
                  axis_v=tuple(v / sv) if sv > 0 else None)
    else:
        kw = dict(type={1: "point", 2: "spot", 3: "sun"}[t], axis_u=tuple(u), axis_v=tuple(v))
    return Light(color=tuple(a["light_color"][j].tolist()), power=1.0,
                 position=tuple(a["light_position"][j].tolist()),
                 direction=tuple(a["light_direction"][j].tolist()),
                 radius=float(a["light_radius"][j]),
                 spot_size=float(a["light_spot_size"][j]),
                 spot_blend=float(a["light_spot_blend"][j]),
                 angle=float(a["light_sun_angle"][j]),
                 camera_visible=bool(a["light_camera_visible"][j]),
                 soft_falloff=bool(a["light_soft_falloff"][j]), name=name, **kw)


def _infer_first_vertex(a):
    """First vertex of each mesh when the metadata lacks it: the smallest index a mesh uses
    (mesh 0 starts at 0; a mesh without triangles starts where the next one does)."""
    M, V = len(a["mesh_first_triangle"]), len(a["positions"])
    first = [None] * M
    for m in range(M):
        t0 = int(a["mesh_first_triangle"][m])
        t1 = t0 + int(a["mesh_triangle_count"][m])
        if t1 > t0:
            first[m] = int(a["indices"][t0:t1].min())
    if M:
        first[0] = 0
    nxt = V
    for m in reversed(range(M)):
        first[m] = nxt if first[m] is None else first[m]
        nxt = first[m]
    return first
