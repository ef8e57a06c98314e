"""Irradiance cache (thesis 3.2.3, 4.4): an analytic furnace, its bias against converged MIS on
the Cornell box and the thesis' own scene, gradients, the visibility check at a concave corner,
capacity overflow, determinism, resets on edits, the passes and the settings' validation."""
from __future__ import annotations

import os
import sys

import numpy as np
import pytest

import parallax_core as pc
from parallax_core import scenes
from parallax_core.scene import Camera, Light, Material, SceneData, World

from helpers import block, render, same_render

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__)))))
from bench import shared_scenes  # noqa: E402

# Small images fill the cache quickly only with a higher creation probability than the default.
# The thesis' mode (paths end at the cache) unless a test says otherwise.
FAST_IC = dict(ic=True, ic_mode="thesis", ic_prepare_frames=12, ic_create_prob=0.05)
CONSISTENT_IC = {**FAST_IC, "ic_mode": "consistent"}
# Tests with sessions of their own set helpers.render's light paths (pc.UNBIASED_LIGHT_PATHS) too,
# so the file compiles one cache pipeline, not a second for the default (Cycles') light paths.


def block_rel_mse(img, ref, k=8):
    """relMSE (Ruppert et al. 2020) of k x k block means: the bias, with most noise averaged."""
    b, r = block(img, k), block(ref, k)
    return float(((b - r) ** 2 / (r ** 2 + 1e-3)).mean())


def closed_sphere(albedo=0.5, emission=1.0, size=24):
    """The camera inside a closed sphere whose inside is diffuse `albedo` and emits `emission`:
    every pixel converges to emission / (1 - albedo)."""
    mesh = scenes.uv_sphere((0.0, 0.0, 0.0), 2.0, 32, 16, 0, "sphere")
    mat = Material("diffuse", (albedo,) * 3, emission=(emission,) * 3, name="furnace")
    camera = Camera.look_at((0.0, 0.0, 0.0), (0.0, 1.0, 0.0), fov_y_degrees=70.0, width=size, height=size)
    return SceneData([mesh], [], [mat], [], [], World((0.0, 0.0, 0.0), 1.0), camera, size, size)


def test_furnace_sphere_gives_the_analytic_answer():
    sc = closed_sphere()
    img, s = render(sc, "mis", spp=64, spp_per_frame=16, max_depth=64, **FAST_IC)
    st = s.stats()
    assert st["ic_entries"] > 0
    # Every visible point was shaded from the cache (first diffuse vertex found entries).
    assert np.all(s.read("ic_irradiance")[..., :3] > 0.0)
    assert abs(img.mean() / 2.0 - 1.0) < 0.01, img.mean()


def cornell_light_at_ceiling(size=64):
    """The Cornell box with its light 1 mm (not 2 cm) below the ceiling. Our light emits from
    both sides (Cycles' mesh emission), so 2 cm below the ceiling it floods the gap above it
    with light as bright as the light itself, which the rest of the room sees only through a
    2 cm slit: about a tenth of the light's power arrives through rays that hit that slit by
    rare chance. A cache entry's 200 hemisphere rays cannot resolve that heavy tail, and the
    mean of an IC render of the original box moves by a few per cent with the seed (measured:
    -3.5 % to +2.4 %). At 1 mm the slit carries about 0.5 % of the power."""
    sc = scenes.cornell_box(size, size)
    light = sc.meshes[-1]
    light.positions = np.array(light.positions, dtype=np.float64)
    light.positions[:, 2] = 1.999
    return sc


@pytest.fixture(scope="module")
def bias_scenes():
    """(name, scene, converged MIS image) for the bias tests."""
    cases = [("cornell_box", cornell_light_at_ceiling())]
    if shared_scenes.available("thesis_irradianceCache"):
        cases.append(("thesis_irradianceCache", shared_scenes.thesis_irradiance_cache(96, 54)))
    else:
        print(f"note: {shared_scenes.SHARED_SCENES} lacks thesis_irradianceCache: Cornell box only")
    return [(name, sc, render(sc, "mis", spp=512, spp_per_frame=32, seed=7)[0]) for name, sc in cases]


