"""Blender integration tests: bpy 5.0.1 in this process, the add-on from the repository."""
import sys

import pytest
from blender_helpers import REPO


@pytest.fixture
def bpy():
    import bpy as bpy_module

    if REPO not in sys.path:
        sys.path.insert(0, REPO)
    import addon

    # The installed copy of the add-on (parallax_blender, which bench code such as
    # bench.converge's Cycles runs registers through its cli) may hold the registration when
    # a test of another tier ran first in this process: hand it to the repository's copy,
    # whose classes the tests compare against.
    installed = sys.modules.get("parallax_blender")
    if installed is not None and installed.properties.ParallaxRenderSettings.is_registered:
        installed.unregister()
    if not hasattr(bpy_module.types.Scene, "parallax"):
        addon.register()
    return bpy_module


@pytest.fixture
def fresh(bpy):
    """An empty scene with a camera, rendered by Parallax."""
    bpy.ops.wm.read_factory_settings(use_empty=True)
    scene = bpy.context.scene
    scene.render.engine = "PARALLAX"
    camera = bpy.data.objects.new("Camera", bpy.data.cameras.new("Camera"))
    scene.collection.objects.link(camera)
    camera.location = (0.0, -6.0, 0.0)
    camera.rotation_euler = (1.5707963, 0.0, 0.0)
    scene.camera = camera
    scene.render.resolution_x = scene.render.resolution_y = 32
    scene.parallax.samples = 4
    scene.parallax.use_denoising = False  # as rendered (test_denoising.py turns it on)
    return scene
