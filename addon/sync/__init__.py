"""Blender's evaluated depsgraph -> ``parallax_core.scene.SceneData``.

The only code of the add-on that reads bpy data. Bulk data goes through ``foreach_get`` into
numpy; per-object Python work is constant. Anything not rendered exactly is approximated and
named once in the returned warnings (see ``Warnings``).
"""
from .. import core
from . import camera, lights, materials, meshes, unsupported, world

PARTS = ("geometry", "instances", "materials", "lights", "camera")


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


class SceneExporter:
    """Keeps what a full export learnt (mesh sharing, material indices) so that a viewport
    edit re-exports only the parts it touched (the core's ``Session.update(parts=...)``)."""

    def __init__(self, world_bake_widths=world.BAKE_WIDTHS):
        self.data = None
        self.world_bake_widths = world_bake_widths  # a world graph's map: (least, most) width
        self._mesh_index = {}
        self._materials = None

    def full(self, depsgraph, width, height, region=None, view_camera=None):
        """Returns (SceneData, warnings) for rendering ``depsgraph`` at ``width`` x ``height``.

        ``region`` = (x, y, w, h) in pixels with y from the bottom (Blender's border) renders
        only that part of the frame; SceneData's resolution is then (w, h). ``view_camera``
        (a Camera) replaces the scene camera (the viewport's view).
        """
        data = core.load().scene.SceneData()
        warnings = Warnings()
        self._materials = materials.MaterialTable(warnings)
        self._mesh_index = meshes.export_geometry(depsgraph, data, self._materials, warnings)
        self._geometry_needs_exported = self._geometry_needs()
        self._materials.build(data)
        lights.export_lights(depsgraph, data, warnings)
        world.export_world(depsgraph.scene.world, data, warnings, self.world_bake_widths)
        unsupported.warn_unsupported(depsgraph, warnings)  # once per full export, not per edit
        data.camera = view_camera or camera.export_camera(depsgraph, width, height, region)
        data.width, data.height = (region[2], region[3]) if region else (width, height)
        if not data.lights and not self._materials.has_emission and world.is_black(data.world):
            warnings.add("the scene has no lights, no emissive materials and a black world: "
                         "the image will be black")
        self.data = data
        return data, list(warnings)

    def _geometry_needs(self):
        """What each material's nodes read from the meshes: the UV maps whose tangents its
        Normal Maps use, the attributes it reads (the geometry holds them: a change needs a
        geometry export)."""
        table = self._materials
        return [(table.tangent_maps(i), table.attribute_requests(i)) for i in range(len(table))]

    def update(self, depsgraph, parts):
        """Re-exports ``parts`` (subset of PARTS) of the last full export into ``self.data``.
        Returns (parts to send, warnings); "geometry" in the result means a full update."""
        warnings = Warnings()
        parts = set(parts)
        if "instances" in parts and not meshes.export_instances(
                depsgraph, self.data, self._mesh_index, self._materials):
            parts.add("geometry")  # an instance of geometry we have not exported
        if "geometry" in parts:
            return {"geometry"}, self.full(depsgraph, self.data.width, self.data.height,
                                           view_camera=self.data.camera)[1]
        if "materials" in parts:
            if self._geometry_needs() != self._geometry_needs_exported:  # e.g. a Normal Map added
                return {"geometry"}, self.full(depsgraph, self.data.width, self.data.height,
                                               view_camera=self.data.camera)[1]
            self._materials.build(self.data, warnings)
        if "lights" in parts:  # exported aside, then swapped in (a render thread may be reading)
            fresh = core.load().scene.SceneData()
            lights.export_lights(depsgraph, fresh, warnings)
            world.export_world(depsgraph.scene.world, fresh, warnings, self.world_bake_widths)
            self.data.lights, self.data.world = fresh.lights, fresh.world
        return parts, list(warnings)


def export_scene(depsgraph, width, height, region=None):
    """(SceneData, warnings) of the whole scene: see ``SceneExporter.full``."""
    return SceneExporter().full(depsgraph, width, height, region)
