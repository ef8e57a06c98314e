"""`parallax render FILE.blend` / `parallax export`: bpy in a subprocess, the F12 code path."""
import re
import subprocess
import sys

import numpy as np
from blender_helpers import SCENES, read_layers

from parallax_core.scene import SceneData

PARALLAX = [sys.executable, "-m", "parallax_core"]
CORNELL = f"{SCENES}/cornell_box.blend"
SMALL = ["--set", "render.resolution_x=24", "--set", "render.resolution_y=16"]


def run(*args, check=True):
    return subprocess.run([*PARALLAX, *args], capture_output=True, text=True, check=check, timeout=300)


def test_render_blend_with_both_engines(tmp_path):
    images = {}
    for engine in ("PARALLAX", "CYCLES"):
        exr, png = tmp_path / f"{engine}.exr", tmp_path / f"{engine}.png"
        r = run("render", CORNELL, "-o", str(exr), "--png", str(png), "--engine", engine,
                "--samples", "8", *SMALL, "--set", "seed=3", "--set", "method='nee'")
        assert f"{engine.lower()}: " in r.stdout
        images[engine] = read_layers(exr)["Combined"]
        assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    for image in images.values():
        assert image.shape == (16, 24, 4) and 0.02 < image[..., :3].mean() < 1.0


def test_export_writes_what_the_core_receives(tmp_path):
    npz = tmp_path / "cornell.npz"
    r = run("export", CORNELL, "-o", str(npz))
    assert "36 triangles" in r.stdout
    scene = SceneData.load(str(npz))
    assert (scene.width, scene.height) == (512, 512)
    assert any(np.any(np.asarray(m.emission) > 0) for m in scene.materials)
    # And it renders without Blender.
    run("render", str(npz), "-o", str(tmp_path / "x.exr"), "--spp", "2", "--width", "16")


def test_bad_arguments_exit_with_a_clear_error(tmp_path):
    out = str(tmp_path / "x.exr")
    for args, message in (
            ((str(tmp_path / "missing.blend"),), "no such file"),
            ((CORNELL, "--set", "no_such_setting=1"), "has no property 'no_such_setting'"),
            ((CORNELL, "--set", "samples"), "expected PROP=VALUE"),
            ((CORNELL, "--set", "method='bogus'"), "bogus"),
            ((CORNELL, "--engine", "EEVEE"), "PARALLAX or CYCLES")):
        r = run("render", *args, "-o", out, check=False)
        assert r.returncode == 2, (args, r.stderr)
        assert "parallax: error:" in r.stderr and message in r.stderr and "Traceback" not in r.stderr


def test_render_blend_with_the_irradiance_cache(tmp_path):
    exr = tmp_path / "ic.exr"
    r = run("render", CORNELL, "-o", str(exr), "--samples", "2", *SMALL, "--set", "ic=true",
            "--set", "ic_prepare_frames=2", "--set", "ic_capacity=5000", "--set", "ic_gradients=1")
    # F12's last stats line (earlier ones may come from frames rendered while the cache compiled)
    found = re.findall(r"IC (\d+)/5000 entries, (\d+) dropped", r.stderr)
    assert found and int(found[-1][0]) > 0, r.stderr
    layers = read_layers(exr)
    assert layers["IC Irradiance"].shape == layers["IC Gradients"].shape == (16, 24, 3)
    assert layers["IC Irradiance"].mean() > 0.0


def test_render_blend_with_rrs_and_its_synonym_adrrs(tmp_path):
    """--set adrrs=1 (ADRRS' old switch, a synonym of rrs=adrrs) on a .blend: the RRS layers are
    written and ADRRS builds the irradiance cache; adrrs=0 turns it off; a bad value is an error
    naming the setting. (rrs=ears, which builds no cache, is rendered by test_cli.py's .npz test:
    the settings reach the core the same way.)"""
    layers = {"ADRRS Estimate", "ADRRS Splits", "RRS Factor", "RRS Cost"}
    short = ("--set", "ic_prepare_frames=2", "--set", "adrrs_estimate_spp=2")
    exr = tmp_path / "adrrs.exr"
    r = run("render", CORNELL, "-o", str(exr), "--samples", "2", *SMALL, *short, "--set", "adrrs=1")
    assert re.findall(r"IC \d+/65536 entries", r.stderr), r.stderr
    found = read_layers(exr)
    assert layers <= set(found), sorted(found)
    assert all(np.isfinite(found[layer]).all() for layer in layers)
    r = run("render", CORNELL, "-o", str(tmp_path / "off.exr"), "--samples", "1", *SMALL, "--set", "adrrs=0")
    assert not layers & set(read_layers(tmp_path / "off.exr"))
    for value, message in (("rrs=bogus", "--set 'rrs=bogus': "), ("adrrs=maybe", "--set 'adrrs=maybe': expected 1/0")):
        r = run("render", CORNELL, "-o", str(tmp_path / "x.exr"), "--set", value, check=False)
        assert r.returncode == 2 and f"parallax: error: {message}" in r.stderr, (value, r.stderr)
        assert "Traceback" not in r.stderr
