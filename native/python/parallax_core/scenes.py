"""Procedural test and benchmark scenes (Blender coordinates: Z up, metres).

Every scene function takes ``width, height`` and returns a SceneData with a camera and that
resolution. The mesh builders are vectorised numpy: no Python loop per triangle.
"""
from __future__ import annotations

import math

import numpy as np

from .scene import (Camera, Light, Material, Mesh, SceneData, World,
                    equirectangular_to_direction)

__all__ = [
    "quad", "box", "uv_sphere", "merge",
    "cornell_box", "veach_mis", "furnace_sphere", "closed_emitter_box",
    "triangle_soup_scene", "many_emitters", "env_map_scene", "sun_room", "lamp_in_glass", "SCENES",
]


# ---- mesh builders ------------------------------------------------------------------------

def _mesh(positions, indices, material=0, name="", **kw):
    indices = np.asarray(indices, dtype=np.int64).reshape(-1, 3)
    return Mesh(np.asarray(positions, dtype=np.float64).reshape(-1, 3), indices,
                material_indices=np.full(len(indices), material, np.int64), name=name, **kw)


def quad(corners, material=0, name=""):
    """Two triangles from 4 corners in counter-clockwise order seen from the front side
    (the normal follows the right-hand rule)."""
    return _mesh(corners, [[0, 1, 2], [0, 2, 3]], material, name)


def box(center, size, rotation_z=0.0, material=0, name=""):
    """Closed box (12 triangles, outward winding, flat shaded) of full ``size`` (scalar or
    (sx,sy,sz)) centred at ``center``, rotated by ``rotation_z`` radians about +Z."""
    s = np.broadcast_to(np.asarray(size, dtype=np.float64), (3,))
    bits = np.array([[i & 1, (i >> 1) & 1, (i >> 2) & 1] for i in range(8)], np.float64)
    local = (bits - 0.5) * s
    c, si = math.cos(rotation_z), math.sin(rotation_z)
    rot = np.array([[c, -si, 0.0], [si, c, 0.0], [0.0, 0.0, 1.0]])
    positions = local @ rot.T + np.asarray(center, dtype=np.float64)
    # Faces as CCW quads seen from outside (vertex id = x + 2y + 4z).
    faces = np.array([[0, 2, 3, 1], [4, 5, 7, 6],   # -Z, +Z
                      [0, 1, 5, 4], [2, 6, 7, 3],   # -Y, +Y
                      [0, 4, 6, 2], [1, 3, 7, 5]])  # -X, +X
    tris = np.concatenate([faces[:, [0, 1, 2]], faces[:, [0, 2, 3]]])
    return _mesh(positions, tris, material, name)


def _sphere_grid(segments, rings):
    """Unit directions on a (rings+1) x (segments+1) latitude/longitude grid (seam and poles
    duplicated), their UVs, and the non-degenerate triangles: 2 * segments * (rings - 1),
    outward winding."""
    theta = np.linspace(0.0, np.pi, rings + 1)[:, None]       # from +Z down
    phi = np.linspace(0.0, 2.0 * np.pi, segments + 1)[None, :]
    st = np.sin(theta)
    dirs = np.stack(np.broadcast_arrays(st * np.cos(phi), st * np.sin(phi), np.cos(theta)),
                    axis=-1).reshape(-1, 3)
    uv = np.stack(np.broadcast_arrays(phi / (2 * np.pi), 1.0 - theta / np.pi),
                  axis=-1).reshape(-1, 2)
    i, j = np.meshgrid(np.arange(rings), np.arange(segments), indexing="ij")
    v00 = i * (segments + 1) + j
    v10, v01, v11 = v00 + segments + 1, v00 + 1, v00 + segments + 2
    lower = np.stack([v00, v10, v11], axis=-1)[:-1]    # degenerate in the bottom ring
    upper = np.stack([v00, v11, v01], axis=-1)[1:]     # degenerate in the top ring
    tris = np.concatenate([lower.reshape(-1, 3), upper.reshape(-1, 3)])
    return dirs, uv, tris