def test_bias_is_bounded(bias_scenes):
    """Converged IC against converged MIS: block relMSE < 0.01 and the mean within 2 %."""
    for name, scene, ref in bias_scenes:
        img, _ = render(scene, "mis", spp=128, spp_per_frame=16, **FAST_IC)
        err, mean_bias = block_rel_mse(img, ref), img.mean() / ref.mean() - 1.0
        print(f"{name}: block relMSE {err:.5f}, mean {mean_bias:+.4f}")
        assert np.isfinite(img).all()
        assert err < 0.01, (name, err)
        assert abs(mean_bias) < 0.02, (name, mean_bias)


def test_consistent_mode_converges(bias_scenes):
    """ic_mode consistent (the default): paths go on past the cache and the image leans on the
    cache's estimate only while the paths are noisier than the cache is wrong (ic_combine). So
    the cache's error left in the image shrinks with samples, where the thesis mode's stays
    (block means: the bias with most noise averaged; measured on the Cornell box 0.00034 ->
    0.00006 from 32 to 1024 spp, the thesis mode 0.00039 -> 0.00017), and at equal samples
    the image is never worse than MIS' per pixel (measured 0.49x at 32 spp, 0.92x at 1024)."""
    name, scene, ref = bias_scenes[0]

    def rel_mse(img):
        return float(((img - ref) ** 2 / (ref ** 2 + 1e-3)).mean())

    block, pixel = {}, {}
    for label, params in (("thesis", FAST_IC), ("consistent", CONSISTENT_IC), ("mis", {})):
        for spp in (32, 1024):
            img, _ = render(scene, "mis", spp=spp, spp_per_frame=32, seed=1, **params)
            block[label, spp], pixel[label, spp] = block_rel_mse(img, ref), rel_mse(img)
    print(f"{name}: block relMSE {block}\nper-pixel relMSE {pixel}")
    assert block["consistent", 1024] < 0.25 * block["consistent", 32], block
    assert block["consistent", 1024] < 0.5 * block["thesis", 1024], block
    assert pixel["consistent", 32] < 0.7 * pixel["mis", 32], pixel
    assert pixel["consistent", 1024] < 1.05 * pixel["mis", 1024], pixel


def test_gradients_reduce_the_error(bias_scenes):
    """Ward & Heckbert's gradients extrapolate each entry to the query point: with large
    entries (accuracy 0.5), where interpolation error dominates, they lower the block error
    (measured: by about half on the Cornell box)."""
    name, scene, ref = bias_scenes[0]
    errors = {}
    for gradients in (False, True):
        img, _ = render(scene, "mis", spp=128, spp_per_frame=16, ic_gradients=gradients,
                        **{**FAST_IC, "ic_accuracy": 0.5})
        errors[gradients] = block_rel_mse(img, ref)
    print(f"{name}: block relMSE without / with gradients {errors}")
    assert errors[True] < 0.8 * errors[False], errors


def table_scene(size=64):
    """The concave space under a table: a floor, a slab 0.35 m above it and a white ceiling
    lit by an upward-facing area light, so everything is lit indirectly from above. The slab's
    top sees the bright ceiling; the floor under it sees the slab's dark underside. Entries on
    the slab's top lie 'in front of' floor points beneath it (Ward's d_i < 0): without the
    visibility check their large radius lets that irradiance leak onto the floor below."""
    mats = [Material("diffuse", (0.8, 0.8, 0.8), name="white")]
    meshes = [
        scenes.quad([(-4, -4, 0), (4, -4, 0), (4, 4, 0), (-4, 4, 0)], 0, "floor"),
        scenes.quad([(-4, -4, 2), (-4, 4, 2), (4, 4, 2), (4, -4, 2)], 0, "ceiling"),
        scenes.box((0.0, 0.0, 0.375), (1.4, 1.4, 0.05), 0.0, 0, "table"),
    ]
    light = Light("area", power=600.0, position=(2.5, 2.5, 1.0), direction=(0.0, 0.0, 1.0), size=1.0)
    camera = Camera.look_at((0.0, -4.5, 0.6), (0.0, 0.0, 0.25), fov_y_degrees=22.0, width=size, height=size)
    return SceneData(meshes, [], mats, [], [light], World((0.0, 0.0, 0.0), 1.0), camera, size, size)


