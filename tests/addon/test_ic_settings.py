"""The irradiance cache in the add-on: settings, panel, passes, viewport restart, stats line,
and an F12 render to a multilayer EXR with the IC layers."""
import dataclasses
import io
import re

import numpy as np
import pytest
from addon.cli import CommandError, apply_settings
from addon.engine import final, viewport
from addon.properties import IC_SETTINGS
from blender_helpers import assert_params, open_scene, render, save_and_reopen

import parallax_core

# The core's interface: every setting with its default, and a value other than the default.
DEFAULTS = dict(ic=False, ic_accuracy=0.2, ic_min_radius=0.1, ic_create_prob=0.01,
                ic_update_prob=1e-5, ic_nee_samples=1, ic_gradients=False, ic_gradient_max=5.0,
                ic_visibility_check=True, ic_prepare_frames=50, ic_capacity=65536,
                ic_rebuild_interval=1, ic_highlight=False)
CHANGED = dict(ic=True, ic_accuracy=0.35, ic_min_radius=0.05, ic_create_prob=0.2,
               ic_update_prob=1e-4, ic_nee_samples=3, ic_gradients=True, ic_gradient_max=2.5,
               ic_visibility_check=False, ic_prepare_frames=7, ic_capacity=1000,
               ic_rebuild_interval=20, ic_highlight=True)
# The core's ranges (min, max; None: unbounded).
RANGES = dict(ic_accuracy=(0.0, 2.0), ic_min_radius=(0.0, None), ic_create_prob=(0.0, 1.0),
              ic_update_prob=(0.0, 1.0), ic_nee_samples=(1, 64), ic_gradient_max=(0.0, None),
              ic_prepare_frames=(0, 10000), ic_capacity=(1, 4_000_000),
              ic_rebuild_interval=(1, 100000))


def test_ic_settings_defaults_and_save_load(fresh, bpy, tmp_path):
    assert set(IC_SETTINGS) == set(DEFAULTS)
    assert_params(fresh.parallax.render_params(), DEFAULTS)
    for name, value in CHANGED.items():
        setattr(fresh.parallax, name, value)
    fresh.view_layers[0].parallax.use_pass_ic_gradients = False
    scene = save_and_reopen(bpy, tmp_path / "ic.blend")
    assert_params(scene.parallax.render_params(), CHANGED)
    assert not scene.view_layers[0].parallax.use_pass_ic_gradients
    assert scene.view_layers[0].parallax.use_pass_ic_irradiance


def test_ic_limits_are_the_cores_ranges(bpy):
    from addon.properties import ParallaxRenderSettings

    props = ParallaxRenderSettings.bl_rna.properties
    for name, (low, high) in RANGES.items():
        prop = props[name]
        # Floats may stop just above an open lower bound (accuracy > 0).
        assert low <= prop.hard_min <= low + (1.01e-3 if prop.type == "FLOAT" else 0), name
        assert prop.hard_max == high if high is not None else prop.hard_max > 1e30, name


def test_core_takes_the_ic_settings(fresh):
    core_defaults = dataclasses.asdict(parallax_core.RenderParams())
    assert_params(core_defaults, DEFAULTS)
    session = parallax_core.Session(8, 8, "cpu")
    for name, value in CHANGED.items():
        setattr(fresh.parallax, name, value)
    session.set_params(**fresh.parallax.render_params())
    assert_params(dataclasses.asdict(session.params), CHANGED)
    # Every value the panel allows, the core accepts.
    props = type(fresh.parallax).bl_rna.properties
    for name, (_, high) in RANGES.items():
        session.set_params(**{name: props[name].hard_min})
        if high is not None:
            session.set_params(**{name: props[name].hard_max})


def test_ic_panel_shows_every_setting(bpy):
    panels = [bpy.types.PARALLAX_PT_ic_accuracy, bpy.types.PARALLAX_PT_ic_creation,
              bpy.types.PARALLAX_PT_ic_gradients, bpy.types.PARALLAX_PT_ic_visualisation]
    shown = ["ic", "ic_gradients"]  # the header checkboxes
    for panel in panels:
        assert panel.bl_parent_id == "PARALLAX_PT_irradiance_cache"
        shown += panel.properties
    assert sorted(shown) == sorted(IC_SETTINGS)


