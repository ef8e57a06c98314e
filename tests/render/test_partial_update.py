"""Partial scene updates (Session.update(scene, parts=...)): re-sending only the part of the
scene an edit changed gives the same images as a fresh session given the whole changed
scene, bit for bit on lavapipe; bad data leaves the old scene rendering unchanged; only a
geometry change rebuilds BLASes."""
import copy
import threading

import numpy as np
import pytest

import parallax_core as pc
from parallax_core import scenes
from parallax_core.scene import (FLAT_KEYS, PART_KEYS, PARTS, Camera, Instance, Light,
                                 Material, Mesh, Texture, World)
from parallax_core.scenes import sky_map

from helpers import same_render

W, H = 32, 32
FRAMES = 3


@pytest.fixture(scope="module")
def device_type():
    return pc.Session(4, 4).device_type


def xf(t=(0.0, 0.0, 0.0), s=1.0, rot_z=0.0):
    c, si = np.cos(rot_z), np.sin(rot_z)
    m = np.eye(4)
    m[:3, :3] = np.array([[c, -si, 0.0], [si, c, 0.0], [0.0, 0.0, 1.0]]) * s
    m[:3, 3] = t
    return m


def base_scene():
    """Cornell box plus what every part's edits need: explicit instances (one mesh twice,
    one mesh unused), a textured sphere with normals and UVs, a point light, a world."""
    sc = scenes.cornell_box(W, H)
    checker = np.kron((np.indices((4, 4)).sum(0) % 2), np.ones((2, 2), int))
    pixels = np.stack([checker * 200 + 30, checker * 60 + 40, 180 - checker * 120], -1)
    sc.textures.append(Texture(pixels.astype(np.uint8), "checker"))
    sc.materials.append(Material("diffuse", (0.9, 0.9, 0.9), base_color_texture=0, name="ball"))
    sc.meshes.append(scenes.uv_sphere((0.45, 0.1, 1.3), 0.25, 12, 6, material=4, name="ball"))
    sc.meshes.append(scenes.box((0.0, 0.0, 0.0), 0.3, 0.0, 0, "spare"))  # mesh 9: no instance
    # 0-4 walls, 5 short box, 6 tall box, 7 light quad, 8 ball; a second short box.
    sc.instances = [Instance(i) for i in range(9)] + [Instance(5, xf((0.0, 0.75, 0.0)))]
    sc.lights.append(Light("point", color=(1.0, 0.9, 0.8), power=30.0,
                           position=(0.5, -0.5, 1.5), radius=0.1, name="bulb"))
    sc.world = World((0.2, 0.25, 0.3), 1.0)
    return sc


def render(session):
    session.set_params(method="mis", samples_per_frame=2, seed=11, max_depth=6)
    session.reset()
    session.render(FRAMES)
    return session.read_all()


def fresh(scene, spatial_order=True):
    s = pc.Session(W, H)
    warnings = s.update(scene, spatial_order)
    return s, warnings


def assert_same(got, want, device_type):
    for name in (p.name for p in pc.PASSES if p.core):
        assert same_render(got[name], want[name], device_type), name


# ---- edits: (id, parts, edit, visible) -----------------------------------------------------
# `edit` changes a deep copy of base_scene() in place; `visible`: the change shows in the
# image (so a partial update that ignored it would fail).

def _camera_orbit(sc):
    sc.camera = Camera.look_at((1.2, -3.6, 1.3), (0.0, 0.0, 1.0), fov_y_degrees=39.3,
                               width=W, height=H, clip_start=0.1)


def _camera_zoom(sc):
    sc.camera.window = tuple(0.7 * x for x in sc.camera.window)


def _camera_ortho(sc):
    sc.camera.type = "orthographic"
    sc.camera.window = (-1.2, 1.2, -1.2, 1.2)


def _move_box(sc):
    sc.instances[6].transform = xf((0.1, -0.2, 0.0), rot_z=0.3)


def _move_emitter(sc):  # the light quad's triangles are in the light table
    sc.instances[7].transform = xf((0.2, 0.1, -0.3))


def _remove_instance(sc):
    del sc.instances[5]


def _singular_instance(sc):  # skipped, with a native warning
    sc.instances[6].transform = xf(s=0.0)


def _use_spare_mesh(sc):  # a mesh no instance used before: needs a new BLAS
    sc.instances.append(Instance(9, xf((-0.4, -0.5, 0.15))))


def _wall_color(sc):
    sc.materials[1].base_color = (0.1, 0.2, 0.7)


def _emission(sc):
    sc.materials[3].emission = (4.0, 10.0, 17.0)