def uv_sphere(center=(0.0, 0.0, 0.0), radius=1.0, segments=48, rings=24, material=0, name=""):
    """UV sphere with smooth per-corner normals and UVs; 2 * segments * (rings - 1) triangles."""
    dirs, uv, tris = _sphere_grid(segments, rings)
    positions = np.asarray(center, dtype=np.float64) + radius * dirs
    return _mesh(positions, tris, material, name, normals=dirs[tris], uvs=uv[tris])


def merge(meshes, name=""):
    """One mesh from several (indices offset; normals/uvs kept only if all have them)."""
    offsets = np.cumsum([0] + [len(m.positions) for m in meshes])
    cat = lambda attr: (np.concatenate([getattr(m, attr) for m in meshes])
                        if all(getattr(m, attr) is not None for m in meshes) else None)
    return Mesh(np.concatenate([m.positions for m in meshes]),
                np.concatenate([np.asarray(m.indices) + o for m, o in zip(meshes, offsets)]),
                normals=cat("normals"), uvs=cat("uvs"),
                material_indices=np.concatenate(
                    [np.zeros(len(m.indices), np.int64) if m.material_indices is None
                     else m.material_indices for m in meshes]),
                name=name)


def _oriented_quad(corners, toward, material, name):
    """quad() whose front faces the point ``toward``."""
    c = np.asarray(corners, dtype=np.float64)
    n = np.cross(c[1] - c[0], c[2] - c[0])
    if np.dot(n, np.asarray(toward) - c.mean(axis=0)) < 0:
        c = c[::-1]
    return quad(c, material, name)


# ---- scenes -------------------------------------------------------------------------------

def cornell_box(width=256, height=256):
    """Cornell box: room x, y in [-1, 1], z in [0, 2], open towards -Y where the camera is;
    red wall at x = -1 (left), green at x = +1, an emissive quad just below the ceiling."""
    materials = [
        Material("diffuse", (0.725, 0.71, 0.68), name="white"),
        Material("diffuse", (0.63, 0.065, 0.05), name="red"),
        Material("diffuse", (0.14, 0.45, 0.091), name="green"),
        Material("emission", (0.0, 0.0, 0.0), emission=(17.0, 12.0, 4.0),
                 emission_strength=1.0, name="light"),
    ]
    inside = (0.0, 0.0, 1.0)
    P = lambda *c: np.array(c, dtype=np.float64)
    walls = {
        "floor": ([P(-1, -1, 0), P(1, -1, 0), P(1, 1, 0), P(-1, 1, 0)], 0),
        "ceiling": ([P(-1, -1, 2), P(1, -1, 2), P(1, 1, 2), P(-1, 1, 2)], 0),
        "back": ([P(-1, 1, 0), P(1, 1, 0), P(1, 1, 2), P(-1, 1, 2)], 0),
        "left": ([P(-1, -1, 0), P(-1, 1, 0), P(-1, 1, 2), P(-1, -1, 2)], 1),
        "right": ([P(1, -1, 0), P(1, 1, 0), P(1, 1, 2), P(1, -1, 2)], 2),
    }
    meshes = [_oriented_quad(c, inside, m, name) for name, (c, m) in walls.items()]
    meshes.append(box((0.33, -0.35, 0.3), 0.6, math.radians(-17.0), 0, "short_box"))
    meshes.append(box((-0.33, 0.3, 0.6), (0.6, 0.6, 1.2), math.radians(17.0), 0, "tall_box"))
    lx, ly, lz = 0.47 / 2, 0.38 / 2, 1.98
    meshes.append(_oriented_quad([P(-lx, -ly, lz), P(lx, -ly, lz), P(lx, ly, lz),
                                  P(-lx, ly, lz)], inside, 3, "light"))
    camera = Camera.look_at((0.0, -3.9, 1.0), (0.0, 0.0, 1.0), fov_y_degrees=39.3,
                            width=width, height=height, clip_start=0.1)
    return SceneData(meshes, [], materials, [], [], World((0.0, 0.0, 0.0), 1.0), camera,
                     width, height)


