"""Denoising with Intel Open Image Denoise (OIDN) through its C API, by ctypes.

Why our own wrapper of the C API: Blender ships OIDN as a shared library (bpy 5.0.1:
``bpy/lib/libOpenImageDenoise.so.2``, OIDN 2.3.3) but no Python binding of it, and the PyPI
package ``pyoidn`` bundles the library with CPU and CUDA devices; the C API (OIDN 2.x,
``oidn.h``) is the same in both, so one small wrapper uses whichever is there. The library,
in this order (``library_candidates``):

1. ``PARALLAX_OIDN_LIBRARY`` if set (that file only: tests and unusual installs);
2. the library of the Blender that runs us (``bpy`` loaded): next to the ``bpy`` module
   (``bpy/lib``) or in ``lib/`` next to the Blender binary (``bpy.app.binary_path``);
3. the one bundled by ``pyoidn`` (``pyoidn/oidn/lib``), found without importing pyoidn:
   the add-on's wheels carry it for Blenders without OIDN (Debian's 3.4) and the CLI;
4. none: ``DenoiserUnavailable`` saying what was tried; callers render on undenoised.

The filter is OIDN's "RT" (ray-traced images) in HDR mode, fed Combined and, as Cycles'
``denoising_input_passes`` says, the Denoising Albedo and Normal passes; the prefilter follows
Cycles' ``denoising_prefilter`` (intern/cycles/integrator/denoiser_oidn.cpp): NONE takes the
auxiliary passes as clean (``cleanAux``), FAST denoises them with the colour (noisy aux),
ACCURATE first denoises albedo and normal with filters of their own, then takes them as clean
(OIDN 2 documentation, "Denoising with prefiltering").
"""
from __future__ import annotations

import ctypes
import importlib.util
import os
import sys
import threading

import numpy as np

INPUT_PASSES = ("RGB", "RGB_ALBEDO", "RGB_ALBEDO_NORMAL")
PREFILTERS = ("NONE", "FAST", "ACCURATE")
# Cycles' denoising_quality -> OIDNQuality (oidn.h: OIDN_QUALITY_FAST 4, BALANCED 5, HIGH 6).
QUALITIES = {"HIGH": 6, "BALANCED": 5, "FAST": 4}

_DEVICE_CPU, _DEVICE_CUDA = 1, 3  # OIDNDeviceType
_FORMAT_FLOAT3 = 3                # OIDNFormat
_ERRORS = {1: "unknown error", 2: "invalid argument", 3: "invalid operation", 4: "out of memory",
           5: "unsupported hardware", 6: "cancelled"}

ENV_LIBRARY = "PARALLAX_OIDN_LIBRARY"


class DenoiserUnavailable(RuntimeError):
    """No usable OIDN library: the message says what was looked for."""


class DenoiseError(RuntimeError):
    """OIDN reported an error (its message)."""


class DenoiseCancelled(DenoiseError):
    """``cancel()`` returned True while the filter ran (the viewport: an edit came in)."""


# bool (*OIDNProgressMonitorFunction)(void* userPtr, double n): false cancels the filter.
_PROGRESS = ctypes.CFUNCTYPE(ctypes.c_bool, ctypes.c_void_p, ctypes.c_double)


def _library_name():
    if sys.platform == "darwin":
        return "libOpenImageDenoise.2.dylib"
    if sys.platform == "win32":
        return "OpenImageDenoise.dll"
    return "libOpenImageDenoise.so.2"


def library_candidates():
    """(where, path) pairs in the search order of the module docstring."""
    name = _library_name()
    override = os.environ.get(ENV_LIBRARY)
    if override:
        return [(f"${ENV_LIBRARY}", override)]
    found = []
    bpy = sys.modules.get("bpy")
    if bpy is not None:
        # bpy as a Python module: bpy/lib, above bpy's scripts (bpy/5.0/scripts/modules/bpy).
        folder = os.path.dirname(getattr(bpy, "__file__", None) or "")
        for _ in range(5 if folder else 0):
            if os.path.exists(os.path.join(folder, "lib", name)):
                found.append(("Blender (bpy)", os.path.join(folder, "lib", name)))
                break
            folder = os.path.dirname(folder)
        binary = getattr(getattr(bpy, "app", None), "binary_path", "") or ""
        if binary:  # a Blender binary: lib/ beside it (Blender 4 and 5 Linux builds)
            found.append(("Blender", os.path.join(os.path.dirname(binary), "lib", name)))
    try:
        spec = importlib.util.find_spec("pyoidn")
    except (ImportError, ValueError):
        spec = None
    if spec is not None and spec.submodule_search_locations:
        for root in spec.submodule_search_locations:
            found.append(("pyoidn", os.path.join(root, "oidn", "lib", name)))
    return found


