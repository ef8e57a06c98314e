"""Path guiding in the add-on: settings (round trip, the core's ranges, --set for .blend and
.npz), the Path Guiding panel, passes, stats line, the viewport's sessions, and an F12 render to
a multilayer EXR with the three guiding layers."""
import dataclasses
import io
import re

import numpy as np
import pytest
from addon.cli import CommandError, apply_settings
from addon.engine import final
from addon.properties import GUIDING_SETTINGS
from blender_helpers import assert_params, open_scene, render, save_and_reopen

import parallax_core

DEFAULTS = dict(guiding=False, guiding_prob=0.5, guiding_parallax=True, guiding_training_spp=32,
                guiding_min_samples=64, guiding_max_components=16, guiding_split_merge=True,
                guiding_region_splits=3, guiding_region_threshold=10000, guiding_max_regions=4096,
                guiding_probe_x=-1, guiding_probe_y=-1, guiding_fit="auto")
CHANGED = dict(guiding=True, guiding_prob=0.7, guiding_parallax=False, guiding_training_spp=0,
               guiding_min_samples=100, guiding_max_components=6, guiding_split_merge=False,
               guiding_region_splits=5, guiding_region_threshold=0, guiding_max_regions=64,
               guiding_probe_x=5, guiding_probe_y=7, guiding_fit="device")
RANGES = dict(guiding_prob=(0.0, 1.0), guiding_training_spp=(0, None), guiding_min_samples=(1, 2**24),
              guiding_max_components=(1, 16), guiding_region_splits=(0, 20), guiding_region_threshold=(0, None),
              guiding_probe_x=(-1, None), guiding_probe_y=(-1, None))


def test_guiding_settings_defaults_and_save_load(fresh, bpy, tmp_path):
    assert set(GUIDING_SETTINGS) == set(DEFAULTS)
    assert_params(fresh.parallax.render_params(), DEFAULTS)
    for name, value in CHANGED.items():
        setattr(fresh.parallax, name, value)
    fresh.view_layers[0].parallax.use_pass_guiding_lobes = False
    scene = save_and_reopen(bpy, tmp_path / "guiding.blend")
    assert_params(scene.parallax.render_params(), CHANGED)
    assert not scene.view_layers[0].parallax.use_pass_guiding_lobes
    assert scene.view_layers[0].parallax.use_pass_guiding_regions


def test_core_takes_the_guiding_settings_and_the_panel_limits(fresh):
    assert_params(dataclasses.asdict(parallax_core.RenderParams()), DEFAULTS)
    session = parallax_core.Session(8, 8, "cpu")
    for name, value in CHANGED.items():
        setattr(fresh.parallax, name, value)
    session.set_params(**fresh.parallax.render_params())
    assert_params(dataclasses.asdict(session.params), CHANGED)
    props = type(fresh.parallax).bl_rna.properties
    session.set_params(guiding_max_regions=2**22)  # room for every region split count
    for name, (low, high) in RANGES.items():
        assert props[name].hard_min == low, name
        assert high is None or props[name].hard_max <= high, name
        session.set_params(**{name: props[name].hard_min})
        session.set_params(**{name: props[name].hard_max})
        session.set_params(**{name: DEFAULTS[name]})


def test_guiding_panel_shows_every_setting(bpy):
    shown = ["guiding"] + list(bpy.types.PARALLAX_PT_guiding.properties)
    for panel in (bpy.types.PARALLAX_PT_guiding_fitting, bpy.types.PARALLAX_PT_guiding_regions,
                  bpy.types.PARALLAX_PT_guiding_visualisation):
        assert panel.bl_parent_id == "PARALLAX_PT_guiding"
        shown += panel.properties
    assert sorted(shown) == sorted(GUIDING_SETTINGS + ("guiding_animate_lobes",))
    assert bpy.types.PARALLAX_PT_guiding.bl_label == "Path Guiding"


