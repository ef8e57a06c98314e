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
    for name in ("cornell_box.md", "cornell_box_convergence.png", "cornell_box_images.png", "results.json"):
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
    assert "ic_update_prob" not in converge.method_params("ic")
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