def _bind(lib):
    """Declares the C signatures used here (OIDN 2.x oidn.h)."""
    p, s, c, b, i = ctypes.c_void_p, ctypes.c_size_t, ctypes.c_char_p, ctypes.c_bool, ctypes.c_int
    signatures = {
        "oidnNewDevice": (p, [i]),
        "oidnCommitDevice": (None, [p]),
        "oidnReleaseDevice": (None, [p]),
        "oidnGetDeviceError": (i, [p, ctypes.POINTER(ctypes.c_char_p)]),
        "oidnGetDeviceInt": (i, [p, c]),
        "oidnSetDeviceBool": (None, [p, c, b]),
        "oidnSetDeviceInt": (None, [p, c, i]),
        "oidnIsCUDADeviceSupported": (b, [i]),
        "oidnNewBuffer": (p, [p, s]),
        "oidnWriteBuffer": (None, [p, s, s, p]),
        "oidnReadBuffer": (None, [p, s, s, p]),
        "oidnReleaseBuffer": (None, [p]),
        "oidnNewFilter": (p, [p, c]),
        "oidnSetFilterImage": (None, [p, c, p, i, s, s, s, s, s]),
        "oidnSetFilterBool": (None, [p, c, b]),
        "oidnSetFilterInt": (None, [p, c, i]),
        "oidnSetFilterProgressMonitorFunction": (None, [p, _PROGRESS, p]),
        "oidnCommitFilter": (None, [p]),
        "oidnExecuteFilter": (None, [p]),
        "oidnReleaseFilter": (None, [p]),
    }
    for fn, (restype, argtypes) in signatures.items():
        f = getattr(lib, fn)  # AttributeError: not an OIDN 2 library
        f.restype, f.argtypes = restype, argtypes
    return lib


_loaded = {}
_load_lock = threading.Lock()


def load_library():
    """(ctypes library, where, path) of the first candidate that loads; DenoiserUnavailable if
    none does. Cached per process (a library once loaded stays loaded)."""
    with _load_lock:
        candidates = library_candidates()
        tried = []
        for where, path in candidates:
            if path in _loaded:
                return _loaded[path], where, path
            if not os.path.exists(path):
                tried.append(f"{where}: no {path}")
                continue
            try:
                lib = _bind(ctypes.CDLL(path))
            except (OSError, AttributeError) as e:
                tried.append(f"{where}: {path} did not load ({e})")
                continue
            _loaded[path] = lib
            return lib, where, path
        if not candidates:
            tried.append("no Blender library and no pyoidn package (pip install pyoidn)")
        raise DenoiserUnavailable("OpenImageDenoise not found, denoising is off: " + "; ".join(tried))


def availability():
    """(True, "OpenImageDenoise from <where>") or (False, why not): for the panel and the CLI."""
    try:
        _, where, _ = load_library()
    except DenoiserUnavailable as e:
        return False, str(e)
    return True, f"OpenImageDenoise from {where}"


def choose_device(render_device_type, cuda_supported):
    """OIDN's device for a render on ``render_device_type`` (``Session.device_type``): CUDA when
    the render runs on a GPU and OIDN can make a CUDA device (``cuda_supported()``), else the
    CPU, as Cycles denoises on the render's GPU when it can (issue 36)."""
    if render_device_type != "cpu" and cuda_supported():
        return "cuda"
    return "cpu"


