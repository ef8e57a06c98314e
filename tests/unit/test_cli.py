"""The `parallax` console script: scene -> npz -> render -> multi-channel EXR."""
import re
import subprocess
import sys

import numpy as np
import pytest

from helpers import UNBIASED_LIGHT_PATH_SETS
from parallax_core.cli import parse_params
from parallax_core.exr import read_exr, write_exr

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
                "Normal.Z", "Denoising Albedo.R", "Denoising Albedo.G", "Denoising Albedo.B", "Ray Depth.X"}
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



def test_set_values_are_parsed_by_the_row_type():
    parsed = parse_params(["ic=on", "ic_accuracy=0.3", "max_depth= 3", "method='nee'", "samples=8"])
    assert parsed == {"ic": True, "ic_accuracy": 0.3, "max_depth": 3, "method": "nee", "samples": 8}
    assert type(parsed["ic"]) is bool and type(parsed["ic_accuracy"]) is float
    for word, value in (("1", True), ("0", False), ("TRUE", True), ("false", False), ("on", True),
                        ("off", False), ("yes", True), ("no", False)):
        assert parse_params([f"ic={word}"]) == {"ic": value}
    assert parse_params(["method=nee", "seed=4", "mis_heuristic=balance"]) == {
        "method": "nee", "seed": 4, "mis_heuristic": "balance"}
    for item, message in (("bogus=1", "method, light_samples"),
                          ("max_depth=2.5", "expected an integer"),
                          ("ic_accuracy=abc", "expected a number"),
                          ("ic_accuracy=nan", "finite"),
                          ("ic=maybe", "yes/no"),
                          ("ic", "expected NAME=VALUE")):
        with pytest.raises(ValueError, match=re.escape(message)):
            parse_params([item])


def test_exr_round_trip(tmp_path):
    pytest.importorskip("OpenEXR")  # installed by make setup; absent on the GPU machines
    rng = np.random.default_rng(0)
    passes = {"combined": rng.random((6, 5, 4), np.float32), "depth": rng.random((6, 5, 1), np.float32),
              "normal": rng.random((6, 5, 3), np.float32), "albedo": rng.random((6, 5, 3), np.float32),
              "ray_depth": rng.random((6, 5), np.float32), "ic_irradiance": rng.random((6, 5, 3), np.float32)}
    write_exr(tmp_path / "a.exr", passes)
    back = read_exr(tmp_path / "a.exr")
    assert set(back) == {"Combined.R", "Combined.G", "Combined.B", "Combined.A", "Depth.Z",
                         "Normal.X", "Normal.Y", "Normal.Z", "Denoising Albedo.R", "Denoising Albedo.G",
                         "Denoising Albedo.B", "Ray Depth.X", "IC Irradiance.R", "IC Irradiance.G", "IC Irradiance.B"}
    np.testing.assert_array_equal(back["Combined.G"], passes["combined"][:, :, 1])
    np.testing.assert_array_equal(back["Normal.Z"], passes["normal"][:, :, 2])
    np.testing.assert_array_equal(back["Ray Depth.X"], passes["ray_depth"])
    # Layers by the PASSES labels only: no made-up names.
    with pytest.raises(ValueError, match="unknown pass 'bogus'"):
        write_exr(tmp_path / "b.exr", {"bogus": passes["depth"]})
    with pytest.raises(ValueError, match="3 channels, the pass has 1"):
        write_exr(tmp_path / "b.exr", {"depth": passes["normal"]})


def _ray_depth(tmp_path, name, *args):
    npz, exr = tmp_path / "cb.npz", tmp_path / f"{name}.exr"
    if not npz.exists():
        run("scene", "cornell_box", "-o", str(npz), "--width", "16", "--height", "12")
    r = run("render", str(npz), "-o", str(exr), "--spp", "4", *args)
    return float(np.mean(read_exr(str(exr))["Ray Depth.X"])), r


def test_set_applies_render_parameters_to_npz_scenes(tmp_path):
    default, r = _ray_depth(tmp_path, "default")
    assert "IC " not in r.stdout
    shallow, _ = _ray_depth(tmp_path, "shallow", "--set", "max_depth=1", "--set", "method=nee")
    assert shallow < default
    for args, message in ((("--set", "bogus=1"), "max_depth"),
                          (("--set", "max_depth=abc"), "expected an integer"),
                          (("--set", "method=bogus"), "bogus"),
                          (("--engine", "CYCLES"), ".blend files only")):
        r = run("render", str(tmp_path / "cb.npz"), "-o", str(tmp_path / "x.exr"), *args, check=False)
        assert r.returncode == 2 and "parallax: error:" in r.stderr and message in r.stderr, (args, r.stderr)
        assert "Traceback" not in r.stderr


def test_npz_render_with_the_irradiance_cache(tmp_path):
    npz, exr = tmp_path / "cb.npz", tmp_path / "ic.exr"
    run("scene", "cornell_box", "-o", str(npz), "--width", "16", "--height", "12")
    r = run("render", str(npz), "-o", str(exr), "--spp", "2", "--set", "ic=1", "--set", "ic_gradients=yes",
            "--set", "ic_prepare_frames=2", "--set", "ic_capacity=5000", "--set", "ic_accuracy=0.3",
            *UNBIASED_LIGHT_PATH_SETS)
    found = re.search(r"IC (\d+)/5000 entries, (\d+) dropped", r.stdout)
    assert found and int(found.group(1)) > 0, r.stdout
    channels = read_exr(str(exr))
    irradiance = np.stack([channels[f"IC Irradiance.{c}"] for c in "RGB"], axis=-1)
    gradients = np.stack([channels[f"IC Gradients.{c}"] for c in "RGB"], axis=-1)
    assert irradiance.shape == gradients.shape == (12, 16, 3)
    assert np.isfinite(irradiance).all() and irradiance.mean() > 0.0
    assert np.isfinite(gradients).all() and (gradients[..., 2] == 0).all()


