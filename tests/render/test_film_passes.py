"""The film holds only the passes that are enabled (Session.passes; issue 32, item 2)."""
import numpy as np
import pytest

import parallax_core as pc
from parallax_core import scenes


def session(passes=None, **params):
    s = pc.Session(24, 18, "cpu")
    if passes is not None:
        s.passes = passes
    s.set_params(samples_per_frame=2, max_depth=3, seed=5, **params)
    s.update(scenes.cornell_box(24, 18))
    s.render(2)
    return s


def test_default_holds_every_pass():
    s = session()
    assert s.passes == [p.name for p in pc.PASSES if p.core]


def test_combined_only_matches_the_full_film_bit_for_bit():
    full, lean = session(), session(["combined"])
    assert lean.passes == ["combined"]
    np.testing.assert_array_equal(lean.read("combined"), full.read("combined"))
    with pytest.raises(ValueError, match="not rendered"):
        lean.read("depth")


def test_a_subset_keeps_each_pass_in_its_place():
    full, some = session(), session(["albedo", "ray_depth"])
    assert some.passes == ["combined", "albedo", "ray_depth"]
    for name in ("combined", "albedo", "ray_depth"):
        np.testing.assert_array_equal(some.read(name), full.read(name))


def test_a_technique_pass_reads_zeros_while_the_technique_is_off():
    s = session(["ic_irradiance"])
    assert not s.read("ic_irradiance").any()


def test_the_engines_pass_is_not_the_films():
    s = pc.Session(8, 8, "cpu")
    with pytest.raises(ValueError, match="made by the engine"):
        s.passes = ["combined", "noisy_image"]


def test_unknown_pass_is_a_clear_error():
    s = pc.Session(8, 8, "cpu")
    with pytest.raises(ValueError, match="unknown pass 'beauty'"):
        s.passes = ["combined", "beauty"]
    assert s.passes == [p.name for p in pc.PASSES if p.core]  # unchanged
