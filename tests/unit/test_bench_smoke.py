"""Smoke tests of bench/throughput.py, bench/image_hashes.py and bench/pipeline_stats.py: tiny
settings, a few seconds each on lavapipe. They check the tools work (and that primitive ordering
does not change the image); timings are never pass/fail (DESIGN: timings belong in bench/)."""
import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

parallax_core = pytest.importorskip("parallax_core")
if not any(d.get("ray_tracing") for d in parallax_core.devices()):
    pytest.skip("no Vulkan device with ray tracing", allow_module_level=True)

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))
from bench import throughput  # noqa: E402


def test_parse_size():
    assert [throughput.parse_size(s) for s in ("1k", "100k", "1M", "2500", "2.5k")] == \
        [1_000, 100_000, 1_000_000, 2_500, 2_500]
    assert throughput.size_label(1_000_000) == "1M" and throughput.size_label(1500) == "1500"


def test_throughput_smoke():
    info = {}
    rows = throughput.run(sizes=[1000], resolution=32, seconds=0.2, progress=lambda msg: None,
                          info=info)
    assert [r["order"] for r in rows] == ["coherent+sort", "shuffled", "shuffled+sort"]
    for r in rows:
        assert r["rays"] > 0 and r["samples_per_pixel"] > 0 and r["frames"] > 0
        assert r["rays_per_s"] > 0 and r["rays_per_cpu_s"] > 0 and r["samples_per_s"] > 0
        assert r["triangles"] >= 900 and r["resolution"] == 32
        assert r["fraction_of_target"] > 0
    # Same geometry in another triangle order: the same image up to noise.
    means = [r["image_mean"] for r in rows]
    assert min(means) > 0
    assert max(means) / min(means) < 1.05, means
    # Markdown table: header, separator, one line per row.
    assert len(throughput.markdown_table(rows, info).splitlines()) == 2 + len(rows)


def test_image_hashes_round_trip(tmp_path, capsys):
    # bench.image_hashes: a case hashed, then compared with itself (exit 0), every film pass in it.
    from bench import image_hashes

    out = tmp_path / "hashes.json"
    assert image_hashes.main(["--cases", "cornell/mis", "--out", str(out)]) == 0
    hashes = json.loads(out.read_text())["cornell/mis"]
    assert "combined" in hashes and hashes["rays"] > 0
    assert image_hashes.main(["--cases", "cornell/mis", "--compare", str(out)]) == 0
    assert "cornell/mis: rays" in capsys.readouterr().out


def test_pipeline_stats_table(tmp_path):
    # bench.pipeline_stats reads the core's PARALLAX_PIPELINE_STATS lines: the device was made
    # before this test, so the log is set in a fresh process.
    log = tmp_path / "stats.jsonl"
    run = subprocess.run([sys.executable, "-m", "bench.pipeline_stats", "--soup", "1000", "--methods", "nee",
                          "--device", "cpu", "--out", str(tmp_path / "rows.json")],
                         cwd=Path(__file__).resolve().parents[2], capture_output=True, text=True, timeout=600,
                         env={**os.environ, "PARALLAX_PIPELINE_STATS": str(log)})
    assert run.returncode == 0, run.stderr
    rows = json.loads((tmp_path / "rows.json").read_text())
    assert rows and rows[0]["method"] == "nee" and rows[0]["constants"]["techniques"] == 0
    assert "| soup1000 | nee | camera | 0 |" in run.stdout
