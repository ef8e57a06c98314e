"""Properties-editor panels, laid out like Cycles'."""
import bpy

from . import core


class _ParallaxPanel:
    bl_space_type = "PROPERTIES"
    bl_region_type = "WINDOW"
    COMPAT_ENGINES = {"PARALLAX"}

    @classmethod
    def poll(cls, context):
        return context.engine in cls.COMPAT_ENGINES


class _RenderPanel(_ParallaxPanel):
    bl_context = "render"

    def draw(self, context):
        layout = self.layout
        layout.use_property_split = True
        layout.use_property_decorate = False
        settings = context.scene.parallax
        for name in self.properties:
            layout.prop(settings, name)


class PARALLAX_PT_sampling(_RenderPanel, bpy.types.Panel):
    bl_label = "Sampling"
    properties = ("samples", "time_limit", "viewport_samples", "viewport_start_pixel_size",
                  "viewport_pass", "samples_per_frame", "seed")


class PARALLAX_PT_light_paths(_RenderPanel, bpy.types.Panel):
    bl_label = "Light Paths"
    properties = ("max_depth", "depth_leeway", "use_russian_roulette")

    def draw(self, context):
        super().draw(context)
        row = self.layout.row()
        row.active = context.scene.parallax.use_russian_roulette
        row.prop(context.scene.parallax, "rr_start_depth")


class PARALLAX_PT_lights(_RenderPanel, bpy.types.Panel):
    bl_label = "Lights"
    properties = ("method", "light_samples", "light_tree")

    def draw(self, context):
        super().draw(context)
        row = self.layout.row()
        row.active = context.scene.parallax.method == "mis"
        row.prop(context.scene.parallax, "mis_heuristic")


class PARALLAX_PT_irradiance_cache(_RenderPanel, bpy.types.Panel):
    bl_label = "Irradiance Cache"
    bl_options = {"DEFAULT_CLOSED"}
    properties = ()

    def draw_header(self, context):
        self.layout.prop(context.scene.parallax, "ic", text="")

    def draw(self, context):
        pass  # the settings are in the sub-panels


class _IrradianceCacheSubPanel(_RenderPanel):
    bl_parent_id = "PARALLAX_PT_irradiance_cache"

    def draw(self, context):
        self.layout.active = self.settings_active(context.scene.parallax)
        super().draw(context)

    def settings_active(self, settings):
        """Greyed out (still editable) when this is False."""
        return settings.ic


class PARALLAX_PT_ic_accuracy(_IrradianceCacheSubPanel, bpy.types.Panel):
    bl_label = "Accuracy"
    properties = ("ic_accuracy", "ic_min_radius", "ic_visibility_check")


class PARALLAX_PT_ic_creation(_IrradianceCacheSubPanel, bpy.types.Panel):
    bl_label = "Creation"
    properties = ("ic_create_prob", "ic_update_prob", "ic_nee_samples", "ic_prepare_frames",
                  "ic_capacity", "ic_rebuild_interval")


class PARALLAX_PT_ic_gradients(_IrradianceCacheSubPanel, bpy.types.Panel):
    bl_label = "Gradients"
    properties = ("ic_gradient_max",)

    def draw_header(self, context):
        settings = context.scene.parallax
        self.layout.active = settings.ic
        self.layout.prop(settings, "ic_gradients", text="")

    def settings_active(self, settings):
        return settings.ic and settings.ic_gradients


class PARALLAX_PT_ic_visualisation(_IrradianceCacheSubPanel, bpy.types.Panel):
    bl_label = "Visualisation"
    properties = ("ic_highlight",)


class PARALLAX_PT_adrrs(_RenderPanel, bpy.types.Panel):
    bl_label = "ADRRS"
    bl_options = {"DEFAULT_CLOSED"}
    properties = ("adrrs_window", "adrrs_rr_min", "adrrs_splitting", "adrrs_max_splits",
                  "adrrs_estimate", "adrrs_estimate_spp", "adrrs_ic_glossy")

    def draw_header(self, context):
        self.layout.prop(context.scene.parallax, "adrrs", text="")

    def draw(self, context):
        self.layout.active = context.scene.parallax.adrrs
        super().draw(context)


class PARALLAX_PT_guiding(_RenderPanel, bpy.types.Panel):
    bl_label = "Path Guiding"
    bl_options = {"DEFAULT_CLOSED"}
    properties = ("guiding_prob", "guiding_parallax", "guiding_training_spp")

    def draw_header(self, context):
        self.layout.prop(context.scene.parallax, "guiding", text="")

    def draw(self, context):
        self.layout.active = context.scene.parallax.guiding
        super().draw(context)


class _GuidingSubPanel(_RenderPanel):
    bl_parent_id = "PARALLAX_PT_guiding"
    bl_options = {"DEFAULT_CLOSED"}

    def draw(self, context):
        self.layout.active = context.scene.parallax.guiding
        super().draw(context)


class PARALLAX_PT_guiding_fitting(_GuidingSubPanel, bpy.types.Panel):
    bl_label = "Fitting"
    properties = ("guiding_fit", "guiding_min_samples", "guiding_max_components", "guiding_split_merge")