class Denoiser:
    """One OIDN device and its filters, for one thread at a time (the F12 worker, the
    viewport's denoise thread). ``device_type``: the render's ``Session.device_type``;
    ``threads``: the CPU device's thread count (None: all cores)."""

    def __init__(self, device_type="cpu", library=None, threads=None):
        self._threads = threads
        if library is None:
            library, self.source, self.path = load_library()
        else:
            self.source, self.path = "given", None
        self._lib = lib = library
        self.device_kind = choose_device(device_type, lambda: bool(lib.oidnIsCUDADeviceSupported(0)))
        self._device = None
        self._filters = {}  # (kind, width, height, options) -> filter
        self._cancel = None  # denoise()'s cancel, asked by OIDN's progress monitor
        self._monitor = _PROGRESS(lambda user, progress: not (self._cancel is not None and self._cancel()))
        self._buffers = {}  # (name, width, height) -> buffer
        if self.device_kind == "cuda":
            try:
                self._device = self._new_device(_DEVICE_CUDA)
            except DenoiseError:  # no usable CUDA device after all: the CPU
                self.device_kind = "cpu"
        if self._device is None:
            self._device = self._new_device(_DEVICE_CPU)
        v = lib.oidnGetDeviceInt(self._device, b"version")
        self.version = f"{v // 10000}.{v // 100 % 100}.{v % 100}"  # OIDN's, as major.minor.patch

    def _new_device(self, kind):
        device = self._lib.oidnNewDevice(kind)
        if not device:
            raise DenoiseError("OIDN could not create a device")
        if kind == _DEVICE_CPU:
            # No thread pinning: the renderer shares these cores, and asking TBB for the core
            # types (OIDN's CPUEngine does, for pinning) loads tbbbind and hwloc, which abort
            # Debian's Blender 3.4 (jemalloc; "free(): invalid pointer" in hwloc).
            self._lib.oidnSetDeviceBool(device, b"setAffinity", False)
            if self._threads:
                self._lib.oidnSetDeviceInt(device, b"numThreads", int(self._threads))
        self._lib.oidnCommitDevice(device)
        try:
            self._check(device)
        except DenoiseError:
            self._lib.oidnReleaseDevice(device)
            raise
        return device

    def _check(self, device=None):
        message = ctypes.c_char_p()
        code = self._lib.oidnGetDeviceError(device or self._device, ctypes.byref(message))
        if code == 6:  # OIDN_ERROR_CANCELLED
            raise DenoiseCancelled("OIDN: cancelled")
        if code:
            text = message.value.decode(errors="replace") if message.value else _ERRORS.get(code, str(code))
            raise DenoiseError(f"OIDN: {text}")

    def _buffer(self, name, width, height):
        key = (name, width, height)
        if key not in self._buffers:
            buffer = self._lib.oidnNewBuffer(self._device, width * height * 12)
            self._check()
            self._buffers[key] = buffer
        return self._buffers[key]

    def _filter(self, kind, width, height, images, options):
        """A committed "RT" filter with ``images`` {OIDN image name: buffer} and ``options``,
        kept for the next image of the same size and options (committing builds the network)."""
        key = (kind, width, height, tuple(sorted(images)), options)
        if key in self._filters:
            return self._filters[key]
        lib = self._lib
        f = lib.oidnNewFilter(self._device, b"RT")
        self._check()
        for name, buffer in images.items():
            lib.oidnSetFilterImage(f, name.encode(), buffer, _FORMAT_FLOAT3, width, height, 0, 0, 0)
        hdr, clean_aux, quality = options
        if hdr:
            lib.oidnSetFilterBool(f, b"hdr", True)
        lib.oidnSetFilterBool(f, b"cleanAux", clean_aux)
        lib.oidnSetFilterInt(f, b"quality", quality)
        lib.oidnSetFilterProgressMonitorFunction(f, self._monitor, None)
        lib.oidnCommitFilter(f)
        try:
            self._check()
        except DenoiseError:
            lib.oidnReleaseFilter(f)
            raise
        self._filters[key] = f
        return f

    def _write(self, buffer, image):
        data = np.ascontiguousarray(image[..., :3], dtype=np.float32)
        self._lib.oidnWriteBuffer(buffer, 0, data.nbytes, data.ctypes.data)

    def denoise(self, color, albedo=None, normal=None, input_passes="RGB_ALBEDO_NORMAL",
                prefilter="ACCURATE", quality="HIGH", cancel=None):
        """The denoised ``color`` ((H, W, 3|4) float, linear HDR; an alpha channel is kept as
        it is). ``albedo`` and ``normal`` ((H, W, 3)) are needed as ``input_passes`` says.
        ``cancel``: asked while OIDN runs (its progress monitor); True stops it, and this
        raises DenoiseCancelled."""
        self._cancel = cancel
        try:
            return self._denoise(color, albedo, normal, input_passes, prefilter, quality)
        finally:
            self._cancel = None

    def _denoise(self, color, albedo, normal, input_passes, prefilter, quality):
        if input_passes not in INPUT_PASSES:
            raise ValueError(f"denoising_input_passes must be one of {', '.join(INPUT_PASSES)}, got {input_passes!r}")
        if prefilter not in PREFILTERS:
            raise ValueError(f"denoising_prefilter must be one of {', '.join(PREFILTERS)}, got {prefilter!r}")
        if quality not in QUALITIES:
            raise ValueError(f"denoising_quality must be one of {', '.join(QUALITIES)}, got {quality!r}")
        color = np.asarray(color, dtype=np.float32)
        if color.ndim != 3 or color.shape[2] not in (3, 4) or color.shape[0] < 1 or color.shape[1] < 1:
            raise ValueError(f"denoise: colour of shape {color.shape}, expected (H, W, 3 or 4)")
        height, width = color.shape[:2]
        aux = {"albedo": albedo if input_passes != "RGB" else None,
               "normal": normal if input_passes == "RGB_ALBEDO_NORMAL" else None}
        for name, image in aux.items():
            wanted = name == "albedo" and input_passes != "RGB" or name == "normal" and input_passes == "RGB_ALBEDO_NORMAL"
            if wanted and image is None:
                raise ValueError(f"denoise: denoising_input_passes {input_passes} needs the {name} pass")
            if image is not None:
                image = np.asarray(image, dtype=np.float32)
                if image.ndim != 3 or image.shape[:2] != (height, width) or image.shape[2] < 3:
                    raise ValueError(f"denoise: {name} of shape {image.shape}, expected ({height}, {width}, 3)")
                aux[name] = image
        q = QUALITIES[quality]
        images = {"color": self._buffer("color", width, height)}
        self._write(images["color"], np.nan_to_num(color, nan=0.0, posinf=0.0, neginf=0.0))
        for name, image in aux.items():
            if image is not None:
                images[name] = self._buffer(name, width, height)
                self._write(images[name], np.nan_to_num(image))
                if prefilter == "ACCURATE":  # the auxiliary image denoised in place, on its own
                    f = self._filter(name, width, height, {name: images[name], "output": images[name]},
                                     (False, False, q))
                    self._lib.oidnExecuteFilter(f)
                    self._check()
        output = self._buffer("output", width, height)
        has_aux = len(images) > 1
        clean_aux = has_aux and prefilter != "FAST"  # NONE: as given; ACCURATE: prefiltered
        f = self._filter("color", width, height, {**images, "output": output}, (True, clean_aux, q))
        self._lib.oidnExecuteFilter(f)  # ctypes releases the GIL for the call
        self._check()
        out = np.empty((height, width, 3), np.float32)
        self._lib.oidnReadBuffer(output, 0, out.nbytes, out.ctypes.data)
        self._check()
        if color.shape[2] == 4:
            out = np.concatenate([out, color[..., 3:]], axis=2)
        return out

    def close(self):
        lib = self._lib
        for f in self._filters.values():
            lib.oidnReleaseFilter(f)
        for b in self._buffers.values():
            lib.oidnReleaseBuffer(b)
        self._filters, self._buffers = {}, {}
        if self._device:
            lib.oidnReleaseDevice(self._device)
            self._device = None

    def __del__(self):
        try:
            self.close()
        except Exception:
            pass


