"""The consistent irradiance-cache mode's image (ic_combine, techniques/irradiance_cache.cpp):
the paths' mean B shrunk toward the cache's estimate A by positive-part James-Stein factors,
each fitted on the window around its pixel. Synthetic images with known truth, noise and cache
error, so every claim is checked against the exact answer."""
from __future__ import annotations

import numpy as np
import pytest

import parallax_core as pc

combine = pc._native.ic_combine


def combined(paths, cached):
    """(the combined image, B) for per-sample path values `paths` (n, H, W, 3) and the cache's
    estimate `cached` (H, W, 3), as the film holds them: Combined's mean and count, and the sums
    of A - B and |A - B|^2 (the IC Residual pass)."""
    n = paths.shape[0]
    b = paths.mean(0)
    rgba = np.concatenate([b, np.ones_like(b[..., :1])], -1).astype(np.float32)
    d = cached[None] - paths
    residual = np.concatenate([d.sum(0), (d ** 2).sum(-1).sum(0)[..., None]], -1).astype(np.float32)
    out = combine(rgba, np.full(b.shape[:2], n, np.float32), residual)
    np.testing.assert_array_equal(out[..., 3], 1.0)  # alpha untouched
    return out[..., :3], b


def smooth_image(rng, h=48, w=64):
    y, x = np.mgrid[0:h, 0:w] / 16.0
    base = 1.0 + 0.5 * np.sin(x)[..., None] * np.cos(y)[..., None] * np.array([1.0, 0.7, 0.4])
    return base + 0.05 * rng.random((h, w, 3))


def test_without_cache_hits_the_image_is_the_paths():
    """Pixels whose paths met no entry have a zero residual: their image is the paths'."""
    rng = np.random.default_rng(1)
    rgba = rng.random((24, 32, 4)).astype(np.float32)
    out = combine(rgba, np.full((24, 32), 8, np.float32), np.zeros((24, 32, 4), np.float32))
    np.testing.assert_array_equal(out, rgba)


@pytest.mark.parametrize("samples", [1, 3])
def test_few_samples_show_the_cache(samples):
    """Before 4 samples the paths' variance is not trusted (heavy tails): the cache's estimate,
    as the thesis mode would show it."""
    rng = np.random.default_rng(2)
    truth = smooth_image(rng)
    cached = truth * 1.05
    out, _ = combined(truth + rng.normal(0.0, 0.3, (samples,) + truth.shape), cached)
    np.testing.assert_allclose(out, cached, rtol=1e-5, atol=1e-5)


def test_noiseless_paths_win_over_a_wrong_cache():
    rng = np.random.default_rng(3)
    truth = smooth_image(rng)
    out, b = combined(np.repeat(truth[None], 4, 0), truth * 1.1)
    np.testing.assert_allclose(out, truth, rtol=1e-5)


@pytest.mark.parametrize("samples", [4, 64])
def test_never_worse_than_the_paths(samples):
    """James and Stein's dominance: whatever the cache's error, the combined image's squared
    error is no larger than the paths' own (within the spread of this one draw), and a good
    cache takes most of the paths' noise away. A biased cache's share shrinks as samples
    grow (the image is consistent)."""
    rng = np.random.default_rng(4 + samples)
    truth = smooth_image(rng)
    sigma = 0.8
    paths = truth + rng.normal(0.0, sigma, (samples,) + truth.shape)
    mse_paths = float(((paths.mean(0) - truth) ** 2).mean())
    ratios = {}
    for error in (0.0, 0.02, 0.1, 0.3, 1.0):
        out, _ = combined(paths, truth * (1.0 + error))
        ratios[error] = float(((out - truth) ** 2).mean()) / mse_paths
    print(f"{samples} samples: MSE / the paths' {ratios}")
    assert max(ratios.values()) < 1.05, ratios
    assert ratios[0.0] < 0.1 and ratios[0.02] < 0.5, ratios


def test_the_cache_error_left_in_the_image_shrinks_with_samples():
    rng = np.random.default_rng(5)
    truth = smooth_image(rng)
    left = []
    for samples in (4, 64, 1024):
        paths = truth + rng.normal(0.0, 0.8, (samples,) + truth.shape)
        out, b = combined(paths, truth * 1.1)
        # The mean error of the image is what is left of the cache's +10 % (the paths' noise
        # averages out over the image).
        left.append(float((out - truth).mean() / (0.1 * truth.mean())))
    # In theory V / (b^2 + V), V the paths' variance of the mean: 0.94, 0.5, 0.06 here.
    print("share of the cache's error left:", left)
    assert left[0] > 0.8 and left[1] < 0.6 * left[0] and left[2] < 0.2 * left[1], left


def test_mismatched_sizes_are_rejected():
    with pytest.raises(ValueError, match="differ in size"):
        combine(np.zeros((4, 4, 4), np.float32), np.zeros((4, 5), np.float32), np.zeros((4, 4, 4), np.float32))


def stratified_paths(rng, truth, n, sigma):
    """n samples per pixel whose mean converges faster than 1/n, as Owen-scrambled Sobol
    points' do: each half is one uniform per stratum of n/2, shuffled (the truth + sigma (u -
    1/2)). Their mean's error is ~ sigma n^-1.5, where Var/n says sigma^2 / (12 n)."""
    half = n // 2
    parts = []
    for _ in range(2):
        u = (np.arange(half)[:, None, None, None] + rng.random((half,) + truth.shape)) / half
        parts.append(rng.permuted(u, axis=0))
    return truth + sigma * (np.concatenate(parts) - 0.5)


