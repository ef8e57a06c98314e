"""Smoke run of the evaluation harness (bench.converge, bench.spp_per_frame, bench.scaling):
tiny images and seconds, so it cannot rot; the numbers are not judged here (DESIGN)."""
import json
import sys
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))
from bench import converge, scaling, spp_per_frame  # noqa: E402


def test_rel_mse_is_ruppert_et_al():
    reference = np.full((10, 100, 3), 0.5)
    image = reference.copy()
    image[0, 0] = 100.0  # one outlier pixel in 1000: dropped
    image[1] += 0.1
    expected = (0.1 ** 2 / (0.25 + 1e-3)) * 100 / 999
    assert converge.rel_mse(image, reference) == pytest.approx(expected)
    assert converge.rel_mse(reference, reference) == 0.0


def test_converge_smoke(tmp_path):
    peers = ["cycles"]
    results = converge.run(scenes=["cornell_box"], seconds=2.0, methods=["pt", "mis", "ic"], peers=peers,
                           width=24, reference_seconds=2.0, out=str(tmp_path),
                           reference_dir=str(tmp_path / "references"))
    rows = results["cornell_box"]
    assert [r["renderer"] for r in rows] == ["Parallax pt", "Parallax mis", "Parallax ic", "Cycles"]
    for row in rows:  # the cache may still be preparing when its time is up: spp may be 0
        assert (row["spp"] > 0 or row["renderer"] == "Parallax ic") and np.isfinite(row["rel_mse"]) and row["curve"]
    for name in ("cornell_box.md", "cornell_box_convergence.png", "cornell_box_images.jpg", "results.json"):
        assert (tmp_path / name).stat().st_size > 0
    assert json.loads((tmp_path / "results.json").read_text())["scenes"]["cornell_box"]
    assert (tmp_path / "references" / "cornell_box_24x24.json").exists()


def test_spp_per_frame_and_scaling_smoke(tmp_path):
    spp_per_frame.SPP = (1, 4)
    spp_per_frame.main(["--scenes", "cornell_box", "--width", "16", "--seconds", "0.1", "--out", str(tmp_path)])
    rates = json.loads((tmp_path / "spp_per_frame.json").read_text())["rates"]["cornell_box"]
    assert set(rates) == {"1", "4"} and all(v > 0 for v in rates.values())
    scaling.main(["--triangles", "2k,8k", "--resolution", "16", "--frames", "1", "--out", str(tmp_path)])
    rows = json.loads((tmp_path / "scaling.json").read_text())["rows"]
    assert [r["triangles"] > 0 and r["frame_ms"] > 0 for r in rows] == [True, True]
    assert rows[1]["triangles"] > rows[0]["triangles"]


def test_thesis_suite_quick(tmp_path):
    """--suite thesis --quick on the thesis' Veach MIS scene: the shared scene is converted to
    .blend (camera, lights and materials as the Mitsuba loader reads them), rendered by both
    engines, tabled in the thesis' layout and summarised beside table 5.2."""
    from bench import shared_scenes, thesis

    if not shared_scenes.available(shared_scenes.VEACH_MIS):
        pytest.skip(f"the shared scene {shared_scenes.VEACH_MIS} is not in {shared_scenes.SHARED_SCENES}")
    assert converge.method_params("ic_noupdate")["ic_update_prob"] == 0.0
    assert converge.method_params("ic_thesis")["ic_update_prob"] == 1e-5  # the thesis' rate (TECHNIQUES.md)
    assert converge.method_params("ic_noupdate")["ic_mode"] == converge.method_params("ic_thesis")["ic_mode"] == "thesis"
    assert "ic_update_prob" not in converge.method_params("ic") and "ic_mode" not in converge.method_params("ic")
    source = shared_scenes.thesis_veach_mis(width=converge.QUICK["width"])
    converted = converge.export_scene("thesis_veach_mis", converge.QUICK["width"])
    assert (converted.width, converted.height) == (source.width, source.height)
    np.testing.assert_allclose(converted.camera.window, source.camera.window, rtol=1e-5)
    np.testing.assert_allclose(converted.camera.camera_to_world, source.camera.camera_to_world, atol=1e-5)
    assert sorted((round(l.power, 2), round(l.radius, 4)) for l in converted.lights) == \
        sorted((round(l.power, 2), round(l.radius, 4)) for l in source.lights)
    assert sorted((m.type, round(m.roughness, 4)) for m in converted.materials) == \
        sorted((m.type, round(m.roughness, 4)) for m in source.materials)

    converge.main(["--suite", "thesis", "--quick", "--scenes", "thesis_veach_mis", "--methods", "pt",
                   "--reference-seconds", "2", "--out", str(tmp_path)])
    table = (tmp_path / "thesis_veach_mis.md").read_text()
    assert "| | Parallax pt | Cycles |" in table and "| SPP |" in table
    results = json.loads((tmp_path / "results.json").read_text())
    rows = results["scenes"]["thesis_veach_mis"]
    assert [r["pixels"] for r in rows] == [source.width * source.height] * 2
    (tmp_path / "gpu_thesis").mkdir()
    (tmp_path / "gpu_thesis" / "results.json").write_text(json.dumps(results))
    summary = Path(thesis.write_summary(str(tmp_path / "SUMMARY.md"), ("gpu_thesis",), str(tmp_path))).read_text()
    pt = [line for line in summary.splitlines() if line.startswith("| Path Tracer |")]
    assert "### Table 5.2 Veach MIS" in summary and len(pt) == 1
    assert pt[0].split("|")[2].strip() == "0.1206"  # the thesis' number beside ours


