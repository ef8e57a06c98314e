"""Blender's Sky Texture as Cycles (Blender 5.0) evaluates it, in numpy: the add-on bakes a world
whose background is a Sky Texture into an environment map (and exports the sun disc as a distant
light).

    sky = Sky(SkyParams.from_node(node))        # precomputes the scattering LUT once
    rgb = sky.radiance(directions)               # (..., 3) linear Rec.709, without the sun disc
    disc = sky.sun()                             # None, or (direction, angular_diameter, mean_rgb)

Supported models: SINGLE_SCATTERING (the former Nishita), MULTIPLE_SCATTERING (Blender 5's
default) and PREETHAM. HOSEK_WILKIE needs the large fitted tables of Hosek and Wilkie's model
and is not supported (``Sky`` raises ``ValueError``; callers warn).

How Cycles does it (the definitions this module follows; Cycles' sources, release/v5.0):
- scene/shader_nodes.cpp, SkyTextureNode: ``simplify_settings`` folds the sun elevation into
  [-pi/2, pi/2] (moving the sun half a turn round when it passes the zenith) and turns the
  rotation into ``2 pi - rotation`` (mod 2 pi); ``sky_texture_precompute_preetham`` and
  ``sky_texture_precompute_nishita`` prepare the kernel's constants; the sun size is clamped to
  at least 0.0005 rad.
- third_party/sky/source/sky_single_scattering.cpp and sky_multiple_scattering.cpp: the
  512 x 256 XYZ look-up table over (azimuth relative to the sun, elevation) and the two XYZ
  radiances of the sun disc's lowest and highest points.
- scene/image_sky.cpp: the table is an image with linear interpolation, extend (clamp) at the
  edges; kernel/device/cpu/image.h: texel centres at (i + 0.5) / N.
- kernel/svm/sky.h: the per-direction evaluation (table look-up with the square-root elevation
  mapping; the sun disc with limb darkening, drawn only above the earth-intersection angle), and
  the XYZ -> RGB conversion clamped at zero (kernel/util/colorspace.h).

Everything here is float64 (Cycles computes in float32 and stores the table as float32) but for
one place where float32 rounding visibly changes Cycles' result and is replayed: the distance
to the ground of rays from an observer near the ground (multiple scattering). Against Cycles'
renders the sky agrees to well under 1 % (tests/addon/test_parity_sky.py).
"""
from __future__ import annotations

import math
import os
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass

import numpy as np

SKY_TYPES = ("SINGLE_SCATTERING", "MULTIPLE_SCATTERING", "PREETHAM")
UNSUPPORTED_SKY_TYPES = ("HOSEK_WILKIE",)

# CIE XYZ (D65 white) -> linear Rec.709, the matrix Cycles' kernel_data.film.xyz_to_{r,g,b} holds
# in Blender 5.0.1. Cycles (scene/shader.cpp, ShaderManager::init_xyz_transforms) prefers the
# OCIO role "aces_interchange" over "XYZ": it takes OCIO's processor scene_linear ->
# aces_interchange, inverts it, and follows it with the inverse of its hard-coded
# ACES-AP0 -> XYZ-D65 (Bradford) matrix. Blender 5.0.1's config
# (bpy/5.0/datafiles/colormanagement/config.ocio) has no "XYZ" role, and aces_interchange:
# ACES2065-1, scene_linear: Linear Rec.709; both are defined from the reference "Linear CIE-XYZ
# E" through "Linear CIE-XYZ D65", so the E <-> D65 adaptation cancels and the result is the
# config's Linear Rec.709 matrix (from XYZ D65) up to the rounding of Cycles' AP0 matrix.
# The values: Cycles' computation replayed with PyOpenColorIO 2.6 on that config (they differ
# from the config's own Linear Rec.709 matrix by under 2e-6; tests/unit/test_sky.py checks that).
XYZ_TO_REC709 = np.array([[3.2409700938, -1.5373845104, -0.4986114518],
                          [-0.9692434841, 1.8759669819, 0.0415546884],
                          [0.0556298796, -0.2039765014, 1.0569711535]])

LUT_WIDTH, LUT_HEIGHT = 512, 256  # scene/image_sky.cpp
_CHUNK = 1 << 15  # directions evaluated at a time by Sky.radiance
MIN_SUN_SIZE = 0.0005  # SkyTextureNode::get_sun_size

# ---------------------------------------------------------------------------------------------
# Single scattering (the former "Nishita" model). Physical constants and tables: Blender's
# third_party/sky/source/sky_single_scattering.cpp (spectral data sampled every 20 nm from 380 to
# 780 nm; lengths in metres).
_SS_RAYLEIGH_SCALE = 8e3
_SS_MIE_SCALE = 1.2e3
_SS_MIE_COEFF = 2e-5
_SS_MIE_G = 0.76
_SS_EARTH_RADIUS = 6360e3
_SS_ATMOSPHERE_RADIUS = 6420e3
_SS_STEPS = 32
_SS_STEP_LAMBDA = 20.0  # (780 - 380) / (21 - 1) nm
# Solar irradiance at the top of the atmosphere (W m^-2 nm^-1).
_SS_IRRADIANCE = np.array([
    1.45756829855592995315, 1.56596305559738380175, 1.65148449067670455293, 1.71496242737209314555,
    1.75797983805020541226, 1.78256407885924539336, 1.79095108475838560302, 1.78541550133410664714,
    1.76815554864306845317, 1.74122069647250410362, 1.70647127164943679389, 1.66556087452739887134,
    1.61993437242451854274, 1.57083597368892080581, 1.51932335059305478886, 1.46628494965214395407,
    1.41245852740172450623, 1.35844961970384092709, 1.30474913844739281998, 1.25174963272610817455,
    1.19975998755420620867])
# Rayleigh scattering coefficients at sea level (m^-1).
_SS_RAYLEIGH_COEFF = np.array([
    0.00005424820087636473, 0.00004418549866505454, 0.00003635151910165377, 0.00003017929012024763,
    0.00002526320226989157, 0.00002130859310621843, 0.00001809838025320633, 0.00001547057129129042,
    0.00001330284977336850, 0.00001150184784075764, 0.00000999557429990163, 0.00000872799973630707,
    0.00000765513700977967, 0.00000674217203751443, 0.00000596134125832052, 0.00000529034598065810,
    0.00000471115687557433, 0.00000420910481110487, 0.00000377218381260133, 0.00000339051255477280,
    0.00000305591531679811])
