"""Every row of the core's tables (parallax_core.SETTINGS, PASSES) reaches every layer of the
add-on: RenderParams, the Blender property, its panel, --set for .blend and .npz scenes, the
viewport, the .blend file, and for a pass its Blender name, the compositor and the EXR layers.
The expectations are the rows themselves: nothing here restates a default or a range."""
import dataclasses
import types

import numpy as np
import pytest
from addon import passes, properties, ui
from addon.cli import CommandError, apply_settings
from helpers import UNBIASED_LIGHT_PATH_SETS
from blender_helpers import SCENES, FakeDepsgraph, FakeWorker, read_layers, save_and_reopen

import parallax_core
from parallax_core import PASSES, SETTINGS

UI_ROWS = [row for row in SETTINGS if row.panel]  # the rows that are Blender properties
TECHNIQUE_ROWS = [row for row in UI_ROWS if row.core and row.technique != "base"]
# The core rows without a panel are the engine's to set: preview frames (viewport.py) and the
# Guiding Lobes spheres' phase, from Animate Lobes (test_guiding_settings.py).
ENGINE_SET = {"preview", "guiding_lobes_phase"}


def changed(row):
    """A valid value of ``row`` other than its default."""
    if row.type == "bool":
        return not row.default
    if row.type == "enum":
        names = [item[0] for item in row.items]
        return names[(names.index(row.default) + 1) % len(names)]
    if row.type == "int":
        return row.default + 1 if row.default < row.max else row.default - 1
    value = 1.5 * row.default if row.default else 1.0
    return value if row.min <= value <= row.max else 0.5 * (row.default + row.min)


def as_text(value):
    """``value`` as --set takes it."""
    return ("on" if value else "off") if isinstance(value, bool) else str(value)


def same(got, expected):
    """Equal, floats to Blender's single precision, with the same type."""
    if isinstance(expected, float):
        return isinstance(got, float) and got == pytest.approx(expected, rel=1e-6)
    return type(got) is type(expected) and got == expected


def test_every_core_row_is_a_render_params_field_at_its_default():
    defaults = dataclasses.asdict(parallax_core.RenderParams())
    assert list(defaults) == [row.name for row in SETTINGS if row.core]
    for row in SETTINGS:
        if row.core:
            assert same(defaults[row.name], row.default), row.name
    assert {row.name for row in SETTINGS if row.core and not row.panel} == ENGINE_SET


def test_every_row_is_a_blender_property_like_the_row(bpy):
    props = properties.ParallaxRenderSettings.bl_rna.properties
    kinds = {"bool": "BOOLEAN", "int": "INT", "float": "FLOAT", "enum": "ENUM"}
    for row in SETTINGS:
        if not row.panel:
            assert row.name not in props, row.name
            continue
        prop = props[row.name]
        assert (prop.type, prop.name, prop.description) == (kinds[row.type], row.label, row.tooltip), row.name
        if row.type == "enum":
            assert prop.default == row.default, row.name
            assert [(i.identifier, i.name, i.description) for i in prop.enum_items] == \
                [tuple(item) for item in row.items], row.name
        else:
            assert same(prop.default, row.default), row.name
        if row.type == "int":
            assert (prop.hard_min, prop.hard_max) == (max(row.min, properties.INT32_MIN),
                                                      min(row.max, properties.INT32_MAX)), row.name
        elif row.type == "float":
            assert prop.hard_min == pytest.approx(row.min, rel=1e-6), row.name
            assert prop.hard_max == pytest.approx(row.max, rel=1e-6), row.name
            assert prop.unit == (properties.UNITS[row.unit]["unit"] if row.unit else "NONE"), row.name


def test_every_row_reaches_the_core_and_survives_save_and_load(fresh, bpy, tmp_path):
    params = fresh.parallax.render_params()
    for row in UI_ROWS:
        if row.core:
            assert same(params[row.name], row.default), row.name
    for row in UI_ROWS:
        setattr(fresh.parallax, row.name, changed(row))
    scene = save_and_reopen(bpy, tmp_path / "settings.blend")
    for row in UI_ROWS:
        assert same(getattr(scene.parallax, row.name), changed(row)), row.name
    session = parallax_core.Session(8, 8, "cpu")
    session.set_params(**scene.parallax.render_params())
    got = dataclasses.asdict(session.params)
    for row in UI_ROWS:
        if row.core:
            assert same(got[row.name], changed(row)), row.name