# ---- time to a clean image (issue 36): mis_clean, cycles_clean, checkpoints, FLIP, GOAL.md ----

def test_mis_clean_is_f12_defaults_with_the_depth_pinned():
    import dataclasses

    import parallax_core as pc

    params, engine = converge.clean_settings()
    assert params == {**dataclasses.asdict(pc.RenderParams()), "max_depth": converge.MAX_DEPTH, "depth_leeway": 0}
    assert engine == {s.name: s.default for s in pc.SETTINGS if not s.core}
    # F12's defaults as issue 36 names them: adaptive sampling at 0.01, OIDN with albedo and normal.
    assert params["use_adaptive_sampling"] and params["adaptive_threshold"] == pytest.approx(0.01)
    assert engine["use_denoising"]
    assert (engine["denoising_input_passes"], engine["denoising_prefilter"], engine["denoising_quality"]) == \
        ("RGB_ALBEDO_NORMAL", "ACCURATE", "HIGH")
    assert converge.method_params("mis_clean") == params


def test_every_method_but_mis_clean_pins_unbiased_light_paths(monkeypatch):
    import parallax_core as pc

    assert converge.method_params("mis")["use_adaptive_sampling"] is False
    pinned = {"rr_start_depth": 0, "light_samples": 2}  # stands in for the light-path settings' values
    monkeypatch.setattr(pc, "UNBIASED_LIGHT_PATHS", pinned, raising=False)
    session = pc.Session(8, 8)
    for method in converge.METHODS:
        params = converge.method_params(method)
        session.set_params(**params)  # every method's settings are RenderParams fields
        if method == "mis_clean":
            assert (params["rr_start_depth"], params["light_samples"]) == (3, 1)  # the table's defaults
        else:
            assert {k: params[k] for k in pinned} == pinned, method
    with pytest.raises(ValueError, match="unknown method"):
        converge.method_params("mis_denoised")


def test_checkpoint_logic():
    assert converge.parse_checkpoints("20,5,60") == (5.0, 20.0, 60.0)
    for bad in ("", "5,x", "0,5", "5,5", "inf", "-1"):
        with pytest.raises(ValueError, match="--checkpoints"):
            converge.parse_checkpoints(bad)
    # A checkpoint is taken before the step that would pass it, several at once if one step
    # would pass them all, and every one left when the image is final (all pixels converged).
    assert converge.due_checkpoints([5, 20, 60], 4.0, 0.5) == []
    assert converge.due_checkpoints([5, 20, 60], 4.6, 0.5) == [5]
    assert converge.due_checkpoints([5, 20, 60], 4.6, 16.0) == [5, 20]
    assert converge.due_checkpoints([20, 60], 30.0, 0.1) == [20]  # late (a long start-up): at once
    assert converge.due_checkpoints([5, 20, 60], 1.0, 0.1, finished=True) == [5, 20, 60]
    # Frames per render() call: about 0.2 s, growing at most 4x a call, within 1..64.
    assert converge.frames_per_call(1, 10.0) == (1, 10.0)  # the call that compiled
    frames, seconds = converge.frames_per_call(4, 0.01)
    assert frames == 16 and seconds == pytest.approx(0.04)
    assert converge.frames_per_call(10, 1.0)[0] == 2
    assert converge.frames_per_call(64, 1e-4)[0] == 64
    with pytest.raises(SystemExit):
        converge.main(["--checkpoints", "5,0"])
    with pytest.raises(SystemExit):
        converge.main(["--peers", "cycles,blender_internal"])


