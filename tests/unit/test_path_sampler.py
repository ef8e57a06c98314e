"""The path sampler (shaders/lib/rng.glsl, run through shaders/tests/sampling_test.comp): the
samples of one pixel form a randomised (0,m,2)-net in every slot, also for any aligned block
of 2^m samples (frames continue the sequence); slots are independent of each other, and a
slot's points are uniform over pixels. DESIGN "Tests", tier 1."""
import numpy as np
import pytest

import parallax_core as pc
from parallax_core import scenes

from test_sampling_chi2 import ALPHA, chi2_pooled

TEST_RNG = 12  # shaders/shared/types.h


@pytest.fixture(scope="module")
def session():
    s = pc.Session(8, 8)
    s.update(scenes.cornell_box(8, 8))
    return s


def draws(session, n, pixel=0, slot=0, stream=0):
    """(n, 6): rnd2 and rnd of slots slot, slot + 1, then of slots slot + 2, slot + 3, for
    samples 0 .. n - 1 of the pixel."""
    r = session.test_sampling(TEST_RNG, [float(pixel), 0.0, 0.0, 0.0, float(slot)], n, seed=stream)
    return np.concatenate([r[:, 0, :3], r[:, 1, :3]], axis=1).astype(np.float64)


def assert_net(points, m):
    """Every elementary interval of area 2^-m (2^a x 2^(m-a) cells) holds exactly one point."""
    for a in range(m + 1):
        ix = np.floor(points[:, 0] * 2**a).astype(np.int64)
        iy = np.floor(points[:, 1] * 2 ** (m - a)).astype(np.int64)
        counts = np.bincount(ix * 2 ** (m - a) + iy, minlength=2**m)
        assert counts.min() == 1 and counts.max() == 1, f"cells {2**a} x {2**(m - a)}: counts {counts.min()}..{counts.max()}"


@pytest.mark.parametrize("pixel,slot", [(0, 0), (17, 3), (12345, 10)])
def test_each_slot_is_a_net_over_the_pixels_samples(session, pixel, slot):
    m = 10
    d = draws(session, 4 * 2**m, pixel=pixel, slot=slot)
    assert np.all((d >= 0.0) & (d < 1.0))
    for block in range(4):  # samples [k 2^m, (k+1) 2^m): the frames after the first too
        b = d[block * 2**m:(block + 1) * 2**m]
        assert_net(b[:, 0:2], m)  # 2D slot
        assert_net(b[:, 3:5], m)
        for col in (2, 5):  # 1D slots: one point per interval of 2^-m
            assert np.array_equal(np.sort(np.floor(b[:, col] * 2**m)), np.arange(2**m))


def test_slots_are_independent(session):
    # Two slots of the same samples, jointly: a net in each does not make them a net together,
    # but they must look independent (the same shuffle would put them on a curve).
    d = draws(session, 2**16, pixel=7)
    for a, b in ((0, 2), (0, 3), (1, 4), (2, 5), (0, 1)):
        h, _, _ = np.histogram2d(d[:, a], d[:, b], bins=16, range=[[0, 1], [0, 1]])
        expected = np.full(h.shape, d.shape[0] / h.size)
        if (a, b) == (0, 1):  # one 2D slot: a (0,16,2)-net, far more even than random
            assert np.abs(h - expected).max() <= 16
            continue
        _, _, p = chi2_pooled(h, expected)
        assert p > ALPHA, f"slot columns {a} and {b}: p = {p:.2e}"


def test_points_are_uniform_over_pixels_and_streams(session):
    # The first sample of 2048 pixels: each pixel its own scramble, so the points are iid uniform.
    first = np.array([draws(session, 1, pixel=p, stream=3)[0] for p in range(2048)])
    for a, b in ((0, 1), (3, 4)):
        h, _, _ = np.histogram2d(first[:, a], first[:, b], bins=8, range=[[0, 1], [0, 1]])
        _, _, p = chi2_pooled(h, np.full(h.shape, len(first) / h.size))
        assert p > ALPHA, f"columns {a}, {b}: p = {p:.2e}"
    # Another stream (seed, frame kind) of the same pixel gives other points.
    assert not np.allclose(draws(session, 64, pixel=5, stream=3), draws(session, 64, pixel=5, stream=4))
