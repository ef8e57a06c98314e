"""The Parallax RenderEngine: thin; F12 rendering lives in final.py, the viewport in
viewport.py."""
import bpy

from .. import passes
from . import final, viewport, warmup


class ParallaxRenderEngine(bpy.types.RenderEngine):
    bl_idname = "PARALLAX"
    bl_label = "Parallax"
    bl_use_preview = False
    bl_use_shading_nodes_custom = False  # keep Cycles/EEVEE material and world nodes
    bl_use_eevee_viewport = True         # Material Preview shading uses EEVEE

    def __init__(self, *args, **kwargs):
        super().__init__(*args, **kwargs)
        self.viewport = None

    def __del__(self):  # the viewport closed, its shading changed or the engine was switched
        view = getattr(self, "viewport", None)
        if view is not None:
            view.free()

    def render(self, depsgraph):
        final.render(self, depsgraph)

    def view_update(self, context, depsgraph):
        if self.viewport is None:
            self.viewport = viewport.ViewportRender()
        self.viewport.update(self, context, depsgraph)

    def view_draw(self, context, depsgraph):
        if self.viewport is not None:
            self.viewport.draw(self, context, depsgraph)

    def update_render_passes(self, scene=None, renderlayer=None):
        passes.register_passes(self, scene, renderlayer)


def register():
    bpy.utils.register_class(ParallaxRenderEngine)
    warmup.register()


def unregister():
    warmup.unregister()
    viewport.stop_all()
    bpy.utils.unregister_class(ParallaxRenderEngine)