def settings_of(values, preview=False):
    """(enabled, input_passes, prefilter, quality) from setting values {name: value} (a dict
    of the SETTINGS rows, or an object with them as attributes): the F12 rows, or with
    ``preview`` the viewport's."""
    get = values.get if isinstance(values, dict) else (lambda name, default=None: getattr(values, name, default))
    prefix = "preview_" if preview else ""
    enabled = get("use_preview_denoising" if preview else "use_denoising")
    return (bool(enabled), get(f"{prefix}denoising_input_passes"), get(f"{prefix}denoising_prefilter"),
            get(f"{prefix}denoising_quality"))


def aux_passes(input_passes):
    """The core passes ``input_passes`` feeds the denoiser, besides Combined."""
    return {"RGB": (), "RGB_ALBEDO": ("albedo",), "RGB_ALBEDO_NORMAL": ("albedo", "normal")}[input_passes]


def film_passes(values, preview=False):
    """The film passes the denoiser reads with these settings (Combined and its inputs)."""
    enabled, input_passes, _, _ = settings_of(values, preview)
    return ("combined",) + aux_passes(input_passes) if enabled else ()


def denoise_images(images, values, denoiser, preview=False, cancel=None):
    """{"combined": denoised, "noisy_image": noisy} from film passes ``images`` ({name: array}
    with Combined and the inputs ``film_passes`` names) and the setting values."""
    _, input_passes, prefilter, quality = settings_of(values, preview)
    noisy = images["combined"]
    denoised = denoiser.denoise(noisy, images.get("albedo"), images.get("normal"), input_passes, prefilter, quality,
                                cancel)
    return {"combined": denoised, "noisy_image": noisy}
