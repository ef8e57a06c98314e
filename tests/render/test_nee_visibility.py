"""The NEE Visibility pass (issue 32, the example pass of the settings and passes tables): the
fraction of a pixel's NEE shadow rays that reached their light."""
import numpy as np
import parallax_core as pc
from parallax_core import scenes


def visibility(scene, method, spp=8):
    s = pc.Session(scene.width, scene.height, "cpu")
    s.update(scene)
    s.set_params(method=method, samples_per_frame=spp, max_depth=3)
    s.render(1)
    return s.read("nee_visibility")[..., 0]


def test_the_pass_is_in_the_tables_and_the_film():
    row = {p.name: p for p in pc.PASSES}["nee_visibility"]
    assert (row.label, row.channels, row.channel_ids, row.setting) == ("NEE Visibility", 1, "X", "")
    assert "nee_visibility" in pc.Session.pass_names()


def test_a_convex_object_under_the_sky_sees_its_light_and_the_sky_traces_none():
    v = visibility(scenes.furnace_sphere(0.5, 32, 32), "nee")
    assert v.min() >= 0.0 and v.max() <= 1.0
    # The sphere's centre faces the camera: nothing but the sky above its surface there (a
    # grazing sample may meet a neighbouring facet of the tessellated sphere).
    centre = v[12:20, 12:20]
    assert np.median(centre) == 1.0 and centre.mean() > 0.9
    # Camera rays through the corners miss everything: no vertex, no shadow ray.
    assert v[:3, :3].max() == 0.0 and v[-3:, -3:].max() == 0.0


def test_shadows_lower_it_and_path_tracing_traces_no_shadow_rays():
    box = scenes.cornell_box(32, 32)
    v = visibility(box, "mis")
    assert v.max() == 1.0 and v.min() < 0.5  # lit surfaces and shadowed ones (behind the blocks)
    assert 0.2 < v.mean() < 0.95
    assert visibility(box, "pt").max() == 0.0
