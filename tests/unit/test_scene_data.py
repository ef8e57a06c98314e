"""Pure-Python tests of SceneData: validation, flatten, npz round trip, cameras, scenes, PNG.

The package's __init__ imports the native module, which these tests must not need, so the
Python modules are loaded under a private package name straight from their files.
"""
import importlib
import math
import sys
import types
from pathlib import Path

import numpy as np
import pytest

_PKG_DIR = Path(__file__).resolve().parents[2] / "native" / "python" / "parallax_core"
_PKG = "_parallax_core_pure"
if _PKG not in sys.modules:
    _pkg = types.ModuleType(_PKG)
    _pkg.__path__ = [str(_PKG_DIR)]
    sys.modules[_PKG] = _pkg
scene = importlib.import_module(f"{_PKG}.scene")
scenes = importlib.import_module(f"{_PKG}.scenes")
exr = importlib.import_module(f"{_PKG}.exr")
cli = importlib.import_module(f"{_PKG}.cli")

SceneData, Mesh, Instance = scene.SceneData, scene.Mesh, scene.Instance
Material, Texture, Light, World, Camera = (scene.Material, scene.Texture, scene.Light,
                                           scene.World, scene.Camera)


# ---- fixtures ----------------------------------------------------------------------------

def grid_mesh(n=2, name="", **kw):
    """n x n quads in the z = 0 plane: (n+1)^2 vertices, 2 n^2 triangles."""
    x, y = np.meshgrid(np.arange(n + 1.0), np.arange(n + 1.0))
    pos = np.stack([x.ravel(), y.ravel(), np.zeros(x.size)], axis=1)
    i, j = np.meshgrid(np.arange(n), np.arange(n), indexing="ij")
    v = (i * (n + 1) + j).ravel()
    tris = np.concatenate([np.stack([v, v + 1, v + n + 2], 1), np.stack([v, v + n + 2, v + n + 1], 1)])
    return Mesh(pos, tris, name=name, **kw)


def rich_scene():
    """Exercises every part of the format."""
    rng = np.random.default_rng(7)
    a = grid_mesh(2, "plain")                                       # 8 tris, no extras
    b = grid_mesh(3, "shaded")                                      # 18 tris
    b.normals = rng.normal(size=(18, 3, 3))
    b.uvs = rng.uniform(size=(18, 3, 2))
    b.material_indices = np.arange(18) % 3
    c = grid_mesh(1, "degenerate")                                  # 2 tris + 2 degenerate
    c.indices = np.concatenate([c.indices, [[0, 0, 1], [0, 1, 1]]])
    c.uvs = rng.uniform(size=(4, 3, 2))
    sphere = scenes.uv_sphere((0, 0, 3), 0.5, 8, 4, material=1, name="ball")
    materials = [
        Material("diffuse", (0.5, 0.4, 0.3), base_color_texture=1, name="tex"),
        Material("conductor", (0.9, 0.8, 0.7), roughness=1.7, name="metal"),
        Material("dielectric", roughness=-0.3, ior=1.5, emission=(1, 2, 3),
                 emission_strength=2.5),
        Material("emission", emission=(4.0, 4.0, 4.0)),
    ]
    textures = [Texture(rng.integers(0, 256, (3, 5, 3), dtype=np.uint8), "rgb"),
                Texture(rng.integers(0, 256, (4, 2, 4), dtype=np.uint8), "rgba"),
                Texture(rng.integers(0, 256, (2, 2), dtype=np.uint8), "grey")]
    lights = [
        Light("point", (1, 0.5, 0.25), 100.0, (1, 2, 3), radius=0.1, name="p"),
        Light("spot", power=50.0, position=(0, 0, 5), direction=(0.3, 0.1, -2.0),
              spot_size=0.7, spot_blend=0.3, radius=0.05),
        Light("sun", (1, 1, 0.9), 3.0, direction=(1, 1, -1), angle=0.01),
        Light("area", power=200.0, position=(0, 0, 4), shape="rectangle", size=2.0,
              size_y=0.5, direction=(0, 0.2, -1)),
        Light("area", power=20.0, shape="disk", size=0.3, axis_u=(1, 0, 0),
              axis_v=(0, -1, 0), direction=(0, 0, 1)),
        Light("area", power=20.0, shape="ellipse", size=0.0, size_y=1.0, name="empty"),
    ]
    t = np.eye(4)
    t[:3, 3] = (1, 2, 3)
    t[:3, :3] *= 2.0
    instances = [Instance(0), Instance(1, t), Instance(2, t[:3]), Instance(3), Instance(1)]
    world = World((0.2, 0.3, 0.4), 2.0, rng.uniform(size=(4, 8, 3)).astype(np.float32))
    camera = Camera.look_at((0, -5, 2), (0, 0, 0), fov_y_degrees=30, width=40, height=30)
    return SceneData([a, b, c, sphere], instances, materials, textures, lights, world,
                     camera, 40, 30)


def assert_flat_equal(f1, f2):
    assert list(f1) == list(f2)
    for k in f1:
        assert f1[k].dtype == f2[k].dtype, k
        assert f1[k].shape == f2[k].shape, k
        assert f1[k].tobytes() == f2[k].tobytes(), k


# ---- validation --------------------------------------------------------------------------

def scene_with(**kw):
    base = dict(meshes=[grid_mesh(2, "floor")], materials=[Material()])
    base.update(kw)
    return SceneData(**base)


def expect_error(s, *fragments):
    with pytest.raises(ValueError) as e:
        s.validate()
    for frag in fragments:
        assert frag in str(e.value), (frag, str(e.value))
    with pytest.raises(ValueError):
        s.flatten()


def test_nan_vertex_named():
    bad = grid_mesh(4, "floor")
    bad.positions[17, 1] = np.nan
    s = SceneData([grid_mesh(1), grid_mesh(1, "a"), bad], materials=[Material()])
    expect_error(s, "mesh 'floor' (mesh 2): vertex 17 is NaN/Inf")
    bad.positions[17, 1] = np.inf
    expect_error(s, "vertex 17")


def test_index_out_of_range():
    m = grid_mesh(2, "x")        # 9 vertices, 8 triangles
    m.positions = np.concatenate([m.positions, np.ones((3, 3))])  # 12 vertices
    m.indices[5, 1] = 99
    expect_error(scene_with(meshes=[m]), "mesh 'x' (mesh 0): triangle 5 index 99 out of range (12 vertices)")
    m.indices[5, 1] = -1
    expect_error(scene_with(meshes=[m]), "triangle 5 index -1")


