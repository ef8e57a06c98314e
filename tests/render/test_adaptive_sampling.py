"""Adaptive sampling (issue 36; Cycles' way: a half buffer, the convergence check every 16
samples after the minimum, a 3x3 filter, and only the pixels still sampled traced): it matches
uniform sampling (per-block z-test) with every technique, spends fewer samples where the image
is flat (the Sample Count pass), stops once every pixel converged, and its settings reach the
core and the CLI."""
from __future__ import annotations

import dataclasses

import numpy as np
import pytest

import parallax_core as pc
from parallax_core import scenes
from parallax_core.scene import Camera, Light, Material, SceneData, World

from helpers import UNBIASED_LIGHT_PATH_SETS, batches, means_agree, z_scores

SIZE = 24
# Quick to converge on the sky; the glass' caustic stays hard.
ADAPTIVE = dict(use_adaptive_sampling=True, adaptive_threshold=0.01, adaptive_min_samples=16)


def sky_floor_glass(size=SIZE, world=0.5):
    """A floor under a constant sky (the top rows of the image: flat, converged at the first
    check), lit by a point light through a glass cube (a caustic: hard)."""
    mats = [Material("diffuse", (0.6, 0.6, 0.6), name="floor"),
            Material("dielectric", (1.0, 1.0, 1.0), roughness=0.0, ior=1.5, name="glass")]
    P = lambda *c: np.array(c, dtype=np.float64)
    meshes = [scenes.quad([P(-2, -2, 0), P(2, -2, 0), P(2, 2, 0), P(-2, 2, 0)], 0, "floor"),
              scenes.box((0.0, 0.0, 0.6), 0.8, 0.3, 1, "glass")]
    lights = [Light("point", power=300.0, position=(0.0, 0.0, 3.0))]
    camera = Camera.look_at((0.0, -4.5, 1.5), (0.0, 0.0, 0.6), fov_y_degrees=50.0, width=size, height=size)
    return SceneData(meshes, [], mats, [], lights, World((world,) * 3, 1.0), camera, size, size)


@pytest.fixture(scope="module")
def scene():
    return sky_floor_glass()


@pytest.fixture(scope="module")
def reference(scene):
    return batches(scene, "mis", 8, 128, spp_per_frame=16)


def adaptive_session(scene, spp_per_frame=16, **params):
    s = pc.Session(scene.width, scene.height, "cpu")
    s.set_params(**{**pc.UNBIASED_LIGHT_PATHS, **ADAPTIVE, "samples_per_frame": spp_per_frame, **params})
    s.update(scene)
    return s


def test_the_settings_and_the_pass_are_cycles():
    rows = {r.name: r for r in pc.SETTINGS}
    assert rows["use_adaptive_sampling"].default is True and rows["use_adaptive_sampling"].core
    assert rows["adaptive_threshold"].default == pytest.approx(0.01) and rows["adaptive_min_samples"].default == 0
    assert rows["use_preview_adaptive_sampling"].default is True and not rows["use_preview_adaptive_sampling"].core
    assert rows["preview_adaptive_threshold"].default == pytest.approx(0.1)
    assert {rows[n].group for n in ("use_adaptive_sampling", "adaptive_threshold", "adaptive_min_samples")} == {
        "Adaptive Sampling"}
    sample_count = {p.name: p for p in pc.PASSES}["sample_count"]
    assert (sample_count.label, sample_count.channels, sample_count.setting) == ("Sample Count", 1, "")
    # Cycles' automatic threshold from the sample target, and the explicit one kept.
    assert pc.adaptive_threshold(0.0, 100) == pytest.approx(0.01)
    assert pc.adaptive_threshold(0.0, 100000) == pytest.approx(0.001)
    assert pc.adaptive_threshold(0.05, 100) == pytest.approx(0.05)


def test_settings_round_trip_and_are_validated():
    s = pc.Session(8, 8, "cpu")
    s.set_params(use_adaptive_sampling=False, adaptive_threshold=0.2, adaptive_min_samples=40)
    p = s.params
    assert (p.use_adaptive_sampling, p.adaptive_min_samples) == (False, 40)
    assert p.adaptive_threshold == pytest.approx(0.2)
    assert dataclasses.asdict(pc.RenderParams(**dataclasses.asdict(p))) == dataclasses.asdict(p)
    with pytest.raises(ValueError, match="adaptive_threshold"):
        s.set_params(adaptive_threshold=-0.1)
    with pytest.raises(ValueError, match="adaptive_min_samples"):
        s.set_params(adaptive_min_samples=5000)
    with pytest.raises(TypeError, match="use_preview_adaptive_sampling"):  # the viewport's: the engine maps it
        s.set_params(use_preview_adaptive_sampling=False)


def test_unbiased_against_uniform_sampling(scene, reference):
    tested = batches(scene, "mis", 8, 128, spp_per_frame=16, **ADAPTIVE)
    active = [st for st in [tested.session.stats()]][0]["adaptive_active_pixels"]
    assert 0 < active < SIZE * SIZE  # the sky stopped, the caustic did not
    z = z_scores(tested.images, reference.images, k=2)
    assert (np.abs(z) > 4).mean() < 0.01, f"{(np.abs(z) > 4).mean():.3f} of blocks beyond |z| > 4"
    ok, a, b, err = means_agree(tested.means, reference.means)
    assert ok, f"image means {a:.5f} vs {b:.5f} (se {err:.5f})"