# Ozone absorption coefficients (m^-1).
_SS_OZONE_COEFF = np.array([
    0.00000000325126849861, 0.00000000585395365047, 0.00000001977191155085, 0.00000007309568762914,
    0.00000020084561514287, 0.00000040383958096161, 0.00000063551335912363, 0.00000096707041180970,
    0.00000154797400424410, 0.00000209038647223331, 0.00000246128056164565, 0.00000273551299461512,
    0.00000215125863128643, 0.00000159051840791988, 0.00000112356197979857, 0.00000073527551487574,
    0.00000046450130357806, 0.00000033096079921048, 0.00000022512612292678, 0.00000014879129266490,
    0.00000016828623364192])
# CIE 1931 colour matching functions at the same wavelengths (x-bar, y-bar, z-bar).
_SS_CMF = np.array([
    [0.00136800000, 0.00003900000, 0.00645000100], [0.01431000000, 0.00039600000, 0.06785001000],
    [0.13438000000, 0.00400000000, 0.64560000000], [0.34828000000, 0.02300000000, 1.74706000000],
    [0.29080000000, 0.06000000000, 1.66920000000], [0.09564000000, 0.13902000000, 0.81295010000],
    [0.00490000000, 0.32300000000, 0.27200000000], [0.06327000000, 0.71000000000, 0.07824999000],
    [0.29040000000, 0.95400000000, 0.02030000000], [0.59450000000, 0.99500000000, 0.00390000000],
    [0.91630000000, 0.87000000000, 0.00165000100], [1.06220000000, 0.63100000000, 0.00080000000],
    [0.85444990000, 0.38100000000, 0.00019000000], [0.44790000000, 0.17500000000, 0.00002000000],
    [0.16490000000, 0.06100000000, 0.00000000000], [0.04677000000, 0.01700000000, 0.00000000000],
    [0.01135916000, 0.00410200000, 0.00000000000], [0.00289932700, 0.00104700000, 0.00000000000],
    [0.00069007860, 0.00024920000, 0.00000000000], [0.00016615050, 0.00006000000, 0.00000000000],
    [0.00004150994, 0.00001499000, 0.00000000000]])
# The 8-point Gauss-Laguerre rule Blender integrates optical depth towards the sun with: nodes
# as fractions of the path to the top of the atmosphere, weights including the exp(x) factor
# (same file; derived there with sympy's gauss_laguerre(8), scaled by 1/25).
_SS_QUAD_NODES = np.array([0.006811185292, 0.03614807107, 0.09004346519, 0.1706680068,
                           0.2818362161, 0.4303406404, 0.6296271457, 0.9145252695])
_SS_QUAD_WEIGHTS = np.array([0.01750893642, 0.04135477391, 0.06678839063, 0.09507698807,
                             0.1283416365, 0.1707430204, 0.2327233347, 0.3562490486])

# ---------------------------------------------------------------------------------------------
# Multiple scattering (Fernando Garcia Linan's spectral sky with a multiple-scattering fit; four
# wavelengths 630, 560, 490, 430 nm). Constants: Blender's
# third_party/sky/source/sky_multiple_scattering.cpp (lengths in km).
_MS_GROUND_ALBEDO = 0.3
_MS_G = 0.8
_MS_EARTH_RADIUS = 6371.0
_MS_ATMOSPHERE_THICKNESS = 100.0
_MS_ATMOSPHERE_RADIUS = _MS_EARTH_RADIUS + _MS_ATMOSPHERE_THICKNESS
_MS_TRANSMITTANCE_STEPS = 64
_MS_INSCATTERING_STEPS = 64
_MS_TRANSMITTANCE_SIZE = (64, 256)  # (altitudes, sun zenith cosines)
_MS_SUN_IRRADIANCE = np.array([1.679, 1.828, 1.986, 1.307])
_MS_MOLECULAR_SCATTERING = np.array([6.605e-3, 1.067e-2, 1.842e-2, 3.156e-2])
_MS_OZONE_CROSS_SECTION = np.array([3.472e-25, 3.914e-25, 1.349e-25, 11.03e-27])
_MS_OZONE_MEAN_DOBSON = 334.5
_MS_AEROSOL_ABSORPTION = np.array([2.8722e-24, 4.6168e-24, 7.9706e-24, 1.3578e-23])
_MS_AEROSOL_SCATTERING = np.array([1.5908e-22, 1.7711e-22, 2.0942e-22, 2.4033e-22])
_MS_AEROSOL_BASE_DENSITY = 1.3681e20
_MS_AEROSOL_BACKGROUND_DENSITY = 2e6
_MS_AEROSOL_HEIGHT_SCALE = 0.73
# The four wavelengths' radiances -> CIE XYZ (rows: wavelengths; columns: X, Y, Z).
_MS_SPECTRAL_XYZ = np.array([
    [53.386917738564668023, 22.981337506691024754, 0.0],
    [43.904844466369358263, 71.347795700053393866, 0.102506867965741307],
    [1.6137278251608962005, 18.422960591455485011, 31.742921188390805758],
    [20.762668673810577145, 2.3614213523314368527, 110.48009643252140334]])
# Fit of the multiple scattering from the rest of the atmosphere (same file).
_MS_FIT_COLOUR = 0.02 * np.array([0.217, 0.347, 0.594, 1.0])

# ---------------------------------------------------------------------------------------------
# Preetham, Shirley and Smits' "A Practical Analytic Model for Daylight": the zenith luminance
# and chromaticity fits and the Perez distribution coefficients (as linear functions of the
# turbidity T), from the paper's appendix as Cycles' sky_texture_precompute_preetham uses them.
# Rows: Y, x, y; columns: (slope, intercept) in T for the 5 Perez coefficients A..E.
_PREETHAM_PEREZ = np.array([
    [[0.1787, -1.4630], [-0.3554, 0.4275], [-0.0227, 5.3251], [0.1206, -2.5771], [-0.0670, 0.3703]],
    [[-0.0193, -0.2592], [-0.0665, 0.0008], [-0.0004, 0.2125], [-0.0641, -0.8989], [-0.0033, 0.0452]],
    [[-0.0167, -0.2608], [-0.0950, 0.0092], [-0.0079, 0.2102], [-0.0441, -1.6537], [-0.0109, 0.0529]]])
