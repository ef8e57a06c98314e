"""Textures (sRGB decode, orientation, bilinear) and the orthographic camera."""
import numpy as np
import pytest

import copy
import dataclasses

import parallax_core as pc
from parallax_core import scenes
from parallax_core.scene import Camera, Instance, Light, Material, Mesh, SceneData, Texture, World


def textured_quad(texture, width=32, height=32, interpolation="linear", base_color=(1.0, 1.0, 1.0)):
    # Quad [-1,1]^2 at z=0, UVs as Blender unwraps it: (0,0) bottom-left, (1,1) top-right.
    p = np.array([[-1, -1, 0], [1, -1, 0], [1, 1, 0], [-1, 1, 0]], float)
    uv = np.array([[0, 0], [1, 0], [1, 1], [0, 1]], float)
    tris = np.array([[0, 1, 2], [0, 2, 3]])
    mesh = Mesh(p, tris, uvs=uv[tris], name="quad")
    mat = Material("diffuse", base_color, base_color_texture=0)
    # Orthographic camera 5 above, looking down, +Y up in the image; ortho_scale 2 spans the quad.
    m = np.eye(4)
    m[:3, 3] = (0, 0, 5)
    cam = Camera.from_blender(m, width, height, type="ORTHO", ortho_scale=2.0)
    return SceneData([mesh], [], [mat], [Texture(texture, interpolation=interpolation)], [], World((1, 1, 1), 1.0),
                     cam, width, height)


def albedo(scene, session=None):
    s = session or pc.Session(scene.width, scene.height)
    s.set_params(method="mis", samples_per_frame=16, **pc.UNBIASED_LIGHT_PATHS)
    s.update(scene)
    s.render(1)
    return s.read("albedo"), s.read("depth")


def test_texture_orientation_and_srgb_decode():
    tex = np.zeros((4, 4, 3), np.uint8)  # four 2x2-texel quadrants
    tex[:2, :2] = (255, 0, 0)      # top-left: red
    tex[:2, 2:] = (0, 255, 0)      # top-right: green
    tex[2:, :2] = (0, 0, 255)      # bottom-left: blue
    tex[2:, 2:] = (128, 128, 128)  # bottom-right: sRGB 0.5 grey -> linear 0.2158
    a, depth = albedo(textured_quad(tex))
    # Between the texel centres of one quadrant bilinear filtering stays inside it.
    assert np.allclose(a[7, 7], (1, 0, 0), atol=1e-3)
    assert np.allclose(a[7, 24], (0, 1, 0), atol=1e-3)
    assert np.allclose(a[24, 7], (0, 0, 1), atol=1e-3)
    assert np.allclose(a[24, 24], 0.2158, atol=2e-3)
    # Orthographic: every pixel is 5 units from the camera along its axis.
    assert np.allclose(depth, 5.0, atol=1e-4)


def test_texture_is_bilinear():
    tex = np.zeros((1, 2, 3), np.uint8)
    tex[0, 0] = 0
    tex[0, 1] = 255
    a, _ = albedo(textured_quad(tex, 64, 8))
    row = a[4, :, 0]
    # As Cycles reads 8-bit sRGB images, the stored values are blended, then decoded: pixel 32
    # lies at texel position f = 32.5 / 64 * 2 - 0.5 between the two (decoding first: f itself).
    f = 32.5 / 64 * 2 - 0.5
    assert row[32] == pytest.approx(((f + 0.055) / 1.055) ** 2.4, abs=0.01)
    # Repeat wrapping: the ramp rises across the middle and falls towards both edges.
    assert row[16] < 0.05 and row[47] > 0.95
    assert np.all(np.diff(row[16:48]) >= -1e-4)


def test_closest_interpolation_shows_only_the_texels():
    """Blender's Closest: each pixel shows the texel it falls in (sharp edges), where Linear
    blends neighbours. A 2x2 checker over 32x32 pixels: texel edges lie on pixel edges."""
    tex = np.array([[[255, 0, 0], [0, 255, 0]], [[0, 0, 255], [255, 255, 255]]], np.uint8)
    s = pc.Session(32, 32)
    closest, _ = albedo(textured_quad(tex, interpolation="closest"), s)
    expected = np.zeros((32, 32, 3), np.float32)
    expected[:16, :16], expected[:16, 16:], expected[16:, :16], expected[16:, 16:] = tex.reshape(4, 3) / 255.0
    assert np.abs(closest - expected).max() < 1e-4
    linear, _ = albedo(textured_quad(tex), s)
    blended = ((linear > 0.02) & (linear < 0.98)).any(axis=2)
    assert blended.mean() > 0.5  # Linear: most pixels mix two or four texels
    assert min(linear[8, 15, 0], linear[8, 15, 1]) > 0.1  # red and green mix at their edge


