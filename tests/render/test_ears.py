"""Efficiency-aware Russian roulette and splitting (rrs=ears; Rath et al. 2022): unbiased against
plain MIS without roulette (per-block z-test, with and without splitting, on the Cornell box
and through glass), statistics that are learnt and used, determinism with a fixed seed, the
split budget, and the passes."""
from __future__ import annotations

import numpy as np
import pytest

import parallax_core as pc
from parallax_core import scenes

from helpers import batches, means_agree, render, same_render, z_scores
from test_adrrs import glass_and_degenerate_scene

SIZE = 32
# Small images: few records per cell, so the tests let a cell's factors count from 16 records
# (the default waits for 256) on a coarse grid, with the first estimate after 2 samples.
EARS = dict(rrs="ears", rrs_min_records=16, rrs_grid=8, adrrs_estimate_spp=2)
PLAIN = dict(rr_start_depth=0)  # the reference: MIS with no roulette at all
BATCHES, SPP, SPP_PER_FRAME = 8, 32, 4


def assert_unbiased(scene, **params):
    reference = batches(scene, "mis", BATCHES, SPP, spp_per_frame=SPP_PER_FRAME, **PLAIN)
    tested = batches(scene, "mis", BATCHES, SPP, session=reference.session, spp_per_frame=SPP_PER_FRAME,
                     **PLAIN, **EARS, **params)
    assert np.isfinite(tested.mean).all()
    z = z_scores(tested.images, reference.images, k=2)
    assert (np.abs(z) > 4).mean() < 0.01, f"{(np.abs(z) > 4).mean():.3f} of blocks beyond |z| > 4"
    ok, a, b, err = means_agree(tested.means, reference.means)
    assert ok, f"image means {a:.5f} vs {b:.5f} (se {err:.5f})"
    stats = reference.session.stats()
    # The last batch decided by learnt factors: EARS was at work, not only the throughput roulette.
    assert stats["ears_iterations"] >= 2 and stats["ears_cells_with_factors"] > 0 and stats["ears_image_factor"] > 0
    return reference.session


@pytest.mark.parametrize("params", [dict(), dict(adrrs_splitting=False)], ids=["split", "rr-only"])
def test_unbiased_on_the_cornell_box(params):
    session = assert_unbiased(scenes.cornell_box(SIZE, SIZE), **params)
    session.passes = ["combined", "adrrs_splits", "rrs_factor"]
    session.render(8)
    factors = session.read("rrs_factor")[..., 0]
    assert (factors < 1).any(), "no roulette"  # paths were ended by EARS' factors ...
    if params.get("adrrs_splitting", True):
        assert (factors > 1).any() and session.read("adrrs_splits").max() > 0  # ... and split


def test_unbiased_through_glass_with_black_pixels():
    """Light through glass (NEE fails behind it), a black patch (a zero estimate) and an
    emitter seen directly: finite and unbiased."""
    assert_unbiased(glass_and_degenerate_scene())


def test_same_seed_same_image():
    """The statistics are summed in fixed point, so the order in which paths add their records
    changes nothing: the same seed gives the same image, splits and all."""
    scene = scenes.cornell_box(SIZE, SIZE)
    a, s = render(scene, "mis", spp=24, spp_per_frame=4, seed=3, **EARS)
    b, _ = render(scene, "mis", spp=24, spp_per_frame=4, seed=3, session=s, **EARS)
    assert s.stats()["ears_cells_with_factors"] > 0
    assert same_render(a, b, s.device_type)
    assert s.read("adrrs_splits").max() > 0


def test_max_splits_bounds_the_copies():
    """Every pixel sample splits off at most adrrs_max_splits copies, whatever EARS asks for."""
    scene = scenes.cornell_box(SIZE, SIZE)
    _, s = render(scene, "mis", spp=32, spp_per_frame=4, **EARS, adrrs_max_splits=1)
    splits = s.read("adrrs_splits")[..., 0]
    assert splits.max() <= 1.0 + 1e-6 and splits.max() > 0


def test_passes_show_the_factors_and_costs():
    scene = scenes.cornell_box(SIZE, SIZE)
    s = pc.Session(SIZE, SIZE)
    s.update(scene)
    s.passes = ["combined", "rrs_factor", "rrs_cost"]
    render(scene, "mis", spp=32, spp_per_frame=4, session=s, **EARS)
    factor, cost = s.read("rrs_factor")[..., 0], s.read("rrs_cost")[..., 0]
    assert np.isfinite(factor).all() and np.isfinite(cost).all()
    assert factor.max() > 0 and cost.max() > 0
    # A continuation costs a few rays against the whole sample's: the relative cost stays near 1.
    assert 0.1 < np.median(cost[cost > 0]) < 2.0


def test_switching_off_and_camera_edits_start_over():
    scene = scenes.cornell_box(SIZE, SIZE)
    _, s = render(scene, "mis", spp=32, spp_per_frame=4, **EARS)
    assert s.stats()["ears_iterations"] > 0
    s.update(scene, parts={"camera"})  # the pixel estimate is per pixel: EARS learns again
    s.render(1)
    assert s.stats()["ears_iterations"] == 0
    s.set_params(rrs="off")
    assert "ears_iterations" not in s.stats()