# Zenith chromaticity x and y: coefficients of [T^2, T, 1] x [theta^3, theta^2, theta, 1].
_PREETHAM_ZENITH_X = np.array([[0.00166, -0.00375, 0.00209, 0.0],
                               [-0.02903, 0.06377, -0.03202, 0.00394],
                               [0.11693, -0.21196, 0.06052, 0.25886]])
_PREETHAM_ZENITH_Y = np.array([[0.00275, -0.00610, 0.00317, 0.0],
                               [-0.04214, 0.08970, -0.04153, 0.00516],
                               [0.15346, -0.26756, 0.06670, 0.26688]])


@dataclass(frozen=True)
class SkyParams:
    """A Sky Texture node's settings, as Blender stores them (angles in radians, altitude in
    metres; no wrapping of the sun angles here: ``Sky`` applies Cycles' own)."""
    sky_type: str
    sun_disc: bool = True
    sun_size: float = 0.009512
    sun_intensity: float = 1.0
    sun_elevation: float = math.radians(15)
    sun_rotation: float = 0.0
    altitude: float = 100.0
    air_density: float = 1.0
    aerosol_density: float = 1.0
    ozone_density: float = 1.0
    sun_direction: tuple = (0.0, 0.0, 1.0)   # Preetham
    turbidity: float = 2.2                    # Preetham

    @classmethod
    def from_node(cls, node) -> "SkyParams":
        """The settings of a bpy ``ShaderNodeTexSky`` (its texture mapping and Vector input
        are not read: Cycles' defaults, the identity and the ray direction, are assumed)."""
        sky_type = str(node.sky_type)
        if sky_type == "NISHITA":  # Blender 4.x: the single-scattering model (before 5.0's changes)
            sky_type = "SINGLE_SCATTERING"
        aerosol = getattr(node, "aerosol_density", None)
        if aerosol is None:  # Blender < 5.0: "dust"
            aerosol = getattr(node, "dust_density", 1.0)
        return cls(sky_type=sky_type, sun_disc=bool(node.sun_disc), sun_size=float(node.sun_size),
                   sun_intensity=float(node.sun_intensity), sun_elevation=float(node.sun_elevation),
                   sun_rotation=float(node.sun_rotation), altitude=float(node.altitude),
                   air_density=float(node.air_density), aerosol_density=float(aerosol),
                   ozone_density=float(node.ozone_density),
                   sun_direction=tuple(float(c) for c in node.sun_direction),
                   turbidity=float(node.turbidity))


def wrap_sun_angles(elevation: float, rotation: float) -> tuple[float, float]:
    """Cycles' SkyTextureNode::simplify_settings: (elevation in [-pi/2, pi/2], the rotation the
    kernel uses, 2 pi - rotation folded into (0, 2 pi])."""
    two_pi = 2.0 * math.pi
    elevation = math.fmod(elevation, two_pi)
    if abs(elevation) >= math.pi:
        elevation -= math.copysign(two_pi, elevation)
    if abs(elevation) >= math.pi / 2:
        # Past the zenith (or nadir): the same point of the sky, seen from the other side.
        elevation = math.copysign(math.pi, elevation) - elevation
        rotation += math.pi
    rotation = math.fmod(rotation, two_pi)
    if rotation < 0.0:
        rotation += two_pi
    return elevation, two_pi - rotation


def earth_intersection_angle(altitude: float) -> float:
    """How far below the horizon (radians) the Earth's limb lies from ``altitude`` metres: the sun
    disc is drawn only above it (SKY_earth_intersection_angle; Earth radius 6371 km)."""
    return math.pi / 2 - math.asin(_MS_EARTH_RADIUS / (_MS_EARTH_RADIUS + altitude / 1000.0))


def _unit(v):
    v = np.asarray(v, dtype=np.float64)
    n = np.linalg.norm(v, axis=-1, keepdims=True)
    return v / np.where(n > 0.0, n, 1.0)


def _xyz_to_rgb(xyz):
    """kernel/util/colorspace.h xyz_to_rgb_clamped with Blender 5.0.1's matrix."""
    return np.maximum(xyz @ XYZ_TO_REC709.T, 0.0)


def _direction_angles(directions):
    """(unit directions, polar angle from +Z, azimuth atan2(y, x)) of (..., 3) directions."""
    d = _unit(directions)
    theta = np.arccos(np.clip(d[..., 2], -1.0, 1.0))
    phi = np.arctan2(d[..., 1], d[..., 0])
    return d, theta, phi


def _sun_vector(elevation, rotation):
    """The kernel's sun direction from the wrapped angles: spherical (elevation - pi/2,
    rotation - pi/2), i.e. azimuth atan2(y, x) = rotation + pi/2 (+Y at rotation 0 of the node)."""
    ce = math.cos(elevation)
    return np.array([-ce * math.sin(rotation), ce * math.cos(rotation), math.sin(elevation)])


def _sphere_exit(origin_dot_dir, origin_len2, radius):
    """Distance along a unit ray from a point inside a sphere (centred at the origin) to its
    surface: the larger root of |o + t d|^2 = radius^2."""
    disc = origin_dot_dir * origin_dot_dir - (origin_len2 - radius * radius)
    return -origin_dot_dir + np.sqrt(np.maximum(disc, 0.0))


def _ray_sphere(origin_dot_dir, origin_len2, radius):
    """sky_math.h ray_sphere_intersection: -1 for a miss (or a sphere behind an outside point),
    the near root from outside, the far root from inside."""
    b = np.asarray(origin_dot_dir, dtype=np.float64)
    c = np.asarray(origin_len2, dtype=np.float64) - radius * radius
    d = b * b - c
    root = np.sqrt(np.maximum(d, 0.0))
    t = np.where(d >= b * b, -b + root, -b - root)
    return np.where(((c > 0.0) & (b > 0.0)) | (d < 0.0), -1.0, t)


def _ray_sphere_f32(r0, sin_elevation, radius):
    """_ray_sphere from (0, 0, r0) along directions of elevation arcsin(sin_elevation), in float32
    operation by operation as Cycles computes it (no FMA): |o|^2 - radius^2 cancels badly near the
    ground (at 100 m, 1274 km^2 from two numbers of 4e7 whose float32 spacing is 4), and the
    ground distance of near-horizontal rays follows Cycles' rounding, not the exact value."""
    f = np.float32
    b = f(r0) * np.asarray(sin_elevation, dtype=np.float64).astype(f)
    c = f(f(r0) * f(r0)) - f(f(radius) * f(radius))
    b2 = b * b
    d = b2 - c
    root = np.sqrt(np.maximum(d, f(0.0)))
    t = np.where(d >= b2, -b + root, -b - root)
    return np.where(((c > 0.0) & (b > 0.0)) | (d < 0.0), -1.0, t.astype(np.float64))