def _new_emitter(sc):  # the green wall starts to emit: light offsets of instances change
    sc.materials[2].emission = (0.0, 2.0, 0.0)


def _conductor(sc):  # a new material type: another pipeline specialization
    sc.materials[0] = Material("conductor", (0.9, 0.8, 0.6), roughness=0.3, name="metal")


def _texture(sc):
    sc.textures[0] = Texture(255 - sc.textures[0].pixels, "inverted")


def _mix(sc):
    sc.materials.append(Material("conductor", (0.9, 0.9, 0.9), roughness=0.1))
    sc.materials[4].mix_next, sc.materials[4].mix_weight = 5, 0.4


def _move_light(sc):
    sc.lights[0].position = (-0.5, -0.3, 1.2)
    sc.lights[0].power = 60.0


def _add_lights(sc):
    sc.lights.append(Light("sun", power=3.0, direction=(0.3, 0.8, -0.5), angle=0.1))
    sc.lights.append(Light("area", power=20.0, position=(0.0, -0.8, 1.9), shape="disk",
                           size=0.4, camera_visible=False))


def _remove_lights(sc):
    sc.lights = []


def _world_color(sc):
    sc.world = World((0.6, 0.3, 0.1), 2.0)


def _world_map(sc):
    sc.world = World((0.0, 0.0, 0.0), 1.0, sky_map(32, sun_radiance=50.0))


def _scale_box(sc):
    m = sc.meshes[6]
    c = m.positions.mean(axis=0)
    m.positions = (m.positions - c) * np.array([1.3, 0.8, 1.1]) + c


def _add_mesh(sc):
    sc.meshes.append(scenes.box((0.5, -0.6, 0.1), 0.2, 0.5, 2, "cube"))
    sc.instances.append(Instance(len(sc.meshes) - 1))


def _edit_everything(sc):
    for edit in (_camera_orbit, _move_box, _wall_color, _move_light, _world_color):
        edit(sc)


EDITS = [
    ("camera-orbit", {"camera"}, _camera_orbit, True),
    ("camera-zoom", {"camera"}, _camera_zoom, True),
    ("camera-ortho", {"camera"}, _camera_ortho, True),
    ("instances-move", {"instances"}, _move_box, True),
    ("instances-move-emitter", {"instances"}, _move_emitter, True),
    ("instances-remove", {"instances"}, _remove_instance, True),
    ("instances-singular", {"instances"}, _singular_instance, True),
    ("materials-color", {"materials"}, _wall_color, True),
    ("materials-emission", {"materials"}, _emission, True),
    ("materials-new-emitter", {"materials"}, _new_emitter, True),
    ("materials-conductor", {"materials"}, _conductor, True),
    ("materials-texture", {"materials"}, _texture, True),
    ("materials-mix", {"materials"}, _mix, True),
    ("lights-move", {"lights"}, _move_light, True),
    ("lights-add", {"lights"}, _add_lights, True),
    ("lights-remove", {"lights"}, _remove_lights, True),
    ("lights-world-color", {"lights"}, _world_color, True),
    ("lights-world-map", {"lights"}, _world_map, True),
    ("geometry-scale", {"geometry"}, _scale_box, True),
    ("geometry+instances-add", {"geometry", "instances"}, _add_mesh, True),
    ("several-parts", {"camera", "instances", "materials", "lights"}, _edit_everything, True),
]


@pytest.mark.parametrize("parts, edit, visible", [e[1:] for e in EDITS], ids=[e[0] for e in EDITS])
def test_partial_update_matches_a_full_one(parts, edit, visible, device_type):
    base = base_scene()
    changed = copy.deepcopy(base)
    edit(changed)
    s = pc.Session(W, H)
    s.update(base)
    before = render(s)
    builds = s.stats()["blas_builds"]
    warnings = s.update(changed, parts=parts)
    got = render(s)
    ref, ref_warnings = fresh(changed)
    want = render(ref)
    assert_same(got, want, device_type)
    assert warnings == ref_warnings == s.warnings
    if visible:
        assert not np.array_equal(want["combined"], before["combined"]), "the edit does not show"
    # Only geometry rebuilds BLASes (all of them); an instance edit builds only the BLAS of
    # a mesh no instance used before.
    grown = s.stats()["blas_builds"] - builds
    if "geometry" in parts:
        assert grown == ref.stats()["blas_builds"]
    else:
        assert grown == 0


