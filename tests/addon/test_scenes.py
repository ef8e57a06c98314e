"""Every scene in blender_scenes/ renders through the engine, with every pass registered."""
import numpy as np
import pytest
from blender_helpers import open_scene, render

SCENE_NAMES = ("cornell_box", "veach_mis", "cornell_dielectric", "light_behind_glass", "atrium")
ALL_PASSES = {"Combined": 4, "Depth": 1, "Normal": 3, "Denoising Normal": 3,
              "Denoising Albedo": 3, "Ray Depth": 1}


@pytest.mark.parametrize("name", SCENE_NAMES)
def test_scene_renders_every_pass(bpy, tmp_path, name):
    scene = open_scene(bpy, name, 40, 30)
    assert scene.render.engine == "PARALLAX"
    scene.parallax.samples = 4
    layer = scene.view_layers[0]
    layer.use_pass_z = layer.use_pass_normal = True
    layer.parallax.use_pass_ray_depth = layer.parallax.use_pass_denoising_data = True
    from addon.engine import final

    passes = render(bpy, tmp_path / f"{name}.exr")
    assert not final.last_report.errors
    assert {k: v.shape[2] for k, v in passes.items()} == ALL_PASSES
    for image in passes.values():
        assert image.shape[:2] == (30, 40) and np.isfinite(image).all()

    combined = passes["Combined"]
    assert combined[..., :3].min() >= 0.0 and combined[..., :3].mean() > 1e-3
    np.testing.assert_allclose(combined[..., 3], 1.0)
    hit = passes["Depth"][..., 0] < 1e9  # Blender's "no hit" depth is 1e10
    assert hit.mean() > 0.5
    assert (passes["Depth"][..., 0][hit] > scene.camera.data.clip_start).all()
    # Averaged over samples the normals of a pixel can partly cancel, but not on average.
    lengths = np.linalg.norm(passes["Normal"][hit], axis=-1)
    assert lengths.max() <= 1.0 + 1e-4 and np.median(lengths) > 0.9
    np.testing.assert_array_equal(passes["Denoising Normal"], passes["Normal"])
    albedo = passes["Denoising Albedo"]
    assert albedo.min() >= 0.0 and albedo.max() <= 1.0 + 1e-4 and albedo[hit].mean() > 0.05
    assert passes["Ray Depth"].min() >= 1.0