VEACH_ROUGHNESS = (0.1, 0.2, 0.35, 0.6)   # plates, top (far) to bottom (near)
VEACH_RADII = (0.03, 0.1, 0.3, 0.9)       # lights, left to right
VEACH_COLORS = ((1.0, 0.3, 0.3), (1.0, 0.8, 0.3), (0.3, 1.0, 0.4), (0.35, 0.5, 1.0))


def veach_mis(width=384, height=256, power=40.0):
    """Veach's MIS scene: four tilted rough conductor plates (roughness VEACH_ROUGHNESS, top
    to bottom) reflecting four sphere lights (radii VEACH_RADII, left to right) of equal
    ``power`` W and distinct colours; dark diffuse floor and back wall. The plates are tilted
    so the lights' mirror reflections reach the camera. Horizontal field of view is fixed."""
    cam, target = np.array([0.0, -15.0, 2.0]), np.array([0.0, -2.5, -2.0])
    light_center = np.zeros(3)
    materials = [Material("diffuse", (0.1, 0.1, 0.1), name="dark")]
    meshes = []
    centers = [(0.0, -0.6, -1.9), (0.0, -1.6, -2.5), (0.0, -2.8, -3.0), (0.0, -4.2, -3.4)]
    for k, (c, r) in enumerate(zip(centers, VEACH_ROUGHNESS)):
        c = np.array(c)
        to_cam = (cam - c) / np.linalg.norm(cam - c)
        to_light = (light_center - c) / np.linalg.norm(light_center - c)
        n = to_cam + to_light
        n /= np.linalg.norm(n)
        ex, ey = np.array([4.0, 0.0, 0.0]), 0.5 * np.cross(n, [1.0, 0.0, 0.0])
        corners = [c - ex - ey, c + ex - ey, c + ex + ey, c - ex + ey]
        materials.append(Material("conductor", (0.8, 0.8, 0.8), roughness=r, name=f"plate{k}"))
        meshes.append(_oriented_quad(corners, c + n, len(materials) - 1, f"plate{k}"))
    meshes.append(quad([(-20, -20, -4.5), (20, -20, -4.5), (20, 3, -4.5), (-20, 3, -4.5)],
                       0, "floor"))
    meshes.append(_oriented_quad([(-20, 3, -4.5), (20, 3, -4.5), (20, 3, 15), (-20, 3, 15)],
                                 cam, 0, "back_wall"))
    lights = [Light("point", color=col, power=power, position=(x, 0.0, 0.0), radius=rad,
                    name=f"light{k}")
              for k, (x, rad, col) in enumerate(zip((-3.75, -1.25, 1.25, 3.75), VEACH_RADII,
                                                    VEACH_COLORS))]
    half_x = math.tan(math.radians(14.0)) * 1.5
    fov_y = 2.0 * math.degrees(math.atan(half_x * height / width))
    camera = Camera.look_at(cam, target, fov_y_degrees=fov_y, width=width, height=height,
                            clip_start=0.1)
    return SceneData(meshes, [], materials, [], lights, World((0.0, 0.0, 0.0), 1.0), camera,
                     width, height)


def _rgb(v):
    return tuple(np.broadcast_to(np.asarray(v, dtype=np.float64), (3,)).tolist())


def furnace_sphere(albedo=0.5, width=128, height=128):
    """Diffuse UV sphere (smooth normals, 2208 triangles) under a uniform white world
    (radiance 1), no lights: every pixel converges to albedo (sphere) or 1 (background)."""
    mesh = uv_sphere((0.0, 0.0, 0.0), 1.0, 48, 24, 0, "sphere")
    camera = Camera.look_at((0.0, -4.0, 0.0), (0.0, 0.0, 0.0), fov_y_degrees=40.0,
                            width=width, height=height)
    return SceneData([mesh], [], [Material("diffuse", _rgb(albedo), name="furnace")], [], [],
                     World((1.0, 1.0, 1.0), 1.0), camera, width, height)