def test_set_takes_every_row_for_blend_and_npz_scenes(fresh):
    from parallax_core.cli import parse_params

    items = [f"{row.name}={as_text(changed(row))}" for row in UI_ROWS]
    apply_settings(fresh, items)
    npz = parse_params(items)
    for row in UI_ROWS:
        assert same(getattr(fresh.parallax, row.name), changed(row)), row.name
        assert same(npz[row.name], changed(row)), row.name
        with pytest.raises(CommandError, match=f"'{row.name}=bogus'"):
            apply_settings(fresh, [f"{row.name}=bogus"])
    with pytest.raises(CommandError, match="has no property 'preview'"):  # not a setting of the scene
        apply_settings(fresh, ["preview=1"])


def test_a_change_of_any_row_reaches_the_viewport(fresh):
    from addon.engine import viewport

    view = viewport.ViewportRender()
    view.worker = FakeWorker()
    depsgraph = FakeDepsgraph(fresh)
    view.update(None, None, depsgraph)
    # The viewport's own adaptive sampling rows take the core fields of F12's (Cycles' preview_*).
    viewport_rows = {"use_preview_adaptive_sampling": "use_adaptive_sampling",
                     "preview_adaptive_threshold": "adaptive_threshold"}
    for row in UI_ROWS:
        handed_over = len(view.worker.submitted)
        setattr(fresh.parallax, row.name, changed(row))
        view.update(None, None, depsgraph)
        if row.name in viewport_rows:
            assert len(view.worker.submitted) == handed_over + 1, row.name
            assert same(view.worker.submitted[-1]["params"][viewport_rows[row.name]], changed(row)), row.name
        elif row.core and row.name not in viewport_rows.values():
            assert len(view.worker.submitted) == handed_over + 1, row.name
            assert same(view.worker.submitted[-1]["params"][row.name], changed(row)), row.name
        elif "preview_denois" in row.name:  # the viewport's denoising, to its denoise thread
            assert len(view.worker.submitted) == handed_over + 1, row.name
            assert same(view.worker.submitted[-1]["denoise"][row.name], changed(row)), row.name
        else:  # F12's samples, time limit, adaptive sampling and denoising: the viewport has its own
            assert len(view.worker.submitted) == handed_over, row.name


class _Layout:
    """Records what a panel's draw() shows."""

    def __init__(self, shown):
        self.shown = shown

    def prop(self, data, name, **kwargs):
        self.shown.append(name)

    def column(self, **kwargs):
        return self

    row = column

    def label(self, **kwargs):
        pass


def drawn(panel, context):
    """The property names ``panel`` draws (header first)."""
    shown = []
    fake = types.SimpleNamespace(layout=_Layout(shown), **{k: getattr(panel, k) for k in
                                                           ("rows", "header", "switches", "bl_idname")
                                                           if hasattr(panel, k)})
    if hasattr(panel, "draw_header"):
        panel.draw_header(fake, context)
    panel.draw(fake, context)
    return shown


def test_every_row_is_drawn_in_its_panel_in_table_order(fresh, bpy):
    context = types.SimpleNamespace(scene=fresh, view_layer=fresh.view_layers[0], engine="PARALLAX")
    table = [row.name for row in UI_ROWS]
    where = {}  # setting -> (panel, sub-panel label or "") it is drawn in
    for panel in ui.classes:
        if panel.bl_context != "render":
            continue
        shown = drawn(panel, context)
        for name in shown:
            assert name not in where, f"{name} drawn twice"
            parent = getattr(panel, "bl_parent_id", None)
            where[name] = (parent, panel.bl_label) if parent else (panel.__name__, "")
        rows = [name for name in shown if name in table]
        assert rows == sorted(rows, key=table.index), panel.__name__
    for row in UI_ROWS:
        assert where.get(row.name) == (f"PARALLAX_PT_{row.panel}", row.group), row.name


def switched(setting, on):
    """A value of the switch ``setting`` (a bool, or an enum with an item "off") that is on or off."""
    row = parallax_core.setting(setting)
    if row.type == "enum":
        return next(i[0] for i in row.items if i[0] != "off") if on else "off"
    return on


def _all_passes_on(scene):
    for setting in properties.pass_switches():
        setattr(scene.parallax, setting, switched(setting, True))
    layer = scene.view_layers[0]
    for toggle in passes.BLENDER_TOGGLES.values():
        if toggle:
            setattr(layer, toggle, True)
    for row in PASSES:
        if passes.has_own_toggle(row):
            setattr(layer.parallax, passes.toggle_name(row), True)