def test_instances_using_a_new_mesh_build_only_its_blas(device_type):
    base = base_scene()
    changed = copy.deepcopy(base)
    _use_spare_mesh(changed)
    s = pc.Session(W, H)
    s.update(base)
    builds = s.stats()["blas_builds"]
    assert builds == 9  # meshes 0-8; the spare mesh has no instance
    s.update(changed, parts={"instances"})
    assert s.stats()["blas_builds"] == builds + 1
    ref, _ = fresh(changed)
    assert_same(render(s), render(ref), device_type)
    # Moving it back out of use and in again reuses the BLAS it got.
    s.update(base, parts={"instances"})
    s.update(changed, parts={"instances"})
    assert s.stats()["blas_builds"] == builds + 1
    assert_same(render(s), render(ref), device_type)


def test_blas_builds_grow_only_on_geometry():
    base = base_scene()
    s = pc.Session(W, H)
    assert s.stats()["blas_builds"] == 0
    s.update(base)
    n = s.stats()["blas_builds"]
    assert n == 9
    changed = copy.deepcopy(base)
    for edit in (_camera_orbit, _move_box, _wall_color, _move_light, _world_map):
        edit(changed)
    for part in ("camera", "instances", "materials", "lights"):
        s.update(changed, parts={part})
        s.render(1)
        assert s.stats()["blas_builds"] == n, part
    s.update(changed, parts={"geometry"})
    assert s.stats()["blas_builds"] == 2 * n
    s.update(changed)
    assert s.stats()["blas_builds"] == 3 * n
    s.reset()
    assert s.stats()["blas_builds"] == 3 * n  # not reset with the accumulation


def test_updates_build_on_each_other(device_type):
    # A chain of partial updates of different parts ends where one full update does.
    scene = base_scene()
    s = pc.Session(W, H)
    s.update(scene)
    for part, edit in (("camera", _camera_orbit), ("lights", _world_map), ("instances", _move_box),
                       ("materials", _new_emitter), ("camera", _camera_zoom), ("lights", _add_lights),
                       ("instances", _move_emitter), ("materials", _texture), ("geometry", _scale_box),
                       ("camera", _camera_ortho)):
        edit(scene)
        s.update(scene, parts={part})
    ref, _ = fresh(scene)
    assert_same(render(s), render(ref), device_type)


def test_partial_update_accumulation_restarts():
    s = pc.Session(W, H)
    s.update(base_scene())
    s.render(2)
    assert s.stats()["samples"] > 0
    s.update(base_scene(), parts={"camera"})
    st = s.stats()
    assert st["samples"] == 0 and st["frames"] == 0 and st["rays"] == 0
    assert not s.read("combined").any()


def test_partial_update_without_spatial_order(device_type):
    base = base_scene()
    changed = copy.deepcopy(base)
    _move_box(changed)
    _remove_instance(changed)
    s = pc.Session(W, H)
    s.update(base, spatial_order=False)
    s.update(changed, spatial_order=False, parts={"instances"})
    ref, _ = fresh(changed, spatial_order=False)
    assert_same(render(s), render(ref), device_type)


# ---- bad input -----------------------------------------------------------------------------

def _truncate_materials(f):
    for k in PART_KEYS["materials"]:
        if k.startswith("material_"):
            f[k] = f[k][:2].copy()


@pytest.mark.parametrize(
    "parts, corrupt, message",
    [
        ({"camera"}, lambda f: f["camera_to_world"].__setitem__((0, 1), np.nan), "camera_to_world is NaN"),
        ({"camera"}, lambda f: f["camera_window"].__setitem__(1, -5.0), "camera_window"),
        ({"instances"}, lambda f: f["instance_mesh"].__setitem__(0, 99), r"instance_mesh\[0\] = 99"),
        ({"instances"}, lambda f: f.pop("instance_transform"), "missing array 'instance_transform'"),
        ({"materials"}, _truncate_materials, "triangle_material refers to material 4 but there are 2"),
        ({"materials"}, lambda f: f["material_texture"].__setitem__(0, 5), "texture 5 out of range"),
        ({"materials"}, lambda f: f["material_mix_next"].__setitem__(1, 1), "mix chain has a cycle"),
        ({"lights"}, lambda f: f["light_direction"].__setitem__(0, 0.0), "light 0: zero direction"),
        ({"lights"}, lambda f: f.__setitem__("world_map", np.zeros((0, 4, 3), np.float32)), "world_map has zero size"),
        ({"geometry"}, lambda f: f["positions"].__setitem__((3, 1), np.nan), r"positions\[3\] is NaN"),
        ({"geometry"}, lambda f: f["triangle_material"].__setitem__(0, 77), r"triangle_material\[0\] = 77"),
    ],
)
def test_bad_partial_update_keeps_the_old_scene(parts, corrupt, message, device_type):
    base = base_scene()
    s = pc.Session(W, H)
    s.update(base)
    before = render(s)
    flat = base.flatten(parts=parts)
    corrupt(flat)
    with pytest.raises(ValueError, match=message):
        s.update(flat, parts=parts)
    assert_same(render(s), before, device_type)
    # The failed update left nothing behind: a later partial update builds on the old scene.
    changed = copy.deepcopy(base)
    _camera_orbit(changed)
    s.update(changed, parts={"camera"})
    ref, _ = fresh(changed)
    assert_same(render(s), render(ref), device_type)