def test_visibility_check_reduces_leaking_at_a_concave_corner():
    sc = table_scene()
    ref, _ = render(sc, "mis", spp=256, spp_per_frame=32, seed=3)
    errors = {}
    for check in (False, True):
        img, _ = render(sc, "mis", spp=64, spp_per_frame=16, ic_accuracy=0.6, ic_visibility_check=check, **FAST_IC)
        errors[check] = block_rel_mse(img, ref, 4)
    print("block relMSE without / with the visibility check:", errors)
    assert errors[True] < 0.6 * errors[False], errors  # measured 0.36-0.42 over three seeds


def test_capacity_overflow_is_counted_and_harmless():
    sc = scenes.cornell_box(32, 32)
    img, s = render(sc, "mis", spp=8, spp_per_frame=4, ic=True, ic_capacity=10, ic_prepare_frames=4,
                    ic_create_prob=0.2)
    st = s.stats()
    assert st["ic_entries"] == 10 and st["ic_capacity"] == 10
    assert st["ic_dropped"] > 0
    assert np.isfinite(img).all() and img.mean() > 0.0
    for name in ("ic_irradiance", "ic_gradients"):
        assert np.isfinite(s.read(name)).all()


def test_same_seed_same_cache_and_image():
    """Requests are sorted on the host, and the queue has room for every request of a frame
    (here all 2304 paths of the first prepare frame ask), so no thread order decides."""
    sc = scenes.cornell_box(48, 48)
    params = dict(spp=8, spp_per_frame=4, ic_gradients=True, **{**FAST_IC, "ic_create_prob": 1.0})
    a, sa = render(sc, "mis", **params)
    b, sb = render(sc, "mis", **params)
    assert sa.stats()["ic_deferred"] == 0 and sa.stats()["ic_merged"] > 0
    assert sa.stats()["ic_entries"] == sb.stats()["ic_entries"]
    assert same_render(a, b, sa.device_type)
    assert same_render(sa.read("ic_irradiance"), sb.read("ic_irradiance"), sa.device_type)


def test_scene_edit_drops_stale_irradiance():
    """After an edit the cache starts over: the edited session renders exactly what a fresh
    session of the edited scene renders (the viewport never shows stale irradiance)."""
    before, after = scenes.cornell_box(24, 24), scenes.cornell_box(24, 24)
    after.materials[0] = Material("diffuse", (0.2, 0.2, 0.9), name="white")
    params = dict(spp=4, spp_per_frame=4, **FAST_IC)
    _, edited = render(before, "mis", **params)
    edited.update(after, parts={"materials"})
    img_edited, _ = render(after, "mis", session=edited, **params)
    img_fresh, fresh = render(after, "mis", **params)
    assert same_render(img_edited, img_fresh, fresh.device_type)
    assert same_render(edited.read("ic_irradiance"), fresh.read("ic_irradiance"), fresh.device_type)


def test_camera_move_keeps_the_cache():
    """Irradiance does not depend on the view: orbiting keeps the entries (no prepare frames
    again), while any edit of the scene data drops them."""
    sc = scenes.cornell_box(24, 24)
    _, s = render(sc, "mis", spp=4, spp_per_frame=4, **FAST_IC)
    entries = s.stats()["ic_entries"]
    assert entries > 0
    sc.camera = Camera.look_at((0.4, -3.8, 1.2), (0.0, 0.0, 1.0), fov_y_degrees=39.3, width=24, height=24)
    s.update(sc, parts={"camera"})
    assert s.stats()["ic_entries"] == entries and s.samples == 0
    assert s.render_rows(24) is True  # no prepare frame first: this call completes a frame
    s.update(sc, parts={"materials"})
    assert s.stats()["ic_entries"] == 0