def test_animate_lobes_follows_the_timeline(fresh):
    """Animate Lobes (thesis fig. 4.20): the spheres' phase is the scene's frame along a loop of
    LOBES_LOOP_FRAMES frames; off, they stay at their regions' centres (-1)."""
    from addon.properties import LOBES_LOOP_FRAMES

    assert fresh.parallax.render_params()["guiding_lobes_phase"] == -1.0
    apply_settings(fresh, ["guiding_animate_lobes=on"])
    session = parallax_core.Session(8, 8, "cpu")
    for frame in (0, 12, LOBES_LOOP_FRAMES + 6):
        fresh.frame_current = frame
        phase = fresh.parallax.render_params()["guiding_lobes_phase"]
        assert phase == pytest.approx((frame % LOBES_LOOP_FRAMES) / LOBES_LOOP_FRAMES)
        session.set_params(**fresh.parallax.render_params())  # the core takes it


def test_set_parses_guiding_settings_for_blend_files(fresh):
    apply_settings(fresh, ["guiding=on", "guiding_parallax=off", "guiding_prob=0.25", "guiding_training_spp=0",
                           "guiding_probe_x=-1", "guiding_probe_y=12", "guiding_fit=device"])
    s = fresh.parallax
    assert (s.guiding, s.guiding_parallax, s.guiding_training_spp, s.guiding_probe_x, s.guiding_probe_y,
            s.guiding_fit) == (True, False, 0, -1, 12, "device")
    assert s.guiding_prob == pytest.approx(0.25)
    with pytest.raises(CommandError):
        apply_settings(fresh, ["guiding=maybe"])
    with pytest.raises(CommandError):
        apply_settings(fresh, ["guiding_prob=high"])
    with pytest.raises(CommandError):
        apply_settings(fresh, ["guiding_fit=gpu"])
    apply_settings(fresh, ["guiding_max_components=17"])  # Blender clamps to the core's range
    assert s.guiding_max_components == 16


def test_set_parses_guiding_settings_for_npz():
    from parallax_core.cli import parse_params

    assert parse_params(["guiding=1", "guiding_prob=0.3", "guiding_probe_x=-1", "guiding_parallax=off",
                         "guiding_fit=device"]) == \
        dict(guiding=True, guiding_prob=0.3, guiding_probe_x=-1, guiding_parallax=False, guiding_fit="device")


def test_guiding_passes_only_with_guiding_on(fresh, bpy):
    tree = bpy.data.node_groups.new("Compositor", "CompositorNodeTree")
    fresh.compositing_node_group = tree
    layers = tree.nodes.new("CompositorNodeRLayers")

    def outputs():
        return {o.name for o in layers.outputs if o.enabled and o.name.startswith("Guiding ")}

    assert outputs() == set()
    fresh.parallax.guiding = True
    assert outputs() == {"Guiding Regions", "Guiding Components", "Guiding Lobes"}
    fresh.view_layers[0].parallax.use_pass_guiding_components = False
    assert outputs() == {"Guiding Regions", "Guiding Lobes"}
    fresh.parallax.guiding = False
    assert outputs() == set()


def test_guiding_setting_change_restarts_the_viewport(fresh):
    from test_ic_settings import _FakeDepsgraph, _FakeWorker
    from addon.engine import viewport

    view = viewport.ViewportRender()
    view.worker = _FakeWorker()
    view.worker.error = None  # a worker that has not failed
    depsgraph = _FakeDepsgraph(fresh)
    view.update(None, None, depsgraph)
    fresh.parallax.guiding = True
    view.update(None, None, depsgraph)
    assert len(view.worker.submitted) == 2 and view.worker.submitted[-1]["params"]["guiding"] is True


def test_viewport_pass_switches_without_a_restart(fresh):
    """Viewport Pass hands the worker another pass to show, not new settings (which would
    restart the image and the guiding field)."""
    from test_ic_settings import _FakeDepsgraph, _FakeWorker
    from addon.engine import viewport

    view = viewport.ViewportRender()
    view.worker = _FakeWorker()
    depsgraph = _FakeDepsgraph(fresh)
    view.update(None, None, depsgraph)
    assert fresh.parallax.viewport_pass == "combined"
    fresh.parallax.viewport_pass = "guiding_lobes"
    view.update(None, None, depsgraph)
    assert view.worker.submitted[-1] == {"display": "guiding_lobes"}