def test_npz_render_with_rrs_and_its_synonym_adrrs(tmp_path):
    """--set rrs=ears / adrrs=1 (ADRRS' old switch, a synonym of rrs=adrrs) reach the core: the
    RRS layers are written, and ADRRS (not EARS) builds the irradiance cache; bad values exit
    with an error naming the setting."""
    npz = tmp_path / "cb.npz"
    run("scene", "cornell_box", "-o", str(npz), "--width", "16", "--height", "12")
    short = ("--set", "ic_prepare_frames=2", "--set", "adrrs_estimate_spp=2", *UNBIASED_LIGHT_PATH_SETS)
    layers = {"ADRRS Estimate.R", "ADRRS Splits.X", "RRS Factor.X", "RRS Cost.X"}
    for name, sets, cache in (("ears", ("rrs=ears",), False), ("adrrs", ("adrrs=1",), True),
                              ("synonym_off", ("rrs=ears", "adrrs=0"), False)):
        exr = tmp_path / f"{name}.exr"
        r = run("render", str(npz), "-o", str(exr), "--spp", "4", *short, *[a for v in sets for a in ("--set", v)])
        assert bool(re.search(r"IC \d+/65536 entries", r.stdout)) == cache, (name, r.stdout)
        channels = read_exr(str(exr))
        if name == "synonym_off":  # the later --set wins: rrs off, no RRS layers
            assert not layers & set(channels), name
            continue
        assert layers <= set(channels), name
        assert all(np.isfinite(channels[c]).all() for c in layers), name
    for value, message in (("rrs=bogus", "rrs must be one of off, adrrs, ears, got 'bogus'"),
                           ("adrrs=maybe", "--set 'adrrs=maybe': expected 1/0"),
                           ("adrrs=ears", "--set 'adrrs=ears': expected 1/0")):
        r = run("render", str(npz), "-o", str(tmp_path / "x.exr"), "--set", value, check=False)
        assert r.returncode == 2 and f"parallax: error: {message}" in r.stderr, (value, r.stderr)
        assert "Traceback" not in r.stderr


def test_npz_denoising_settings_round_trip(tmp_path):
    """Denoising is on by default (as Cycles'): the EXR holds the denoised Combined and the
    Noisy Image; --set turns it off or changes its settings; bad values fail before rendering;
    with no OIDN the render is written undenoised with a warning."""
    npz = tmp_path / "cb.npz"
    run("scene", "cornell_box", "-o", str(npz), "--width", "24", "--height", "16")

    def render(name, *args, env=None):
        exr = tmp_path / f"{name}.exr"
        r = subprocess.run([*PARALLAX, "render", str(npz), "-o", str(exr), "--spp", "2", "--seed", "1", *args],
                           capture_output=True, text=True, timeout=120, env=env)
        assert r.returncode == 0, r.stderr
        return read_exr(str(exr)), r

    def rgb(channels, layer):
        return np.stack([channels[f"{layer}.{c}"] for c in "RGB"], axis=-1)

    default, r = render("default")
    assert "Denoised with OpenImageDenoise" in r.stdout
    noisy = rgb(default, "Noisy Image")
    assert not np.allclose(rgb(default, "Combined"), noisy)
    # The denoised image is smoother: less difference between neighbouring pixels.
    assert np.abs(np.diff(rgb(default, "Combined"), axis=1)).mean() < 0.7 * np.abs(np.diff(noisy, axis=1)).mean()
    off, r = render("off", "--set", "use_denoising=off")
    assert "Noisy Image.R" not in off and "Denoised" not in r.stdout
    np.testing.assert_array_equal(rgb(off, "Combined"), noisy)  # the same film, same seed
    rgb_only, _ = render("rgb", "--set", "denoising_input_passes=RGB", "--set", "denoising_prefilter=NONE",
                         "--set", "denoising_quality=FAST")
    np.testing.assert_array_equal(rgb(rgb_only, "Noisy Image"), noisy)
    assert not np.array_equal(rgb(rgb_only, "Combined"), rgb(default, "Combined"))
    for value, message in (("denoising_prefilter=BEST", "NONE, FAST, ACCURATE"),
                           ("use_denoising=maybe", "expected 1/0"),
                           ("preview_denoising_start_sample=-1", "preview_denoising_start_sample must be in")):
        r = run("render", str(npz), "-o", str(tmp_path / "x.exr"), "--set", value, check=False)
        assert r.returncode == 2 and message in r.stderr and "Traceback" not in r.stderr, r.stderr
    import os

    missing, r = render("missing", env={**os.environ, "PARALLAX_OIDN_LIBRARY": str(tmp_path / "none.so")})
    assert "OpenImageDenoise not found" in r.stderr and "not denoised" in r.stdout
    np.testing.assert_array_equal(rgb(missing, "Combined"), noisy)
    np.testing.assert_array_equal(rgb(missing, "Noisy Image"), noisy)