def test_bad_scene_data_in_a_partial_update(device_type):
    base = base_scene()
    s = pc.Session(W, H)
    s.update(base)
    before = render(s)
    bad = copy.deepcopy(base)
    bad.camera.camera_to_world[0, 0] = np.inf
    with pytest.raises(ValueError, match="camera"):
        s.update(bad, parts={"camera"})
    assert_same(render(s), before, device_type)


def test_partial_update_before_a_full_one():
    s = pc.Session(W, H)
    with pytest.raises(RuntimeError, match="whole scene first"):
        s.update(base_scene(), parts={"camera"})
    with pytest.raises(RuntimeError, match="no scene"):
        s.render(1)
    s.update(base_scene())  # then it works
    s.update(base_scene(), parts={"camera"})


def test_unknown_or_empty_parts():
    s = pc.Session(W, H)
    s.update(base_scene())
    with pytest.raises(ValueError, match="unknown scene part"):
        s.update(base_scene(), parts={"meshes"})
    with pytest.raises(ValueError, match="unknown scene part"):
        s.update(base_scene(), parts="cameras")
    with pytest.raises(ValueError, match="no scene parts"):
        s.update(base_scene(), parts=set())
    with pytest.raises(ValueError, match="unknown scene part 'world'"):
        s._update(base_scene().flatten(parts={"lights"}), True, ["world"])
    with pytest.raises(ValueError, match="unknown scene part"):
        base_scene().flatten(parts={"textures"})
    s.update(base_scene(), parts="camera")  # one name is a set of one


def test_native_update_rejects_arrays_of_other_parts():
    s = pc.Session(W, H)
    sc = base_scene()
    s.update(sc)
    flat = sc.flatten(parts={"instances", "camera"})
    with pytest.raises(ValueError, match="'camera_.*' belongs to scene part 'camera', which this update"):
        s._update(flat, True, ["instances"])


def test_all_parts_is_a_full_update(device_type):
    # Naming every part needs no earlier update and replaces the whole scene.
    s = pc.Session(W, H)
    s.update(base_scene(), parts=PARTS)
    ref, _ = fresh(base_scene())
    assert_same(render(s), render(ref), device_type)


# ---- what a partial update sends and checks -------------------------------------------------

def test_every_flat_key_is_in_exactly_one_part():
    assert tuple(PART_KEYS) == PARTS == pc.PARTS
    keys = [k for p in PARTS for k in PART_KEYS[p]]
    assert sorted(keys) == sorted(FLAT_KEYS) and len(keys) == len(set(keys))
    assert set(PART_KEYS["camera"]) == {k for k in FLAT_KEYS if k.startswith("camera_")}
    assert set(PART_KEYS["instances"]) == {"instance_transform", "instance_mesh"}
    assert set(PART_KEYS["lights"]) == {k for k in FLAT_KEYS if k.startswith(("light_", "world_"))}
    assert set(PART_KEYS["materials"]) == {k for k in FLAT_KEYS if k.startswith(("material_", "texture_"))}
    assert set(PART_KEYS["geometry"]) == {"positions", "indices", "triangle_material", "corner_normals",
                                          "corner_uvs", "mesh_first_triangle", "mesh_triangle_count",
                                          "mesh_has_normals", "mesh_has_uvs", "mesh_texspace",
                                          "corner_tangents", "mesh_has_tangents", "corner_attributes",
                                          "mesh_attribute_mask"}


def test_flatten_parts_sends_only_those_keys():
    sc = base_scene()
    full = sc.flatten()
    cam = sc.flatten(parts={"camera"})
    assert set(cam) == set(PART_KEYS["camera"]) and all(k.startswith("camera_") for k in cam)
    for part in PARTS:
        flat = sc.flatten(parts={part})
        assert set(flat) == set(PART_KEYS[part])
        for k, v in flat.items():
            assert v.dtype == full[k].dtype and np.array_equal(v, full[k]), k
    both = sc.flatten(parts={"lights", "instances"})
    assert set(both) == set(PART_KEYS["lights"]) | set(PART_KEYS["instances"])