def closed_emitter_box(albedo=0.5, emission=1.0, width=64, height=64):
    """Camera inside a closed 2 m box whose walls are all diffuse ``albedo`` and emit
    ``emission`` (radiance). Every pixel converges to emission / (1 - albedo)."""
    mat = Material("diffuse", _rgb(albedo), emission=_rgb(emission), emission_strength=1.0,
                   name="emitter")
    camera = Camera.look_at((0.0, 0.0, 0.0), (0.0, 1.0, 0.0), fov_y_degrees=60.0,
                            width=width, height=height)
    return SceneData([box((0.0, 0.0, 0.0), 2.0, 0.0, 0, "box")], [], [mat], [], [],
                     World((0.0, 0.0, 0.0), 1.0), camera, width, height)


def _bumpy_radius(dirs, amplitude=0.08, waves=12, seed=1234):
    """Smooth pseudo-noise on the unit sphere: a sum of random plane waves."""
    rng = np.random.default_rng(seed)
    k = rng.normal(size=(waves, 3)) * rng.uniform(2.0, 12.0, size=(waves, 1))
    phase = rng.uniform(0.0, 2 * np.pi, size=waves)
    amp = 1.0 / np.linalg.norm(k, axis=1)
    noise = np.sin(dirs @ k.T + phase) @ amp / amp.sum()
    return 1.0 + amplitude * noise


def triangle_soup_scene(n_triangles=100_000, width=256, height=256, shuffle=False, seed=0):
    """Benchmark scene: a noise-displaced sphere of about ``n_triangles`` triangles (flat
    shaded) on a floor, lit by a 2 m square area light. ``shuffle`` randomly permutes the
    sphere's triangle order (seeded), leaving the geometry unchanged."""
    rings = max(2, int(round(math.sqrt(n_triangles / 4.0))) + 1)
    segments = max(3, int(round(n_triangles / (2.0 * (rings - 1)))))
    dirs, uv, tris = _sphere_grid(segments, rings)
    positions = dirs * _bumpy_radius(dirs)[:, None] + np.array([0.0, 0.0, 1.25])
    if shuffle:
        tris = tris[np.random.default_rng(seed).permutation(len(tris))]
    materials = [Material("diffuse", (0.5, 0.5, 0.5), name="floor"),
                 Material("diffuse", (0.6, 0.65, 0.8), name="sphere")]
    meshes = [quad([(-5, -5, 0), (5, -5, 0), (5, 5, 0), (-5, 5, 0)], 0, "floor"),
              _mesh(positions, tris, 1, "soup")]
    light = Light("area", power=300.0, position=(0.0, 0.0, 4.0), direction=(0.0, 0.0, -1.0),
                  shape="square", size=2.0, name="area")
    camera = Camera.look_at((0.0, -5.0, 2.5), (0.0, 0.0, 1.0), fov_y_degrees=40.0,
                            width=width, height=height)
    return SceneData(meshes, [], materials, [], [light], World((0.05, 0.05, 0.05), 1.0),
                     camera, width, height)


def many_emitters(n_emitters=1000, width=64, height=64, seed=0):
    """Light-selection scene: a diffuse floor under ``n_emitters`` small emissive triangles
    (8 strengths from 1 to 128, log-spaced; random orientations) scattered 0.3-1 m above
    it over 8 x 8 m, seen from above (the floor alone: see clip_start). Each floor point is lit
    mostly by the few emitters near it: where a light tree beats picking lights by power."""
    rng = np.random.default_rng(seed)
    centres = np.column_stack([rng.uniform(-4.0, 4.0, n_emitters), rng.uniform(-4.0, 4.0, n_emitters),
                               rng.uniform(0.3, 1.0, n_emitters)])
    corners = centres[:, None, :] + np.clip(0.06 * rng.normal(size=(n_emitters, 3, 3)), -0.2, 0.2)
    emitters = _mesh(corners.reshape(-1, 3), np.arange(3 * n_emitters).reshape(-1, 3), 0, "emitters")
    emitters.material_indices = rng.integers(1, 9, n_emitters)
    materials = [Material("diffuse", (0.7, 0.7, 0.7), name="floor")]
    materials += [Material("emission", emission=(2.0**k,) * 3, name=f"emission {2**k}") for k in range(8)]
    meshes = [quad([(-4.5, -4.5, 0), (4.5, -4.5, 0), (4.5, 4.5, 0), (-4.5, 4.5, 0)], 0, "floor"), emitters]
    # The camera sees the floor alone: the emitters (corners above z = 0.05) are nearer than
    # clip_start (depth 6.95 is z = 0.05), so pixel noise is the light sampling's, not that of
    # emitters partly covering pixels.
    camera = Camera.look_at((0.0, 0.0, 7.0), (0.0, 0.0, 0.0), up=(0.0, 1.0, 0.0), fov_y_degrees=60.0,
                            width=width, height=height, clip_start=6.95)
    return SceneData(meshes, [], materials, [], [], World((0.0, 0.0, 0.0), 1.0), camera, width, height)