# ------------------------------------------------------------------------------ single scattering
def _ss_densities(height):
    """(..., 3) Rayleigh, Mie and ozone density factors at heights above sea level (m)."""
    return np.stack([np.exp(-height / _SS_RAYLEIGH_SCALE), np.exp(-height / _SS_MIE_SCALE),
                     np.maximum(0.0, 1.0 - np.abs(height - 25000.0) / 15000.0)], axis=-1)


def _ss_optical_depth_to_space(p_len2, p_dot_dir):
    """Optical depth factors (..., 3) from points (given |P|^2 and P.d, d a unit direction) to
    the top of the atmosphere along d, by Blender's Gauss-Laguerre rule."""
    length = _sphere_exit(p_dot_dir, p_len2, _SS_ATMOSPHERE_RADIUS)
    s = _SS_QUAD_NODES * length[..., None]
    heights = np.sqrt(p_len2[..., None] + 2.0 * s * p_dot_dir[..., None] + s * s) - _SS_EARTH_RADIUS
    return np.einsum("...kc,k->...c", _ss_densities(heights), _SS_QUAD_WEIGHTS) * length[..., None]


def _ss_sun_xyz(elevation, altitude, air, aerosol, solid_angle):
    """The sun's XYZ radiance seen at ``elevation`` through the atmosphere (no ozone, as Blender)."""
    r0 = _SS_EARTH_RADIUS + altitude
    depth = _ss_optical_depth_to_space(np.array(r0 * r0), np.array(r0 * math.sin(elevation)))
    tau = _SS_RAYLEIGH_COEFF * depth[0] * air + 1.11 * _SS_MIE_COEFF * depth[1] * aerosol
    spectrum = _SS_IRRADIANCE * np.exp(-tau) / solid_angle
    return _SS_STEP_LAMBDA * spectrum @ _SS_CMF


def _ss_rows(rows, r0, sun, scale):
    """XYZ (len(rows), 256, 3) of the single-scattering table's left half (rows above the horizon)."""
    half_w, half_h = LUT_WIDTH // 2, LUT_HEIGHT // 2
    g2 = _SS_MIE_G * _SS_MIE_G
    extinction = np.stack([_SS_RAYLEIGH_COEFF, np.full(21, 1.11 * _SS_MIE_COEFF), _SS_OZONE_COEFF])  # (3, 21)
    longitude = 2.0 * math.pi / LUT_WIDTH * np.arange(half_w) - math.pi
    latitude = math.pi / 2 * (rows / half_h - 1.0) ** 2
    sin_lat, cos_lat = np.sin(latitude), np.cos(latitude)
    # The view ray to the top of the atmosphere, cut into segments evaluated at their middle.
    segment = _sphere_exit(r0 * sin_lat, r0 * r0, _SS_ATMOSPHERE_RADIUS) / _SS_STEPS  # (R,)
    s = segment[:, None] * (np.arange(_SS_STEPS) + 0.5)  # (R, S) distance to each middle
    p_len2 = r0 * r0 + 2.0 * s * r0 * sin_lat[:, None] + s * s
    density = _ss_densities(np.sqrt(p_len2) - _SS_EARTH_RADIUS) * scale  # (R, S, 3)
    view_depth = np.cumsum(density, axis=1) * segment[:, None, None]  # up to the segment's end

    # Per view direction (R, C): the phase functions; per sample (R, C, S): P.sun.
    mu = cos_lat[:, None] * np.cos(longitude) * sun[0] + sin_lat[:, None] * sun[2]
    phase_r = 3.0 / (16.0 * math.pi) * (1.0 + mu * mu)
    phase_m = (3.0 * (1.0 - g2) * (1.0 + mu * mu)
               / (8.0 * math.pi * (2.0 + g2) * (1.0 + g2 - 2.0 * _SS_MIE_G * mu) ** 1.5))
    p_dot_sun = s[:, None, :] * mu[:, :, None] + r0 * sun[2]
    p_len2_b = np.broadcast_to(p_len2[:, None, :], p_dot_sun.shape)
    light_depth = _ss_optical_depth_to_space(p_len2_b, p_dot_sun) * scale  # (R, C, S, 3)
    light_depth += view_depth[:, None]
    attenuation = np.exp(-(light_depth @ extinction))  # (R, C, S, 21)
    if sun[2] < 0.0:  # Blender's test: a sun below the horizontal plane may be behind the Earth
        b = 2.0 * p_dot_sun
        shadowed = b * b - 4.0 * (p_len2_b - _SS_EARTH_RADIUS ** 2) >= 0.0
        attenuation[shadowed] = 0.0
    rayleigh = np.einsum("rcsw,rs->rcw", attenuation, density[..., 0])
    mie = np.einsum("rcsw,rs->rcw", attenuation, density[..., 1])
    spectrum = (phase_r[..., None] * rayleigh * _SS_RAYLEIGH_COEFF
                + phase_m[..., None] * mie * _SS_MIE_COEFF) * _SS_IRRADIANCE * segment[:, None, None]
    return _SS_STEP_LAMBDA * spectrum @ _SS_CMF