def test_every_pass_reaches_the_compositor_and_its_toggle_is_drawn(fresh, bpy):
    tree = bpy.data.node_groups.new("Compositor", "CompositorNodeTree")
    fresh.compositing_node_group = tree
    layers = tree.nodes.new("CompositorNodeRLayers")

    def outputs():  # the node shows Combined as Image
        return {"Combined" if o.name == "Image" else o.name for o in layers.outputs if o.enabled}

    _all_passes_on(fresh)
    names = {p.name for p in passes.blender_passes()}
    assert {row.label for row in PASSES} <= names <= outputs()
    for setting in properties.pass_switches():
        setattr(fresh.parallax, setting, switched(setting, False))
    assert {row.label for row in PASSES if row.setting}.isdisjoint(outputs())
    assert {row.label for row in PASSES if not row.setting} <= outputs()

    context = types.SimpleNamespace(scene=fresh, view_layer=fresh.view_layers[0], engine="PARALLAX")
    shown = drawn(ui.PARALLAX_PT_passes, context)
    toggles = [passes.toggle_name(row) for row in PASSES if passes.has_own_toggle(row)]
    assert shown == [t for t in passes.BLENDER_TOGGLES.values() if t] + [passes.DENOISING_TOGGLE] + toggles


def test_every_pass_is_in_the_viewport_pass_menu(bpy):
    items = properties.ParallaxRenderSettings.bl_rna.properties["viewport_pass"].enum_items
    assert [(i.identifier, i.name) for i in items] == [(p.name, p.label) for p in PASSES]


def _recorded_params(monkeypatch):
    """Every set_params call of a Session from now on, as the full RenderParams it made."""
    calls = []
    real = parallax_core.Session.set_params

    def set_params(session, **changes):
        real(session, **changes)
        calls.append(dataclasses.asdict(session.params))

    monkeypatch.setattr(parallax_core.Session, "set_params", set_params)
    return calls


def test_blend_render_with_every_technique_row_set(bpy, tmp_path, monkeypatch):
    """`parallax render FILE.blend --set NAME=VALUE` for every technique row: the values reach
    the core's session, and every pass reaches the EXR under its Blender name."""
    from addon.cli import render
    from addon.engine import final

    calls = _recorded_params(monkeypatch)
    layer = "view_layers[0]"
    toggles = [f"{layer}.{t}=1" for t in passes.BLENDER_TOGGLES.values() if t] + \
        [f"{layer}.parallax.{passes.DENOISING_TOGGLE}=1"] + \
        [f"{layer}.parallax.{passes.toggle_name(row)}=1" for row in PASSES if passes.has_own_toggle(row)]
    items = [f"{row.name}={as_text(changed(row))}" for row in TECHNIQUE_ROWS]
    exr = tmp_path / "every.exr"
    render(f"{SCENES}/cornell_box.blend", str(exr), samples=2,
           assignments=items + toggles + ["render.resolution_x=16", "render.resolution_y=16"])
    assert not final.last_report.errors and final.last_report.samples == 2
    for row in TECHNIQUE_ROWS:
        assert same(calls[-1][row.name], changed(row)), row.name
    found = read_layers(exr)
    for p in passes.blender_passes():
        assert found[p.name].shape == (16, 16, p.channels), p.name
        assert np.isfinite(found[p.name]).all(), p.name
    assert {row.label for row in PASSES} <= set(found)


def test_npz_render_with_every_technique_row_set(tmp_path, monkeypatch):
    """`parallax render SCENE.npz --set NAME=VALUE` for every technique row: the values reach
    the core's session, and every pass reaches the EXR under its label and channel ids."""
    from parallax_core import cli, scenes
    from parallax_core.exr import read_exr

    calls = _recorded_params(monkeypatch)
    npz, exr = tmp_path / "box.npz", tmp_path / "box.exr"
    scenes.cornell_box(16, 16).save(str(npz))
    sets = [a for row in TECHNIQUE_ROWS for a in ("--set", f"{row.name}={as_text(changed(row))}")]
    # The light paths of blender_scenes/cornell_box.blend: the pipeline the test above compiled.
    sets += UNBIASED_LIGHT_PATH_SETS
    assert cli.main(["render", str(npz), "-o", str(exr), "--spp", "2", *sets]) == 0
    for row in TECHNIQUE_ROWS:
        assert same(calls[-1][row.name], changed(row)), row.name
    channels = read_exr(exr)
    assert set(channels) == {f"{p.label}.{c}" for p in PASSES for c in p.channel_ids}