def test_bad_shapes():
    m = grid_mesh(2, "x")
    m.indices = m.indices[:6]
    m.normals = np.zeros((4, 3, 3))
    expect_error(scene_with(meshes=[m]), "mesh 'x'", "normals has shape (4, 3, 3), expected (T,3,3) with T=6")
    m.normals, m.uvs = None, np.zeros((6, 3, 3))
    expect_error(scene_with(meshes=[m]), "uvs has shape (6, 3, 3), expected (T,3,2) with T=6")
    m.uvs = np.zeros((6, 3, 2))
    m.uvs[2, 1, 0] = np.nan
    expect_error(scene_with(meshes=[m]), "uvs of triangle 2 is NaN/Inf")
    m.uvs = None
    m.positions = m.positions[:, :2]
    expect_error(scene_with(meshes=[m]), "positions has shape")
    m = grid_mesh(2, "x")
    m.indices = m.indices.astype(np.float32)
    expect_error(scene_with(meshes=[m]), "indices must be integers")


def test_material_errors_and_clamps():
    expect_error(scene_with(materials=[Material(), Material(), Material(), Material(base_color_texture=7)],
                            textures=[Texture(np.zeros((1, 1, 3), np.uint8))] * 2),
                 "material 3: base_color_texture 7 out of range (2 textures)")
    expect_error(scene_with(materials=[Material(roughness=float("nan"), name="m")]),
                 "material 'm' (material 0): roughness is NaN/Inf")
    expect_error(scene_with(materials=[Material(ior=float("inf"))]), "material 0: ior is NaN/Inf")
    expect_error(scene_with(materials=[Material("plastic")]), "material 0: unknown type 'plastic'")
    expect_error(scene_with(materials=[Material(base_color=(1, 2))]), "material 0: base_color")
    flat = scene_with(materials=[Material(roughness=1.7), Material(roughness=-0.2), Material()]).flatten()
    assert flat["material_roughness"].tolist() == [1.0, 0.0, 0.5]
    # IOR has one policy, the core's: outside its range is an error, never a silent clamp.
    expect_error(scene_with(materials=[Material(ior=-1.0)]), "material 0: ior must be positive")
    expect_error(scene_with(materials=[Material(ior=1e4)]), "material 0: ior must be positive, in 0.001..1000")


def test_material_index_out_of_range():
    m = grid_mesh(2, "x", material_indices=np.array([0, 1, 0, 1, 2, 0, 0, 0]))
    expect_error(scene_with(meshes=[m], materials=[Material(), Material()]),
                 "mesh 'x' (mesh 0): triangle 4 material 2 out of range (2 materials)")
    m.material_indices = np.zeros(3, int)
    expect_error(scene_with(meshes=[m]), "material_indices has shape (3,)")


def test_default_material_and_instances():
    flat = SceneData([grid_mesh(1), grid_mesh(1)]).flatten()
    assert flat["material_type"].tolist() == [0]          # one default Material()
    assert flat["instance_mesh"].tolist() == [0, 1]        # one identity instance per mesh
    np.testing.assert_array_equal(flat["instance_transform"], np.tile(np.eye(4)[:3], (2, 1, 1)))


def test_instance_errors():
    insts = [Instance(0)] * 4 + [Instance(9)]
    expect_error(scene_with(instances=insts), "instance 4: mesh 9 out of range (1 meshes)")
    t = np.eye(4)
    t[1, 3] = np.nan
    expect_error(scene_with(instances=[Instance(0, t)]), "instance 0: transform is NaN/Inf")
    expect_error(scene_with(instances=[Instance(0, np.eye(3))]), "instance 0: transform has shape")
    t = np.eye(4)
    t[3, 0] = 1
    expect_error(scene_with(instances=[Instance(0, t)]), "instance 0: transform is projective")
    w = scene_with(instances=[Instance(0, np.zeros((3, 4)))]).validate()
    assert w == ["instance 0: transform is singular"]


def test_texture_and_world_errors():
    expect_error(scene_with(textures=[Texture(np.zeros((0, 4, 3), np.uint8))]),
                 "texture 0: zero-size image")
    expect_error(scene_with(textures=[Texture(np.zeros((2, 2, 3), np.int32), "t")]),
                 "texture 't' (texture 0): pixels must be uint8 sRGB or float linear, got int32")
    expect_error(scene_with(textures=[Texture(np.full((2, 2, 3), np.inf, np.float32), "t")]),
                 "texture 't' (texture 0): float pixels must be finite")
    expect_error(scene_with(textures=[Texture(np.zeros((2, 2, 3), np.uint8), "t", "cubic")]),
                 "texture 't' (texture 0): unknown interpolation 'cubic'")
    expect_error(scene_with(textures=[Texture(np.zeros((2, 2, 2), np.uint8))]),
                 "texture 0: pixels has shape")
    expect_error(scene_with(world=World(map=np.zeros((0, 0, 3), np.float32))),
                 "world map: zero-size image")
    m = np.ones((4, 8, 3), np.float32)
    m[2, 5, 1] = np.nan
    expect_error(scene_with(world=World(map=m)), "world map: pixel (row 2, column 5) is NaN/Inf")
    expect_error(scene_with(world=World(color=(np.nan, 0, 0))), "world")


def test_light_errors():
    good = Light()
    expect_error(scene_with(lights=[good, good, Light("foo")]), "light 2: unknown type 'foo'")
    expect_error(scene_with(lights=[Light("area", shape="star")]), "light 0: unknown area shape 'star'")
    expect_error(scene_with(lights=[Light(power=float("nan"), name="L")]),
                 "light 'L' (light 0): power is NaN/Inf")
    expect_error(scene_with(lights=[Light(position=(0, np.inf, 0))]), "light 0: position")
    expect_error(scene_with(lights=[Light(direction=(0, 0, 0))]), "light 0: direction has zero length")
    expect_error(scene_with(lights=[Light("area", axis_u=(0, 0, 0), axis_v=(0, 1, 0))]),
                 "light 0: axis_u")


def test_camera_errors():
    expect_error(scene_with(camera=Camera(window=(1, -1, -1, 1))), "camera: bad window")
    expect_error(scene_with(camera=Camera(clip_start=5, clip_end=1)), "camera: bad clip")
    expect_error(scene_with(camera=Camera(type="fisheye")), "camera: unknown type")
    m = np.eye(4)[:3].copy()
    m[0, 0] = np.nan
    expect_error(scene_with(camera=Camera(m)), "camera: camera_to_world")
    expect_error(scene_with(camera=None), "camera")