def test_ic_passes_only_with_ic_on(fresh, bpy):
    """The compositor's Render Layers node shows the IC passes when the scene's cache is on
    and the view layer's toggle is."""
    tree = bpy.data.node_groups.new("Compositor", "CompositorNodeTree")
    fresh.compositing_node_group = tree
    layers = tree.nodes.new("CompositorNodeRLayers")

    def ic_outputs():
        return {o.name for o in layers.outputs if o.enabled and o.name.startswith("IC ")}

    assert ic_outputs() == set()
    fresh.parallax.ic = True
    assert ic_outputs() == {"IC Irradiance", "IC Gradients"}
    fresh.view_layers[0].parallax.use_pass_ic_gradients = False
    assert ic_outputs() == {"IC Irradiance"}
    fresh.parallax.ic = False
    assert ic_outputs() == set()


def test_set_parses_ic_settings_for_blend_files(fresh):
    apply_settings(fresh, ["ic=1", "ic_gradients=true", "ic_visibility_check=off",
                           "ic_highlight=Yes", "ic_accuracy=0.3", "ic_capacity=1000"])
    s = fresh.parallax
    assert (s.ic, s.ic_gradients, s.ic_visibility_check, s.ic_highlight) == (True, True, False, True)
    assert s.ic_accuracy == pytest.approx(0.3) and s.ic_capacity == 1000
    apply_settings(fresh, ["ic=0", "render.use_border=True"])
    assert not s.ic and fresh.render.use_border
    with pytest.raises(CommandError, match="expected one of"):
        apply_settings(fresh, ["ic=maybe"])


class _FakeWorker:
    device = "auto"
    error = None  # a worker stopped by an error would be replaced
    display = "combined"

    def __init__(self):
        self.submitted = []

    def submit(self, scene=None, parts=(), **changes):
        self.submitted.append(changes)


class _FakeDepsgraph:
    def __init__(self, scene):
        self.scene, self.updates = scene, []


def test_ic_setting_change_restarts_the_viewport(fresh):
    view = viewport.ViewportRender()
    view.worker = _FakeWorker()
    depsgraph = _FakeDepsgraph(fresh)
    view.update(None, None, depsgraph)  # hands over the current settings
    view.update(None, None, depsgraph)  # nothing changed: nothing to hand over
    assert len(view.worker.submitted) == 1
    fresh.parallax.ic_accuracy = 0.5
    view.update(None, None, depsgraph)
    assert len(view.worker.submitted) == 2
    assert view.worker.submitted[-1]["params"]["ic_accuracy"] == pytest.approx(0.5)


def test_ic_status_line():
    assert final.ic_status({"ic_entries": 12, "ic_capacity": 100, "ic_dropped": 3}) == \
        "IC 12/100 entries, 3 dropped"


def test_f12_writes_the_ic_layers_and_stats(bpy, tmp_path, monkeypatch):
    scene = open_scene(bpy, "cornell_box", 16, 16)
    scene.parallax.samples = 2
    stream = io.StringIO()
    monkeypatch.setattr(final, "progress_stream", stream)
    passes = render(bpy, tmp_path / "off.exr")
    assert "Sample 2/2" in stream.getvalue() and "IC " not in stream.getvalue()
    assert not any(name.startswith("IC ") for name in passes)

    scene.parallax.ic, scene.parallax.ic_gradients = True, True
    scene.parallax.ic_prepare_frames, scene.parallax.ic_capacity = 2, 5000
    stream.seek(0), stream.truncate()
    passes = render(bpy, tmp_path / "ic.exr")
    report = final.last_report
    assert not report.errors and report.samples == 2
    irradiance, gradients = passes["IC Irradiance"], passes["IC Gradients"]
    assert irradiance.shape == gradients.shape == (16, 16, 3)
    assert np.isfinite(irradiance).all() and irradiance.mean() > 0.0  # the box lights itself
    assert np.isfinite(gradients).all() and (gradients >= 0).all() and (gradients[..., 2] == 0).all()
    line = stream.getvalue().strip().split("\r")[-1]
    found = re.search(r"IC (\d+)/5000 entries, (\d+) dropped", line)
    assert found and 0 < int(found.group(1)) <= 5000, line
