"""Parallax settings: ``scene.parallax`` (render) and ``view_layer.parallax`` (passes).

Both are made from the core's tables when the add-on registers: one Blender property per row
of ``parallax_core.SETTINGS`` that has a panel (type, default, range, items, label and tooltip
from the row), and one view-layer toggle per row of ``parallax_core.PASSES`` that Blender's
own toggles do not cover (passes.py). What is declared here is the add-on's own: the
viewport's settings, the device and Animate Lobes.
"""
import math

import bpy
from bpy.props import BoolProperty, EnumProperty, FloatProperty, IntProperty, PointerProperty

from . import core, passes

INT32_MIN, INT32_MAX = -2**31, 2**31 - 1  # Blender's IntProperty is 32-bit
LOBES_LOOP_FRAMES = 48  # Animate Lobes: frames per loop of the spheres through their regions (2 s at 24 fps)
# A float row's unit as Blender shows it.
UNITS = {"time": dict(subtype="TIME_ABSOLUTE", unit="TIME_ABSOLUTE"),
         "length": dict(subtype="DISTANCE", unit="LENGTH"),
         "pixel": dict(subtype="PIXEL", unit="NONE")}
# Rows whose Cycles setting has another name (the others share Cycles' names).
CYCLES_NAMES = {"max_depth": "max_bounces"}
DEVICE_ITEMS = (
    ("auto", "Automatic", "An NVIDIA or other ray-tracing GPU if present, else the CPU (lavapipe)"),
    ("cpu", "CPU", "Mesa lavapipe: Vulkan on the CPU"),
    ("gpu", "GPU", "The first GPU with Vulkan ray tracing; fails if there is none"),
)


def table_rows():
    """The setting rows that are Blender properties, in table order: every row with a panel
    (a row without one, such as the viewport's preview frames, is the engine's to set)."""
    return [row for row in core.load().SETTINGS if row.panel]


def technique_switches():
    """The rows that switch a technique on (``ic``, ``rrs``, ``guiding``): the first of each
    technique's table (parallax_core.technique_switch), a bool or an enum with an item "off"."""
    pc = core.load()
    return [pc.technique_switch(technique) for technique in pc.TECHNIQUES]


def pass_switches():
    """Names of the settings that add or remove passes (a technique's switch)."""
    return {p.setting for p in core.load().PASSES if p.setting}


def viewport_pass_items():
    """What the Rendered viewport can show (as Cycles' viewport Render Pass): any pass of the
    same session (the film's, or a technique's while it is on)."""
    labels = {row.name: row.label for row in core.load().SETTINGS}
    return tuple((p.name, p.label, p.description + (f" ({labels[p.setting]} on)" if p.setting else ""))
                 for p in core.load().PASSES)


def _precision(row):
    """Digits enough to show a float row's default and lower limit (1e-5 needs 6)."""
    smallest = min((abs(v) for v in (row.default, row.min) if v), default=1.0)
    return max(3, min(6, 1 - math.floor(math.log10(smallest))))


def setting_property(row, update=None):
    """The Blender property of a setting row."""
    common = dict(name=row.label, description=row.tooltip, default=row.default)
    if update is not None:
        common["update"] = update
    if row.type == "bool":
        return BoolProperty(**common)
    if row.type == "enum":
        return EnumProperty(items=tuple(tuple(item) for item in row.items), **common)
    if row.type == "int":
        return IntProperty(min=max(int(row.min), INT32_MIN), max=min(int(row.max), INT32_MAX), **common)
    # Dragging stays usable on long ranges: the soft limit is 10 times the default (at least 10).
    soft_max = min(row.max, 10.0 * max(abs(row.default), 1.0))
    if row.unit:
        common.update(UNITS[row.unit])
    elif row.min >= 0.0 and row.max == 1.0:  # a probability: a slider
        common["subtype"] = "FACTOR"
    return FloatProperty(min=row.min, max=row.max, soft_max=soft_max, precision=_precision(row), **common)


def _update_scene_passes(settings, context):
    # A scene setting that adds or removes passes: every view layer of the scene.
    for view_layer in settings.id_data.view_layers:
        view_layer.update_render_passes()


def _update_passes(settings, context):
    # The compositor's Render Layers node picks up pass changes on this call.
    view_layer = getattr(context, "view_layer", None)
    if view_layer is not None:
        view_layer.update_render_passes()


