"""The `parallax` console script: scene -> npz -> render -> multi-channel EXR."""
import subprocess
import sys

import numpy as np

from parallax_core.exr import read_exr

PARALLAX = [sys.executable, "-m", "parallax_core"]


def run(*args, check=True):
    return subprocess.run([*PARALLAX, *args], capture_output=True, text=True, check=check, timeout=120)


def test_info_lists_a_ray_tracing_device():
    out = run("info").stdout
    assert "ray tracing: yes" in out and "chosen" in out


def test_scene_render_writes_every_pass(tmp_path):
    npz, exr, png = tmp_path / "cb.npz", tmp_path / "cb.exr", tmp_path / "cb.png"
    run("scene", "cornell_box", "-o", str(npz), "--width", "32", "--height", "24")
    r = run("render", str(npz), "-o", str(exr), "--png", str(png), "--spp", "16", "--spp-per-frame", "4",
            "--method", "nee", "--seed", "3")
    assert "16 spp" in r.stdout + r.stderr
    channels = read_exr(str(exr))
    expected = {"Combined.R", "Combined.G", "Combined.B", "Combined.A", "Depth.Z", "Normal.X", "Normal.Y",
                "Normal.Z", "Albedo.R", "Albedo.G", "Albedo.B", "RayDepth.V"}
    assert expected <= set(channels)
    assert channels["Combined.R"].shape == (24, 32)
    assert 0.05 < float(np.mean(channels["Combined.R"])) < 1.0
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_errors_exit_cleanly(tmp_path):
    r = run("render", str(tmp_path / "missing.npz"), "-o", str(tmp_path / "x.exr"), check=False)
    assert r.returncode == 2 and "parallax: error:" in r.stderr and "Traceback" not in r.stderr
    bad = tmp_path / "bad.npz"
    run("scene", "cornell_box", "-o", str(bad), "--width", "8", "--height", "8")
    data = dict(np.load(bad))
    data["positions"][0, 0] = np.nan
    np.savez(bad, **data)
    r = run("render", str(bad), "-o", str(tmp_path / "x.exr"), check=False)
    assert r.returncode == 2 and "NaN" in r.stderr and "Traceback" not in r.stderr