def test_degenerate_triangles_dropped_and_reported():
    m = grid_mesh(2, "x", material_indices=np.arange(8) % 2)     # 8 triangles
    m.normals = np.arange(8 * 9, dtype=float).reshape(8, 3, 3)
    m.positions = np.concatenate([m.positions, [[5, 5, 5]]])      # vertex 9
    m.indices[1] = (0, 0, 4)                  # repeated index
    m.indices[3] = (0, 1, 2)                  # collinear (y = 0 row)
    m.indices[6] = (9, 9, 9)
    s = scene_with(meshes=[grid_mesh(1), m], materials=[Material(), Material()])
    assert s.validate() == ["mesh 'x' (mesh 1): 3 degenerate triangles skipped"]
    warnings = []
    flat = s.flatten(warnings)
    assert warnings == s.validate()
    keep = [0, 2, 4, 5, 7]
    assert flat["mesh_triangle_count"].tolist() == [2, 5]
    assert flat["mesh_first_triangle"].tolist() == [0, 2]
    np.testing.assert_array_equal(flat["indices"][2:], m.indices[keep] + 4)
    np.testing.assert_array_equal(flat["triangle_material"][2:], np.array(keep) % 2)
    np.testing.assert_array_equal(flat["corner_normals"][2:], m.normals[keep])
    np.testing.assert_array_equal(flat["corner_normals"][:2], 0)   # mesh 0 has none
    assert flat["mesh_has_normals"].tolist() == [0, 1]
    assert flat["positions"].shape == (4 + 10, 3)                   # vertices are kept


def test_empty_scene_is_valid():
    s = SceneData()
    assert s.validate() == []
    flat = s.flatten()
    expect = {"positions": (0, 3), "indices": (0, 3), "triangle_material": (0,),
              "corner_normals": (0, 3, 3), "corner_uvs": (0, 3, 2), "mesh_first_triangle": (0,),
              "instance_transform": (0, 3, 4), "instance_mesh": (0,), "material_type": (1,),
              "texture_texels": (0, 4), "texture_info": (0, 3), "light_type": (0,),
              "light_position": (0, 3), "world_map": (0, 0, 3), "camera_type": (1,)}
    for k, shape in expect.items():
        assert flat[k].shape == shape, k
    assert flat["world_color"].tolist() == pytest.approx([0.05] * 3)


# ---- flatten -----------------------------------------------------------------------------

def test_flatten_keys_dtypes_shapes():
    s = rich_scene()
    flat = s.flatten()
    assert list(flat) == list(scene.FLAT_KEYS)
    for k, (dt, _) in scene.FLAT_KEYS.items():
        assert flat[k].dtype == dt, k
        assert flat[k].flags.c_contiguous, k
    T, M, I, K, L = 8 + 18 + 2 + 48, 4, 5, 4, 5
    shapes = {"positions": (9 + 16 + 4 + 45, 3), "indices": (T, 3), "triangle_material": (T,),
              "corner_normals": (T, 3, 3), "corner_uvs": (T, 3, 2), "mesh_first_triangle": (M,),
              "mesh_triangle_count": (M,), "mesh_has_normals": (M,), "mesh_has_uvs": (M,),
              "instance_transform": (I, 3, 4), "instance_mesh": (I,), "material_type": (K,),
              "material_base_color": (K, 3), "material_roughness": (K,), "material_ior": (K,),
              "material_emission": (K, 3), "material_texture": (K,),
              "texture_texels": (15 + 8 + 4, 4), "texture_info": (3, 3), "light_type": (L,),
              "light_position": (L, 3), "light_direction": (L, 3), "light_axis_u": (L, 3),
              "light_axis_v": (L, 3), "light_radius": (L,), "light_color": (L, 3),
              "light_spot_size": (L,), "light_spot_blend": (L,), "light_sun_angle": (L,),
              "world_color": (3,), "world_map": (4, 8, 3), "camera_to_world": (3, 4),
              "camera_type": (1,), "camera_window": (4,), "camera_clip": (2,)}
    for k, shape in shapes.items():
        assert flat[k].shape == shape, k
    assert flat["mesh_first_triangle"].tolist() == [0, 8, 26, 28]
    assert flat["mesh_has_normals"].tolist() == [0, 1, 0, 1]
    assert flat["mesh_has_uvs"].tolist() == [0, 1, 1, 1]
    assert flat["indices"].max() < len(flat["positions"])
    assert flat["indices"][8:26].min() == 9          # mesh 1 offset by mesh 0's vertices
    assert flat["material_type"].tolist() == [0, 1, 2, 3]
    assert flat["material_texture"].tolist() == [1, -1, -1, -1]
    np.testing.assert_allclose(flat["material_emission"][2], [2.5, 5.0, 7.5])
    assert flat["texture_info"].tolist() == [[0, 5, 3], [15, 2, 4], [23, 2, 2]]
    np.testing.assert_array_equal(flat["texture_texels"][:15, :3], s.textures[0].pixels.reshape(-1, 3))
    assert (flat["texture_texels"][:15, 3] == 255).all()
    np.testing.assert_array_equal(flat["texture_texels"][15:23], s.textures[1].pixels.reshape(-1, 4))
    np.testing.assert_array_equal(flat["texture_texels"][23:, 0], s.textures[2].pixels.ravel())
    np.testing.assert_allclose(flat["world_color"], [0.4, 0.6, 0.8])
    np.testing.assert_allclose(flat["world_map"], s.world.map * 2.0, rtol=1e-6)
    np.testing.assert_allclose(flat["instance_transform"][1][:, 3], [1, 2, 3])


