"""ADRRS in the add-on: settings (round trip, the core's ranges, --set), panel, passes,
viewport restart, and an F12 render to a multilayer EXR with the ADRRS layers."""
import dataclasses

import numpy as np
import pytest
from addon.cli import CommandError, apply_settings
from addon.properties import ADRRS_SETTINGS
from blender_helpers import assert_params, open_scene, render, save_and_reopen

import parallax_core

DEFAULTS = dict(adrrs=False, adrrs_splitting=True, adrrs_window=5.0, adrrs_rr_min=0.1,
                adrrs_max_splits=10, adrrs_estimate_spp=4, adrrs_estimate="ic", adrrs_ic_glossy=True)
CHANGED = dict(adrrs=True, adrrs_splitting=False, adrrs_window=3.0, adrrs_rr_min=0.25,
               adrrs_max_splits=4, adrrs_estimate_spp=9, adrrs_estimate="image", adrrs_ic_glossy=False)
RANGES = dict(adrrs_window=(1.0, 1e6), adrrs_rr_min=(0.0, 1.0), adrrs_max_splits=(0, 64),
              adrrs_estimate_spp=(1, 65536))


def test_adrrs_settings_defaults_and_save_load(fresh, bpy, tmp_path):
    assert set(ADRRS_SETTINGS) == set(DEFAULTS)
    assert_params(fresh.parallax.render_params(), DEFAULTS)
    for name, value in CHANGED.items():
        setattr(fresh.parallax, name, value)
    fresh.view_layers[0].parallax.use_pass_adrrs_splits = False
    scene = save_and_reopen(bpy, tmp_path / "adrrs.blend")
    assert_params(scene.parallax.render_params(), CHANGED)
    assert not scene.view_layers[0].parallax.use_pass_adrrs_splits


def test_core_takes_the_adrrs_settings_and_the_panel_limits(fresh):
    assert_params(dataclasses.asdict(parallax_core.RenderParams()), DEFAULTS)
    session = parallax_core.Session(8, 8, "cpu")
    for name, value in CHANGED.items():
        setattr(fresh.parallax, name, value)
    session.set_params(**fresh.parallax.render_params())
    assert_params(dataclasses.asdict(session.params), CHANGED)
    props = type(fresh.parallax).bl_rna.properties
    for name, (low, high) in RANGES.items():
        assert low <= props[name].hard_min and props[name].hard_max <= high, name
        session.set_params(**{name: props[name].hard_min})
        session.set_params(**{name: props[name].hard_max})


def test_adrrs_panel_shows_every_setting(bpy):
    panel = bpy.types.PARALLAX_PT_adrrs
    assert sorted(("adrrs",) + panel.properties) == sorted(ADRRS_SETTINGS)


def test_set_parses_adrrs_settings_for_blend_files(fresh):
    apply_settings(fresh, ["adrrs=on", "adrrs_splitting=0", "adrrs_window=2.5", "adrrs_estimate=image",
                           "adrrs_max_splits=3"])
    s = fresh.parallax
    assert (s.adrrs, s.adrrs_splitting, s.adrrs_estimate, s.adrrs_max_splits) == (True, False, "image", 3)
    assert s.adrrs_window == pytest.approx(2.5)
    with pytest.raises(CommandError):
        apply_settings(fresh, ["adrrs_estimate=blur"])


def test_set_parses_adrrs_settings_for_npz():
    from parallax_core.cli import parse_params

    assert parse_params(["adrrs=1", "adrrs_estimate=image", "adrrs_window=3"]) == \
        dict(adrrs=True, adrrs_estimate="image", adrrs_window=3.0)


def test_adrrs_setting_change_restarts_the_viewport(fresh):
    from test_ic_settings import _FakeDepsgraph, _FakeWorker
    from addon.engine import viewport

    view = viewport.ViewportRender()
    view.worker = _FakeWorker()
    depsgraph = _FakeDepsgraph(fresh)
    view.update(None, None, depsgraph)
    fresh.parallax.adrrs = True
    view.update(None, None, depsgraph)
    assert len(view.worker.submitted) == 2 and view.worker.submitted[-1]["params"]["adrrs"] is True


def test_f12_writes_the_adrrs_layers(bpy, tmp_path):
    scene = open_scene(bpy, "cornell_box", 16, 16)
    scene.parallax.samples = 4
    passes = render(bpy, tmp_path / "off.exr")
    assert not any(name.startswith("ADRRS ") for name in passes)
    scene.parallax.adrrs = True
    scene.parallax.ic_prepare_frames, scene.parallax.adrrs_estimate_spp = 4, 2
    scene.view_layers[0].parallax.use_pass_ray_depth = True
    passes = render(bpy, tmp_path / "adrrs.exr")
    estimate, splits = passes["ADRRS Estimate"], passes["ADRRS Splits"]
    assert estimate.shape == (16, 16, 3) and splits.shape[:2] == (16, 16)
    assert np.isfinite(estimate).all() and estimate.mean() > 0.0
    assert np.isfinite(splits).all() and (splits >= 0).all()
    assert "Ray Depth" in passes
