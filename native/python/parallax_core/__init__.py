"""Parallax native core: a Vulkan ray-tracing path tracer.

    from parallax_core import Session, SceneData
    s = Session(256, 256)              # device: PARALLAX_DEVICE or "auto"
    s.set_params(method="mis", samples_per_frame=4)
    s.update(scene)                    # SceneData or its flatten() dict
    s.update(scene, parts={"camera"})  # after an edit: only what changed (see PARTS)
    s.render(16)                       # 16 frames, GIL released
    image = s.read("combined")         # float32 (H, W, 4)
"""
from __future__ import annotations

import atexit
import dataclasses
import operator
import os

from ._native import (LIMITS, METHODS, DeviceMemoryError, background_compiles, devices, light_tree_min_lights, memory,
                      primitive_order, set_light_tree_min_lights, set_memory_budget, validation_enabled,
                      validation_messages, wait_for_background_compiles)
from ._native import Session as _NativeSession
from ._native import _RenderParams
from .scene import PART_KEYS, PARTS, parts_set

__all__ = ["Session", "RenderParams", "devices", "METHODS", "PASSES", "PARTS", "LIMITS", "DeviceMemoryError",
           "memory", "set_memory_budget", "validation_enabled", "validation_messages", "light_tree_min_lights",
           "set_light_tree_min_lights", "primitive_order", "background_compiles", "wait_for_background_compiles"]

# A pipeline still compiling on a worker thread when the process tears down crashed it: wait.
atexit.register(wait_for_background_compiles)

PASSES = tuple(_NativeSession.pass_names())
HEURISTICS = ("balance", "power")
ADRRS_ESTIMATES = ("ic", "image")  # px::ADRRS_ESTIMATE_IC, ADRRS_ESTIMATE_IMAGE
GUIDING_FITS = ("cpu", "device", "auto")  # px::GUIDING_FIT_CPU, GUIDING_FIT_DEVICE, GUIDING_FIT_AUTO
SIGNED_FIELDS = ("guiding_probe_x", "guiding_probe_y")  # -1: the image centre