def test_flatten_lights():
    s = rich_scene()
    flat = s.flatten()
    assert "light 'empty' (light 5): zero-size area light skipped" in s.validate()
    assert flat["light_type"].tolist() == [1, 2, 3, 4, 5]
    np.testing.assert_allclose(flat["light_color"][0], [100, 50, 25])
    np.testing.assert_allclose(np.linalg.norm(flat["light_direction"], axis=1), 1, rtol=1e-6)
    d = np.array([0.3, 0.1, -2.0])
    np.testing.assert_allclose(flat["light_direction"][1], d / np.linalg.norm(d), rtol=1e-6)
    assert flat["light_spot_size"][1] == pytest.approx(0.7)
    assert flat["light_spot_blend"][1] == pytest.approx(0.3)
    assert flat["light_sun_angle"][2] == pytest.approx(0.01)
    assert flat["light_radius"][0] == pytest.approx(0.1)
    # Derived basis: u x v = -direction (the light's local Z), extents size and size_y.
    u, v, n = flat["light_axis_u"][3], flat["light_axis_v"][3], flat["light_direction"][3]
    assert np.linalg.norm(u) == pytest.approx(2.0) and np.linalg.norm(v) == pytest.approx(0.5)
    np.testing.assert_allclose(np.cross(u / 2.0, v / 0.5), -n, atol=1e-6)
    assert abs(np.dot(u, v)) < 1e-6
    # Given axes, disk: both extents = size.
    np.testing.assert_allclose(flat["light_axis_u"][4], [0.3, 0, 0], atol=1e-7)
    np.testing.assert_allclose(flat["light_axis_v"][4], [0, -0.3, 0], atol=1e-7)
    # Non-area lights: unit axes.
    np.testing.assert_allclose(np.linalg.norm(flat["light_axis_u"][:3], axis=1), 1, rtol=1e-6)
    # Default direction (0,0,-1) gives Blender's identity axes.
    f = scene_with(lights=[Light("area", shape="square", size=3)]).flatten()
    np.testing.assert_allclose(f["light_axis_u"][0], [3, 0, 0])
    np.testing.assert_allclose(f["light_axis_v"][0], [0, 3, 0])


def test_float_and_closest_textures_flatten_and_load(tmp_path):
    """Float pixels become linear half texels of their own array (values > 1 kept, negatives
    clamped to 0); the interpolation and the kind travel in texture_flags; a file round-trips."""
    hdr = np.linspace(-1.0, 4.0, 18, dtype=np.float32).reshape(2, 3, 3)
    s = scene_with(textures=[Texture(np.zeros((2, 2, 3), np.uint8), "bytes", "closest"),
                             Texture(hdr, "hdr"), Texture(hdr[..., 2], "grey", "closest")])
    flat = s.flatten()
    assert flat["texture_flags"].tolist() == [scene.TEXTURE_FLAG_CLOSEST, scene.TEXTURE_FLAG_HALF,
                                              scene.TEXTURE_FLAG_CLOSEST | scene.TEXTURE_FLAG_HALF]
    assert flat["texture_info"].tolist() == [[0, 2, 2], [0, 3, 2], [6, 3, 2]]
    assert flat["texture_texels"].shape == (4, 4) and flat["texture_half_texels"].shape == (12, 4)
    halves = flat["texture_half_texels"].view(np.float16).astype(np.float32)
    np.testing.assert_allclose(halves[:6, :3], np.maximum(hdr, 0).reshape(-1, 3), rtol=1e-3)
    assert halves.max() == pytest.approx(4.0) and (halves[:, 3] == 1).all()
    s.save(tmp_path / "t.npz")
    loaded = SceneData.load(tmp_path / "t.npz")
    assert [t.interpolation for t in loaded.textures] == ["closest", "linear", "closest"]
    assert_flat_equal(flat, loaded.flatten())
    old = {k: v for k, v in flat.items() if k not in ("texture_flags", "texture_half_texels")}
    old["texture_info"], old["texture_texels"] = flat["texture_info"][:1], flat["texture_texels"]
    assert [t.interpolation for t in SceneData.from_flat(old).textures] == ["linear"]  # older files


# ---- files -------------------------------------------------------------------------------

def test_npz_round_trip_exact(tmp_path):
    s = rich_scene()
    flat = s.flatten()
    path = tmp_path / "scene.npz"
    s.save(path)
    loaded = SceneData.load(path)
    assert (loaded.width, loaded.height) == (40, 30)
    assert [m.name for m in loaded.meshes] == ["plain", "shaded", "degenerate", "ball"]
    assert [m.name for m in loaded.materials][:2] == ["tex", "metal"]
    assert [t.name for t in loaded.textures] == ["rgb", "rgba", "grey"]
    assert_flat_equal(flat, loaded.flatten())
    # Twice more, and through from_flat without metadata.
    loaded.save(tmp_path / "again.npz")
    assert_flat_equal(flat, SceneData.load(tmp_path / "again.npz").flatten())
    assert_flat_equal(flat, SceneData.from_flat(flat).flatten())
    np.savez(tmp_path / "bare.npz", **flat)
    assert_flat_equal(flat, SceneData.load(tmp_path / "bare.npz").flatten())


def test_npz_round_trip_procedural(tmp_path):
    for build in (scenes.cornell_box, scenes.veach_mis, scenes.env_map_scene):
        s = build(width=32, height=24)
        s.save(tmp_path / "s.npz")
        assert_flat_equal(s.flatten(), SceneData.load(tmp_path / "s.npz").flatten())


def test_npz_missing_array(tmp_path):
    flat = rich_scene().flatten()
    del flat["light_color"]
    np.savez(tmp_path / "bad.npz", **flat)
    with pytest.raises(ValueError, match="light_color"):
        SceneData.load(tmp_path / "bad.npz")


# ---- mix chains --------------------------------------------------------------------------

def test_mix_chain_validation():
    mats = lambda *m: scene_with(materials=[Material(name="a"), *m])
    expect_error(mats(Material(mix_next=2, name="b"), Material(mix_next=1)),
                 "material 'b' (material 1): mix chain has a cycle (1 -> 2 -> 1)")
    expect_error(mats(Material(mix_next=1)), "material 1: mix chain has a cycle (1 -> 1)")
    # A chain running into a cycle names the first material of the cycle.
    expect_error(mats(Material(mix_next=2), Material(mix_next=3), Material(mix_next=2)),
                 "material 2: mix chain has a cycle (2 -> 3 -> 2)")
    expect_error(mats(Material(mix_next=5)), "material 1: mix_next 5 out of range (2 materials)")
    expect_error(mats(Material(mix_next=-1)), "material 1: mix_next -1 out of range")
    expect_error(mats(Material(mix_next=0.0)), "material 1: mix_next must be None or a material index")
    expect_error(mats(Material(mix_next=True)), "material 1: mix_next must be None")
    expect_error(mats(Material(mix_next=0, mix_weight=float("nan"), name="m")),
                 "material 'm' (material 1): mix_weight is NaN/Inf")
    expect_error(mats(Material(mix_next=0, mix_weight=float("inf"))), "material 1: mix_weight")
    expect_error(mats(Material(mix_weight=(0.5, 0.5))), "material 1: mix_weight")
    n = scene.MIX_CHAIN_MAX
    chain = [Material(mix_next=k + 1) for k in range(n)] + [Material()]   # n + 1 materials
    expect_error(scene_with(materials=chain), f"material 0: mix chain of {n + 1} materials "
                                              f"is longer than the limit of {n}")
    chain[0].mix_next = None                                              # n: allowed
    assert scene_with(materials=chain).validate() == []


