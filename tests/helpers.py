"""Shared helpers for render tests (batched renders with per-pixel error estimates) and for
installing the add-on like a user."""
from __future__ import annotations

import dataclasses
import os
import shutil

import numpy as np

import parallax_core as pc


def render(scene, method="mis", spp=64, spp_per_frame=None, seed=0, session=None, **params):
    """Render `scene` with `spp` samples; returns (combined rgb, session)."""
    s = session or pc.Session(scene.width, scene.height)
    k = spp_per_frame or min(spp, 64)
    # Every parameter set explicitly: a shared session keeps what earlier tests set.
    defaults = dataclasses.asdict(pc.RenderParams())
    s.set_params(**{**defaults, "method": method, "samples_per_frame": k, "seed": seed, **params})
    if session is None:
        s.update(scene)
    s.reset()
    s.render(max(1, spp // k))
    return s.read("combined")[..., :3], s


def batches(scene, method, n_batches=8, spp=64, session=None, stats=None, **params):
    """From n_batches independent renders (seeds differ): the mean image, its per-pixel
    standard error, the session, and each batch's whole-image mean. `stats`, a list, gets
    each batch's session stats."""
    images = []
    for b in range(n_batches):
        img, session = render(scene, method, spp, seed=1000 + b, session=session, **params)
        images.append(img)
        if stats is not None:
            stats.append(session.stats())
    stack = np.stack(images)
    return stack.mean(0), stack.std(0, ddof=1) / np.sqrt(n_batches), session, stack.mean(axis=(1, 2, 3))


def means_agree(batch_means_a, batch_means_b, sigmas=5.0):
    """Whether two estimates of a whole-image mean agree within `sigmas` standard errors
    (each error from its batch-to-batch spread)."""
    a, b = np.asarray(batch_means_a), np.asarray(batch_means_b)
    se = np.hypot(a.std(ddof=1) / np.sqrt(a.size), b.std(ddof=1) / np.sqrt(b.size))
    return abs(a.mean() - b.mean()) <= sigmas * se, a.mean(), b.mean(), se


def same_render(a, b, device_type):
    """Images of the same scene, seed and settings from two sessions: bit for bit on lavapipe.
    NVIDIA's BVH builder may order a fresh tree differently, so a ray through a shared edge can
    report the other triangle and change the last bits of a pixel."""
    if device_type == "cpu":
        return np.array_equal(a, b)
    return np.allclose(a, b, rtol=1e-4, atol=1e-6)


def block(img, k):
    """Average over k x k pixel blocks."""
    h, w, c = img.shape
    return img[: h // k * k, : w // k * k].reshape(h // k, k, w // k, k, c).mean(axis=(1, 3))


def z_scores(mean_a, se_a, mean_b, se_b, k=4):
    """Per-block z-scores of the difference of two batch-estimated images. The standard error
    of a block mean is estimated from the block-averaged batch errors (conservatively, as if
    pixels were fully correlated: se of a mean <= mean of se)."""
    a, b = block(mean_a, k), block(mean_b, k)
    sa, sb = block(se_a, k), block(se_b, k)
    denom = np.sqrt(sa**2 + sb**2) + 1e-6 * (np.abs(a) + np.abs(b)) + 1e-9
    return (a - b) / denom


def rel_mse(img, ref, drop=0.001):
    """relMSE of Ruppert et al. 2020 (as in the thesis): mean of (x-r)^2/(r^2+0.001) over pixels
    and channels with the largest `drop` fraction removed."""
    e = ((img - ref) ** 2 / (ref**2 + 1e-3)).mean(axis=-1).ravel()
    keep = int(np.ceil(e.size * (1 - drop)))
    return float(np.sort(e)[:keep].mean())


def install_addon_copy(folder, wheel):
    """addon/ copied to folder/parallax with the core wheel bundled, as a user installs it."""
    addon = os.path.join(folder, "parallax")
    repo = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    shutil.copytree(os.path.join(repo, "addon"), addon,
                    ignore=shutil.ignore_patterns("__pycache__", "wheels", "_site"))
    os.makedirs(os.path.join(addon, "wheels"))
    shutil.copy(wheel, os.path.join(addon, "wheels"))
    return addon
