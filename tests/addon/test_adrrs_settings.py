"""ADRRS in the add-on beyond its settings (which test_settings_tables.py checks row by row):
an F12 render to a multilayer EXR with the ADRRS layers."""
import numpy as np
from blender_helpers import open_scene, render


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