def test_float_texture_keeps_values_above_one_and_interpolates_linearly():
    """A float (linear) image: values above 1 survive and blends are linear, with no 8-bit
    quantisation; the render's mean is the texture's mean times the base colour (a diffuse
    quad under a white world reflects its albedo)."""
    tex = np.array([[[0.5, 0.5, 0.5], [3.5, 3.5, 3.5]]], np.float32)
    sc = textured_quad(tex, 64, 8, base_color=(0.25, 0.25, 0.25))
    s = pc.Session(64, 8)
    albedo(sc, s)
    s.render(7)  # 128 samples per pixel: the albedo pass's pixel-footprint noise below 1e-3
    a = s.read("albedo")
    # Bilinear at the pixel centres, repeat wrapping: texel position x = (i + 0.5) / 64 * 2 - 0.5.
    x = (np.arange(64) + 0.5) / 64 * 2 - 0.5
    f = x - np.floor(x)
    left = np.where(np.floor(x) % 2 == 0, 0.5, 3.5)
    right = np.where(np.floor(x) % 2 == 0, 3.5, 0.5)
    np.testing.assert_allclose(a[4, :, 0], 0.25 * ((1 - f) * left + f * right), atol=3e-3)
    assert a.max() > 0.85  # 0.25 * 3.5 near the right texel's centre
    mean = s.read("combined")[..., :3].mean()
    assert mean == pytest.approx(0.25 * 2.0, rel=0.02)


def test_instance_transform_matches_baked_geometry():
    """An instance's rotation and non-uniform scale act on its normals like on baked vertices
    (normals go through the inverse transpose)."""
    base = scenes.cornell_box(32, 32)
    angle, scale = 0.6, np.diag([0.7, 1.3, 1.0])
    rotation = np.array([[np.cos(angle), -np.sin(angle), 0], [np.sin(angle), np.cos(angle), 0], [0, 0, 1]])
    linear = rotation @ scale
    box = scenes.box((0.0, 0.0, 0.5), (0.4, 0.4, 1.0))
    corners = box.positions[box.indices]
    face = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
    face /= np.linalg.norm(face, axis=-1, keepdims=True)
    box.normals = np.repeat(face[:, None], 3, axis=1).astype(np.float32)  # explicit shading normals
    transform = np.eye(4)
    transform[:3, :3], transform[:3, 3] = linear, (0.1, 0.1, 0.0)

    instanced, baked = copy.deepcopy(base), copy.deepcopy(base)
    instanced.meshes.append(box)
    instanced.instances = instanced.effective_instances()[:-1] + [Instance(len(base.meshes), transform)]
    flat = copy.deepcopy(box)
    flat.positions = (box.positions @ linear.T + transform[:3, 3]).astype(np.float32)
    normals = box.normals @ np.linalg.inv(linear)  # n' = A^-T n, as row vectors
    flat.normals = (normals / np.linalg.norm(normals, axis=-1, keepdims=True)).astype(np.float32)
    baked.meshes.append(flat)
    baked.instances = baked.effective_instances()

    images = []
    for scene in (instanced, baked):
        s = pc.Session(32, 32)
        s.set_params(samples_per_frame=4, **pc.UNBIASED_LIGHT_PATHS)
        s.update(scene)
        s.render(1)
        images.append((s.read("normal"), s.read("combined")))
    np.testing.assert_allclose(images[0][0], images[1][0], atol=1e-3)
    np.testing.assert_allclose(images[0][1], images[1][1], atol=1e-3)