class ParallaxRenderSettings(bpy.types.PropertyGroup):
    # The table's rows are added by register(); these are the engine's own.
    viewport_samples: IntProperty(
        name="Viewport Samples", description="Samples per pixel the viewport renders before it "
        "stops (0 = until something changes)", default=1024, min=0, max=2**24)
    viewport_start_pixel_size: EnumProperty(
        name="Start Pixel Size", description="After an edit the viewport first shows a frame "
        "with pixels this large, then refines; Automatic picks 1 to 8 from the measured frame "
        "time", items=(("AUTO", "Automatic", "From the measured frame time"),
                       ("1", "1", "Full resolution at once"), ("2", "2", "2x2 pixels"),
                       ("4", "4", "4x4 pixels"), ("8", "8", "8x8 pixels")), default="AUTO")
    guiding_animate_lobes: BoolProperty(
        name="Animate Lobes", description="Guiding Lobes pass: the spheres move through their "
        f"regions with the timeline (a loop every {LOBES_LOOP_FRAMES} frames) and show the mixture "
        "where they are, so parallax-aware lobes turn to keep aiming at their lights (thesis fig. 4.20)",
        default=False)
    device: EnumProperty(
        name="Device", description="Vulkan device to render on", items=DEVICE_ITEMS, default="auto")

    def render_params(self):
        """Keyword arguments for ``parallax_core.Session.set_params``: every core row's value,
        the scene's Cycles light paths where this scene never set Parallax's (cycles_light_paths)."""
        params = {row.name: getattr(self, row.name) for row in table_rows() if row.core}
        params.update(self.cycles_light_paths())
        params["guiding_lobes_phase"] = self.guiding_lobes_phase()
        return params

    def cycles_light_paths(self):
        """The light-path and pixel-filter rows that take the scene's Cycles values: those set
        in Cycles (``is_property_set``) and never in Parallax, so a scene made with Cycles renders
        with its bounces, clamps and filter when a user switches engine. Cycles' Total counts
        every bounce: where it sets Max Bounces, Discrete Leeway is 0 unless set here."""
        cycles = getattr(self.id_data, "cycles", None)
        if cycles is None:  # Cycles not enabled
            return {}
        values = {}
        for row in table_rows():
            name = CYCLES_NAMES.get(row.name, row.name)
            if (row.panel not in ("light_paths", "film") or self.is_property_set(row.name)
                    or name not in cycles.bl_rna.properties or not cycles.is_property_set(name)):
                continue
            value = getattr(cycles, name)
            if row.type == "enum" and value not in {item[0] for item in row.items}:
                continue
            if row.type in ("int", "float") and not row.min <= value <= row.max:
                continue
            values[row.name] = value
        if "max_depth" in values and not self.is_property_set("depth_leeway"):
            values["depth_leeway"] = 0
        return values

    def engine_values(self):
        """The engine's rows (no core field: samples, time limit, denoising) by name."""
        return {row.name: getattr(self, row.name) for row in table_rows() if not row.core}

    def guiding_lobes_phase(self):
        """Where the Guiding Lobes spheres are: -1 at their regions' centres, or with Animate
        Lobes the scene's frame along their loop, in [0, 1)."""
        if not self.guiding_animate_lobes:
            return -1.0
        return (self.id_data.frame_current % LOBES_LOOP_FRAMES) / LOBES_LOOP_FRAMES


class ParallaxViewLayerSettings(bpy.types.PropertyGroup):
    # The passes' toggles are added by register().
    use_pass_denoising_data: BoolProperty(
        name="Denoising Data", description="Denoising Albedo and Denoising Normal passes, for "
        "the compositor's Denoise node", default=True, update=_update_passes)


def _add_table_properties():
    settings = ParallaxRenderSettings.__annotations__
    switches = pass_switches()
    for row in table_rows():
        settings[row.name] = setting_property(row, _update_scene_passes if row.name in switches else None)
    settings["viewport_pass"] = EnumProperty(
        name="Viewport Pass", description="What the Rendered viewport shows: the image or a "
        "visualisation pass, live (switching keeps the samples and the trained guiding field)",
        items=viewport_pass_items(), default=core.load().PASSES[0].name)
    # A technique's passes are on by default (they show only with the technique on); the film's
    # extra passes are off by default, as Cycles' are.
    labels = {row.name: row.label for row in core.load().SETTINGS}
    toggles = ParallaxViewLayerSettings.__annotations__
    for row in core.load().PASSES:
        if passes.has_own_toggle(row):
            toggles[passes.toggle_name(row)] = BoolProperty(
                name=row.label, default=bool(row.setting), update=_update_passes,
                description=row.description + (f" (with {labels[row.setting]} on)" if row.setting else ""))


classes = (ParallaxRenderSettings, ParallaxViewLayerSettings)


def register():
    _add_table_properties()
    for cls in classes:
        bpy.utils.register_class(cls)
    bpy.types.Scene.parallax = PointerProperty(type=ParallaxRenderSettings)
    bpy.types.ViewLayer.parallax = PointerProperty(type=ParallaxViewLayerSettings)


def unregister():
    del bpy.types.ViewLayer.parallax
    del bpy.types.Scene.parallax
    for cls in reversed(classes):
        bpy.utils.unregister_class(cls)