@dataclasses.dataclass
class RenderParams:
    """Integrator settings; mirrors px::RenderParams (native/src/render/session.h)."""

    method: str = "mis"             # pt | nee | mis
    mis_heuristic: str = "power"    # balance | power
    samples_per_frame: int = 1
    max_depth: int = 8              # bounces (Cycles' "max bounces")
    depth_leeway: int = 4           # delta bounces not counted towards max_depth
    rr_start_depth: int = 3         # Russian roulette from this bounce on; 0 = off
    light_samples: int = 1          # NEE samples per vertex
    light_tree: bool = True         # local lights picked through the light tree (Cycles' Light Tree); off: by power
    seed: int = 0
    preview: bool = False           # first-hit shading only (preview.rgen): compiles in a fraction
                                    # of the path tracer's time; the viewport's first frame
    # Irradiance cache (thesis 3.2.3, 4.4; px::IcParams in shaders/shared/techniques.h, which
    # checks the ranges).
    ic: bool = False                # on/off
    ic_accuracy: float = 0.2        # Ward's a: influence radius a*R, weight threshold 1/a
    ic_min_radius: float = 0.1      # lower clamp of the harmonic-mean distance R (metres)
    ic_create_prob: float = 0.01    # an uncovered diffuse vertex queues a new entry
    ic_update_prob: float = 1e-5    # per path and frame: refresh one entry (round robin)
    ic_nee_samples: int = 1         # light samples per vertex of the entries' hemisphere paths
    ic_gradients: bool = False      # Ward & Heckbert rotational + translational gradients
    ic_gradient_max: float = 5.0    # clamp of the relative gradients' length
    ic_visibility_check: bool = True  # skip entries in front of the query point (Ward 1988)
    ic_prepare_frames: int = 50     # frames that only fill the cache before accumulation
    ic_capacity: int = 65536        # entries
    ic_rebuild_interval: int = 1    # frames between BLAS rebuilds (refits in between)
    ic_highlight: bool = False      # IC Irradiance pass shows the colour only (fig. 4.13)
    # Adjoint-driven Russian roulette and splitting (thesis 3.2.4, 4.5; px::AdrrsParams). It
    # builds the irradiance cache for its adjoint, with or without ic.
    adrrs: bool = False             # on/off
    adrrs_splitting: bool = True    # split paths above the weight window (else roulette only)
    adrrs_window: float = 5.0       # s: delta+ = s * delta-, delta- = 2C / (1 + s)
    adrrs_rr_min: float = 0.1       # lowest survival probability below the window
    adrrs_max_splits: int = 10      # extra paths per pixel sample
    adrrs_estimate_spp: int = 4     # ic: estimate frames; image: samples before the first estimate
    adrrs_estimate: str = "ic"      # pixel estimate: ic (NEE + cache at the first hit) | image (blurred)
    adrrs_ic_glossy: bool = True    # the ic estimate reads the cache at glossy vertices too
    # Path guiding with parallax-aware vMF mixtures (thesis 3.2.5-3.2.8, 4.6; Ruppert et al. 2020;
    # px::GuidingParams in shaders/shared/guiding.h, checked by px::validate_guiding_params).
    guiding: bool = False           # on/off
    guiding_prob: float = 0.5       # one-sample MIS: probability of sampling the VMM (else the BSDF)
    guiding_parallax: bool = True   # lobes aim at their target points (thesis eq. 4.5)
    guiding_training_spp: int = 32  # 1-spp training frames before the image accumulates; 0 = keep training
    guiding_min_samples: int = 64  # a region fits once it has accumulated this many lit samples
    guiding_max_components: int = 16  # lobes per region (1..16)
    guiding_split_merge: bool = True  # split and merge lobes (Ruppert et al. 2020, sec. 4)
    guiding_region_splits: int = 3  # 2^k initial regions (halvings of the scene box), refined as they gather light
    guiding_region_threshold: int = 10000  # lit samples (non-zero weight) before a region splits; 0 = never
    guiding_max_regions: int = 4096  # adaptive refinement stops here
    guiding_probe_x: int = -1       # pixel of the Guiding Lobes inset; -1 = image centre
    guiding_probe_y: int = -1
    guiding_lobes_phase: float = -1.0  # Guiding Lobes spheres: at the regions' centres (-1) or moving through them, [0, 1) (fig. 4.20)
    guiding_fit: str = "auto"       # where mixtures are fitted: cpu (readback) | device (compute passes) | auto

    def validate(self) -> None:
        if self.method not in METHODS:
            raise ValueError(f"unknown method {self.method!r} (choose from {', '.join(METHODS)})")
        if self.mis_heuristic not in HEURISTICS:
            raise ValueError(f"unknown MIS heuristic {self.mis_heuristic!r} (balance or power)")
        if self.adrrs_estimate not in ADRRS_ESTIMATES:
            raise ValueError(f"unknown adrrs_estimate {self.adrrs_estimate!r} (ic or image)")
        if self.guiding_fit not in GUIDING_FITS:
            raise ValueError(f"unknown guiding_fit {self.guiding_fit!r} (cpu, device or auto)")
        for f in dataclasses.fields(self):
            value = getattr(self, f.name)
            if f.name in SIGNED_FIELDS:
                if isinstance(value, bool) or not isinstance(value, int) or not -1 <= value < 2**31:
                    raise ValueError(f"{f.name} must be an integer >= -1, got {value!r}")
            elif f.type in ("int", "bool"):
                if not isinstance(value, int) or value < 0 or value >= 2**32 or (f.type == "bool" and value > 1):
                    kind = "a boolean" if f.type == "bool" else "a non-negative integer"
                    raise ValueError(f"{f.name} must be {kind}, got {value!r}")
            elif f.type == "float":
                if isinstance(value, bool) or not isinstance(value, (int, float)):
                    raise ValueError(f"{f.name} must be a number, got {value!r}")

    def native(self):
        """The px::RenderParams these settings make (the core validates the ranges)."""
        p = _RenderParams()
        for f in dataclasses.fields(self):
            value = getattr(self, f.name)
            if f.name == "method":
                value = METHODS.index(value)
            elif f.name == "mis_heuristic":
                value = HEURISTICS.index(value)
            elif f.name == "adrrs_estimate":
                value = ADRRS_ESTIMATES.index(value)
            elif f.name == "guiding_fit":
                value = GUIDING_FITS.index(value)
            elif f.type == "bool":
                value = int(bool(value))
            elif f.type == "float":
                value = float(value)
            setattr(p, f.name, value)
        return p


