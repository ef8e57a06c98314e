"""parallax_core.denoise: our ctypes wrapper of OIDN's C API (issue 36). A synthetic image of
known clean value (an albedo checker, two normals with different shading) times noise of mean
1: the denoiser must remove most of the error, each input pass must help where its pass has
the detail, the prefilter must help with noisy auxiliary passes, and a missing library must
say so clearly. Device selection (CUDA on a GPU render) is checked against a fake library."""
import ctypes
import sys
import types

import numpy as np
import pytest

from parallax_core import denoise


def synthetic(h=96, w=128, seed=1):
    """(clean, noisy, albedo, normal): the clean image is albedo x shading, the shading 1 where
    the normal is +Z (left half) and 0.25 where it is +X (right half)."""
    y, x = np.mgrid[0:h, 0:w]
    checker = ((x // 8 + y // 8) % 2).astype(np.float32)
    albedo = np.stack([0.2 + 0.6 * checker, 0.3 + 0.4 * checker, np.full((h, w), 0.5, np.float32)], -1)
    right = x >= w // 2
    normal = np.zeros((h, w, 3), np.float32)
    normal[..., 2], normal[..., 0] = np.where(right, 0.0, 1.0), np.where(right, 1.0, 0.0)
    shading = np.where(right, 0.25, 1.0)[..., None] * (0.8 + 0.2 * np.sin(y / 30.0))[..., None]
    clean = (albedo * shading).astype(np.float32)
    noise = np.random.default_rng(seed).gamma(2.0, 0.5, clean.shape)  # mean 1, variance 0.5
    return clean, (clean * noise).astype(np.float32), albedo.astype(np.float32), normal


def relmse(image, reference):
    return float(np.mean((image[..., :3] - reference) ** 2 / (reference ** 2 + 1e-2)))


@pytest.fixture(scope="module")
def denoiser():
    available, why = denoise.availability()
    if not available:
        pytest.fail(f"OIDN is part of the environment (pyoidn in scripts/requirements.txt): {why}")
    d = denoise.Denoiser("cpu")
    yield d
    d.close()


def test_denoising_removes_most_of_the_noise(denoiser):
    clean, noisy, albedo, normal = synthetic()
    before = relmse(noisy, clean)
    after = relmse(denoiser.denoise(noisy, albedo, normal), clean)  # Cycles' defaults
    assert after < 0.02 * before, (before, after)
    assert denoiser.device_kind == "cpu" and denoiser.version.startswith("2.")


def test_each_input_pass_helps_where_it_has_the_detail(denoiser):
    """The albedo pass keeps the checker, the normal pass the shading edge."""
    clean, noisy, albedo, normal = synthetic()
    error = {mode: relmse(denoiser.denoise(noisy, albedo, normal, mode, "NONE"), clean)
             for mode in denoise.INPUT_PASSES}
    assert error["RGB"] < 0.3 * relmse(noisy, clean)
    assert error["RGB_ALBEDO"] < 0.6 * error["RGB"], error
    assert error["RGB_ALBEDO_NORMAL"] < 0.6 * error["RGB_ALBEDO"], error


def test_prefilter_with_noisy_auxiliary_passes(denoiser):
    """Taking noisy albedo and normal as clean (NONE) leaves their noise in; FAST and ACCURATE
    (Cycles' prefilters) do better."""
    clean, noisy, albedo, normal = synthetic()
    rng = np.random.default_rng(5)
    noisy_albedo = (albedo * rng.gamma(8.0, 1 / 8.0, albedo.shape)).astype(np.float32)
    noisy_normal = (normal + rng.normal(0.0, 0.15, normal.shape)).astype(np.float32)
    error = {p: relmse(denoiser.denoise(noisy, noisy_albedo, noisy_normal, "RGB_ALBEDO_NORMAL", p), clean)
             for p in denoise.PREFILTERS}
    assert error["ACCURATE"] < 0.7 * error["NONE"] and error["FAST"] < 0.7 * error["NONE"], error


def test_alpha_is_kept_and_inputs_are_checked(denoiser):
    clean, noisy, albedo, normal = synthetic(24, 32)
    rgba = np.concatenate([noisy, np.linspace(0, 1, 24 * 32, dtype=np.float32).reshape(24, 32, 1)], axis=2)
    out = denoiser.denoise(rgba, albedo, normal, quality="FAST")
    assert out.shape == rgba.shape and np.array_equal(out[..., 3], rgba[..., 3])
    with pytest.raises(ValueError, match="needs the normal pass"):
        denoiser.denoise(noisy, albedo, None)
    with pytest.raises(ValueError, match="albedo of shape"):
        denoiser.denoise(noisy, albedo[:5], normal)
    with pytest.raises(ValueError, match="denoising_prefilter must be one of NONE, FAST, ACCURATE"):
        denoiser.denoise(noisy, albedo, normal, prefilter="BEST")
    with pytest.raises(ValueError, match="expected \\(H, W, 3 or 4\\)"):
        denoiser.denoise(noisy[..., 0])
    assert np.isfinite(denoiser.denoise(np.where(clean > 0.3, np.nan, noisy), albedo, normal)).all()


def test_a_missing_library_is_a_clear_error(monkeypatch, tmp_path):
    monkeypatch.setenv(denoise.ENV_LIBRARY, str(tmp_path / "libOpenImageDenoise.so.2"))
    with pytest.raises(denoise.DenoiserUnavailable, match="OpenImageDenoise not found.*no .*libOpenImageDenoise"):
        denoise.Denoiser("cpu")
    found, why = denoise.availability()  # what the panel and the CLI show
    assert not found and "PARALLAX_OIDN_LIBRARY" in why
    not_a_library = tmp_path / "junk.so"
    not_a_library.write_text("not a library")
    monkeypatch.setenv(denoise.ENV_LIBRARY, str(not_a_library))
    with pytest.raises(denoise.DenoiserUnavailable, match="did not load"):
        denoise.load_library()
    monkeypatch.delenv(denoise.ENV_LIBRARY)
    monkeypatch.setattr(denoise.importlib.util, "find_spec", lambda name: None)
    monkeypatch.delitem(sys.modules, "bpy", raising=False)
    with pytest.raises(denoise.DenoiserUnavailable, match="pip install pyoidn"):
        denoise.load_library()


def test_blenders_library_comes_before_pyoidn(monkeypatch, tmp_path):
    """A running Blender's OIDN first (bpy module: bpy/lib above its scripts; a Blender binary:
    lib/ beside it), then pyoidn's."""
    name = denoise._library_name()
    module_lib = tmp_path / "bpy" / "lib"
    module_lib.mkdir(parents=True)
    (module_lib / name).write_bytes(b"")
    scripts = tmp_path / "bpy" / "5.0" / "scripts" / "modules" / "bpy"
    scripts.mkdir(parents=True)
    fake = types.SimpleNamespace(__file__=str(scripts / "__init__.py"),
                                 app=types.SimpleNamespace(binary_path=str(tmp_path / "blender" / "blender")))
    monkeypatch.delenv(denoise.ENV_LIBRARY, raising=False)
    monkeypatch.setitem(sys.modules, "bpy", fake)
    found = denoise.library_candidates()
    assert found[0] == ("Blender (bpy)", str(module_lib / name))
    assert found[1] == ("Blender", str(tmp_path / "blender" / "lib" / name))
    assert [where for where, _ in found[2:]] == ["pyoidn"]


class FakeOidn:
    """The C functions Denoiser calls, recording the devices it asks for."""

    def __init__(self, cuda_supported, cuda_works=True):
        self.cuda_supported, self.cuda_works = cuda_supported, cuda_works
        self.new_devices, self.error = [], 0

    def oidnIsCUDADeviceSupported(self, device_id):
        return self.cuda_supported

    def oidnNewDevice(self, kind):
        self.new_devices.append(kind)
        self.error = 5 if kind == 3 and not self.cuda_works else 0  # OIDN_ERROR_UNSUPPORTED_HARDWARE
        return len(self.new_devices)

    def oidnSetDeviceBool(self, device, name, value):
        assert (name, value) == (b"setAffinity", False) and self.new_devices[-1] == 1  # CPU only

    def oidnSetDeviceInt(self, device, name, value):
        assert name == b"numThreads" and value == 2 and self.new_devices[-1] == 1

    def oidnCommitDevice(self, device):
        pass

    def oidnGetDeviceError(self, device, message):
        error, self.error = self.error, 0
        return error

    def oidnReleaseDevice(self, device):
        pass

    def oidnGetDeviceInt(self, device, name):
        return 20501 if name == b"version" else 0


@pytest.mark.parametrize("render_device, cuda_supported, cuda_works, expected", [
    ("cpu", True, True, "cpu"),                    # a lavapipe render denoises on the CPU
    ("discrete-gpu", True, True, "cuda"),          # a GPU render on OIDN's CUDA device
    ("discrete-gpu", False, True, "cpu"),          # no CUDA device in OIDN: the CPU
    ("discrete-gpu", True, False, "cpu"),          # CUDA reported but failing: the CPU
])
def test_device_selection(render_device, cuda_supported, cuda_works, expected):
    assert denoise.choose_device(render_device, lambda: cuda_supported) == (
        "cuda" if render_device != "cpu" and cuda_supported else "cpu")
    lib = FakeOidn(cuda_supported, cuda_works)
    d = denoise.Denoiser(render_device, library=lib, threads=2)
    assert d.device_kind == expected and d.version == "2.5.1"
    assert lib.new_devices[-1] == {"cpu": 1, "cuda": 3}[expected]  # OIDN_DEVICE_TYPE_CPU / _CUDA
    assert lib.new_devices[0] == (3 if render_device != "cpu" and cuda_supported else 1)


def test_settings_pick_the_film_passes():
    values = {"use_denoising": True, "denoising_input_passes": "RGB_ALBEDO", "denoising_prefilter": "FAST",
              "denoising_quality": "HIGH", "use_preview_denoising": False, "preview_denoising_input_passes": "RGB",
              "preview_denoising_prefilter": "NONE", "preview_denoising_quality": "FAST"}
    assert denoise.film_passes(values) == ("combined", "albedo")
    assert denoise.film_passes(values, preview=True) == ()
    assert denoise.film_passes({**values, "use_preview_denoising": True}, preview=True) == ("combined",)
    assert denoise.settings_of(values) == (True, "RGB_ALBEDO", "FAST", "HIGH")


def test_ctypes_releases_the_gil_while_oidn_runs():
    """The viewport's denoise thread relies on it: CDLL calls drop the GIL (PyDLL would not)."""
    lib, _, _ = denoise.load_library()
    assert isinstance(lib, ctypes.CDLL) and not isinstance(lib, ctypes.PyDLL)


def test_cancel_stops_oidn_and_the_filter_still_works(denoiser):
    """The viewport cancels a denoise when an edit comes in (OIDN's progress monitor)."""
    clean, noisy, albedo, normal = synthetic()
    asked = []

    def cancel():
        asked.append(1)
        return True

    with pytest.raises(denoise.DenoiseCancelled):
        denoiser.denoise(noisy, albedo, normal, "RGB_ALBEDO", "FAST", "BALANCED", cancel=cancel)
    assert asked
    out = denoiser.denoise(noisy, albedo, normal, "RGB_ALBEDO", "FAST", "BALANCED", cancel=lambda: False)
    assert relmse(out, clean) < 0.1 * relmse(noisy, clean)