def test_passes():
    sc = scenes.cornell_box(32, 32)
    _, s = render(sc, "mis", spp=4, spp_per_frame=4, ic_gradients=True, **FAST_IC)
    irradiance, gradients = s.read("ic_irradiance"), s.read("ic_gradients")
    assert irradiance.shape == (32, 32, 3) and gradients.shape == (32, 32, 3)
    assert (irradiance.sum(-1) > 0).mean() > 0.8  # most first hits are covered by entries
    assert np.all(gradients >= 0.0) and np.all(gradients[..., :2] <= 1.0 + 1e-5)  # |g| / g_max
    assert gradients[..., :2].max() > 0.0 and np.all(gradients[..., 2] == 0.0)
    # Colour highlight (thesis fig. 4.13): the white part removed, so one channel is 0.
    _, h = render(sc, "mis", spp=4, spp_per_frame=4, ic_highlight=True, **FAST_IC)
    highlight = h.read("ic_irradiance")
    assert np.allclose(highlight.min(-1), 0.0, atol=1e-6)
    assert highlight.max() > 0.0
    # Off: the passes stay black.
    _, off = render(sc, "mis", spp=4, spp_per_frame=4)
    assert off.read("ic_irradiance").max() == 0.0 and off.stats()["ic_entries"] == 0


def test_next_frame_finds_new_entries():
    """After a frame that makes entries the lookup grid is built again (ic_grid): the next
    frame's queries find them, and its uncovered points ask for few new ones (a grid left
    unbuilt found none: IC Irradiance 0 everywhere, and every point asked again)."""
    s = pc.Session(32, 32)
    s.set_params(method="mis", ic=True, ic_mode="thesis", ic_prepare_frames=0, ic_create_prob=0.3,
                 samples_per_frame=1, seed=1, **pc.UNBIASED_LIGHT_PATHS)
    s.update(scenes.cornell_box(32, 32))
    s.render(1)
    first = s.stats()["ic_entries"]
    s.render(1)  # queries the first frame's entries
    covered = float((s.read("ic_irradiance").max(axis=-1) > 0).mean())
    print(f"entries after one frame {first}, after two {s.stats()['ic_entries']}; covered {covered:.2f}")
    assert first > 0 and covered > 0.25, (first, covered)
    assert s.stats()["ic_entries"] < 1.6 * first


def test_prepare_frames_fill_before_accumulation():
    """render_rows runs one prepare frame per call (nothing accumulates) until the cache covers
    98% of the first diffuse hits or ic_prepare_frames are done; then frames accumulate."""
    sc = scenes.cornell_box(32, 32)
    s = pc.Session(32, 32)
    s.update(sc)
    for limit in (3, 200):
        s.set_params(samples_per_frame=1, **{**FAST_IC, "ic_prepare_frames": limit, "ic_create_prob": 0.3},
                     **pc.UNBIASED_LIGHT_PATHS)
        calls = 0
        while not s.render_rows(32):
            calls += 1
            assert s.samples == 0 and calls <= limit
        assert s.samples == 1 and s.stats()["ic_entries"] > 0
        if limit == 3:
            assert calls == 3
        else:  # ended early, once covered
            assert calls < limit
            assert (s.read("ic_irradiance").sum(-1) > 0).mean() > 0.85  # the rest: light, edges


def test_radius_and_residual_passes():
    """IC Radius: the validity radius, accuracy * R, of the nearest entry the query read, where
    an entry covers the first diffuse hit (0 elsewhere). IC Residual (consistent mode): the cache's estimate less the
    path's, a = its squared norm, so a >= |rgb|^2 (Jensen) wherever paths met the cache."""
    sc = scenes.cornell_box(32, 32)
    params = dict(spp=8, spp_per_frame=4, **CONSISTENT_IC)
    _, s = render(sc, "mis", **params)
    irradiance, radius, residual = s.read("ic_irradiance"), s.read("ic_radius")[..., 0], s.read("ic_residual")
    covered = irradiance.max(-1) > 0
    assert covered.mean() > 0.8
    bound = 0.2 * 64 * 0.1  # the default a * IC_MAX_RADIUS_FACTOR * the default ic_min_radius
    assert np.all(radius[covered] > 0) and np.all(radius[~covered] == 0) and radius.max() <= bound + 1e-5
    assert np.isfinite(residual).all() and np.abs(residual[covered][:, :3]).max() > 0
    assert np.all(residual[..., 3] >= (residual[..., :3] ** 2).sum(-1) * (1 - 1e-4) - 1e-6)
    _, thesis = render(sc, "mis", **{**params, "ic_mode": "thesis"})
    assert thesis.read("ic_residual").max() == 0.0  # paths end at the cache: nothing to compare


