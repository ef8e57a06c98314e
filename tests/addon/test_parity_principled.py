"""Parity with Cycles for the Principled BSDF (issue 14): every patch of the material grid
(blender_scenes/principled_grid.py: roughness x metallic x IOR Level x transmission, coat,
sheen, F82-tinted metal, smooth dielectric and glass) within 5% of Cycles' mean radiance.
Cycles is set up as for the .blend scenes (blender_scenes/build.py). Both engines render
seeds 0 and 1; a patch's value is the mean over the pixels well inside it, both seeds.
"""
import os

import numpy as np
from blender_helpers import load_scene_module, render_engine

grid = load_scene_module("principled_grid")

SAMPLES = int(os.environ.get("PARALLAX_PARITY_SAMPLES", 256))


def test_principled_grid_matches_cycles(bpy, tmp_path):
    scene = grid.build(bpy)
    ours = sum(grid.patch_means(render_engine(bpy, tmp_path, scene, "PARALLAX", s, SAMPLES)) for s in (0, 1)) / 2
    theirs = sum(grid.patch_means(render_engine(bpy, tmp_path, scene, "CYCLES", s, SAMPLES)) for s in (0, 1)) / 2
    ratio = ours / theirs  # per patch and channel
    for (label, _), r, o, t in zip(grid.patches(), ratio, ours, theirs):
        print(f"{label:24s} ratio {np.round(r, 3)}  ours {np.round(o, 4)}  Cycles {np.round(t, 4)}")
    worst = np.abs(ratio - 1.0).max(axis=1)
    assert np.all(worst < 0.05), [(label, round(float(w), 3)) for (label, _), w in zip(grid.patches(), worst)]