def test_mix_chain_limit_matches_the_shader():
    header = (_PKG_DIR.parents[2] / "shaders" / "shared" / "types.h").read_text()
    line = next(l for l in header.splitlines() if "uint MIX_CHAIN_MAX" in l)
    assert int(line.split("=")[1].strip(" ;")) == scene.MIX_CHAIN_MAX


def test_mix_chain_flatten():
    s = scene_with(materials=[Material(mix_next=1, mix_weight=1.7), Material(mix_next=2, mix_weight=-0.5),
                              Material(mix_next=np.int64(3), mix_weight=0.25), Material(mix_weight=0.3)])
    flat = s.flatten()
    assert flat["material_mix_next"].dtype == np.int32
    assert flat["material_mix_weight"].dtype == np.float32
    assert flat["material_mix_next"].tolist() == [1, 2, 3, -1]
    assert flat["material_mix_weight"].tolist() == [1.0, 0.0, 0.25, 1.0]  # clamped; None: 1
    flat = scene_with().flatten()
    assert flat["material_mix_next"].tolist() == [-1]
    assert flat["material_mix_weight"].tolist() == [1.0]


def test_mix_chain_npz_round_trip(tmp_path):
    s = rich_scene()
    s.materials[0].mix_next, s.materials[0].mix_weight = 1, 0.25
    s.materials[1].mix_next, s.materials[1].mix_weight = 2, 0.6
    s.materials[3].mix_weight = 0.1          # ignored without mix_next
    flat = s.flatten()
    assert flat["material_mix_next"].tolist() == [1, 2, -1, -1]
    np.testing.assert_array_equal(flat["material_mix_weight"], np.float32([0.25, 0.6, 1.0, 1.0]))
    s.save(tmp_path / "mix.npz")
    loaded = SceneData.load(tmp_path / "mix.npz")
    assert [(m.mix_next, m.mix_weight) for m in loaded.materials] == [
        (1, 0.25), (2, pytest.approx(0.6)), (None, 1.0), (None, 1.0)]
    assert_flat_equal(flat, loaded.flatten())
    assert_flat_equal(flat, SceneData.from_flat(flat).flatten())
    # Files and dicts from before mix chains (no mix keys) load as "no mixes".
    old = {k: v for k, v in flat.items() if not k.startswith("material_mix_")}
    np.savez(tmp_path / "old.npz", **old)
    loaded = SceneData.load(tmp_path / "old.npz")
    assert all(m.mix_next is None and m.mix_weight == 1.0 for m in loaded.materials)
    again = loaded.flatten()
    assert again["material_mix_next"].tolist() == [-1] * 4
    assert again["material_mix_weight"].tolist() == [1.0] * 4
    for k in old:
        assert again[k].tobytes() == flat[k].tobytes(), k
    assert_flat_equal(again, SceneData.from_flat(old).flatten())


# ---- cameras -----------------------------------------------------------------------------

def window(cam):
    return np.array(cam.window)


def test_blender_auto_fit_landscape():
    cam = Camera.from_blender(np.eye(4), 1920, 1080, lens=50.0)
    np.testing.assert_allclose(window(cam), [-0.36, 0.36, -0.2025, 0.2025])
    assert cam.type == "perspective"


def test_blender_auto_fit_portrait_uses_sensor_width():
    cam = Camera.from_blender(np.eye(4), 1080, 1920, lens=50.0, sensor_height=24.0)
    np.testing.assert_allclose(window(cam), [-0.2025, 0.2025, -0.36, 0.36])


def test_blender_vertical_and_horizontal_fit():
    cam = Camera.from_blender(np.eye(4), 1920, 1080, lens=50.0, sensor_fit="VERTICAL")
    # sensor_height 24 spans the 1080 px: half height 12/50, half width 0.24 * 16/9.
    np.testing.assert_allclose(window(cam), [-0.24 * 16 / 9, 0.24 * 16 / 9, -0.24, 0.24])
    cam = Camera.from_blender(np.eye(4), 1080, 1920, lens=35.0, sensor_fit="HORIZONTAL")
    hx = 18.0 / 35.0
    np.testing.assert_allclose(window(cam), [-hx, hx, -hx * 16 / 9, hx * 16 / 9])


def test_blender_ortho_and_shift():
    cam = Camera.from_blender(np.eye(4), 1920, 1080, type="ORTHO", ortho_scale=7.0)
    assert cam.type == "orthographic"
    np.testing.assert_allclose(window(cam), [-3.5, 3.5, -1.96875, 1.96875])
    # Shift in units of the fitted (larger) dimension: 0.1 * 0.72 = 0.072 on both axes.
    cam = Camera.from_blender(np.eye(4), 1920, 1080, shift_x=0.1, shift_y=0.1)
    np.testing.assert_allclose(window(cam), [-0.288, 0.432, -0.1305, 0.2745])
    cam = Camera.from_blender(np.eye(4), 1000, 2000, type="ORTHO", ortho_scale=4.0,
                              shift_x=-0.25)
    np.testing.assert_allclose(window(cam), [-2.0, 0.0, -2.0, 2.0])


def test_blender_pixel_aspect_matrix_and_clip():
    # Pixels twice as wide: 1000x1000 px look like a 2:1 image; horizontal fit.
    cam = Camera.from_blender(np.eye(4), 1000, 1000, pixel_aspect=2.0)
    np.testing.assert_allclose(window(cam), [-0.36, 0.36, -0.18, 0.18])
    m = np.diag([2.0, 2.0, 2.0, 1.0])
    m[:3, 3] = (1, 2, 3)
    cam = Camera.from_blender(m, 64, 64, clip_start=0.5, clip_end=50.0)
    np.testing.assert_allclose(cam.camera_to_world, np.column_stack([np.eye(3), [1, 2, 3]]))
    assert (cam.clip_start, cam.clip_end) == (0.5, 50.0)
    with pytest.raises(ValueError, match="CUSTOM"):
        Camera.from_blender(np.eye(4), 64, 64, type="CUSTOM")


