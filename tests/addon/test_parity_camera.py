"""Parity with Cycles for the camera (issue 37): thin-lens depth of field (f-stop, focus object,
blades, rotation, anamorphic ratio) on perspective and orthographic cameras, and every
panoramic projection Blender offers.

Each scene is built with blender_scenes/build.py's helpers and rendered by both engines with
seeds 0 and 1, as in test_parity_features.py: R = squared block difference of the seed means
over the noise the seed pairs estimate (about 1 when the engines agree) must stay below 3,
and the image means within 3%. The images are wider than tall, so a sensor fit or an aspect
mistake shows.
"""
import math
import os

import pytest
from blender_helpers import build_scene, parity_figures

WIDTH, HEIGHT, BLOCK = 48, 32, 4
SAMPLES = int(os.environ.get("PARALLAX_PARITY_SAMPLES", 256))


def _room(b):
    """Coloured walls round the origin, boxes at several depths, a small bright sphere far
    behind them (its bokeh takes the aperture's shape) and a ceiling light."""
    walls = {"-x": b.diffuse("Red", (0.7, 0.15, 0.1)), "+x": b.diffuse("Green", (0.15, 0.6, 0.2)),
             "-y": b.diffuse("Blue", (0.2, 0.3, 0.7)), "+y": b.diffuse("White", (0.7, 0.7, 0.7)),
             "-z": b.diffuse("Floor", (0.5, 0.45, 0.35)), "+z": b.diffuse("Ceiling", (0.8, 0.8, 0.8))}
    b.add_room("Room", (-3, -3, 0), (3, 3, 3), walls)
    b.add_box("Near", (0.4, 0.4, 0.8), b.diffuse("Near", (0.8, 0.7, 0.2)), (-0.5, -1.0, 0.4), rot_z=0.3)
    focus = b.add_box("Focus", (0.5, 0.5, 1.0), b.diffuse("Focus", (0.2, 0.7, 0.8)), (0.3, 0.6, 0.5), rot_z=-0.5)
    b.add_box("Far", (0.6, 0.6, 1.4), b.diffuse("Far", (0.8, 0.3, 0.6)), (-0.9, 2.2, 0.7), rot_z=0.8)
    b.add_uv_sphere("Spark", 0.06, (1.2, 2.7, 1.6), b.emission("Spark", (1.0, 0.9, 0.7), 200.0),
                    segments=16, rings=8)
    b.add_rect("Lamp", 1.0, 1.0, b.emission("Lamp", (1.0, 1.0, 1.0), 8.0), (0, 0, 2.99), (math.pi, 0, 0))
    b.set_world()
    return focus


def _bokeh_targets(b, camera_location, distances):
    """Small bright squares facing the camera at several distances, on a black world: out of
    focus each images the aperture, its size, blades, rotation and squeeze."""
    import bpy
    from mathutils import Vector

    material = b.emission("Target", (1.0, 0.9, 0.7), 20.0)
    for k, (x, distance, z) in enumerate(distances):
        location = Vector(camera_location) + Vector((x, distance, z))
        b.add_rect(f"Target{k}", 0.08 * distance, 0.08 * distance, material, location, (math.pi / 2, 0, 0))
    b.set_world()
    bpy.context.view_layer.update()


def perspective_dof(b):
    """f/0.1 at 31 mm (60 degrees) focused on the middle target (a focus object) 0.6 m away,
    a pentagonal aperture turned 20 degrees and squeezed 1.6x (anamorphic); the others are 1.6x
    nearer and farther: blurred 14 and 9 pixels wide."""
    eye = (0.0, -0.6, 0.2)
    _bokeh_targets(b, eye, [(-0.14, 0.375, 0.05), (0.0, 0.6, -0.03), (0.28, 0.96, 0.09), (-0.33, 0.96, -0.15)])
    focus = b.add_object("FocusPoint", None, (0.0, 0.0, 0.5))
    camera = b.add_camera(eye, (0.0, 0.0, 0.2), 60.0)
    camera.data.clip_start = 0.01
    dof = camera.data.dof
    dof.use_dof, dof.focus_object, dof.aperture_fstop = True, focus, 0.1
    dof.aperture_blades, dof.aperture_rotation, dof.aperture_ratio = 5, math.radians(20.0), 1.6


def orthographic_dof(b):
    """An orthographic camera with depth of field: aperture radius 1 / (2 f-stop) = 1 m,
    focused by distance on the middle target; the others are blurred 9 and 7 pixels wide
    (a pentagon)."""
    eye = (0.0, -4.0, 1.0)
    _bokeh_targets(b, eye, [(-0.9, 2.5, 0.3), (0.0, 4.0, -0.2), (1.2, 6.4, 0.6)])
    camera = b.add_camera(eye, (0.0, 0.0, 1.0), 60.0)
    camera.data.type, camera.data.ortho_scale = "ORTHO", 4.0
    dof = camera.data.dof
    dof.use_dof, dof.focus_distance, dof.aperture_fstop, dof.aperture_blades = True, 4.0, 0.5, 5


