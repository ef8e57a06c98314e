"""Path guiding in the add-on beyond its settings (which test_settings_tables.py checks row by
row): Animate Lobes, the viewport's pass switching and live guiding pass, the stats line, and
an F12 render to a multilayer EXR with the three guiding layers."""
import dataclasses
import io
import re

import numpy as np
import pytest
from addon.cli import apply_settings
from addon.engine import final
from blender_helpers import FakeDepsgraph, FakeWorker, open_scene, render

import parallax_core


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


def test_viewport_pass_switches_without_a_restart(fresh):
    """Viewport Pass hands the worker another pass to show, not new settings (which would
    restart the image and the guiding field)."""
    from addon.engine import viewport

    view = viewport.ViewportRender()
    view.worker = FakeWorker()
    depsgraph = FakeDepsgraph(fresh)
    view.update(None, None, depsgraph)
    assert fresh.parallax.viewport_pass == "combined"
    fresh.parallax.viewport_pass = "guiding_lobes"
    view.update(None, None, depsgraph)
    assert view.worker.submitted[-1] == {"display": "guiding_lobes"}


def test_viewport_worker_shows_a_guiding_pass_live():
    """The viewport worker publishes the chosen pass of its full-size session (RGBA, grey for one
    channel). Switching from Guiding Lobes, which has pipelines of its own, starts the film over
    without it; switching between the other passes keeps the samples and the trained field."""
    import time

    from addon.engine import viewport
    from parallax_core import scenes

    params = {**dataclasses.asdict(parallax_core.RenderParams()), "method": "mis", "samples_per_frame": 4,
              "guiding": True, "guiding_min_samples": 32, "guiding_region_splits": 3,
              "guiding_probe_x": 6, "guiding_probe_y": 6,
              **parallax_core.UNBIASED_LIGHT_PATHS}  # the F12 test's pipelines: no compile of their own
    worker = viewport._Worker("auto", params, 8, 1, display="guiding_lobes")
    worker.submit(scenes.cornell_box(16, 16), parts={"geometry"}, size=(16, 16))
    worker.start()

    def wait_done():  # an event, not a rate: the worker reaches its sample target
        while not worker.done and worker.error is None and worker.is_alive():
            time.sleep(0.05)
        assert worker.error is None and worker.done

    try:
        wait_done()
        lobes, samples, pixel_size, _, _ = worker.frame
        session = worker._full
        assert pixel_size == 1 and samples == 8 and lobes.shape == (16, 16, 4)
        np.testing.assert_array_equal(lobes[..., :3], session.read("guiding_lobes"))
        assert np.allclose(lobes[6, 6, :3], 1.0)  # the probe's cross
        assert "guiding_lobes" in session.passes
        worker.submit(display="guiding_components")
        wait_done()
        assert "guiding_lobes" not in session.passes and "guiding_regions" in session.passes
        fits = session.stats()["guiding_region_fits"]
        components = worker.frame[0]
        np.testing.assert_array_equal(components[..., 0], session.read("guiding_components")[..., 0])
        assert np.array_equal(components[..., 0], components[..., 2]) and (components[..., 3] == 1).all()
        worker.submit(display="combined")
        wait_done()
        image, samples, _, _, _ = worker.frame
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
    # Training happens in the image's own frames: both of the render's frames trained (of 24 spp).
    found = re.search(r"Guiding (\d+)/8 regions, (\d+) lobes, 2 training frames", line)
    assert found and int(found.group(1)) > 0, line
