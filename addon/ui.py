"""Properties-editor panels, laid out like Cycles'.

The render panels are made from the settings table when the add-on registers: one panel per
``panel`` of ``parallax_core.SETTINGS``, drawing its rows in table order. A technique's panel
is named by the technique's switch (parallax_core.technique_switch: the first row of its
table) and greys its other rows while that is off: a bool switch is the header checkbox, an
enum switch (Russian Roulette & Splitting's rrs) the first row, and rows that apply to some
of its items only (ONLY_WITH) are greyed while it has another. Rows with a ``group`` go to a
sub-panel of that name, in table order; a bool row labelled as its group is that sub-panel's
header checkbox.
"""
import bpy

from . import core, passes, properties

# The add-on's own settings (properties.py), placed as (panel, sub-panel) among the table's.
OWN_SETTINGS = (
    ("sampling", "Viewport", ("viewport_samples", "viewport_start_pixel_size", "viewport_pass")),
    ("guiding", "Visualisation", ("guiding_animate_lobes",)),
)
# Rows that apply to some items of an enum switch only (the technique's other rows apply
# whenever it is on): greyed while the switch has another item. EARS decides by its own
# statistics on the image's estimate: ADRRS' weight window, estimate and cache reads are its own.
ONLY_WITH = {
    "adrrs_window": ("rrs", ("adrrs",)),
    "adrrs_estimate": ("rrs", ("adrrs",)),
    "adrrs_ic_glossy": ("rrs", ("adrrs",)),
    "rrs_grid": ("rrs", ("ears",)),
    "rrs_min_records": ("rrs", ("ears",)),
}


def switched_on(settings, name):
    """Whether the switch ``name`` (a bool, or an enum with an item "off") is on in ``settings``."""
    return core.load().setting_on(name, getattr(settings, name))


def applies(settings, name):
    """Whether row ``name`` applies to the item its enum switch has (ONLY_WITH; other rows: True)."""
    switch, items = ONLY_WITH.get(name, (None, ()))
    return switch is None or getattr(settings, switch) in items


class _ParallaxPanel:
    bl_space_type = "PROPERTIES"
    bl_region_type = "WINDOW"
    COMPAT_ENGINES = {"PARALLAX"}

    @classmethod
    def poll(cls, context):
        return context.engine in cls.COMPAT_ENGINES


def _split(layout):
    layout.use_property_split = True
    layout.use_property_decorate = False
    return layout


class _SettingsPanel(_ParallaxPanel):
    """A panel of setting rows: ``rows`` drawn in order; ``header`` (a bool row) as the header
    checkbox; greyed while any of ``switches`` is off (an enum switch among the rows stays
    active), and a row of ONLY_WITH while its switch has another item."""
    bl_context = "render"
    rows = ()
    header = None
    switches = ()

    def draw(self, context):
        settings = context.scene.parallax
        layout = _split(self.layout)
        note = PANEL_NOTES.get(getattr(self, "bl_idname", ""))
        if note is not None:
            for line, icon in note():
                layout.label(text=line, icon=icon)
        on = all(switched_on(settings, name) for name in self.switches)
        for name in self.rows:
            col = layout.column()
            col.active = name in self.switches or (on and applies(settings, name))
            col.prop(settings, name)


_denoiser_line = None


def denoiser_status():
    """The Denoising panel's first line: which OpenImageDenoise denoises, or that none was
    found and renders stay noisy (checked once per Blender session)."""
    global _denoiser_line
    if _denoiser_line is None:
        try:
            found, text = core.load().denoise.availability()
        except ImportError as e:
            found, text = False, f"Native core unavailable: {e}"
        _denoiser_line = [(text, "INFO")] if found else \
            [("OpenImageDenoise not found: renders are not denoised", "ERROR")] + \
            [(part.strip(), "NONE") for part in text.split(":", 1)[-1].split(";")]
    return _denoiser_line


# Lines drawn at the top of a panel (by its bl_idname).
PANEL_NOTES = {"PARALLAX_PT_denoising": denoiser_status}


def _draw_header(self, context):
    settings = context.scene.parallax
    self.layout.active = all(switched_on(settings, name) for name in self.switches[:-1])
    self.layout.prop(settings, self.header, text="")


def _slug(text):
    return "".join(c if c.isalnum() else "_" for c in text.lower()).strip("_")


