"""Bad input gets a clear exception and the process stays alive (DESIGN: Errors)."""
import numpy as np
import pytest

import parallax_core as pc
from parallax_core import scenes
from parallax_core.scene import Mesh, SceneData, Texture


@pytest.fixture(scope="module")
def session():
    return pc.Session(8, 8)


def flat(scene=None):
    return (scene or scenes.cornell_box(8, 8)).flatten()


def test_zero_size_session_is_rejected():
    with pytest.raises(ValueError, match="image size"):
        pc.Session(0, 16)


def test_unknown_device_selector():
    with pytest.raises(RuntimeError, match="unknown device selector"):
        pc.Session(8, 8, device="tpu")
    with pytest.raises(RuntimeError, match="out of range"):
        pc.Session(8, 8, device="7")


def test_render_before_update(session):
    fresh = pc.Session(4, 4)
    with pytest.raises(RuntimeError, match="no scene"):
        fresh.render(1)


def test_unknown_pass_and_params(session):
    session.update(scenes.cornell_box(8, 8))
    with pytest.raises(ValueError, match="unknown pass"):
        session.read("beauty")
    with pytest.raises(ValueError, match="unknown method"):
        session.set_params(method="bdpt")
    with pytest.raises(ValueError, match="samples_per_frame"):
        session.set_params(samples_per_frame=0)
    with pytest.raises(TypeError, match="unknown render parameter"):
        session.set_params(bounces=3)


# The native layer validates the raw arrays on its own (a hand-made dict or npz bypasses
# SceneData's checks): each corruption names the array and the element.
@pytest.mark.parametrize(
    "corrupt, message",
    [
        (lambda a: a["positions"].__setitem__((3, 1), np.nan), r"positions\[3\] is NaN"),
        (lambda a: a["positions"].__setitem__((0, 0), np.inf), r"positions\[0\] is NaN or infinite"),
        (lambda a: a["indices"].__setitem__((2, 1), 10**6), r"indices\[2\] refers to vertex 1000000"),
        (lambda a: a["triangle_material"].__setitem__(0, 99), r"triangle_material\[0\] = 99"),
        (lambda a: a.__setitem__("triangle_material", a["triangle_material"][:-1]), "triangle_material has"),
        (lambda a: a.__setitem__("positions", a["positions"][:, :2].copy()), r"'positions' has shape"),
        (lambda a: a.__setitem__("positions", a["positions"].astype(np.float64)), "wrong dtype"),
        (lambda a: a.pop("material_ior"), "missing array 'material_ior'"),
        (lambda a: a["instance_mesh"].__setitem__(0, 50), r"instance_mesh\[0\] = 50"),
        (lambda a: a["instance_transform"].__setitem__((0, 0, 0), np.nan), r"instance_transform\[0\]"),
        (lambda a: a["material_ior"].__setitem__(0, -1.0), "ior must be positive"),
        (lambda a: a["material_texture"].__setitem__(0, 3), "texture 3 out of range"),
        (lambda a: a["mesh_triangle_count"].__setitem__(0, 10**6), "mesh 0 covers triangles"),
        (lambda a: a["camera_window"].__setitem__(1, -5.0), "camera_window"),
        (lambda a: a.__setitem__("world_map", np.zeros((0, 4, 3), np.float32)), "world_map has zero size"),
    ],
)
def test_native_validation_names_the_problem(session, corrupt, message):
    arrays = flat()
    corrupt(arrays)
    with pytest.raises(ValueError, match=message):
        session.update(arrays)
    # The session is intact: a good scene still renders.
    session.update(scenes.cornell_box(8, 8))
    session.render(1)
    assert np.isfinite(session.read("combined")).all()


def test_non_array_value(session):
    arrays = flat()
    arrays["positions"] = "not an array"
    with pytest.raises(TypeError, match="positions"):
        session.update(arrays)


def test_scene_data_errors_name_the_mesh(session):
    sc = scenes.cornell_box(8, 8)
    sc.meshes[0].positions[1, 2] = np.nan
    with pytest.raises(ValueError, match="NaN"):
        session.update(sc)


def test_zero_size_texture(session):
    sc = scenes.cornell_box(8, 8)
    sc.textures.append(Texture(np.zeros((0, 4, 3), np.uint8)))
    with pytest.raises(ValueError, match="zero-size"):
        session.update(sc)


def test_degenerate_triangles_are_skipped_with_a_warning(session):
    sc = scenes.cornell_box(8, 8)
    m = sc.meshes[0]
    bad = Mesh(np.array([[0, 0, 0], [1, 1, 1], [2, 2, 2]], float), np.array([[0, 1, 2]]), name="line")
    sc.meshes.append(bad)
    warnings = session.update(sc)
    assert any("degenerate" in w for w in warnings), warnings
    session.render(1)
    assert m is sc.meshes[0]


def test_empty_scene_renders_the_world(session):
    sc = scenes.furnace_sphere(0.5, 8, 8)
    sc.meshes, sc.instances = [], []
    session.update(sc)
    session.set_params(method="mis", samples_per_frame=4)
    session.render(1)
    img = session.read("combined")[..., :3]
    assert np.allclose(img, 1.0, atol=1e-5)  # the white world everywhere
    assert session.read("depth").min() == pytest.approx(1e10)


def test_no_lights_renders_black(session):
    sc = scenes.cornell_box(8, 8)
    sc.materials[3].emission = (0.0, 0.0, 0.0)
    session.update(sc)
    for method in pc.METHODS:
        session.set_params(method=method)
        session.render(1)
        assert session.read("combined")[..., :3].max() == 0.0