def single_scattering_lut(sun_elevation, altitude, air, aerosol, ozone, rows_per_chunk=4, workers=None):
    """The (256, 512, 3) XYZ table of SKY_single_scattering_precompute_texture: row r (from the
    bottom) at latitude pi/2 (r/128 - 1)^2, column c < 256 at longitude 2 pi c/512 - pi from the
    sun (c >= 256 mirrors 511 - c); 32 steps along the view ray, the sun's optical depth by the
    Gauss-Laguerre rule; the lower half is the horizon row faded out. Blocks of rows run on
    ``workers`` threads (None: up to 4, the CPU count)."""
    altitude = min(max(altitude, 1.0), 59999.0)
    half_w, half_h = LUT_WIDTH // 2, LUT_HEIGHT // 2
    r0 = _SS_EARTH_RADIUS + altitude
    sun = np.array([math.cos(sun_elevation), 0.0, math.sin(sun_elevation)])
    scale = np.array([air, aerosol, ozone])
    lut = np.zeros((LUT_HEIGHT, LUT_WIDTH, 3))

    def block(start):
        rows = np.arange(start, min(start + rows_per_chunk, LUT_HEIGHT))
        xyz = _ss_rows(rows, r0, sun, scale)
        lut[rows, :half_w] = xyz
        lut[rows, half_w:] = xyz[:, ::-1]

    _run_blocks(block, range(half_h, LUT_HEIGHT, rows_per_chunk), workers)
    # Below the horizon: the horizon row, faded by the mirrored latitude's height.
    rows = np.arange(half_h)
    z = np.sin(math.pi / 2 * (rows / half_h - 1.0) ** 2)
    fade = np.where(z < 0.4, (1.0 - 2.5 * z) ** 3, 0.0)
    lut[:half_h] = lut[half_h][None] * fade[:, None, None]
    return lut


def single_scattering_sun(sun_elevation, angular_diameter, altitude, air, aerosol):
    """(XYZ at the disc's bottom, XYZ at its top) as SKY_single_scattering_precompute_sun: black
    when the disc's top is below the horizon, the bottom clamped to the horizon."""
    altitude = min(max(altitude, 1.0), 59999.0)
    half = angular_diameter / 2.0
    solid_angle = 2.0 * math.pi * (1.0 - math.cos(half))
    bottom, top = max(sun_elevation - half, 0.0), max(sun_elevation + half, 0.0)
    if top <= 0.0:
        return np.zeros(3), np.zeros(3)
    return tuple(_ss_sun_xyz(e, altitude, air, aerosol, solid_angle) for e in (bottom, top))


# ---------------------------------------------------------------------------- multiple scattering
class _Atmosphere:
    """The multiple-scattering model's atmosphere (altitudes in km) with its transmittance table."""

    def __init__(self, air, aerosol, ozone):
        # Each collision coefficient is a fixed spectrum (4,) times a profile of the altitude.
        self.molecular = _MS_MOLECULAR_SCATTERING * air
        self.ozone = _MS_OZONE_CROSS_SECTION * _MS_OZONE_MEAN_DOBSON * 3.78547397e20 * ozone
        self.aerosol_scattering = _MS_AEROSOL_SCATTERING * _MS_AEROSOL_BASE_DENSITY * aerosol
        self.aerosol = (_MS_AEROSOL_SCATTERING + _MS_AEROSOL_ABSORPTION) * _MS_AEROSOL_BASE_DENSITY * aerosol
        self._table = None

    @staticmethod
    def profiles(altitude):
        """The altitude profiles (molecules, ozone, aerosols) of the collision coefficients."""
        molecular = np.exp(-0.07771971 * altitude ** 1.16364243)
        log_h = np.log(np.maximum(altitude, 1e-4))
        ozone = np.exp(-(log_h - 3.22261) ** 2 * 5.55555555 - log_h)
        background = _MS_AEROSOL_BACKGROUND_DENSITY / _MS_AEROSOL_BASE_DENSITY
        aerosol = np.exp(-altitude / _MS_AEROSOL_HEIGHT_SCALE) + background
        return molecular, ozone, aerosol

    def extinction(self, profiles):
        """(..., 4) extinction from the altitude profiles (..., 3 arrays)."""
        m, o, a = (p[..., None] for p in profiles)
        return self.molecular * m + self.ozone * o + self.aerosol * a

    def transmittance(self, cos_zenith, normalized_altitude):
        """(..., 4) transmittance to space towards a sun at zenith cosine ``cos_zenith`` from
        ``normalized_altitude`` (0 ground, 1 top), marched in 64 midpoint steps."""
        cos_zenith, normalized_altitude = np.broadcast_arrays(np.asarray(cos_zenith, np.float64),
                                                              np.asarray(normalized_altitude, np.float64))
        radius = _MS_EARTH_RADIUS + normalized_altitude * _MS_ATMOSPHERE_THICKNESS
        length = _ray_sphere(radius * cos_zenith, radius * radius, _MS_ATMOSPHERE_RADIUS)
        dt = length / _MS_TRANSMITTANCE_STEPS
        t = dt[..., None] * (np.arange(_MS_TRANSMITTANCE_STEPS) + 0.5)
        # |origin + t sun|, the origin (0, 0, radius) and the sun direction (-sin, 0, cos).
        distance = np.sqrt(radius[..., None] ** 2 + 2.0 * t * (radius * cos_zenith)[..., None] + t * t)
        profiles = self.profiles(np.maximum(distance - _MS_EARTH_RADIUS, 0.0))
        depth = self.extinction([p.sum(axis=-1) for p in profiles])
        return np.exp(-depth * dt[..., None])

    def table(self):
        """The 64 x 256 transmittance table, channel-major with the last column repeated (so a
        texel's right neighbour is always the next one): (4, 64, 257). Rows: altitude 0..1;
        columns: zenith cosine -1..1."""
        if self._table is None:
            ny, nx = _MS_TRANSMITTANCE_SIZE
            v = np.arange(ny) / (ny - 1)
            u = np.arange(nx) / (nx - 1)
            table = np.empty((ny, nx + 1, 4))
            for row in range(0, ny, 4):  # small blocks: cheap on memory
                table[row:row + 4, :nx] = self.transmittance(u * 2.0 - 1.0, v[row:row + 4, None])
            table[:, nx] = table[:, nx - 1]
            self._table = np.ascontiguousarray(table.transpose(2, 0, 1))
        return self._table

    def lookup_rows(self, cos_zenith, normalized_altitude):
        """Bilinear look-ups in the table (the model's own: corner-aligned, clamped) at zenith
        cosines (R, C, S) and altitudes (R, S) shared along C; and the altitude-0 row at the same
        cosines. Returns two lists of 4 channel arrays (R, C, S): (T, T_ground)."""
        table = self.table()
        ny, nx = _MS_TRANSMITTANCE_SIZE
        r, s = normalized_altitude.shape
        y = (ny - 1) * np.clip(normalized_altitude, 0.0, 1.0)
        y0 = y.astype(np.int64)
        y1, fy = np.minimum(y0 + 1, ny - 1), (y - y0)[..., None]
        x = (nx - 1) * np.clip(cos_zenith * 0.5 + 0.5, 0.0, 1.0)
        x0 = x.astype(np.int64)
        fx = x - x0
        # Each (R, S) altitude's row, interpolated once; then one gather per texel pair.
        index = np.arange(r * s).reshape(r, 1, s) * (nx + 1) + x0
        to_sun, to_ground = [], []
        for channel in table:
            row = channel[y0]
            row += (channel[y1] - row) * fy
            row = row.reshape(-1)
            for source, index_k, out in ((row, index, to_sun), (channel[0], x0, to_ground)):
                value = source.take(index_k)
                step = source.take(index_k + 1)
                step -= value
                step *= fx
                step += value
                out.append(step)
        return to_sun, to_ground

    def lookup_zenith(self, normalized_altitude):
        """The table's zenith column (sun straight up), interpolated in altitude: (..., 4)."""
        column = self.table()[:, :, -1].T
        ny = column.shape[0]
        y = (ny - 1) * np.clip(np.asarray(normalized_altitude, np.float64), 0.0, 1.0)
        y0 = y.astype(np.int64)
        fy = (y - y0)[..., None]
        return column[y0] * (1.0 - fy) + column[np.minimum(y0 + 1, ny - 1)] * fy


