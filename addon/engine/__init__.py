"""The Parallax RenderEngine: thin; F12 rendering lives in final.py."""
import bpy

from .. import passes
from . import final


class ParallaxRenderEngine(bpy.types.RenderEngine):
    bl_idname = "PARALLAX"
    bl_label = "Parallax"
    bl_use_preview = False
    bl_use_shading_nodes_custom = False  # keep Cycles/EEVEE material and world nodes
    bl_use_eevee_viewport = True         # Material Preview shading uses EEVEE

    def render(self, depsgraph):
        final.render(self, depsgraph)

    def update_render_passes(self, scene=None, renderlayer=None):
        passes.register_passes(self, scene, renderlayer)


def register():
    bpy.utils.register_class(ParallaxRenderEngine)


def unregister():
    bpy.utils.unregister_class(ParallaxRenderEngine)