def _make_panel(idname, label, rows, header, switches, parent=None, closed=False):
    namespace = dict(bl_label=label, rows=tuple(rows), header=header, switches=tuple(switches))
    if header is not None:
        namespace["draw_header"] = _draw_header
    if parent is not None:
        namespace["bl_parent_id"] = parent
    if closed:
        namespace["bl_options"] = {"DEFAULT_CLOSED"}
    return type(bpy.types.Panel)(idname, (_SettingsPanel, bpy.types.Panel), namespace)


def settings_panels():
    """The render panels and sub-panels, in table order (parents before their children)."""
    by_panel = {}
    for row in properties.table_rows():
        by_panel.setdefault(row.panel, []).append(row)
    own = {panel: (group, names) for panel, group, names in OWN_SETTINGS}
    made = []
    for panel, rows in by_panel.items():
        idname = f"PARALLAX_PT_{panel}"
        # A technique's panel: its switch names the panel ("Irradiance Cache"); a bool switch
        # is the header, an enum switch (rrs) the first row.
        pc = core.load()
        switch_row = pc.technique_switch(panel) if panel in pc.TECHNIQUES else None
        switch = switch_row.name if switch_row else None
        checkbox = switch if switch_row and switch_row.type == "bool" else None
        label = switch_row.label if switch_row else panel.replace("_", " ").title()
        switches = (switch,) if switch else ()
        groups = {}  # sub-panel label -> row names, in table order
        for row in rows:
            groups.setdefault(row.group, []).append(row.name)
        if panel in own:
            group, names = own[panel]
            groups.setdefault(group, []).extend(names)
        top = [name for name in groups.pop("", []) if name != checkbox]
        made.append(_make_panel(idname, label, top, checkbox, switches, closed=bool(switch)))
        bool_labels = {row.name: row.label for row in rows if row.type == "bool"}
        for group, names in groups.items():
            header = next((n for n in names if bool_labels.get(n) == group), None)
            made.append(_make_panel(
                f"{idname}_{_slug(group)}", group, [n for n in names if n != header], header,
                switches + ((header,) if header else ()), parent=idname))
    return made


class PARALLAX_PT_device(_ParallaxPanel, bpy.types.Panel):
    bl_label = "Device"
    bl_context = "render"

    def draw(self, context):
        layout = _split(self.layout)
        layout.prop(context.scene.parallax, "device")
        col = layout.column(align=True)
        for line in detected_devices():
            col.label(text=line)


class PARALLAX_PT_passes(_ParallaxPanel, bpy.types.Panel):
    """The view layer's pass toggles: Blender's own and the film's under Include, then each
    technique's under its name, greyed while the technique is off."""
    bl_label = "Parallax Passes"
    bl_context = "view_layer"

    def draw(self, context):
        layout = _split(self.layout)
        view_layer, settings = context.view_layer, context.scene.parallax
        include = layout.column(heading="Include")
        for label, toggle in passes.BLENDER_TOGGLES.items():
            if toggle is not None:
                include.prop(view_layer, toggle, text=label)
        include.prop(view_layer.parallax, passes.DENOISING_TOGGLE)
        by_setting = {}
        for row in core.load().PASSES:
            if passes.has_own_toggle(row):
                by_setting.setdefault(row.setting, []).append(row)
        for setting, rows in by_setting.items():
            col = include
            if setting:
                col = layout.column(heading=core.load().setting(setting).label)
                col.active = switched_on(settings, setting)
            prefix = _common_first_word([row.label for row in rows]) if setting else ""
            for row in rows:
                col.prop(view_layer.parallax, passes.toggle_name(row), text=row.label[len(prefix):])


def _common_first_word(labels):
    """"IC " for "IC Irradiance" and "IC Gradients": the column's heading says it already."""
    first = labels[0].split(" ", 1)[0] + " "
    return first if all(label.startswith(first) and len(label) > len(first) for label in labels) else ""


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


classes = []

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
    classes[:] = settings_panels() + [PARALLAX_PT_device, PARALLAX_PT_passes]
    for cls in classes:
        bpy.utils.register_class(cls)
    for panel in _shared_panels():
        panel.COMPAT_ENGINES.add("PARALLAX")


def unregister():
    for panel in _shared_panels():
        panel.COMPAT_ENGINES.discard("PARALLAX")
    for cls in reversed(classes):
        bpy.utils.unregister_class(cls)
