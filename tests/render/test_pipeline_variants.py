"""With PARALLAX_SCENE_FEATURES=folded, the test suite's setting (conftest.py), pipelines carry
the features of FEATURES_FOLDED (light types, vertex normals and UVs, conductors) whatever the
scene holds, so that a scene's mix of features is not a cold compile of its own
(Session::pipeline_key, pipeline_features); renders specialise for exactly the scene's. Both
must render the same images."""
import numpy as np
import pytest

from parallax_core import scenes

from helpers import render, same_render

# Each scene has some of the folded features and lacks others: triangle lights and flat meshes;
# sphere lights and conductors; an environment map, vertex normals and UVs; the sun.
SCENES = {"cornell_box": lambda: scenes.cornell_box(24, 24), "veach_mis": lambda: scenes.veach_mis(24, 16),
          "env_map_scene": lambda: scenes.env_map_scene(16, 16, map_width=32), "sun_room": lambda: scenes.sun_room(16, 16)}


def render_with(monkeypatch, features, scene):
    monkeypatch.setenv("PARALLAX_SCENE_FEATURES", features)
    image, session = render(scene, "mis", spp=4, seed=3)
    return image, session.device_type


@pytest.mark.parametrize("name", SCENES)
def test_folded_features_render_what_exact_ones_do(monkeypatch, name):
    scene = SCENES[name]()
    exact, device = render_with(monkeypatch, "exact", scene)
    folded, _ = render_with(monkeypatch, "folded", scene)
    assert np.isfinite(exact).all() and exact.mean() > 0
    # The same code runs where the scene has the feature; elsewhere the folded pipeline's
    # tests of the scene data (a light's type, a mesh's normals) skip it: bit for bit.
    assert same_render(exact, folded, device), np.abs(exact - folded).max()