def sky_map(map_width=512, sun_elevation=35.0, sun_azimuth=-50.0, sun_radiance=500.0,
            sun_sigma=2.0):
    """Procedural equirectangular (map_width/2, map_width, 3) float32 map in Blender's
    convention: a sky gradient, a dark ground and a small bright Gaussian "sun" blob
    (angles in degrees, azimuth = atan2(y, x) of the direction to the sun)."""
    h, w = map_width // 2, map_width
    u = (np.arange(w) + 0.5) / w
    v = 1.0 - (np.arange(h) + 0.5) / h
    d = equirectangular_to_direction(u[None, :], v[:, None])
    z = d[..., 2:3]
    horizon, zenith = np.array([0.9, 0.95, 1.0]), np.array([0.25, 0.45, 0.9])
    t = np.sqrt(np.clip(z, 0.0, 1.0))
    sky = np.where(z >= 0, horizon * (1 - t) + zenith * t, np.array([0.12, 0.11, 0.1]))
    e, a = math.radians(sun_elevation), math.radians(sun_azimuth)
    sun = np.array([math.cos(e) * math.cos(a), math.cos(e) * math.sin(a), math.sin(e)])
    angle = np.degrees(np.arccos(np.clip(d @ sun, -1.0, 1.0)))
    blob = sun_radiance * np.exp(-(angle / sun_sigma) ** 2)
    return (sky + blob[..., None] * np.array([1.0, 0.95, 0.85])).astype(np.float32)


def env_map_scene(width=256, height=256, map_width=512, sun_elevation=35.0,
                  sun_azimuth=-50.0, sun_radiance=500.0):
    """Diffuse sphere on a floor under ``sky_map(...)`` (no lights): for environment map
    importance sampling."""
    materials = [Material("diffuse", (0.5, 0.5, 0.5), name="floor"),
                 Material("diffuse", (0.8, 0.8, 0.8), name="sphere")]
    meshes = [quad([(-4, -4, 0), (4, -4, 0), (4, 4, 0), (-4, 4, 0)], 0, "floor"),
              uv_sphere((0.0, 0.0, 1.0), 1.0, 48, 24, 1, "sphere")]
    world = World((0.0, 0.0, 0.0), 1.0,
                  sky_map(map_width, sun_elevation, sun_azimuth, sun_radiance))
    camera = Camera.look_at((0.0, -6.0, 2.5), (0.0, 0.0, 0.9), fov_y_degrees=40.0,
                            width=width, height=height)
    return SceneData(meshes, [], materials, [], [], world, camera, width, height)


# Sun room (metres, Z up): the room spans x in [-SUN_ROOM_SIZE[0]/2, +...], likewise y, and
# z in [0, SUN_ROOM_SIZE[2]]; the window is a hole in the +X wall (centre y, centre z,
# width, height); the sun stands SUN_ROOM_SUN_ELEVATION degrees above the horizon, in the
# direction of azimuth SUN_ROOM_SUN_AZIMUTH degrees (atan2(y, x)): outside the window.
SUN_ROOM_SIZE = (4.0, 5.0, 2.8)
SUN_ROOM_WINDOW = (0.6, 1.55, 1.2, 1.0)
SUN_ROOM_SUN_ELEVATION = 36.6
SUN_ROOM_SUN_AZIMUTH = 20.0
SUN_ROOM_SUN_STRENGTH = 5.0     # W/m^2
SUN_ROOM_SUN_ANGLE = 0.5        # degrees
SUN_ROOM_WORLD = (0.02, 0.025, 0.035)