class Session(_NativeSession):
    """A render session on one Vulkan device (see the module docstring)."""

    def __init__(self, width: int, height: int, device: str | None = None):
        size = []
        for name, value in (("width", width), ("height", height)):
            try:
                size.append(operator.index(value))
            except TypeError:
                size.append(None)
            if isinstance(value, bool) or size[-1] is None or not 1 <= size[-1] <= 16384:
                raise ValueError(f"image size: {name} must be an integer in 1..16384, got {value!r}")
        device = device or os.environ.get("PARALLAX_DEVICE", "auto")
        super().__init__(*size, str(device))
        self._params = RenderParams()
        self.warnings: list[str] = []
        self._part_warnings: dict[str, list[str]] = {}  # the scene's warnings by part

    @property
    def params(self) -> RenderParams:
        return dataclasses.replace(self._params)

    def set_params(self, **changes) -> None:
        """Change integrator settings (RenderParams fields); resets accumulation if any differ."""
        unknown = set(changes) - {f.name for f in dataclasses.fields(RenderParams)}
        if unknown:
            raise TypeError(f"unknown render parameter(s): {', '.join(sorted(unknown))}")
        params = dataclasses.replace(self._params, **changes)
        params.validate()
        self._set_params(params.native())
        self._params = params

    def update(self, scene, spatial_order: bool = True, parts=None) -> list[str]:
        """Upload a SceneData (or its flatten() dict). Returns and keeps the warnings.

        ``parts=None`` replaces the whole scene. Otherwise ``parts`` names the parts that
        changed since the last update (an iterable of PARTS: "geometry", "instances",
        "materials", "lights" (analytic lights and the world), "camera"): only those are
        validated, flattened and sent, and the session re-prepares and re-uploads only them
        and what depends on them, keeping the rest (a camera move uploads the camera alone;
        only "geometry" rebuilds BLASes). The other parts must still fit: indices into
        meshes, materials and textures refer to the kept ones. Needs an earlier whole update.
        Either way accumulation restarts, and the warnings returned are the whole scene's.
        ``spatial_order`` reorders triangles and instances for devices whose BVH builder splits
        them in input order (lavapipe); on GPUs, whose drivers build their own trees, the
        scene's order is kept either way.
        """
        selected = parts_set(parts)
        whole = selected == frozenset(PARTS)
        if hasattr(scene, "_flatten_parts"):
            scene, by_part = scene._flatten_parts(selected)
        elif hasattr(scene, "flatten"):
            by_part = {"geometry": list(scene.validate() or [])}
            scene = scene.flatten()
        else:
            by_part = {}
        if not isinstance(scene, dict):
            raise TypeError("update() takes a SceneData or a dict of arrays")
        if not whole:
            keys = {k for p in selected for k in PART_KEYS[p]}
            scene = {k: v for k, v in scene.items() if k in keys}
        native = self._update(scene, spatial_order, [] if whole else [p for p in PARTS if p in selected])
        if whole:
            self._part_warnings = {}
        self._part_warnings.update({p: by_part.get(p, []) for p in selected})
        warnings = [w for p in PARTS for w in self._part_warnings.get(p, [])] + list(native)
        self.warnings = warnings
        return warnings

    def read_all(self) -> dict:
        """Every pass, by name."""
        return {name: self.read(name) for name in PASSES}

    def test_sampling(self, routine: int, params, count: int, seed: int = 0, directions=None, constants=None):
        """Run shaders/tests/sampling_test.comp; returns float32 (count, 2, 4). Test use only.
        ``constants``: float32 values (a multiple of 4) the routine reads after the samples."""
        import numpy as np

        data = []
        if directions is not None or constants is not None:
            d = np.zeros((count, 2, 4), np.float32)
            if directions is not None:
                d[:, 0, :3] = directions
            data = d.ravel()
            if constants is not None:
                data = np.concatenate([data, np.asarray(constants, np.float32).ravel()])
            data = data.tolist()
        return self._test_sampling(routine, [float(x) for x in params], count, seed, data)