def _ms_rows(atmosphere, rows, r0, sun):
    """XYZ (len(rows), 256, 3) of the multiple-scattering table's left half (azimuth < pi)."""
    width, height = LUT_WIDTH, LUT_HEIGHT
    g2 = _MS_G * _MS_G
    azimuth = 2.0 * math.pi * (np.arange(width // 2) + 0.5) / width
    l = 2.0 * (rows + 0.5) / height - 1.0
    elevation = np.copysign(l * l, l) * (math.pi / 2)
    sin_e, cos_e = np.sin(elevation), np.cos(elevation)
    # Distance to march (R,): to the ground where the ray meets it, else to space.
    to_space = _ray_sphere_f32(r0, sin_e, _MS_ATMOSPHERE_RADIUS)
    to_earth = _ray_sphere_f32(r0, sin_e, _MS_EARTH_RADIUS)
    dt = np.where(to_earth < 0.0, to_space, to_earth) / _MS_INSCATTERING_STEPS
    t = dt[:, None] * (np.arange(_MS_INSCATTERING_STEPS) + 0.5)  # (R, S)
    radius = np.sqrt(r0 * r0 + 2.0 * t * r0 * sin_e[:, None] + t * t)
    altitude = np.maximum(radius - _MS_EARTH_RADIUS, 0.0)
    normalized = altitude / _MS_ATMOSPHERE_THICKNESS
    profiles = atmosphere.profiles(altitude)
    extinction = atmosphere.extinction(profiles)  # (R, S, 4)
    molecular = atmosphere.molecular * profiles[0][..., None]
    aerosol = atmosphere.aerosol_scattering * profiles[2][..., None]
    # Hillaire's step integral: each step adds S (1 - T_step) / extinction times the
    # transmittance before it.
    step = np.exp(-dt[:, None, None] * extinction)
    before = np.cumprod(np.concatenate([np.ones_like(step[:, :1]), step[:, :-1]], axis=1), axis=1)
    weight = before * (1.0 - step) / np.maximum(extinction, 1e-7)
    wm, wa = weight * molecular, weight * aerosol
    # Light scattered once off the ground into the multiple-scattering term, less its
    # sun-angle factor T_ground(cos) cos: isotropic phase x planet solid angle x albedo / pi x
    # transmittance ground -> sample (from the zenith column: T(0) / T(h)).
    omega = 2.0 * math.pi * (1.0 - np.sqrt(np.maximum(1.0 - (_MS_EARTH_RADIUS / radius) ** 2, 0.0)))
    ground = ((_MS_GROUND_ALBEDO / (4.0 * math.pi * math.pi)) * omega[..., None]
              * atmosphere.lookup_zenith(0.0) / atmosphere.lookup_zenith(normalized))
    w_ms = (wm + wa) * ground  # (R, S, 4)
    w_fit = (wm + wa) * _MS_FIT_COLOUR

    # Per view ray (R, C): phase functions; per sample (R, C, S): the sun's zenith cosine.
    view_dot_sun = cos_e[:, None] * np.cos(azimuth) * sun[0] + sin_e[:, None] * sun[2]
    cos_theta = -view_dot_sun  # angle between the sun's direction and the way back along the ray
    phase_m = 3.0 / (16.0 * math.pi) * (1.0 + cos_theta ** 2)
    den = 1.0 + g2 + 2.0 * _MS_G * cos_theta
    phase_a = (1.0 - g2) / (4.0 * math.pi * den * np.sqrt(den))
    sample_cos = (t[:, None, :] * view_dot_sun[:, :, None] + r0 * sun[2]) / radius[:, None, :]
    to_sun, to_ground = atmosphere.lookup_rows(sample_cos, normalized)
    fit = 1.0 / (1.0 + 5.0 * np.exp(-17.92 * sample_cos))
    radiance = fit @ w_fit  # (R, C, 4): the multiple-scattering fit
    for k in range(4):
        sun_terms = to_sun[k] @ np.stack([wm[..., k], wa[..., k]], axis=-1)  # (R, C, 2)
        to_ground[k] *= sample_cos
        radiance[..., k] += (phase_m * sun_terms[..., 0] + phase_a * sun_terms[..., 1]
                             + (to_ground[k] @ w_ms[..., k, None])[..., 0])
    return (radiance * _MS_SUN_IRRADIANCE) @ _MS_SPECTRAL_XYZ


def multiple_scattering_lut(sun_elevation, altitude, air, aerosol, ozone, rows_per_chunk=8, workers=1):
    """The (256, 512, 3) XYZ table of SKY_multiple_scattering_precompute_texture: texel (c, r) at
    azimuth 2 pi (c + 0.5)/512 (the sun at pi) and elevation sign(l) l^2 pi/2, l = 2 (r + 0.5)/256
    - 1 (r from the bottom); in-scattering marched in 64 steps with Hillaire's energy-conserving
    step integral: single scattering, the model's fit of the multiple scattering, and light
    scattered once off a grey (0.3) ground. Blocks of rows run on ``workers`` threads (None: up
    to 4, the CPU count; 1 by default: its batched matrix products use BLAS' own threads, and
    more Python threads only contend for the GIL)."""
    atmosphere = _Atmosphere(air, aerosol, ozone)
    atmosphere.table()
    altitude = min(max(altitude, 1.0), 99999.0) / 1000.0
    # The observer's distance from the Earth's centre as Cycles has it: in float32 (at 10 m the
    # rounding alone is 2 % of the altitude).
    r0 = float(np.float32(_MS_EARTH_RADIUS) + np.float32(altitude))
    sun_cos = math.cos(math.pi / 2 - sun_elevation)
    sun = np.array([-math.sqrt(max(1.0 - sun_cos * sun_cos, 0.0)), 0.0, sun_cos])
    half_w = LUT_WIDTH // 2
    lut = np.empty((LUT_HEIGHT, LUT_WIDTH, 3))

    def block(start):
        rows = np.arange(start, min(start + rows_per_chunk, LUT_HEIGHT))
        xyz = _ms_rows(atmosphere, rows, r0, sun)
        lut[rows, :half_w] = xyz
        lut[rows, half_w:] = xyz[:, ::-1]  # mirrored about the sun's azimuth

    _run_blocks(block, range(0, LUT_HEIGHT, rows_per_chunk), workers)
    return lut


def multiple_scattering_sun(sun_elevation, angular_diameter, altitude, air, aerosol, ozone):
    """(XYZ at the disc's bottom, XYZ at its top) as SKY_multiple_scattering_precompute_sun (the
    transmittance marched directly, not from the table; no horizon test)."""
    atmosphere = _Atmosphere(air, aerosol, ozone)
    altitude = min(max(altitude, 1.0), 99999.0) / 1000.0
    half = angular_diameter / 2.0
    solid_angle = 2.0 * math.pi * (1.0 - math.cos(half))
    out = []
    for e in (sun_elevation - half, sun_elevation + half):
        transmittance = atmosphere.transmittance(math.cos(math.pi / 2 - e), altitude / _MS_ATMOSPHERE_THICKNESS)
        out.append((_MS_SUN_IRRADIANCE * transmittance / solid_angle) @ _MS_SPECTRAL_XYZ)
    return tuple(out)


def _run_blocks(function, starts, workers):
    """function(start) for every start, on a few threads."""
    starts = list(starts)
    if workers is None:
        workers = min(4, os.cpu_count() or 1)
    if workers <= 1:
        for start in starts:
            function(start)
        return
    with ThreadPoolExecutor(workers) as pool:
        for future in [pool.submit(function, start) for start in starts]:
            future.result()


def sample_lut(lut, u, v):
    """Cycles' linear image look-up with extension EXTEND: texel centres at (i + 0.5) / N, the
    neighbours clamped to the edge (no wrap, in either axis)."""
    h, w = lut.shape[:2]
    x, y = u * w - 0.5, v * h - 0.5
    x0, y0 = np.floor(x), np.floor(y)
    tx, ty = (x - x0)[..., None], (y - y0)[..., None]
    x0, y0 = x0.astype(np.int64), y0.astype(np.int64)
    xa, xb = np.clip(x0, 0, w - 1), np.clip(x0 + 1, 0, w - 1)
    ya, yb = np.clip(y0, 0, h - 1), np.clip(y0 + 1, 0, h - 1)
    flat = lut.reshape(h * w, -1)
    return ((1.0 - ty) * ((1.0 - tx) * flat[ya * w + xa] + tx * flat[ya * w + xb])
            + ty * ((1.0 - tx) * flat[yb * w + xa] + tx * flat[yb * w + xb]))


# ------------------------------------------------------------------------------------- Preetham
def _perez(coefficients, theta, gamma):
    a, b, c, d, e = coefficients
    return (1.0 + a * np.exp(b / np.cos(theta))) * (1.0 + c * np.exp(d * gamma) + e * np.cos(gamma) ** 2)


class _Preetham:
    def __init__(self, sun_direction, turbidity):
        sun = np.asarray(sun_direction, dtype=np.float64)
        n = float(np.linalg.norm(sun))
        sun = sun / n if n > 0.0 else np.array([0.0, 0.0, 1.0])
        self.theta = math.acos(max(-1.0, min(1.0, sun[2])))
        self.phi = math.atan2(sun[0], sun[1])  # measured from +Y towards +X, as Cycles
        t, th = turbidity, self.theta
        chi = (4.0 / 9.0 - t / 120.0) * (math.pi - 2.0 * th)
        zenith_luminance = 0.06 * ((4.0453 * t - 4.9710) * math.tan(chi) - 0.2155 * t + 2.4192)
        powers_t, powers_th = np.array([t * t, t, 1.0]), np.array([th ** 3, th ** 2, th, 1.0])
        zenith = np.array([zenith_luminance, powers_t @ _PREETHAM_ZENITH_X @ powers_th,
                           powers_t @ _PREETHAM_ZENITH_Y @ powers_th])
        self.perez = _PREETHAM_PEREZ[..., 0] * t + _PREETHAM_PEREZ[..., 1]  # (Y x y, A..E)
        # Normalised so that the zenith has the fitted zenith values.
        self.zenith = zenith / np.array([_perez(c, 0.0, th) for c in self.perez])

    def radiance(self, directions):
        _, theta, phi = _direction_angles(directions)
        phi = math.pi / 2 - phi
        cos_gamma = (np.sin(theta) * math.sin(self.theta) * np.cos(self.phi - phi)
                     + np.cos(theta) * math.cos(self.theta))
        gamma = np.arccos(np.clip(cos_gamma, -1.0, 1.0))
        theta = np.minimum(theta, math.pi / 2 - 0.001)
        big_y, x, y = (self.zenith[i] * _perez(self.perez[i], theta, gamma) for i in range(3))
        safe_y = np.where(y != 0.0, y, 1.0)
        xyz = np.stack([np.where(y != 0.0, x / safe_y * big_y, 0.0), big_y,
                        np.where((y != 0.0) & (big_y != 0.0), (1.0 - x - y) / safe_y * big_y, 0.0)], -1)
        return _xyz_to_rgb(xyz)


# ------------------------------------------------------------------------------------------ Sky
class Sky:
    """A Sky Texture as Cycles shades it (the node's Color output; Vector unlinked, identity
    texture mapping)."""

    def __init__(self, params: SkyParams):
        if params.sky_type not in SKY_TYPES:
            raise ValueError(f"sky type {params.sky_type!r} is not supported (supported: {', '.join(SKY_TYPES)})")
        self.params = params
        self.preetham = None
        self.lut = None
        if params.sky_type == "PREETHAM":
            self.preetham = _Preetham(params.sun_direction, params.turbidity)
            return
        p = params
        self.sun_elevation, self.sun_rotation = wrap_sun_angles(p.sun_elevation, p.sun_rotation)
        self.angular_diameter = max(p.sun_size, MIN_SUN_SIZE)
        self.earth_angle = earth_intersection_angle(p.altitude)
        if p.sky_type == "MULTIPLE_SCATTERING":
            self.lut = multiple_scattering_lut(self.sun_elevation, p.altitude, p.air_density,
                                               p.aerosol_density, p.ozone_density)
            self.pixel_bottom, self.pixel_top = multiple_scattering_sun(
                self.sun_elevation, self.angular_diameter, p.altitude, p.air_density, p.aerosol_density,
                p.ozone_density)
        else:
            self.lut = single_scattering_lut(self.sun_elevation, p.altitude, p.air_density,
                                             p.aerosol_density, p.ozone_density)
            self.pixel_bottom, self.pixel_top = single_scattering_sun(
                self.sun_elevation, self.angular_diameter, p.altitude, p.air_density, p.aerosol_density)

    def sky_xyz(self, directions):
        """The table's XYZ for (..., 3) directions (scattering models only), as the kernel looks
        it up: u = fract((-phi - pi/2 + rotation) / 2 pi) with phi = atan2(y, x); v from the
        elevation through the table's square-root mapping."""
        _, theta, phi = _direction_angles(directions)
        u = (-phi - math.pi / 2 + self.sun_rotation) / (2.0 * math.pi)
        u = u - np.floor(u)
        elevation = math.pi / 2 - theta
        v = np.copysign(np.sqrt(np.abs(elevation) * (2.0 / math.pi)), elevation) * 0.5 + 0.5
        return sample_lut(self.lut, u, v)

    def radiance(self, directions) -> np.ndarray:
        """(N, 3) (or (..., 3)) world directions, Z up, any length but zero (they are normalised
        here) -> linear Rec.709 radiance (float64) as Cycles' Sky Texture Color output, WITHOUT
        the sun disc (``sun()`` describes it)."""
        directions = np.asarray(directions, dtype=np.float64)
        flat = directions.reshape(-1, 3)
        out = np.empty(flat.shape)
        evaluate = self.preetham.radiance if self.preetham is not None else lambda d: _xyz_to_rgb(self.sky_xyz(d))
        for start in range(0, len(flat), _CHUNK):  # blocks: the temporaries stay small
            out[start:start + _CHUNK] = evaluate(flat[start:start + _CHUNK])
        return out.reshape(directions.shape)

    def sun_direction(self):
        """Unit vector towards the sun's centre (Preetham: the node's normalised Sun Direction)."""
        if self.preetham is not None:
            t, phi = self.preetham.theta, self.preetham.phi
            return np.array([math.sin(t) * math.sin(phi), math.sin(t) * math.cos(phi), math.cos(t)])
        return _sun_vector(self.sun_elevation, self.sun_rotation)

    def disc_xyz(self, directions):
        """The disc's XYZ (without the sky) at (..., 3) directions as the kernel draws it: zero
        outside the disc and below the earth-intersection angle."""
        p = self.params
        d, theta, _ = _direction_angles(directions)
        sun = self.sun_direction()
        # precise_angle: 2 atan2(|a - b|, |a + b|)
        angle = 2.0 * np.arctan2(np.linalg.norm(d - sun, axis=-1), np.linalg.norm(d + sun, axis=-1))
        half = self.angular_diameter * 0.5
        elevation = math.pi / 2 - theta
        inside = p.sun_disc & (angle < half) & (elevation > -self.earth_angle)
        y = ((elevation - self.sun_elevation) / self.angular_diameter + 0.5)[..., None]
        limb = 1.0 - 0.6 * (1.0 - np.sqrt(np.maximum(1.0 - (angle / half) ** 2, 0.0)))
        xyz = (self.pixel_bottom + (self.pixel_top - self.pixel_bottom) * y) * (p.sun_intensity * limb)[..., None]
        return np.where(inside[..., None], xyz, 0.0)

    def sun(self, rings=256, sectors=512):
        """None where Cycles draws no disc (sun_disc off, Preetham, or all of the disc below the
        horizon as Cycles cuts it, or black); else (direction: unit (3,) towards the sun's centre,
        angular_diameter: radians (the node's size, at least 0.0005), mean_rgb: (3,) linear Rec.709
        radiance of the disc over the sky, averaged over the disc's whole solid angle
        2 pi (1 - cos(angular_diameter / 2)), so that mean_rgb times that solid angle is the
        disc's power per unit area; the parts Cycles cuts off count as black)."""
        if self.preetham is not None or not self.params.sun_disc:
            return None
        half = self.angular_diameter * 0.5
        if self.sun_elevation + half <= -self.earth_angle:
            return None
        sun = self.sun_direction()
        # Quadrature over the disc: rings of equal angular width (weights: their exact solid
        # angle), sectors of equal azimuth, each evaluated at its centre.
        edges = np.linspace(0.0, half, rings + 1)
        rho = 0.5 * (edges[1:] + edges[:-1])
        ring_weight = np.cos(edges[:-1]) - np.cos(edges[1:])
        psi = (np.arange(sectors) + 0.5) * (2.0 * math.pi / sectors)
        helper = np.array([1.0, 0.0, 0.0]) if abs(sun[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
        e1 = np.cross(sun, helper)
        e1 /= np.linalg.norm(e1)
        e2 = np.cross(sun, e1)
        ring_dir = np.cos(psi)[:, None] * e1 + np.sin(psi)[:, None] * e2  # (P, 3)
        dirs = (np.cos(rho)[:, None, None] * sun + np.sin(rho)[:, None, None] * ring_dir[None])  # (K, P, 3)
        sky = self.sky_xyz(dirs)
        disc = _xyz_to_rgb(sky + self.disc_xyz(dirs)) - _xyz_to_rgb(sky)
        mean = np.einsum("kpc,k->c", disc, ring_weight) / sectors / (1.0 - math.cos(half))
        # A channel the clamp at zero keeps dark can come out a hair below zero: no light is
        # negative.
        mean = np.maximum(mean, 0.0)
        if not np.any(mean > 0.0):
            return None
        return sun, self.angular_diameter, mean
