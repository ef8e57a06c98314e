"""Russian roulette and splitting (rrs = off | adrrs | ears) in the add-on beyond its settings
(which test_settings_tables.py checks row by row): rrs through the .blend file to the core,
older files whose ADRRS switch (the bool adrrs, now gone) was on, the panel, the passes, and
an F12 render to a multilayer EXR with the ADRRS layers."""
import types

import numpy as np
import pytest
from addon import passes, properties, ui, versioning
from addon.cli import CommandError, apply_settings, open_blend
from blender_helpers import open_scene, render, save_and_reopen

import parallax_core

ADRRS_ONLY = {"adrrs_window", "adrrs_estimate", "adrrs_ic_glossy"}  # apply with rrs adrrs only
SHARED = {"adrrs_splitting", "adrrs_rr_min", "adrrs_max_splits", "adrrs_estimate_spp"}  # with rrs on
EARS_ONLY = {"rrs_grid", "rrs_min_records"}  # with rrs ears only


def test_f12_writes_the_adrrs_layers(bpy, tmp_path):
    scene = open_scene(bpy, "cornell_box", 16, 16)
    scene.parallax.samples = 4
    passes_off = render(bpy, tmp_path / "off.exr")
    assert not any(name.startswith(("ADRRS ", "RRS ")) for name in passes_off)
    scene.parallax.rrs = "adrrs"
    scene.parallax.ic_prepare_frames, scene.parallax.adrrs_estimate_spp = 4, 2
    scene.view_layers[0].parallax.use_pass_ray_depth = True
    found = render(bpy, tmp_path / "adrrs.exr")
    estimate, splits = found["ADRRS Estimate"], found["ADRRS Splits"]
    assert estimate.shape == (16, 16, 3) and splits.shape[:2] == (16, 16)
    assert np.isfinite(estimate).all() and estimate.mean() > 0.0
    assert np.isfinite(splits).all() and (splits >= 0).all()
    assert "Ray Depth" in found


def test_rrs_round_trips_through_the_file_to_the_core(fresh, bpy, tmp_path):
    prop = properties.ParallaxRenderSettings.bl_rna.properties["rrs"]
    assert prop.type == "ENUM" and prop.name == "Russian Roulette & Splitting" and prop.default == "off"
    assert [i.identifier for i in prop.enum_items] == ["off", "adrrs", "ears"]
    assert "adrrs" not in properties.ParallaxRenderSettings.bl_rna.properties  # the old switch is gone
    scene = fresh
    for value in ("adrrs", "ears", "off"):
        scene.parallax.rrs = value
        scene = save_and_reopen(bpy, tmp_path / f"{value}.blend")
        assert scene.parallax.rrs == value
        params = scene.parallax.render_params()
        assert params["rrs"] == value and "adrrs" not in params
        session = parallax_core.Session(4, 4, "cpu")
        session.set_params(**params)
        assert session.params.rrs == value
    with pytest.raises(TypeError, match="bogus"):  # Blender's own check of the enum
        scene.parallax.rrs = "bogus"


def test_set_takes_rrs_and_the_synonym_adrrs(fresh):
    apply_settings(fresh, ["rrs=ears"])
    assert fresh.parallax.rrs == "ears"
    for text, rrs in (("1", "adrrs"), ("off", "off"), ("true", "adrrs"), ("0", "off")):
        apply_settings(fresh, [f"adrrs={text}"])
        assert fresh.parallax.rrs == rrs, text
    apply_settings(fresh, ["adrrs=1", "rrs=ears"])  # in order: the last wins
    assert fresh.parallax.rrs == "ears"
    with pytest.raises(CommandError, match="'adrrs=maybe': expected 1/0"):
        apply_settings(fresh, ["adrrs=maybe"])
    with pytest.raises(CommandError, match="'rrs=bogus'"):
        apply_settings(fresh, ["rrs=bogus"])
    assert fresh.parallax.rrs == "ears"


def _save_old_file(bpy, scene, path, adrrs, rrs=None):
    """Saves ``scene`` as the add-on before rrs (issue 34) did: with its bool property adrrs,
    and rrs set as well if given (a file saved by a version that had both)."""
    from bpy.props import BoolProperty

    settings_class = properties.ParallaxRenderSettings
    settings_class.adrrs = BoolProperty(name="ADRRS", default=False)
    try:
        scene.parallax.adrrs = adrrs
        if rrs is not None:
            scene.parallax.rrs = rrs
        bpy.ops.wm.save_as_mainfile(filepath=str(path))
    finally:
        del settings_class.adrrs
    bpy.ops.wm.read_factory_settings(use_empty=True)


def _stale(scene):
    return versioning._stored(scene.parallax).get("adrrs")