def _wall_with_hole(x, y_range, z_range, hole, toward, material, name):
    """The wall plane x = ``x`` over y_range x z_range, minus the rectangular ``hole``
    (y0, y1, z0, z1), as four quads facing ``toward``."""
    (ya, yb), (za, zb) = y_range, z_range
    y0, y1, z0, z1 = hole
    P = lambda y, z: (x, y, z)
    rects = [(ya, yb, za, z0), (ya, yb, z1, zb),   # below and above the hole
             (ya, y0, z0, z1), (y1, yb, z0, z1)]   # beside it
    return merge([_oriented_quad([P(r[0], r[2]), P(r[1], r[2]), P(r[1], r[3]), P(r[0], r[3])],
                                 toward, material, name) for r in rects], name)


def sun_room(width=256, height=256):
    """An interior lit mostly indirectly: a closed 4 x 5 x 2.8 m room (diffuse walls of
    different light colours, a wooden floor, a cabinet against the back wall and a low bench)
    whose only opening is a 1.2 x 1.0 m window in the +X wall. A sun of
    SUN_ROOM_SUN_STRENGTH W/m^2 (angle SUN_ROOM_SUN_ANGLE degrees) shines through it onto
    the floor and the bench; a dim world colour is the sky seen through the window. The
    camera stands in the corner opposite the window (-X, -Y) and looks across the room:
    apart from the sun patch, everything it sees is lit indirectly."""
    hx, hy, hz = SUN_ROOM_SIZE[0] / 2, SUN_ROOM_SIZE[1] / 2, SUN_ROOM_SIZE[2]
    wy, wz, ww, wh = SUN_ROOM_WINDOW
    materials = [
        Material("diffuse", (0.60, 0.45, 0.32), name="floor"),
        Material("diffuse", (0.80, 0.80, 0.78), name="ceiling"),
        Material("diffuse", (0.78, 0.74, 0.62), name="wall_cream"),   # +X (window) and -X
        Material("diffuse", (0.62, 0.70, 0.78), name="wall_blue"),    # +Y
        Material("diffuse", (0.66, 0.76, 0.62), name="wall_green"),   # -Y
        Material("diffuse", (0.62, 0.30, 0.24), name="cabinet"),
        Material("diffuse", (0.30, 0.38, 0.55), name="bench"),
    ]
    inside = (0.0, 0.0, hz / 2)
    P = lambda *c: np.array(c, dtype=np.float64)
    walls = {
        "floor": ([P(-hx, -hy, 0), P(hx, -hy, 0), P(hx, hy, 0), P(-hx, hy, 0)], 0),
        "ceiling": ([P(-hx, -hy, hz), P(hx, -hy, hz), P(hx, hy, hz), P(-hx, hy, hz)], 1),
        "wall_west": ([P(-hx, -hy, 0), P(-hx, hy, 0), P(-hx, hy, hz), P(-hx, -hy, hz)], 2),
        "wall_north": ([P(-hx, hy, 0), P(hx, hy, 0), P(hx, hy, hz), P(-hx, hy, hz)], 3),
        "wall_south": ([P(-hx, -hy, 0), P(hx, -hy, 0), P(hx, -hy, hz), P(-hx, -hy, hz)], 4),
    }
    hole = (wy - ww / 2, wy + ww / 2, wz - wh / 2, wz + wh / 2)
    # One mesh, so its shared edges are watertight: no sunlight slips in between walls.
    meshes = [merge([_oriented_quad(c, inside, m, name) for name, (c, m) in walls.items()]
                    + [_wall_with_hole(hx, (-hy, hy), (0.0, hz), hole, inside, 2, "wall_east")],
                    "room")]
    meshes.append(box((-0.4, 2.1, 0.45), (1.4, 0.6, 0.9), 0.0, 5, "cabinet"))
    meshes.append(box((0.25, 0.55, 0.25), (1.2, 0.5, 0.5), math.radians(15.0), 6, "bench"))
    el, az = math.radians(SUN_ROOM_SUN_ELEVATION), math.radians(SUN_ROOM_SUN_AZIMUTH)
    to_sun = (math.cos(el) * math.cos(az), math.cos(el) * math.sin(az), math.sin(el))
    sun = Light("sun", color=(1.0, 0.95, 0.88), power=SUN_ROOM_SUN_STRENGTH,
                direction=tuple(-c for c in to_sun), angle=math.radians(SUN_ROOM_SUN_ANGLE),
                camera_visible=False, name="sun")
    camera = Camera.look_at((-1.8, -2.3, 1.6), (1.2, 1.0, 0.9), fov_y_degrees=65.0,
                            width=width, height=height, clip_start=0.05)
    return SceneData(meshes, [], materials, [], [sun], World(SUN_ROOM_WORLD, 1.0), camera,
                     width, height)