def test_partial_update_sends_only_the_parts(monkeypatch):
    sc = base_scene()
    s = pc.Session(W, H)
    s.update(sc)
    sent = []
    native_update = pc.Session._update
    monkeypatch.setattr(pc.Session, "_update",
                        lambda self, arrays, spatial, parts: (sent.append((set(arrays), parts)),
                                                              native_update(self, arrays, spatial, parts))[1])
    s.update(sc, parts={"camera"})
    s.update(sc.flatten(), parts={"lights", "camera"})  # a whole dict is cut down to the parts
    s.update(sc)
    assert sent[0] == (set(PART_KEYS["camera"]), ["camera"])
    assert sent[1] == (set(PART_KEYS["lights"]) | set(PART_KEYS["camera"]), ["lights", "camera"])
    assert sent[2] == (set(FLAT_KEYS), [])


def test_validate_checks_only_the_parts():
    sc = base_scene()
    sc.meshes[0].positions = sc.meshes[0].positions.copy()
    sc.meshes[0].positions[0, 0] = np.nan
    sc.lights[0].direction = (0.0, 0.0, 0.0)
    with pytest.raises(ValueError, match="NaN"):
        sc.validate()
    with pytest.raises(ValueError, match="zero length"):
        sc.validate(parts={"lights"})
    assert sc.validate(parts={"camera"}) == []
    assert sc.validate(parts={"instances", "materials", "camera"}) == []
    assert set(sc.flatten(parts={"camera"})) == set(PART_KEYS["camera"])
    with pytest.raises(ValueError, match="NaN"):
        sc.flatten(parts={"geometry"})


def test_partial_update_returns_the_whole_scenes_warnings():
    sc = base_scene()
    sc.meshes.append(Mesh(np.array([[0, 0, 0], [1, 1, 1], [2, 2, 2]], float), np.array([[0, 1, 2]]),
                          name="line"))
    sc.lights.append(Light("area", size=0.0, name="flat"))
    sc.instances[6].transform = xf(s=0.0)
    s = pc.Session(W, H)
    full = s.update(sc)
    assert any("degenerate" in w for w in full)
    assert any("zero-size area light" in w for w in full)
    assert any("singular" in w for w in full) and any("skipped" in w for w in full)
    assert s.update(sc, parts={"camera"}) == full
    assert s.update(sc, parts={"materials"}) == full
    sc.instances[6].transform = np.eye(4)  # fixes the instance warnings only
    fixed = s.update(sc, parts={"instances"})
    assert fixed == fresh(sc)[1]
    assert not any("singular" in w or "instance(s)" in w for w in fixed)
    assert any("degenerate" in w for w in fixed) and any("zero-size" in w for w in fixed)
    sc.lights.pop()
    assert s.update(sc, parts={"lights"}) == fresh(sc)[1]
    assert s.warnings == fresh(sc)[1]


def test_camera_updates_while_another_thread_renders(device_type):
    base = base_scene()
    s = pc.Session(W, H)
    s.set_params(method="mis", samples_per_frame=1, seed=11, max_depth=6)
    s.update(base)
    stop, errors = threading.Event(), []

    def work():
        try:
            while not stop.is_set():
                s.render(1)
        except Exception as e:  # noqa: BLE001 - reported below
            errors.append(e)

    t = threading.Thread(target=work)
    t.start()
    try:
        changed = copy.deepcopy(base)
        for k in range(8):
            changed.camera = Camera.look_at((0.2 * k, -3.9, 1.0), (0.0, 0.0, 1.0), fov_y_degrees=39.3,
                                            width=W, height=H, clip_start=0.1)
            s.update(changed, parts={"camera"})
            changed.instances[6].transform = xf((0.02 * k, 0.0, 0.0))
            s.update(changed, parts={"instances"})
    finally:
        stop.set()
        t.join(timeout=120)
    assert not errors
    ref, _ = fresh(changed)
    assert_same(render(s), render(ref), device_type)


def test_update_latency_bench_smoke():
    # bench/update_latency.py with tiny settings: it runs and every partial row builds no
    # BLAS (timings are never pass/fail).
    import sys
    from pathlib import Path

    sys.path.insert(0, str(Path(__file__).resolve().parents[2]))
    from bench import update_latency

    rows = update_latency.run((24, 16), triangles=500, repeats=1, max_depth=2,
                              progress=lambda msg: None)
    assert [r["row"] for r in rows] == list(update_latency.ROWS) * 2
    for r in rows:
        assert r["update_ms"] > 0 and r["render_ms"] > 0
        assert (r["blas_builds"] > 0) == (r["row"] in ("full", "geometry")), r
    assert "parts={'camera'}" in update_latency.table(rows)