def _panorama(kind, **settings):
    def build(b):
        _room(b)
        camera = b.add_camera((0.3, -1.0, 1.3), (0.4, 1.0, 1.2), 60.0)
        camera.data.type, camera.data.panorama_type = "PANO", kind
        for name, value in settings.items():
            setattr(camera.data, name, value)
    build.__name__ = kind.lower()
    return build


def _with_depth_of_field(build):
    """The panorama ``build`` makes, with a pentagonal aperture of 0.3 m focused at 1.5 m."""
    def with_dof(b):
        import bpy

        build(b)
        dof = bpy.context.scene.camera.data.dof
        dof.use_dof, dof.focus_distance, dof.aperture_fstop, dof.aperture_blades = True, 1.5, 0.05, 5
    with_dof.__name__ = build.__name__ + "_dof"
    return with_dof


PANORAMAS = [
    _panorama("EQUIRECTANGULAR", latitude_min=-1.2, latitude_max=1.4, longitude_min=-2.5, longitude_max=2.9),
    _panorama("EQUIANGULAR_CUBEMAP_FACE"),
    _panorama("MIRRORBALL"),
    _panorama("FISHEYE_EQUIDISTANT", fisheye_fov=math.radians(200.0)),
    _panorama("FISHEYE_EQUISOLID", fisheye_lens=8.0, fisheye_fov=math.radians(170.0), shift_x=0.05),
    _panorama("FISHEYE_LENS_POLYNOMIAL"),
    _panorama("CENTRAL_CYLINDRICAL", central_cylindrical_range_u_min=-2.0, central_cylindrical_range_u_max=2.4,
              central_cylindrical_range_v_min=-0.8, central_cylindrical_range_v_max=1.0,
              central_cylindrical_radius=1.3),
]
PANORAMAS += [_with_depth_of_field(PANORAMAS[0]), _with_depth_of_field(PANORAMAS[4])]


def compare(bpy, tmp_path, builder, samples=SAMPLES, size=(WIDTH, HEIGHT), block=BLOCK):
    """(R, block relMSE, our mean, Cycles' mean) of the scene ``builder`` makes."""
    return parity_figures(bpy, tmp_path, builder.__name__, build_scene(bpy, builder, *size), samples, block)


@pytest.mark.parametrize("builder", [perspective_dof, orthographic_dof], ids=lambda f: f.__name__)
def test_depth_of_field_matches_cycles(bpy, tmp_path, builder):
    # Finer: the blur discs' shape (blades, rotation, squeeze) lives in a few pixels of edge.
    ratio, _, ours, theirs = compare(bpy, tmp_path, builder, size=(2 * WIDTH, 2 * HEIGHT), block=2)
    assert ours == pytest.approx(theirs, rel=0.03)
    assert ratio < 3.0


@pytest.mark.parametrize("builder", PANORAMAS, ids=lambda f: f.__name__)
def test_panorama_matches_cycles(bpy, tmp_path, builder):
    ratio, _, ours, theirs = compare(bpy, tmp_path, builder, samples=min(SAMPLES, 128))
    assert ours == pytest.approx(theirs, rel=0.03)
    assert ratio < 3.0


def room_dof(b):
    """The room through a 50 mm lens at f/0.8 focused on the middle box (a focus object): the
    near box and the far wall blurred; a hexagonal aperture."""
    import bpy

    focus = _room(b)
    camera = b.add_camera((0.4, -2.6, 1.2), (0.0, 0.8, 0.6), 50.0)
    dof = camera.data.dof
    dof.use_dof, dof.focus_object, dof.aperture_fstop, dof.aperture_blades = True, focus, 0.8, 6
    bpy.context.view_layer.update()


def test_depth_of_field_at_the_issue_size(bpy, tmp_path):
    """Issue 37's check for depth of field, as test_parity_nodes.py checks the node grid:
    160 x 120, 256 samples, 8 x 8-block relMSE below 0.005 and the mean within 2%."""
    from blender_helpers import block_means, render_engine

    scene = build_scene(bpy, room_dof, 160, 120)
    ours, theirs = (render_engine(bpy, tmp_path, scene, engine, 0, 256) for engine in ("PARALLAX", "CYCLES"))
    P, C = block_means(ours, 8), block_means(theirs, 8)
    rel_mse = float(((P - C) ** 2).sum() / max((C ** 2).sum(), 1e-30))
    print(f"room_dof: mean {ours.mean():.4f} vs Cycles {theirs.mean():.4f}, 8x8-block relMSE {rel_mse:.5f}")
    assert rel_mse < 0.005
    assert ours.mean() == pytest.approx(theirs.mean(), rel=0.02)
