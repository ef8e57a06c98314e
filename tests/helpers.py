"""Shared helpers for render tests (batched renders with per-pixel error estimates) and for
installing the add-on like a user."""
from __future__ import annotations

import dataclasses
import glob
import hashlib
import os
import shutil
import sys
from typing import NamedTuple

import numpy as np

import parallax_core as pc


# render()'s light paths as CLI --set arguments: a CLI render with them reuses the render
# tier's pipelines instead of compiling variants of its own (CI time).
UNBIASED_LIGHT_PATH_SETS = tuple(arg for name, value in pc.UNBIASED_LIGHT_PATHS.items()
                                 for arg in ("--set", f"{name}={value}"))


def render(scene, method="mis", spp=64, spp_per_frame=None, seed=0, session=None, **params):
    """Render `scene` with `spp` samples; returns (combined rgb, session)."""
    s = session or pc.Session(scene.width, scene.height)
    k = spp_per_frame or min(spp, 64)
    # Every parameter set explicitly: a shared session keeps what earlier tests set. Adaptive
    # sampling off unless a test asks for it: estimators are compared at equal sample counts.
    # Unbiased light paths (no kind budget, no clamp, a one-pixel box) unless a test asks.
    defaults = {**dataclasses.asdict(pc.RenderParams()), "use_adaptive_sampling": False, **pc.UNBIASED_LIGHT_PATHS}
    s.set_params(**{**defaults, "method": method, "samples_per_frame": k, "seed": seed, **params})
    if session is None:
        s.update(scene)
    s.reset()
    s.render(max(1, spp // k))
    return s.read("combined")[..., :3], s


class Batches(NamedTuple):
    """batches()'s result."""
    mean: np.ndarray  # (h, w, 3): the mean image
    se: np.ndarray  # (h, w, 3): each pixel's standard error, from the batch-to-batch spread
    session: object  # the session that rendered them
    means: np.ndarray  # (n,): each batch's whole-image mean
    images: np.ndarray  # (n, h, w, 3): each batch's image (what z_scores reads)


def own_seed_base(scene, method, spp, params):
    """A seed base of its own for each estimator: derived from the scene, the method, the
    sample count and the settings, so a reference and the method tested against it never
    render with the same seeds (their errors would be correlated, and the test's standard
    error, which assumes independent estimates, wrong). Deterministic: a test gets the same
    seeds whatever ran before it."""
    h = hashlib.sha256(repr((method, spp, sorted(params.items()))).encode())
    for name, array in sorted(scene.flatten().items()):
        h.update(name.encode())
        h.update(np.ascontiguousarray(array).tobytes())
    return int.from_bytes(h.digest()[:4], "little") % (1 << 30)


def batches(scene, method, n_batches=8, spp=64, session=None, stats=None, seed_base=None, **params):
    """n_batches independent renders of `spp` samples each, batch b with seed seed_base + b
    (by default a base of this estimator's own: own_seed_base()). `stats`, a list, gets each
    batch's session stats."""
    base = own_seed_base(scene, method, spp, params) if seed_base is None else seed_base
    images = []
    for b in range(n_batches):
        img, session = render(scene, method, spp, seed=base + b, session=session, **params)
        images.append(img)
        if stats is not None:
            stats.append(session.stats())
    stack = np.stack(images)
    return Batches(stack.mean(0), stack.std(0, ddof=1) / np.sqrt(n_batches), session, stack.mean(axis=(1, 2, 3)),
                   stack)


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
    """Average over k x k pixel blocks of an (..., h, w, c) image or stack of images."""
    *lead, h, w, c = img.shape
    img = img[..., : h // k * k, : w // k * k, :]
    return img.reshape(*lead, h // k, k, w // k, k, c).mean(axis=(-4, -2))


def z_scores(images_a, images_b, k=4):
    """Per-block z-scores of the difference of two estimates, each given by its independent
    batches' images (n, h, w, c), as in Batches.images.

    Each block's standard error comes from the batch-to-batch spread of that block's mean:
    se_a^2 = var_b(block mean of batch b) / n_a, likewise se_b, and t = (a - b) / sqrt(se_a^2 +
    se_b^2), Welch's t with nu = (se_a^2 + se_b^2)^2 / (se_a^4 / (n_a - 1) + se_b^4 / (n_b - 1))
    degrees of freedom (Welch-Satterthwaite). (Averaging the pixels' own errors instead, as
    before, overstates a k x k block's error about k times: its pixels are nearly independent.)
    With few batches t has heavy tails, so it is mapped to the normal deviate of the same tail
    probability (Wallace 1959, within 2% for nu >= 3): z = (8 nu + 1) / (8 nu + 3) *
    sqrt(nu * ln(1 + t^2 / nu)). A threshold on |z| then means what it means for a normal
    deviate, whatever the number of batches."""
    a, b = block(np.asarray(images_a), k), block(np.asarray(images_b), k)
    na, nb = len(a), len(b)
    if na < 2 or nb < 2:
        raise ValueError("z_scores needs at least 2 batches of each estimate")
    ma, mb = a.mean(0), b.mean(0)
    va, vb = a.var(0, ddof=1) / na, b.var(0, ddof=1) / nb
    se = np.sqrt(va + vb) + 1e-6 * (np.abs(ma) + np.abs(mb)) + 1e-9  # noiseless blocks: no 0/0
    t = (ma - mb) / se
    with np.errstate(invalid="ignore", divide="ignore"):
        nu = (va + vb) ** 2 / (va**2 / (na - 1) + vb**2 / (nb - 1))
    nu = np.where(np.isfinite(nu), nu, na + nb - 2)
    return np.sign(t) * (8 * nu + 1) / (8 * nu + 3) * np.sqrt(nu * np.log1p(t * t / nu))


def rel_mse(img, ref, drop=0.001):
    """relMSE of Ruppert et al. 2020 (as in the thesis): mean of (x-r)^2/(r^2+0.001) over pixels
    and channels with the largest `drop` fraction removed."""
    e = ((img - ref) ** 2 / (ref**2 + 1e-3)).mean(axis=-1).ravel()
    keep = int(np.ceil(e.size * (1 - drop)))
    return float(np.sort(e)[:keep].mean())


def oidn_wheel(out_dir):
    """pyoidn's wheel, packed from this venv's install as `make extension` packs it."""
    repo = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    sys.path.insert(0, os.path.join(repo, "scripts"))
    try:
        from wheel_from_installed import wheel_from_installed
    finally:
        sys.path.pop(0)
    return wheel_from_installed("pyoidn", out_dir)


def install_addon_copy(folder, wheel):
    """addon/ copied to folder/parallax with the core wheel and pyoidn's bundled (as
    blender_manifest.toml lists them), as a user installs it."""
    addon = os.path.join(folder, "parallax")
    repo = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    shutil.copytree(os.path.join(repo, "addon"), addon,
                    ignore=shutil.ignore_patterns("__pycache__", "wheels", "_site"))
    os.makedirs(os.path.join(addon, "wheels"))
    shutil.copy(wheel, os.path.join(addon, "wheels"))
    oidn = os.path.join(os.path.dirname(wheel), "oidn")  # packed once per wheel folder
    found = glob.glob(os.path.join(oidn, "pyoidn-*.whl")) or [oidn_wheel(oidn)]
    shutil.copy(found[0], os.path.join(addon, "wheels"))
    return addon
