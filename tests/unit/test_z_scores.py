"""The render tier's referee (tests/helpers.py z_scores, batches' seeds) on synthetic batches
with a known answer: no false alarms beyond the normal rate with few batches, a block's error
taken from its own mean's spread (not k times too large), and independent seeds per estimator.
tests/render/test_referee_power.py checks the same on real renders."""
from __future__ import annotations

import math

import numpy as np
import pytest

from parallax_core import scenes

from helpers import block, own_seed_base, z_scores


def noise(rng, n, size=64, sigma=1.0):
    """n batches of independent per-pixel Gaussian noise around 10 (an image of 3 channels)."""
    return 10.0 + sigma * rng.standard_normal((n, size, size, 3))


def normal_tail(z):
    return math.erfc(z / math.sqrt(2.0))  # P(|Z| > z)


@pytest.mark.parametrize("n", [4, 8, 16])
def test_no_bias_gives_normal_tails(n):
    """Under no bias the mapped scores are beyond a limit no more often than a normal deviate,
    whatever the batch count (a raw Welch t with 8 batches is beyond 3 about 3.5 times as
    often), and not much less often either (a test that could never fail)."""
    rng = np.random.default_rng(n)
    z = np.concatenate([z_scores(noise(rng, n), noise(rng, n), k=4).ravel() for _ in range(40)])
    for limit in (2.0, 3.0):
        rate, expected = (np.abs(z) > limit).mean(), normal_tail(limit)
        # 30720 scores: about 1400 beyond 2 and 83 beyond 3 expected (binomial error 3%, 11%).
        # Few batches make the mapping conservative: 0.7 times the normal rate at n = 4.
        assert 0.6 * expected < rate < 1.3 * expected, (limit, rate, expected)


def test_a_block_error_is_its_mean_spread():
    """A bias of one standard error of a block's difference (pixels of error sigma, k x k of
    them independent: sigma / k per batch) moves the scores by about one. The old referee
    took the mean of the pixels' errors, k times larger, and moved them by 1 / k."""
    rng = np.random.default_rng(1)
    n, k, sigma = 16, 4, 1.0
    block_se = sigma / k * math.sqrt(2.0 / n)  # of the difference of two n-batch estimates
    z = z_scores(noise(rng, n) + block_se, noise(rng, n), k=k)
    assert 0.85 < np.median(z) < 1.15, np.median(z)


def test_a_small_bias_in_a_quarter_fails_and_none_passes():
    """A 2% bias in one quarter of 8 batches of 64x64 pixels with 5% noise each: 13 standard
    errors of the difference of a 16x16 block's means (0.8 in the old referee)."""
    rng = np.random.default_rng(2)
    n = 8
    a, b = noise(rng, n, sigma=0.5), noise(rng, n, sigma=0.5)
    assert np.abs(z_scores(a, b, k=16)).max() < 5.0
    assert np.abs(z_scores(a, b, k=4)).max() < 5.0
    a[:, :32, :32] *= 1.02
    z = np.abs(z_scores(a, b, k=16)).max(-1)  # 4x4 blocks, the biased quarter's are [:2, :2]
    assert z[:2, :2].max() > 5.0, z
    z[:2, :2] = 0.0
    assert z.max() < 5.0, z


def test_block_keeps_the_batch_axis():
    stack = np.arange(2 * 4 * 4 * 3, dtype=float).reshape(2, 4, 4, 3)
    np.testing.assert_array_equal(block(stack, 2)[1], block(stack[1], 2))
    with pytest.raises(ValueError, match="2 batches"):
        z_scores(stack[:1], stack, k=2)


def test_estimators_get_their_own_seeds():
    """Reference and tested method differ in method, settings or scene: their seeds differ;
    the same estimator gets the same seeds in any run."""
    box, furnace = scenes.cornell_box(8, 8), scenes.furnace_sphere(0.5, 8, 8)
    base = own_seed_base(box, "mis", 64, {"rr_start_depth": 0})
    assert base == own_seed_base(scenes.cornell_box(8, 8), "mis", 64, {"rr_start_depth": 0})
    others = {own_seed_base(box, "pt", 64, {"rr_start_depth": 0}),
              own_seed_base(box, "mis", 64, {"rr_start_depth": 0, "rrs": "adrrs"}),
              own_seed_base(box, "mis", 32, {"rr_start_depth": 0}),
              own_seed_base(furnace, "mis", 64, {"rr_start_depth": 0})}
    assert len(others) == 4 and base not in others