@pytest.mark.parametrize("name,value", [("ic_mode", "bogus"), ("ic_accuracy", 0.0), ("ic_accuracy", 3.0),
                                        ("ic_min_radius", 0.0), ("ic_create_prob", 1.5), ("ic_capacity", 0), ("ic_nee_samples", 0),
                                        ("ic_gradient_max", float("nan"))])
def test_bad_settings_are_rejected(name, value):
    s = pc.Session(4, 4)
    with pytest.raises(ValueError, match=name):
        s.set_params(ic=True, **{name: value})
    assert s.params.ic is False  # nothing changed


def test_consistent_mode_host_steps_wait_longer_each_time():
    """Consistent mode: the host step (creation, refreshes, the lookup grid) waits 1, 2, 4, ...
    up to 16 frames; the requests of the frames in between stay queued for it, so the cache
    and the image are those of a fixed seed (two sessions agree), however the frames are split
    into render() calls."""
    sc = scenes.cornell_box(24, 24)
    params = dict(**{**CONSISTENT_IC, "ic_create_prob": 0.2}, samples_per_frame=1, seed=2, **pc.UNBIASED_LIGHT_PATHS)
    runs = []
    for calls in ((96,), (1,) * 40 + (56,)):
        s = pc.Session(24, 24)
        s.set_params(**params)
        s.update(sc)
        for frames in calls:
            s.render(frames)
        runs.append((s.read("combined"), s.stats()))
    (a, st), (b, st_b) = runs
    print({k: st[k] for k in ("ic_host_steps", "ic_entries", "ic_jobs", "ic_deferred")})
    assert st["ic_host_steps"] < 96 / 4, st["ic_host_steps"]
    assert st["ic_entries"] == st_b["ic_entries"] > 0 and st["ic_deferred"] == 0
    assert st["ic_host_steps"] == st_b["ic_host_steps"]
    assert same_render(a, b, "cpu")


def test_entries_hemisphere_by_mode():
    """Consistent mode's entries rest on 6 x 12 hemisphere rays and refreshes refine them (the
    default update probability); the thesis' mode keeps its 10 x 20 (thesis eq. 3.20)."""
    sc = scenes.cornell_box(24, 24)
    for params, strata in ((CONSISTENT_IC, 6 * 12), (FAST_IC, 10 * 20)):
        s = pc.Session(24, 24)
        s.set_params(**params, samples_per_frame=1, seed=2, **pc.UNBIASED_LIGHT_PATHS)
        s.update(sc)
        s.render(32)
        st = s.stats()
        refreshes = st["ic_jobs"] - st["ic_entries"]  # every other job created an entry
        assert st["ic_entries"] > 0 and refreshes > 0, st
        assert st["ic_job_rays"] == strata * st["ic_jobs"], (params["ic_mode"], st)


def test_consistent_mode_leaves_the_pipeline_where_the_paths_need_no_cache():
    """On Veach's direct-lit scene the pixels go back to the paths at the first handover (8
    spp); once three quarters have, the render frames trace without the cache's pipeline and
    its host steps stop, until the view changes. Every pixel shows the paths' mean, B, which
    is MIS' estimator: with the same seed the image is MIS' (measured equal to 4 digits)."""
    sc = scenes.veach_mis(32, 24)
    s = pc.Session(32, 24)
    s.set_params(**CONSISTENT_IC, samples_per_frame=1, seed=4, **pc.UNBIASED_LIGHT_PATHS)
    s.update(sc)
    s.render(8)
    st = s.stats()
    assert st["ic_left"] == 1 and st["ic_paths_only"] >= 0.75 * 32 * 24, st
    steps = st["ic_host_steps"]
    s.render(24)
    assert s.stats()["ic_host_steps"] == steps
    mis = pc.Session(32, 24)
    mis.set_params(method="mis", samples_per_frame=1, seed=4, **pc.UNBIASED_LIGHT_PATHS)
    mis.update(sc)
    mis.render(32)
    img, ref = s.read("combined")[..., :3], mis.read("combined")[..., :3]
    assert np.isfinite(img).all() and abs(img.mean() / ref.mean() - 1) < 0.01, (img.mean(), ref.mean())
    sc.camera = Camera.look_at((0.0, -1.0, 0.5), (0.0, 0.0, 0.5), fov_y_degrees=40.0, width=32, height=24)
    s.update(sc, parts={"camera"})
    assert s.stats()["ic_left"] == 0