@pytest.mark.parametrize("kind", ["point", "area", "sun"])
def test_lights_hidden_from_the_camera_still_light_the_scene(kind):
    """Blender's per-light Camera visibility: camera rays pass through the light, every other
    ray sees it (so the lighting is unchanged)."""
    floor = scenes.quad([(-6, -6, 0), (6, -6, 0), (6, 6, 0), (-6, 6, 0)])
    light = {"point": Light("point", power=400.0, position=(0, 0, 1.5), radius=0.4),
             "area": Light("area", power=400.0, position=(0, 0, 1.5), size=1.0, direction=(0, 0, -1)),
             "sun": Light("sun", power=3.0, direction=(0.3, 0.2, -1.0), angle=0.5)}[kind]
    # Looking up at the light over the floor it lights (or into the sun).
    eye, target = ((0, -3, 0.3), (0, 0, 1.5)) if kind != "sun" else ((0, 0, 1), (-0.3, -0.2, 2.0))
    camera = Camera.look_at(eye, target, fov_y_degrees=60, width=24, height=24)
    meshes = [floor] if kind != "sun" else []
    images = {}
    for visible in (True, False):
        light.camera_visible = visible
        scene = SceneData(meshes, [], [Material()], [], [light], World((0, 0, 0), 0.0), camera, 24, 24)
        s = pc.Session(24, 24)
        s.set_params(samples_per_frame=64, seed=1, **pc.UNBIASED_LIGHT_PATHS)
        s.update(scene)
        s.render(1)
        images[visible] = s.read("combined")[..., :3]
    centre = (slice(9, 15), slice(9, 15))  # where the light (or the sun disc) is seen
    assert images[True][centre].mean() > 10 * max(images[False][centre].mean(), 1e-3)
    changed = np.abs(images[True] - images[False]).max(axis=-1) > 1e-6
    if kind != "sun":  # away from the light, the lit floor is the same image
        assert not changed[-3:].any() and images[False][-3:].mean() > 0.01


# ---- the thin lens and panoramas (issue 37; their parity with Cycles: tests/addon/test_parity_camera.py) ----

def combined(scene, samples=16):
    s = pc.Session(scene.width, scene.height)
    s.set_params(method="mis", samples_per_frame=samples, **pc.UNBIASED_LIGHT_PATHS)
    s.update(scene)
    s.render(1)
    return s.read("combined"), s.read("depth")


def test_a_pinhole_ignores_the_lens_settings_and_depth_of_field_keeps_the_focus_plane():
    scene = scenes.cornell_box(width=24, height=24)
    pinhole, _ = combined(scene)
    scene.camera = dataclasses.replace(scene.camera, focus_distance=1.0, aperture_blades=5, aperture_ratio=2.0)
    again, _ = combined(scene)
    assert np.array_equal(pinhole, again)  # a pinhole draws no lens sample: the same paths
    # Looking straight at a textured quad 5 m away, focused on it: the albedo keeps its texels
    # whatever the aperture (every lens point sees the same point of the focus plane).
    tex = np.zeros((4, 4, 3), np.uint8)
    tex[:2, :2], tex[2:, 2:] = 255, 128
    quad = textured_quad(tex)
    m = np.eye(4)
    m[:3, 3] = (0, 0, 5)
    quad.camera = Camera.from_blender(m, 32, 32, lens=180.0, sensor_width=36.0)  # 2 m wide at 5 m
    session = pc.Session(32, 32)
    sharp, depth = albedo(quad, session)

    def camera_update(**lens):  # the camera alone, as the viewport sends it: the lens switches on
        quad.camera = dataclasses.replace(quad.camera, **lens)
        session.update(quad, parts={"camera"})
        session.render(1)
        return session.read("albedo"), session.read("depth")

    focused, focused_depth = camera_update(aperture_radius=0.5, focus_distance=5.0)
    np.testing.assert_allclose(focused, sharp, atol=1e-3)
    np.testing.assert_allclose(focused_depth, depth, rtol=1e-4)
    assert np.abs(camera_update(focus_distance=2.0)[0] - sharp).max() > 0.3  # out of focus: texel edges blur
    np.testing.assert_allclose(camera_update(aperture_radius=0.0)[0], sharp, atol=1e-3)  # and off again


def test_a_fisheye_renders_nothing_outside_its_image_circle():
    scene = scenes.cornell_box(width=32, height=32)
    scene.camera = dataclasses.replace(scene.camera, type="panorama", window=(0.0, 1.0, 0.0, 1.0),
                                panorama_type="FISHEYE_EQUIDISTANT", fisheye_fov=np.pi)
    image, depth = combined(scene)
    y, x = np.mgrid[:32, :32]
    r = np.hypot((x + 0.5) / 16 - 1, (y + 0.5) / 16 - 1)
    assert np.all(image[r > 1.05, :3] == 0) and np.all(depth[r > 1.05] == 0)
    assert image[r < 0.3, :3].mean() > 0.05
