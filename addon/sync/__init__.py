"""Blender's evaluated depsgraph -> ``parallax_core.scene.SceneData``.

The only code of the add-on that reads bpy data. Bulk data goes through ``foreach_get`` into
numpy; per-object Python work is constant. Anything not rendered exactly is approximated and
named once in the returned warnings (see ``Warnings``).
"""
from .. import core
from . import camera, lights, materials, meshes, world


class Warnings:
    """Collects approximation/skip messages, each listed once, in order."""

    def __init__(self):
        self._seen = {}

    def add(self, message):
        self._seen.setdefault(message, None)

    def __iter__(self):
        return iter(self._seen)

    def __len__(self):
        return len(self._seen)


def export_scene(depsgraph, width, height, region=None):
    """Returns (SceneData, warnings) for rendering ``depsgraph`` at ``width`` x ``height``.

    ``region`` = (x, y, w, h) in pixels with y from the bottom (Blender's border) renders
    only that part of the frame; SceneData's resolution is then (w, h).
    """
    scene_module = core.load().scene
    warnings = Warnings()
    data = scene_module.SceneData()
    material_table = materials.MaterialTable(data, warnings)
    meshes.export_geometry(depsgraph, data, material_table, warnings)
    lights.export_lights(depsgraph, data, warnings)
    world.export_world(depsgraph.scene.world, data, warnings)
    data.camera = camera.export_camera(depsgraph, width, height, region)
    data.width, data.height = (region[2], region[3]) if region else (width, height)
    if not data.lights and not material_table.has_emission and world.is_black(data.world):
        warnings.add("the scene has no lights, no emissive materials and a black world: "
                     "the image will be black")
    return data, list(warnings)