def test_blender_panorama_and_depth_of_field():
    # A panorama's image is the (u, v) square, shifted (Cycles); the fisheye sensor is fitted
    # to the image's aspect, here the width (36 mm) to 300 px of 300 x 200.
    cam = Camera.from_blender(np.eye(4), 300, 200, type="PANO", panorama_type="fisheye_equisolid", shift_x=0.1,
                              fisheye_lens=8.0, aperture_radius=0.02, focus_distance=3.0, aperture_blades=5)
    assert (cam.type, cam.panorama_type) == ("panorama", "FISHEYE_EQUISOLID")
    np.testing.assert_allclose(window(cam), [0.1, 1.1, 0.0, 1.0])
    np.testing.assert_allclose(cam.fisheye_sensor, [36.0, 24.0])
    assert (cam.fisheye_lens, cam.aperture_radius, cam.focus_distance, cam.aperture_blades) == (8.0, 0.02, 3.0, 5)
    cam = Camera.from_blender(np.eye(4), 200, 300, type="PANO", sensor_fit="AUTO")
    np.testing.assert_allclose(cam.fisheye_sensor, [24.0, 36.0])
    with pytest.raises(ValueError, match="unknown settings"):
        Camera.from_blender(np.eye(4), 64, 64, fstop=2.0)


def test_node_programs_round_trip(tmp_path):
    nodes = importlib.import_module(f"{_PKG}.nodes")
    s = scenes.cornell_box(width=32, height=24)
    programs = []
    for k in (0, 2):
        p = nodes.Program()
        p.store("roughness", p.math("MULTIPLY", p.separate(p.uv(), k % 2), 0.5 + k))
        programs.append(tuple(p.finish()))
    s.materials[0].node_program, s.materials[2].node_program = programs
    s.meshes[0].texspace = (0.0, 1.0, 0.5, 2.0, 2.0, 1.0)  # Generated coordinates' space
    flat = s.flatten()
    assert list(flat["material_node_program"][:3]) == [0, -1, len(programs[0])]
    s.save(tmp_path / "nodes.npz")
    loaded = SceneData.load(tmp_path / "nodes.npz")
    assert [m.node_program for m in loaded.materials[:3]] == [programs[0], (), programs[1]]
    assert loaded.meshes[0].texspace == (0.0, 1.0, 0.5, 2.0, 2.0, 1.0)
    np.testing.assert_allclose(loaded.meshes[1].texspace[3:], (loaded.meshes[1].positions.max(0) -
                                                               loaded.meshes[1].positions.min(0)) / 2)  # its bounds
    assert_flat_equal(flat, loaded.flatten())
    del flat["material_node_program"], flat["material_node_programs"], flat["mesh_texspace"]  # older files
    older = SceneData.from_flat(flat)
    assert all(m.node_program == () for m in older.materials)
    np.testing.assert_allclose([m.texspace for m in older.meshes[1:]], [m.texspace for m in loaded.meshes[1:]], atol=1e-6)
    s.meshes[0].texspace = (0.0, 1.0, np.nan, 2.0, 2.0, 1.0)
    with pytest.raises(ValueError, match="texspace"):
        s.flatten()


def test_tangents_round_trip_and_older_files(tmp_path):
    s = scenes.cornell_box(width=32, height=24)
    T = len(s.meshes[1].indices)
    rng = np.random.default_rng(2)
    tangents = np.concatenate([rng.normal(size=(T, 3, 3)), np.sign(rng.normal(size=(T, 3, 1)))], -1)
    s.meshes[1].tangents = tangents  # Normal Map tangents on one mesh only
    flat = s.flatten()
    assert flat["corner_tangents"].shape == (len(flat["indices"]), 3, 4)
    assert list(flat["mesh_has_tangents"][:3]) == [0, 1, 0]
    s.save(tmp_path / "tangents.npz")
    loaded = SceneData.load(tmp_path / "tangents.npz")
    np.testing.assert_allclose(loaded.meshes[1].tangents, tangents, rtol=1e-6)
    assert loaded.meshes[0].tangents is None
    assert_flat_equal(flat, loaded.flatten())
    del flat["corner_tangents"], flat["mesh_has_tangents"]  # files before tangents
    assert all(m.tangents is None for m in SceneData.from_flat(flat).meshes)
    s.meshes[1].tangents = tangents[:-1]
    with pytest.raises(ValueError, match="tangents has shape"):
        s.flatten()
    s.meshes[1].tangents = np.where(np.arange(4) == 3, np.nan, tangents)
    with pytest.raises(ValueError, match="tangents of triangle 0 is NaN"):
        s.flatten()


def test_attributes_round_trip_and_older_files(tmp_path):
    s = scenes.cornell_box(width=32, height=24)
    rng = np.random.default_rng(4)
    T0, T2 = len(s.meshes[0].indices), len(s.meshes[2].indices)
    paint, second = rng.random((T0, 3, 4)), rng.random((T2, 3, 4))
    s.meshes[0].attributes = {1: paint}  # slot 1 only: slot 0 is another mesh's
    s.meshes[2].attributes = {0: second, 1: rng.random((T2, 3, 4))}
    flat = s.flatten()
    T = len(flat["indices"])
    assert flat["corner_attributes"].shape == (2 * T, 3, 4)
    assert list(flat["mesh_attribute_mask"][:3]) == [2, 0, 3]
    s.save(tmp_path / "attributes.npz")
    loaded = SceneData.load(tmp_path / "attributes.npz")
    assert sorted(loaded.meshes[0].attributes) == [1] and loaded.meshes[1].attributes == {}
    np.testing.assert_allclose(loaded.meshes[0].attributes[1], paint, rtol=1e-6)
    np.testing.assert_allclose(loaded.meshes[2].attributes[0], second, rtol=1e-6)
    assert_flat_equal(flat, loaded.flatten())
    del flat["corner_attributes"], flat["mesh_attribute_mask"]  # files before attributes
    assert all(m.attributes == {} for m in SceneData.from_flat(flat).meshes)
    s.meshes[0].attributes = {8: paint}
    with pytest.raises(ValueError, match="attribute slot 8 is not an integer in 0..7"):
        s.flatten()
    s.meshes[0].attributes = {0: paint[:, :, :3]}
    with pytest.raises(ValueError, match="attribute slot 0 has shape"):
        s.flatten()


