"""bench/shared_scenes.py: the thesis' irradiance-cache scene (Mitsuba 0.6 XML + OBJ, read
from the shared scenes folder, never copied into the repository) as SceneData, and a small
render against the thesis' reference EXR."""
import math
import sys
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))
from bench import shared_scenes  # noqa: E402

needs_scene = pytest.mark.skipif(
    not shared_scenes.available(shared_scenes.IRRADIANCE_CACHE),
    reason=f"shared scene {shared_scenes.IRRADIANCE_CACHE} not found in "
           f"{shared_scenes.SHARED_SCENES} (PARALLAX_SHARED_SCENES names the shared folder)")


def test_read_obj_fans_and_negative_indices(tmp_path):
    path = tmp_path / "quad.obj"
    path.write_text("v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nvn 0 0 1\nvt 0 0\n"
                    "f -4//1 -3//1 -2//1 -1//1\nf 1/1 2/1 3/1\n")
    positions, indices, normals, uvs = shared_scenes.read_obj(path)
    assert positions.shape == (4, 3)
    assert indices.tolist() == [[0, 1, 2], [0, 2, 3], [0, 1, 2]]
    assert normals.shape == (3, 3, 3) and np.allclose(normals, [0, 0, 1])
    assert uvs.shape == (3, 3, 2)



def test_mitsuba_subset(tmp_path):
    """<default>/$var, a <ref> to a named twosided diffuse, transforms, an emissive rectangle,
    point and constant emitters, fovAxis x, and Y up -> Z up."""
    (tmp_path / "tri.obj").write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n")
    (tmp_path / "s.xml").write_text("""<scene version="0.6.0">
      <default name="albedo" value="0.25"/>
      <bsdf type="twosided" id="grey"><bsdf type="diffuse">
        <rgb name="reflectance" value="$albedo, $albedo, 0.5"/></bsdf></bsdf>
      <shape type="obj"><string name="filename" value="tri.obj"/><ref id="grey"/>
        <transform name="toWorld"><scale value="2"/><translate x="1"/></transform></shape>
      <shape type="rectangle"><ref id="grey"/>
        <emitter type="area"><rgb name="radiance" value="3"/></emitter>
        <transform name="toWorld"><rotate x="1" angle="90"/><translate y="4"/></transform>
      </shape>
      <emitter type="point"><point name="position" x="0" y="2" z="0"/>
        <spectrum name="intensity" value="10"/></emitter>
      <emitter type="constant"><rgb name="radiance" value="0.1 0.2 0.3"/></emitter>
      <sensor type="perspective"><float name="fov" value="90"/>
        <transform name="toWorld"><lookAt origin="0 0 -5" target="0 0 0" up="0 1 0"/></transform>
        <film type="hdrfilm"><integer name="width" value="40"/>
          <integer name="height" value="20"/></film></sensor>
    </scene>""")
    scene, notes = shared_scenes.load_mitsuba(tmp_path / "s.xml")
    assert scene.validate() == [] and (scene.width, scene.height) == (40, 20)
    tri, rect = scene.meshes
    # (x, y, z) -> 2 (x, y, z) + (1, 0, 0), then Y up -> Z up: (x, -z, y).
    assert np.allclose(tri.positions, [[1, 0, 0], [3, 0, 0], [1, 0, 2]])
    assert np.allclose(rect.positions[:, 2], 4.0)  # the rectangle lies at Mitsuba y = 4
    mats = scene.materials
    assert mats[tri.material_indices[0]].base_color == (0.25, 0.25, 0.5)
    assert mats[rect.material_indices[0]].emission == (3.0, 3.0, 3.0)
    (light,) = scene.lights
    assert np.allclose(light.position, (0, 0, 2)) and light.power == pytest.approx(40 * math.pi)
    assert scene.world.color == (0.1, 0.2, 0.3)
    cam = scene.camera
    m = np.asarray(cam.camera_to_world)
    assert np.allclose(m[:, 3], (0, 5, 0))      # Mitsuba (0, 0, -5)
    assert np.allclose(-m[:, 2], (0, -1, 0))    # looking along Mitsuba +z = Z-up -y
    assert np.allclose(m[:, 1], (0, 0, 1))      # up
    assert np.allclose(m[:, 0], (-1, 0, 0))     # right = dir x up
    assert np.allclose(cam.window, (-1, 1, -0.5, 0.5))  # fov 90 along x
    assert notes  # the one-sided area emitter is mentioned

@needs_scene
def test_loader():
    scene = shared_scenes.thesis_irradiance_cache()
    assert (scene.width, scene.height) == (1280, 720)
    assert len(scene.meshes) == 4
    for mesh in scene.meshes:
        assert len(mesh.indices) > 0 and np.isfinite(mesh.positions).all()
    assert sum(len(m.indices) for m in scene.meshes) == 2 + 1196 + 1276 + 12
    assert scene.validate() == []
    (light,) = scene.lights
    assert light.type == "point" and light.radius == pytest.approx(0.9)
    # Mitsuba's sphere of radiance 1000, Y up (10, 10, 0) -> Z up (10, 0, 10).
    assert np.allclose(light.position, (10.0, 0.0, 10.0))
    assert light.power == pytest.approx(1000.0 * 4 * math.pi ** 2 * 0.81)
    cam = scene.camera
    m = np.asarray(cam.camera_to_world)
    assert m.shape == (3, 4) and np.isfinite(m).all()
    assert np.allclose(m[:, :3].T @ m[:, :3], np.eye(3), atol=1e-9)
    assert np.linalg.det(m[:, :3]) == pytest.approx(1.0)
    assert np.allclose(m[:, 3], (-3.0, -10.0, 5.0))  # origin (-3, 5, 10), Y up
    l, r, b, t = cam.window
    assert t == pytest.approx(math.tan(math.radians(22.5)))  # fov 45 along the smaller axis
    assert (r - l) / (t - b) == pytest.approx(1280 / 720)
    assert shared_scenes.thesis_irradiance_cache(width=64).height == 36


@needs_scene
def test_render_matches_reference():
    pc = pytest.importorskip("parallax_core")
    if not any(d.get("ray_tracing") for d in pc.devices()):
        pytest.skip("no Vulkan device with ray tracing")
    scene = shared_scenes.thesis_irradiance_cache(width=32)  # 32 x 18, the film's aspect
    image = shared_scenes.render(scene, spp=32, max_depth=8)
    ref = shared_scenes.reference(scene.width, scene.height)
    assert image.shape == ref.shape == (18, 32, 3)
    assert np.isfinite(image).all()
    mean, ref_mean = image.mean(axis=(0, 1)), ref.mean(axis=(0, 1))
    assert np.all(np.abs(mean / ref_mean - 1.0) < 0.15), (mean, ref_mean)