class PARALLAX_PT_guiding_regions(_GuidingSubPanel, bpy.types.Panel):
    bl_label = "Regions"
    properties = ("guiding_region_splits", "guiding_region_threshold", "guiding_max_regions")


class PARALLAX_PT_guiding_visualisation(_GuidingSubPanel, bpy.types.Panel):
    bl_label = "Visualisation"
    properties = ("guiding_probe_x", "guiding_probe_y", "guiding_animate_lobes")


class PARALLAX_PT_device(_RenderPanel, bpy.types.Panel):
    bl_label = "Device"
    properties = ("device",)

    def draw(self, context):
        super().draw(context)
        col = self.layout.column(align=True)
        for line in detected_devices():
            col.label(text=line)


class PARALLAX_PT_passes(_ParallaxPanel, bpy.types.Panel):
    bl_label = "Parallax Passes"
    bl_context = "view_layer"

    def draw(self, context):
        layout = self.layout
        layout.use_property_split = True
        layout.use_property_decorate = False
        view_layer = context.view_layer
        col = layout.column(heading="Include")
        col.prop(view_layer, "use_pass_z", text="Depth")
        col.prop(view_layer, "use_pass_normal", text="Normal")
        col.prop(view_layer.parallax, "use_pass_denoising_data")
        col.prop(view_layer.parallax, "use_pass_ray_depth")
        col = layout.column(heading="Irradiance Cache")
        col.active = context.scene.parallax.ic
        col.prop(view_layer.parallax, "use_pass_ic_irradiance", text="Irradiance")
        col.prop(view_layer.parallax, "use_pass_ic_gradients", text="Gradients")
        col = layout.column(heading="ADRRS")
        col.active = context.scene.parallax.adrrs
        col.prop(view_layer.parallax, "use_pass_adrrs_estimate", text="Estimate")
        col.prop(view_layer.parallax, "use_pass_adrrs_splits", text="Splits")
        col = layout.column(heading="Path Guiding")
        col.active = context.scene.parallax.guiding
        col.prop(view_layer.parallax, "use_pass_guiding_regions", text="Regions")
        col.prop(view_layer.parallax, "use_pass_guiding_components", text="Components")
        col.prop(view_layer.parallax, "use_pass_guiding_lobes", text="Lobes")


_device_lines = None


def detected_devices():
    """One line per Vulkan device (queried once per Blender session)."""
    global _device_lines
    if _device_lines is None:
        try:
            found = core.load().devices()
            _device_lines = [
                f"{d.get('name')} ({d.get('type')})" + ("" if d.get("ray_tracing") else ": no ray tracing")
                + ("  [auto]" if d.get("chosen") else "") for d in found] or ["No Vulkan device found"]
        except (ImportError, RuntimeError) as e:
            _device_lines = [f"Native core unavailable: {e}"]
    return _device_lines


classes = (PARALLAX_PT_sampling, PARALLAX_PT_light_paths, PARALLAX_PT_lights,
           PARALLAX_PT_irradiance_cache, PARALLAX_PT_ic_accuracy, PARALLAX_PT_ic_creation,
           PARALLAX_PT_ic_gradients, PARALLAX_PT_ic_visualisation, PARALLAX_PT_adrrs,
           PARALLAX_PT_guiding, PARALLAX_PT_guiding_fitting, PARALLAX_PT_guiding_regions,
           PARALLAX_PT_guiding_visualisation, PARALLAX_PT_device,
           PARALLAX_PT_passes)

# Built-in panels that make sense for Parallax: output, format, colour management, and
# Cycles' material, world, light and object panels (we read the same node trees and lights).
_SHARED_PANEL_PREFIXES = ("RENDER_PT_", "DATA_PT_", "MATERIAL_PT_", "WORLD_PT_", "OBJECT_PT_",
                          "VIEWLAYER_PT_", "CYCLES_MATERIAL_PT_", "CYCLES_WORLD_PT_",
                          "CYCLES_LIGHT_PT_", "NODE_DATA_PT_")
_EXCLUDED_PANELS = {"RENDER_PT_eevee_", "RENDER_PT_simplify", "VIEWLAYER_PT_eevee"}


def _shared_panels():
    for panel in bpy.types.Panel.__subclasses__():
        engines = getattr(panel, "COMPAT_ENGINES", None)
        name = panel.__name__
        if (engines is not None and name.startswith(_SHARED_PANEL_PREFIXES)
                and not any(name.startswith(x) for x in _EXCLUDED_PANELS)
                and ("BLENDER_RENDER" in engines or "CYCLES" in engines)):
            yield panel


def register():
    for cls in classes:
        bpy.utils.register_class(cls)
    for panel in _shared_panels():
        panel.COMPAT_ENGINES.add("PARALLAX")


def unregister():
    for panel in _shared_panels():
        panel.COMPAT_ENGINES.discard("PARALLAX")
    for cls in reversed(classes):
        bpy.utils.unregister_class(cls)