def test_mean_flip():
    rng = np.random.default_rng(1)
    reference = rng.random((24, 32, 3)).astype(np.float32)
    assert converge.mean_flip(reference, reference) == 0.0
    noisy = reference + 0.2 * rng.standard_normal(reference.shape).astype(np.float32)
    slightly = reference + 0.02 * rng.standard_normal(reference.shape).astype(np.float32)
    assert 0.0 < converge.mean_flip(slightly, reference) < converge.mean_flip(noisy, reference) < 1.0
    noisy[0, 0] = (np.nan, -1.0, np.inf)  # no NaN out of the package
    assert np.isfinite(converge.mean_flip(noisy, reference))


def _load_build_module():
    import importlib.util

    spec = importlib.util.spec_from_file_location("blender_scenes_build",
                                                  Path(converge.REPO) / "blender_scenes" / "build.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_cycles_clean_restores_cycles_defaults():
    from types import SimpleNamespace

    from parallax_blender import cli

    # Every Cycles setting blender_scenes pins (configure_render) is one cycles_clean restores.
    pinned = []

    class Recorder:
        def __setattr__(self, name, value):
            pinned.append(name)

    _load_build_module().configure_render(
        SimpleNamespace(render=SimpleNamespace(), display_settings=SimpleNamespace(),
                        view_settings=SimpleNamespace(), cycles=Recorder()), 64, 64)
    assert "pixel_filter_type" in pinned and set(pinned) - {"samples"} <= set(converge.CYCLES_F12)

    scene = cli.open_blend(converge.blend_path("cornell_box"), "CYCLES", 32)
    cycles = scene.cycles
    props = cycles.bl_rna.properties
    assert not cycles.use_denoising and cycles.pixel_filter_type == "BOX"  # as the .blend pins it
    converge.cycles_clean_settings(scene)
    for name in converge.CYCLES_F12:
        expected = converge.MAX_DEPTH if name == "max_bounces" else props[name].default
        assert getattr(cycles, name) == pytest.approx(expected) if isinstance(expected, float) else \
            getattr(cycles, name) == expected, name
    assert cycles.use_adaptive_sampling and cycles.adaptive_threshold == pytest.approx(0.01)
    assert cycles.use_denoising and cycles.denoiser == "OPENIMAGEDENOISE" and not cycles.denoising_use_gpu
    assert (cycles.pixel_filter_type, cycles.sample_clamp_indirect) == ("BLACKMAN_HARRIS", pytest.approx(10.0))
    assert cycles.samples == converge.NO_SAMPLE_CAP and all(layer.cycles.use_denoising for layer in scene.view_layers)


def test_cycles_denoise_seconds_from_status_lines():
    lines = [(0.2, "Mem: 33M | Sample 0/1048576"), (0.3, "Remaining: 00:00.96 | Mem: 33M | Sample 1/1048576"),
             (1.2, "Mem: 33M | Sample 39/1048576"), (1.6, "Mem: 33M | Sample 0/1048576"), (1.65, "Mem: 33M | Finished")]
    assert converge.cycles_denoise_seconds(lines) == pytest.approx(0.45)
    assert converge.cycles_denoise_seconds(lines[:3]) is None


def _clean_point(checkpoint, rel_mse, flip, spp=100, seconds=None, denoise=0.1):
    return dict(checkpoint=checkpoint, rel_mse=rel_mse, flip=flip, spp=spp, seconds=seconds or checkpoint,
                denoise_seconds=denoise)


def test_goal_table(tmp_path):
    from bench import clean_goal

    ours, theirs = converge.CLEAN_ROWS["mis_clean"], converge.CLEAN_ROWS["cycles_clean"]
    results = {"device": "llvmpipe", "width": 160, "scenes": {
        "cornell_box": [dict(renderer=ours, checkpoints=[_clean_point(5, 0.01, 0.1), _clean_point(20, 0.004, 0.05)]),
                        dict(renderer="Parallax mis", checkpoints=[]),
                        dict(renderer=theirs, checkpoints=[_clean_point(5, 0.02, 0.12, denoise=None),
                                                           _clean_point(20, 0.003, 0.04)])],
        "atrium": [dict(renderer=ours, checkpoints=[_clean_point(5, 0.5, 0.3)])],  # no Cycles row: left out
    }}
    text = clean_goal.goal_table(results)
    assert "**Goal holds at 1 of 2 points.**" in text
    assert "| cornell_box | 5 | 0.01 | 0.02 | 0.500 | 0.1 | 0.12 | y |" in text
    assert "| cornell_box | 20 | 0.004 | 0.003 | 1.333 | 0.05 | 0.04 | n |" in text
    assert "| cornell_box | 5 | 100 | 100 | 5.0 | 5.0 | 0.10 | n/a |" in text
    assert "atrium" not in text
    path = tmp_path / "results.json"
    path.write_text(json.dumps(results))
    assert Path(clean_goal.write_goal(str(path))).read_text() == text
    assert (tmp_path / "GOAL.md").exists()
    results["scenes"]["cornell_box"][0]["checkpoints"] = [_clean_point(60, 0.01, 0.1)]  # no shared checkpoint
    with pytest.raises(ValueError, match="mis_clean"):
        clean_goal.goal_table(results)
    with pytest.raises(SystemExit):
        clean_goal.main([str(tmp_path / "missing.json")])


def test_clean_rows_smoke(tmp_path):
    """mis_clean and cycles_clean end to end on a tiny image: both rows have every checkpoint,
    denoised (their denoise timed), scored by relMSE and FLIP; GOAL.md tables them."""
    from bench import clean_goal

    marks = (0.5, 1.0)
    results = converge.run(scenes=["cornell_box"], seconds=1.0, methods=["mis_clean"], peers=["cycles_clean"],
                           width=16, reference_seconds=1.0, out=str(tmp_path), clean_checkpoints=marks,
                           reference_dir=str(tmp_path / "references"))
    rows = results["cornell_box"]
    assert [r["renderer"] for r in rows] == [converge.CLEAN_ROWS["mis_clean"], converge.CLEAN_ROWS["cycles_clean"]]
    for row in rows:
        assert [p["checkpoint"] for p in row["checkpoints"]] == list(marks), row["renderer"]
        for p in row["checkpoints"]:
            assert p["spp"] > 0 and np.isfinite(p["rel_mse"]) and 0.0 <= p["flip"] <= 1.0
            assert p["denoise_seconds"] is not None and p["denoise_seconds"] >= 0.0
            image = f"cornell_box__{converge._slug(row['renderer'])}__{p['checkpoint']:g}s.npy"
            assert (tmp_path / "raw" / image).exists()
        assert row["rel_mse"] == pytest.approx(row["checkpoints"][-1]["rel_mse"])
    parallax = rows[0]["checkpoints"]
    assert parallax[0]["seconds"] <= parallax[1]["seconds"] and "noisy_rel_mse" in parallax[0]
    assert "Denoised with OpenImageDenoise" in rows[0]["info"]["denoiser"]
    note = json.loads((tmp_path / "references" / "cornell_box_16x16.json").read_text())
    assert note["denoised"] is False and note["seed"] == converge.REFERENCE_SEED
    assert "| checkpoint (s) |" in (tmp_path / "cornell_box.md").read_text()
    goal = Path(clean_goal.write_goal(str(tmp_path / "results.json"))).read_text()
    assert "| cornell_box | 0.5 |" in goal and "| cornell_box | 1 |" in goal


def test_guiding_goal_table():
    """bench.guiding_goal: guiding_auto against the best unguided method, the median over seeds;
    the glass-lit scenes need 4x, the others never more than 1.1x."""
    from bench import guiding_goal

    def run(auto_box, auto_clocks, pipeline):
        return {"scenes": {
            "cornell_box": [dict(renderer="Parallax mis", rel_mse=1.0), dict(renderer="Parallax pt", rel_mse=9.0),
                            dict(renderer="Parallax guiding_auto", rel_mse=auto_box,
                                 info=dict(guiding_pipeline=pipeline))],
            "clocks": [dict(renderer="Parallax pt", rel_mse=4.0), dict(renderer="Parallax mis", rel_mse=11.0),
                       dict(renderer="Parallax guiding_auto", rel_mse=auto_clocks, info=dict(guiding_pipeline=1))],
            "veach_mis": [dict(renderer="Parallax guiding_auto", rel_mse=1.0)],  # nothing to compare: left out
        }}

    text = guiding_goal.table([run(1.05, 2.0, 0), run(1.3, 0.9, 0), run(1.0, 0.8, 1)])
    assert "| cornell_box | 1.05 | mis 1 | 1.05 | holds | off/off/on | 3 |" in text
    assert "| clocks | 0.9 | pt 4 | 0.23 | holds | on/on/on | 3 |" in text
    assert "veach_mis" not in text
    assert "misses (<= 1.1)" in guiding_goal.table([run(1.2, 0.9, 0)])
    assert "misses (<= 0.25)" in guiding_goal.table([run(1.0, 2.0, 0)])