def lamp_in_glass(width=128, height=128, strength=100.0, lamp=(1.55, 1.55, 2.1), lamp_size=0.1, shell_size=0.3,
                  albedo=0.8):
    """light_behind_glass without Blender (blender_scenes/build.py): a closed room of diffuse
    walls whose only light is a small emissive cube inside a hollow glass cube (1 cm walls)
    near the ceiling (the shell's walls are 1 cm thick whatever its size). Shadow rays cannot pass the glass: every wall is lit by caustic paths
    only, which BSDF sampling finds rarely (the thesis' "clocks" situation, sec. 5.3.4)."""
    materials = [Material("diffuse", (albedo, albedo, albedo), name="white"),
                 Material("diffuse", (0.5, 0.45, 0.4), name="floor"),
                 Material("dielectric", (1.0, 1.0, 1.0), roughness=0.0, ior=1.5, name="glass"),
                 Material("emission", (0.0, 0.0, 0.0), emission=(1.0, 0.9, 0.75), emission_strength=strength,
                          name="lamp")]
    P = lambda *c: np.array(c, dtype=np.float64)
    lo, hi = P(-2, -2, 0), P(2, 2, 2.5)
    inside = (lo + hi) / 2
    x0, y0, z0 = lo
    x1, y1, z1 = hi
    walls = [([P(x0, y0, z0), P(x1, y0, z0), P(x1, y1, z0), P(x0, y1, z0)], 1, "floor"),
             ([P(x0, y0, z1), P(x1, y0, z1), P(x1, y1, z1), P(x0, y1, z1)], 0, "ceiling"),
             ([P(x0, y0, z0), P(x0, y1, z0), P(x0, y1, z1), P(x0, y0, z1)], 0, "wall_-x"),
             ([P(x1, y0, z0), P(x1, y1, z0), P(x1, y1, z1), P(x1, y0, z1)], 0, "wall_+x"),
             ([P(x0, y0, z0), P(x1, y0, z0), P(x1, y0, z1), P(x0, y0, z1)], 0, "wall_-y"),
             ([P(x0, y1, z0), P(x1, y1, z0), P(x1, y1, z1), P(x0, y1, z1)], 0, "wall_+y")]
    meshes = [_oriented_quad(c, inside, m, name) for c, m, name in walls]
    meshes.append(box((0.3, 0.2, 0.4), (0.6, 0.6, 0.8), math.radians(20.0), 0, "block"))
    inner = box(lamp, shell_size - 0.02, material=2)
    inner.indices = np.asarray(inner.indices)[:, ::-1].copy()  # facing the cavity: out of the glass
    meshes.append(merge([box(lamp, shell_size, material=2), inner], "glass_shell"))
    meshes.append(box(lamp, lamp_size, material=3, name="lamp"))
    camera = Camera.look_at((-1.8, -1.2, 1.2), (0.0, 1.3, 1.2), fov_y_degrees=75.0, width=width, height=height,
                            clip_start=0.05)
    return SceneData(meshes, [], materials, [], [], World((0.0, 0.0, 0.0), 1.0), camera, width, height)


# name -> builder, for `parallax scene NAME`
SCENES = {
    "cornell_box": cornell_box,
    "veach_mis": veach_mis,
    "furnace_sphere": furnace_sphere,
    "closed_emitter_box": closed_emitter_box,
    "triangle_soup": triangle_soup_scene,
    "env_map_scene": env_map_scene,
    "sun_room": sun_room,
    "lamp_in_glass": lamp_in_glass,
}