def test_viewport_worker_shows_a_guiding_pass_live():
    """The viewport worker publishes the chosen pass of its full-size session (RGBA, grey for one
    channel), and switching back to Combined keeps the samples and the trained field."""
    import time

    from addon.engine import viewport
    from parallax_core import scenes

    params = {**dataclasses.asdict(parallax_core.RenderParams()), "method": "mis", "samples_per_frame": 4,
              "guiding": True, "guiding_min_samples": 32, "guiding_region_splits": 3,
              "guiding_probe_x": 6, "guiding_probe_y": 6}
    worker = viewport._Worker("auto", params, 8, 1, display="guiding_lobes")
    worker.submit(scenes.cornell_box(16, 16), parts={"geometry"}, size=(16, 16))
    worker.start()

    def wait_done():  # an event, not a rate: the worker reaches its sample target
        while not worker.done and worker.error is None and worker.is_alive():
            time.sleep(0.05)
        assert worker.error is None and worker.done

    try:
        wait_done()
        lobes, samples, pixel_size, _ = worker.frame
        session = worker._full
        assert pixel_size == 1 and samples == 8 and lobes.shape == (16, 16, 4)
        np.testing.assert_array_equal(lobes[..., :3], session.read("guiding_lobes"))
        assert np.allclose(lobes[6, 6, :3], 1.0)  # the probe's cross
        fits = session.stats()["guiding_region_fits"]
        worker.submit(display="guiding_components")
        wait_done()
        components = worker.frame[0]
        np.testing.assert_array_equal(components[..., 0], session.read("guiding_components")[..., 0])
        assert np.array_equal(components[..., 0], components[..., 2]) and (components[..., 3] == 1).all()
        worker.submit(display="combined")
        wait_done()
        image, samples, _, _ = worker.frame
        assert samples == 8 and session.stats()["guiding_region_fits"] == fits
        np.testing.assert_array_equal(image, session.read("combined"))
    finally:
        worker.stop(wait=300)


def test_guiding_status_line():
    assert final.guiding_status({"guiding_trained_regions": 3, "guiding_regions": 16, "guiding_lobes": 24,
                                 "guiding_training_frames": 8}) == \
        "Guiding 3/16 regions, 24 lobes, 8 training frames"


def test_f12_writes_the_guiding_layers(bpy, tmp_path, monkeypatch):
    scene = open_scene(bpy, "cornell_box", 16, 16)
    scene.parallax.samples = 2
    passes = render(bpy, tmp_path / "off.exr")
    assert not any(name.startswith("Guiding ") for name in passes)
    s = scene.parallax
    s.guiding, s.guiding_training_spp, s.guiding_min_samples, s.guiding_region_splits = True, 24, 32, 3
    stream = io.StringIO()
    monkeypatch.setattr(final, "progress_stream", stream)
    passes = render(bpy, tmp_path / "guiding.exr")
    report = final.last_report
    assert not report.errors and report.samples == 2
    regions, components, lobes = passes["Guiding Regions"], passes["Guiding Components"], passes["Guiding Lobes"]
    assert regions.shape[:2] == components.shape[:2] == lobes.shape[:2] == (16, 16)
    assert regions[..., :3].max() > 0 and len({tuple(c) for c in regions[..., :3].reshape(-1, 3)}) > 1
    assert np.isfinite(components).all() and 0 <= components.min() and components.max() <= 1
    assert np.isfinite(lobes).all() and lobes.max() > 0
    line = stream.getvalue().strip().split("\r")[-1]
    found = re.search(r"Guiding (\d+)/8 regions, (\d+) lobes, 24 training frames", line)
    assert found and int(found.group(1)) > 0, line