def test_fewer_samples_where_the_image_is_flat(scene):
    s = adaptive_session(scene)
    s.render(8)  # 128 samples: checks after 32, 48, ...
    count = s.read("sample_count")[..., 0]
    stats = s.stats()
    sky = count[:3]  # the top rows: sky only
    assert count.max() == stats["samples"] == 128
    assert sky.max() == 32  # stopped at the first check (min samples 16, Cycles' step of 16)
    # Pixels that took the last frame were in its active list (with more that a neighbour
    # brought back, as Cycles' filter does).
    assert count.mean() < 100 and stats["adaptive_active_pixels"] >= int((count == 128).sum())
    # Row bands of the active list's virtual image (F12's render_rows) trace its pixels once each.
    before = s.read("sample_count")[..., 0]
    while not s.render_rows(1):
        pass
    grew = s.read("sample_count")[..., 0] - before
    active = s.stats()["adaptive_active_pixels"]  # the list of that frame (checked at its start)
    assert set(np.unique(grew)) <= {0.0, 16.0} and int((grew == 16).sum()) == active > 0
    # Without adaptive sampling every pixel takes every sample.
    s.set_params(use_adaptive_sampling=False)
    s.render(8)
    assert (s.read("sample_count")[..., 0] == 128).all() and s.stats()["adaptive_active_pixels"] == SIZE * SIZE


def test_stops_once_every_pixel_converged():
    # Sky everywhere: every pixel converges at the first check; then nothing more is traced.
    scene = sky_floor_glass(world=0.3)
    scene.camera = Camera.look_at((0.0, -4.5, 1.5), (0.0, 0.0, 20.0), fov_y_degrees=20.0, width=SIZE, height=SIZE)
    s = adaptive_session(scene, spp_per_frame=8)
    s.render(6)
    assert s.converged and s.stats()["adaptive_active_pixels"] == 0 and s.samples == 24
    assert s.render(3) == 0 and not s.render_rows(4) and s.samples == 24
    assert np.allclose(s.read("combined")[..., :3], 0.3, rtol=1e-5)
    s.reset()  # starts over
    assert not s.converged and s.render(1) == 1


@pytest.mark.parametrize("technique", [dict(ic=True, ic_prepare_frames=5),
                                       dict(rrs="adrrs", ic_prepare_frames=5, ic_create_prob=0.05),
                                       dict(guiding=True)], ids=["ic", "adrrs", "guiding"])
def test_with_a_technique_it_renders_and_matches(scene, reference, technique):
    """Host frames stay whole-image; ADRRS' splits land on their pixels through the list."""
    tested = batches(scene, "mis", 8, 128, spp_per_frame=16, **ADAPTIVE, **technique)
    stats = tested.session.stats()
    assert 0 < stats["adaptive_active_pixels"] < SIZE * SIZE
    if technique.get("rrs") == "adrrs":
        # Splits happened. They are rare here (0 to 2 pixels of a 128-sample batch split, by
        # seed), so look over up to 16 batches' worth rather than at the last batch alone.
        session = adaptive_session(scene, **technique)
        for seed in range(16):
            session.set_params(seed=seed)
            session.render(8)
            if session.read("adrrs_splits")[..., 0].max() > 0:
                break
        assert session.read("adrrs_splits")[..., 0].max() > 0
    z = z_scores(tested.images, reference.images, k=2)
    assert (np.abs(z) > 4).mean() < 0.02, f"{(np.abs(z) > 4).mean():.3f} of blocks beyond |z| > 4"
    ok, a, b, err = means_agree(tested.means, reference.means)
    assert ok, f"image means {a:.5f} vs {b:.5f} (se {err:.5f})"


def test_background_compile_fallback_frames_then_the_technique(scene):
    s = adaptive_session(scene, ic=True, ic_prepare_frames=3)
    s.background_compile = True
    s.render(1)  # starts the technique's compile in the background (or finds it compiled)
    pc.wait_for_background_compiles()  # the event, not a number of frames (a cold compile outlasts 200)
    for _ in range(200):
        s.render(1)
        if not s.fallback_film and s.samples >= 64:
            break
    assert not s.fallback_film and s.samples >= 64
    count = s.read("sample_count")[..., 0]
    assert np.isfinite(s.read("combined")).all() and count.min() < count.max() == s.samples


def test_a_fallback_film_never_reads_as_converged(scene):
    # F12 stops once every pixel converged: the fallback's samples, thrown away when the
    # technique's pipelines are ready, must not end it (a 16-px F12 did, after 3616 of them).
    s = adaptive_session(scene, rrs="adrrs", adaptive_threshold=0.5, adaptive_min_samples=1)
    s.background_compile = True
    s.render(1)
    while s.fallback_film and pc.background_compiles():
        assert not s.converged
        s.render(1)


def test_cli_set_for_npz(tmp_path, scene):
    from parallax_core import cli
    from parallax_core.cli import parse_params

    assert parse_params(["use_adaptive_sampling=false", "adaptive_threshold=0.05"]) == {
        "use_adaptive_sampling": False, "adaptive_threshold": 0.05}
    path = tmp_path / "scene.npz"
    scene.save(str(path))
    for value in ("false", "true"):
        out = tmp_path / f"out_{value}.exr"
        assert cli.main(["render", str(path), "-o", str(out), "--device", "cpu", "--spp", "48", "--spp-per-frame", "16",
                         "--set", f"use_adaptive_sampling={value}", "--set", "adaptive_min_samples=16",
                         "--set", "use_preview_adaptive_sampling=false", *UNBIASED_LIGHT_PATH_SETS]) == 0
        assert out.exists()