def test_camera_lens_round_trip_and_older_files(tmp_path):
    s = scenes.cornell_box(width=32, height=24)
    s.camera = Camera(s.camera.camera_to_world, "panorama", (0.0, 1.0, 0.0, 1.0), 0.1, 100.0,
                      aperture_radius=0.05, focus_distance=2.5, aperture_blades=6, aperture_rotation=0.3,
                      aperture_ratio=1.5, panorama_type="FISHEYE_LENS_POLYNOMIAL", panorama_range=(-1, 1, -0.5, 0.5),
                      fisheye_fov=2.0, fisheye_lens=9.0, fisheye_sensor=(30.0, 20.0),
                      fisheye_polynomial=(0.0, -0.02, 0.0, 1e-6, 0.0))
    s.save(tmp_path / "lens.npz")
    loaded = SceneData.load(tmp_path / "lens.npz")
    assert_flat_equal(s.flatten(), loaded.flatten())
    assert (loaded.camera.panorama_type, loaded.camera.aperture_blades) == ("FISHEYE_LENS_POLYNOMIAL", 6)
    # Files from before the thin lens and panoramas: a pinhole.
    flat = scenes.cornell_box(width=32, height=24).flatten()
    for key in ("camera_aperture", "camera_panorama_type", "camera_panorama_range", "camera_fisheye"):
        del flat[key]
    old = SceneData.from_flat(flat).camera
    assert (old.aperture_radius, old.type, old.panorama_type) == (0.0, "perspective", "EQUIRECTANGULAR")


def test_look_at():
    cam = Camera.look_at((0, -4, 1), (0, 0, 1), fov_y_degrees=90, width=200, height=100)
    m = np.asarray(cam.camera_to_world)
    np.testing.assert_allclose(-m[:, 2], [0, 1, 0], atol=1e-12)    # looks down -Z
    np.testing.assert_allclose(m[:, 1], [0, 0, 1], atol=1e-12)     # +Y up
    np.testing.assert_allclose(m[:, 0], [1, 0, 0], atol=1e-12)     # +X right
    np.testing.assert_allclose(m[:, 3], [0, -4, 1])
    np.testing.assert_allclose(window(cam), [-2, 2, -1, 1])
    cam = Camera.look_at((0, 0, 5), (0, 0, 0))                      # along the up vector
    assert np.isfinite(cam.camera_to_world).all()


def test_with_resolution_keeps_vertical_extent():
    s = scenes.cornell_box(200, 100).with_resolution(100, 100)
    l, r, b, t = s.camera.window
    assert (s.width, s.height) == (100, 100)
    assert r - l == pytest.approx(t - b)