def test_an_older_file_with_adrrs_on_loads_as_rrs_adrrs(fresh, bpy, tmp_path):
    path = tmp_path / "old_on.blend"
    _save_old_file(bpy, fresh, path, True)
    bpy.ops.wm.open_mainfile(filepath=str(path))
    scene = bpy.context.scene
    assert scene.parallax.rrs == "adrrs" and _stale(scene) is None
    assert scene.parallax.render_params()["rrs"] == "adrrs"
    # Saved again, the file holds rrs alone; turned off, it stays off.
    scene.parallax.rrs = "off"
    scene = save_and_reopen(bpy, tmp_path / "saved_again.blend")
    assert scene.parallax.rrs == "off" and _stale(scene) is None
    # `parallax render FILE.blend` opens it the same way.
    assert open_blend(str(path)).parallax.rrs == "adrrs"


def test_an_older_file_with_adrrs_off_or_rrs_set_keeps_its_rrs(fresh, bpy, tmp_path):
    _save_old_file(bpy, fresh, tmp_path / "old_off.blend", False)
    bpy.ops.wm.open_mainfile(filepath=str(tmp_path / "old_off.blend"))
    assert bpy.context.scene.parallax.rrs == "off" and _stale(bpy.context.scene) is None
    # rrs set in the file wins over the stale switch.
    _save_old_file(bpy, bpy.context.scene, tmp_path / "both.blend", True, rrs="ears")
    bpy.ops.wm.open_mainfile(filepath=str(tmp_path / "both.blend"))
    assert bpy.context.scene.parallax.rrs == "ears" and _stale(bpy.context.scene) is None
    assert versioning.migrate_scene(bpy.context.scene) == []  # nothing left to move


class _Layout:
    """Records each property a panel draws and whether it is active (not greyed)."""

    def __init__(self, shown, active=True):
        self.shown, self.active = shown, active

    def column(self, **kwargs):
        return _Layout(self.shown, self.active)

    row = column

    def prop(self, data, name, **kwargs):
        self.shown[name] = self.active

    def label(self, **kwargs):
        pass


def _drawn(panel, scene):
    shown = {}
    fake = types.SimpleNamespace(layout=_Layout(shown), rows=panel.rows, header=panel.header,
                                 switches=panel.switches, bl_idname=panel.__name__)
    panel.draw(fake, types.SimpleNamespace(scene=scene, view_layer=scene.view_layers[0], engine="PARALLAX"))
    return shown


def test_the_panel_is_rrs_and_greys_what_does_not_apply(fresh):
    (panel,) = [p for p in ui.classes if p.__name__ == "PARALLAX_PT_adrrs"]
    assert panel.bl_label == "Russian Roulette & Splitting" == parallax_core.setting("rrs").label
    assert panel.header is None and panel.switches == ("rrs",)  # an enum: the first row, not a checkbox
    rows = [row.name for row in parallax_core.SETTINGS if row.panel == "adrrs"]
    assert list(panel.rows) == rows and rows[0] == "rrs" and set(rows) == {"rrs"} | ADRRS_ONLY | EARS_ONLY | SHARED
    for rrs in ("off", "adrrs", "ears"):
        fresh.parallax.rrs = rrs
        shown = _drawn(panel, fresh)
        assert list(shown) == rows and shown["rrs"], rrs
        assert all(shown[name] == (rrs == "adrrs") for name in ADRRS_ONLY), (rrs, shown)
        assert all(shown[name] == (rrs != "off") for name in SHARED), (rrs, shown)
        assert all(shown[name] == (rrs == "ears") for name in EARS_ONLY), (rrs, shown)


def test_the_rrs_passes_follow_rrs(fresh):
    own = {p.label for p in parallax_core.PASSES if p.setting == "rrs"}
    assert own == {"ADRRS Estimate", "ADRRS Splits", "RRS Factor", "RRS Cost"}
    layer = fresh.view_layers[0]
    for row in parallax_core.PASSES:
        if row.setting == "rrs":
            setattr(layer.parallax, passes.toggle_name(row), True)
    for rrs in ("off", "adrrs", "ears"):
        fresh.parallax.rrs = rrs
        enabled = {p.name for p in passes.enabled(fresh, layer)}
        assert (own <= enabled) if rrs != "off" else not (own & enabled), rrs
    # The view layer's toggles: the column headed by rrs' label, greyed while rrs is off.
    shown = {}
    for rrs in ("off", "ears"):
        fresh.parallax.rrs = rrs
        fake = types.SimpleNamespace(layout=_Layout(shown))
        ui.PARALLAX_PT_passes.draw(fake, types.SimpleNamespace(scene=fresh, view_layer=layer, engine="PARALLAX"))
        assert all(shown[passes.toggle_name(row)] == (rrs != "off")
                   for row in parallax_core.PASSES if row.setting == "rrs"), rrs


def test_the_viewport_preview_frames_turn_rrs_off(fresh):
    from addon.engine import viewport

    fresh.parallax.rrs, fresh.parallax.ic = "ears", True
    params = viewport._without_techniques(fresh.parallax.render_params())
    assert params["rrs"] == "off" and params["ic"] is False and params["guiding"] is False
    parallax_core.RenderParams(**params, preview=True).validate()
    assert [row.name for row in properties.technique_switches()] == ["ic", "rrs", "guiding"]