def snapshot(paths, cached):
    """IC Residual's sums as a snapshot holds them: rgb the sums of A - B, w the sample count."""
    d = (cached[None] - paths).sum(0)
    return np.concatenate([d, np.full(d.shape[:2] + (1,), paths.shape[0])], -1).astype(np.float32)


def test_sequence_variance_of_independent_samples():
    """ic_sequence_variance from snapshots at n_a and n_b: n_b Var(mean of n_b), summed over
    rgb; for independent samples of variance sigma^2 per channel, 3 sigma^2 on average over
    pixels, and negative (unknown) while a part has fewer than 4 samples."""
    rng = np.random.default_rng(7)
    truth = smooth_image(rng)
    paths = truth + rng.normal(0.0, 0.5, (24,) + truth.shape)
    measured = pc._native.ic_sequence_variance(snapshot(paths[:8], truth), snapshot(paths, truth))
    assert measured.shape == truth.shape[:2]
    assert abs(measured.mean() / (3 * 0.25) - 1) < 0.1, measured.mean()
    early = pc._native.ic_sequence_variance(snapshot(paths[:3], truth), snapshot(paths[:8], truth))
    assert (early < 0).all()


def test_sequence_variance_lets_a_faster_sequence_leave_the_cache():
    """With samples whose mean converges faster than 1/n, Var/n overestimates the paths' error,
    and a cache 2 % off keeps its share of the image: worse than the paths alone. The measured
    sequence variance (halves of the samples) sees the real error: the image is then no worse
    than the paths, and a right cache still helps."""
    rng = np.random.default_rng(8)
    truth = smooth_image(rng)
    n = 64
    paths = stratified_paths(rng, truth, n, 2.0)
    mse_paths = float(((paths.mean(0) - truth) ** 2).mean())
    ratios = {}
    for error in (0.0, 0.02):
        cached = truth * (1.0 + error)
        _, b = combined(paths, cached)
        variance = pc._native.ic_sequence_variance(snapshot(paths[: n // 2], cached), snapshot(paths, cached))
        rgba = np.concatenate([b, np.ones_like(b[..., :1])], -1).astype(np.float32)
        d = cached[None] - paths
        residual = np.concatenate([d.sum(0), (d ** 2).sum(-1).sum(0)[..., None]], -1).astype(np.float32)
        samples = np.full(b.shape[:2], n, np.float32)
        for label, extra in (("Var/n", None), ("halves", variance)):
            out = combine(rgba, samples, residual, extra)[..., :3]
            ratios[label, error] = float(((out - truth) ** 2).mean()) / mse_paths
    print(f"MSE / the paths': {ratios}")
    assert ratios["Var/n", 0.02] > 1.5, ratios  # the case this fixes
    assert ratios["halves", 0.02] < 1.1, ratios
    assert ratios["halves", 0.0] < 0.5, ratios


def test_sequence_variance_must_match_the_image():
    with pytest.raises(ValueError, match="differ in size"):
        combine(np.zeros((4, 4, 4), np.float32), np.zeros((4, 4), np.float32), np.zeros((4, 4, 4), np.float32),
                np.zeros((4, 5), np.float32))


def test_pixels_the_cache_cannot_help_go_back_to_the_paths():
    """ic_hand_over: where the residual's variance (what a perfect cache could take away) is a
    small share of the paths' own over the window, the pixel stops asking the cache for good;
    where it is most of it, or unknown, the pixel keeps the cache. ic_combine then shows B there
    and leaves it out of its neighbours' factors."""
    h, w = 24, 64
    paths = np.full((h, w), 1.0, np.float32)
    residual = np.full((h, w), 0.9, np.float32)
    residual[:, :24] = 0.01  # direct light dominates: the cache cannot pay for itself
    residual[:, 56:] = -1.0  # unknown yet (too few samples)
    means = np.full((h, w), 0.5, np.float32)
    flags = pc._native.ic_hand_over(np.zeros((h, w), np.uint32), residual, paths, means)
    assert flags.dtype == np.uint32 and flags.shape == (h, w)
    assert (flags[:, :16] == 1).all() and (flags[:, 32:] == 0).all()
    # Flags stay set, whatever the next snapshot says.
    again = pc._native.ic_hand_over(flags, np.full((h, w), 0.9, np.float32), paths, means)
    np.testing.assert_array_equal(again, flags)
    # Handed-over pixels show the paths' mean B, the others may lean on the cache.
    rng = np.random.default_rng(9)
    truth = smooth_image(rng, h, w)
    samples = truth + rng.normal(0.0, 0.8, (8,) + truth.shape)
    b = samples.mean(0)
    d = truth[None] * 1.01 - samples
    rgba = np.concatenate([b, np.ones_like(b[..., :1])], -1).astype(np.float32)
    sums = np.concatenate([d.sum(0), (d ** 2).sum(-1).sum(0)[..., None]], -1).astype(np.float32)
    out = combine(rgba, np.full((h, w), 8, np.float32), sums, None, flags)
    np.testing.assert_array_equal(out[flags == 1], rgba[flags == 1])
    assert np.abs(out[flags == 0] - rgba[flags == 0]).max() > 0.01