def test_equirectangular_convention():
    u, v = scene.direction_to_equirectangular(np.array([[0, 0, 1], [1, 0, 0], [0, 1, 0], [-1, 0, 0]]))
    np.testing.assert_allclose(v, [1.0, 0.5, 0.5, 0.5])
    np.testing.assert_allclose(u[1:3], [0.5, 0.25])
    assert u[3] in (0.0, 1.0)
    d = np.random.default_rng(1).normal(size=(100, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    np.testing.assert_allclose(scene.equirectangular_to_direction(*scene.direction_to_equirectangular(d)),
                               d, atol=1e-12)


# ---- procedural scenes -------------------------------------------------------------------

def face_normals(flat, mesh):
    t0 = flat["mesh_first_triangle"][mesh]
    tri = flat["indices"][t0:t0 + flat["mesh_triangle_count"][mesh]]
    p = flat["positions"].astype(np.float64)
    return np.cross(p[tri[:, 1]] - p[tri[:, 0]], p[tri[:, 2]] - p[tri[:, 0]]), p[tri].mean(axis=1)


def test_builders_winding():
    b = scenes.box((1, 2, 3), (1, 2, 3), 0.4)
    s = SceneData([b])
    n, c = face_normals(s.flatten(), 0)
    assert len(n) == 12 and (np.einsum("ij,ij->i", n, c - (1, 2, 3)) > 0).all()
    sp = scenes.uv_sphere((0, 0, 1), 2.0, 16, 8)
    assert len(sp.indices) == 2 * 16 * 7
    s = SceneData([sp])
    assert s.validate() == []
    n, c = face_normals(s.flatten(), 0)
    assert (np.einsum("ij,ij->i", n, c - (0, 0, 1)) > 0).all()
    np.testing.assert_allclose(np.linalg.norm(sp.normals, axis=2), 1.0)
    corners = sp.positions[sp.indices]
    np.testing.assert_allclose(sp.normals, (corners - (0, 0, 1)) / 2.0, atol=1e-12)
    q = scenes.quad([(0, 0, 0), (1, 0, 0), (1, 1, 0), (0, 1, 0)])
    n, _ = face_normals(SceneData([q]).flatten(), 0)
    assert (n[:, 2] > 0).all()


def test_cornell_box():
    s = scenes.cornell_box(64, 48)
    assert s.validate() == []
    flat = s.flatten()
    assert (s.width, s.height) == (64, 48)
    assert len(flat["indices"]) == 5 * 2 + 2 * 12 + 2
    names = [m.name for m in s.meshes]
    for i, name in enumerate(names):       # walls and light face the room's inside
        if name in ("floor", "ceiling", "back", "left", "right", "light"):
            n, c = face_normals(flat, i)
            assert (np.einsum("ij,ij->i", n, np.array([0, 0, 1.0]) - c) > 0).all(), name
    light = names.index("light")
    k = flat["triangle_material"][flat["mesh_first_triangle"][light]]
    assert flat["material_type"][k] == 3
    np.testing.assert_allclose(flat["material_emission"][k], [17, 12, 4])
    red = flat["material_base_color"].tolist().index(pytest.approx([0.63, 0.065, 0.05]))
    n, c = face_normals(flat, names.index("left"))
    assert (c[:, 0] < 0).all() and flat["triangle_material"][flat["mesh_first_triangle"][names.index("left")]] == red
    # the camera sees the room: looks along +Y from the open front
    m = np.asarray(s.camera.camera_to_world)
    assert m[1, 3] < -1 and -m[1, 2] > 0.99


def test_veach_mis():
    s = scenes.veach_mis(96, 64)
    assert s.validate() == []
    flat = s.flatten()
    assert flat["light_type"].tolist() == [1, 1, 1, 1]
    np.testing.assert_allclose(flat["light_radius"], scenes.VEACH_RADII, rtol=1e-6)
    assert len({tuple(c) for c in flat["light_color"].round(4).tolist()}) == 4
    conductors = flat["material_type"] == 1
    np.testing.assert_allclose(sorted(flat["material_roughness"][conductors]),
                               scenes.VEACH_ROUGHNESS, rtol=1e-6)
    # Plates mirror the light row into the camera: half vector = plate normal.
    cam = np.asarray(s.camera.camera_to_world)[:, 3]
    for i in range(4):
        n, c = face_normals(flat, i)
        n, c = n[0] / np.linalg.norm(n[0]), c.mean(axis=0)     # plate centre
        h = (cam - c) / np.linalg.norm(cam - c) + (-c) / np.linalg.norm(c)
        np.testing.assert_allclose(n, h / np.linalg.norm(h), atol=0.05)


def test_furnace_and_closed_box():
    s = scenes.furnace_sphere(0.3, 32, 32)
    assert s.validate() == []
    flat = s.flatten()
    assert 2000 <= len(flat["indices"]) <= 2500 and flat["mesh_has_normals"].tolist() == [1]
    np.testing.assert_allclose(flat["world_color"], [1, 1, 1])
    np.testing.assert_allclose(flat["material_base_color"][0], [0.3] * 3, rtol=1e-6)
    assert len(flat["light_type"]) == 0
    s = scenes.closed_emitter_box(0.5, 2.0, 16, 16)
    flat = s.flatten()
    np.testing.assert_allclose(flat["material_emission"][0], [2, 2, 2])
    cam = np.asarray(s.camera.camera_to_world)[:, 3]
    assert (np.abs(cam) < 1).all() and (np.abs(flat["positions"]) == 1).all()


def test_env_map_scene():
    s = scenes.env_map_scene(32, 32, map_width=64)
    flat = s.flatten()
    m = flat["world_map"]
    assert m.shape == (32, 64, 3)
    # The sun blob is the brightest texel, at the requested elevation.
    r, c = np.unravel_index(np.argmax(m.sum(axis=2)), m.shape[:2])
    d = scene.equirectangular_to_direction((c + 0.5) / 64, 1 - (r + 0.5) / 32)
    assert math.degrees(math.asin(d[2])) == pytest.approx(35.0, abs=4.0)
    assert m[0].mean() < m[r, c].mean() and m[-1].mean() < m[0].mean()   # ground darker than zenith


def test_triangle_soup():
    # (How long building and flattening take is bench/throughput.py's business, not a test's.)
    for n in (1000, 100_000):
        s = scenes.triangle_soup_scene(n, 32, 32)
        assert abs(len(s.meshes[1].indices) - n) < 0.02 * n
    flat = s.flatten()
    assert s.validate() == [] and flat["light_type"].tolist() == [4]
    shuffled = scenes.triangle_soup_scene(100_000, 32, 32, shuffle=True, seed=3)
    a, b = s.meshes[1].indices, shuffled.meshes[1].indices
    assert not np.array_equal(a, b)
    key = lambda tri: np.sort(tri[:, 0] * 2**40 + tri[:, 1] * 2**20 + tri[:, 2])
    np.testing.assert_array_equal(key(a), key(b))     # same triangles, other order


# ---- EXR / PNG / CLI ---------------------------------------------------------------------

def test_png(tmp_path):
    import zlib
    img = np.zeros((3, 4, 3))
    img[0, 0] = (1.0, 0.5, 0.0)
    img[2, 3] = (2.0, -1.0, 0.0031308)
    exr.write_png(tmp_path / "a.png", img)
    data = (tmp_path / "a.png").read_bytes()
    assert data[:8] == b"\x89PNG\r\n\x1a\n"
    idat = data.index(b"IDAT")
    size = int.from_bytes(data[idat - 4:idat], "big")
    raw = np.frombuffer(zlib.decompress(data[idat + 4:idat + 4 + size]), np.uint8).reshape(3, 1 + 12)
    px = raw[:, 1:].reshape(3, 4, 3)
    assert px[0, 0].tolist() == [255, 188, 0] and px[2, 3].tolist() == [255, 0, 10]


def test_cli_scene(tmp_path, capsys):
    out = tmp_path / "cb.npz"
    assert cli.main(["scene", "cornell_box", "-o", str(out), "--width", "40", "--height", "30"]) == 0
    s = SceneData.load(out)
    assert (s.width, s.height) == (40, 30)
    assert cli.main(["scene", "triangle_soup", "-o", str(out), "--triangles", "2000", "--shuffle"]) == 0
    assert abs(sum(len(m.indices) for m in SceneData.load(out).meshes) - 2002) < 40
    assert cli.main(["render", str(tmp_path / "missing.npz"), "-o", str(tmp_path / "x.exr")]) == 2
    assert "parallax: error:" in capsys.readouterr().err


def test_principled_npz_round_trip_and_validation(tmp_path):
    s = rich_scene()
    s.materials.append(Material("principled", (0.7, 0.5, 0.3), roughness=0.4, ior=1.6, metallic=1.3,
                                transmission=0.2, specular_ior_level=0.8, specular_tint=(1.0, 0.9, -0.5),
                                coat_weight=0.5, coat_roughness=0.1, coat_ior=0.7, coat_tint=(0.9, 1.0, 0.8),
                                sheen_weight=0.3, sheen_roughness=1.4, sheen_tint=(0.2, 0.4, 1.0),
                                multiscatter=True, name="layered"))
    flat = s.flatten()
    # Cycles' clamps: metallic, roughnesses to [0, 1], tints >= 0, coat IOR >= 1.
    np.testing.assert_allclose(flat["material_principled"][-1],
                               [1.0, 0.9, 0.0, 1.0, 0.9, 1.0, 0.8, 0.5, 0.2, 0.4, 1.0, 0.3,
                                0.2, 0.8, 0.1, 1.0, 1.0], rtol=1e-6)
    s.save(tmp_path / "principled.npz")
    loaded = SceneData.load(tmp_path / "principled.npz")
    m = loaded.materials[-1]
    assert m.type == "principled" and m.multiscatter and m.sheen_tint == pytest.approx((0.2, 0.4, 1.0))
    assert_flat_equal(flat, loaded.flatten())
    # Files from before the principled type load with zero rows.
    old = {k: v for k, v in rich_scene().flatten().items() if k != "material_principled"}
    np.savez(tmp_path / "old.npz", **old)
    assert SceneData.load(tmp_path / "old.npz").flatten()["material_principled"].shape == (4, 17)
    expect_error(scene_with(materials=[Material("principled", coat_weight=float("nan"))]),
                 "material 0: coat_weight is NaN/Inf")
    expect_error(scene_with(materials=[Material("principled", sheen_tint=(1.0, 1.0))]),
                 "material 0: sheen_tint has shape (2,)")
