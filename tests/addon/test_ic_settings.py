"""The irradiance cache in the add-on beyond its settings (which test_settings_tables.py checks
row by row): the stats line, and an F12 render to a multilayer EXR with the IC layers."""
import io
import re

import numpy as np
from addon.engine import final
from blender_helpers import open_scene, render


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
