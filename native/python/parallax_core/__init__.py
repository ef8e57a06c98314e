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
import collections
import dataclasses
import operator
import os

import numpy

from ._native import (LIMITS, DeviceMemoryError, background_compiles, devices, light_tree_min_lights, memory, primitive_order,
                      pixel_filter_table, set_light_tree_min_lights, set_memory_budget, validation_enabled,
                      validation_messages, wait_for_background_compiles)
from ._native import Session as _NativeSession
from ._native import _PASSES, _SETTINGS, _make_params, _setting_index
from . import denoise  # noqa: F401  (OIDN: parallax_core.denoise)
from . import nodes  # noqa: F401  (material node programs: parallax_core.nodes)
from . import node_fields, sky  # noqa: F401  (graphs evaluated on the host: worlds, lights)
from .scene import PART_KEYS, PARTS, parts_set

__all__ = ["Session", "RenderParams", "UNBIASED_LIGHT_PATHS", "SETTINGS", "PASSES", "setting", "devices", "METHODS",
           "TECHNIQUES", "technique_switch", "setting_on", "setting_off", "SYNONYMS", "synonym", "resolve_synonyms",
           "PARTS", "LIMITS",
           "DeviceMemoryError", "memory", "set_memory_budget", "validation_enabled", "validation_messages",
           "light_tree_min_lights", "set_light_tree_min_lights", "primitive_order", "pixel_filter_table",
           "background_compiles",
           "wait_for_background_compiles", "adaptive_threshold"]

# A pipeline still compiling on a worker thread when the process tears down crashed it: wait.
atexit.register(wait_for_background_compiles)

# The core's tables (native/src/render/params.cpp and each technique's module), in order: the
# base path tracer's settings first, then the irradiance cache's, ADRRS' and guiding's.
# type: bool | int | float | enum; min/max: None for bool and enum; items: (name, label,
# description) of an enum; panel: the UI panel ("" = none); group: the sub-panel inside it
# ("" = the panel itself); unit: "" | "time" | "length" | "pixel"; core: a RenderParams field (False for
# the engine's samples and time_limit).
Setting = collections.namedtuple(
    "Setting", "name technique type default min max items label tooltip panel group unit core")
SETTINGS = tuple(Setting(**row) for row in _SETTINGS)
# Passes in film order; label: the Blender pass and EXR layer name; setting: the setting
# that enables the pass ("" = always); core: read from the film by Session.read (False: made by
# the engine in Python, as the denoiser's Noisy Image, parallax_core.denoise).
Pass = collections.namedtuple("Pass", "name label channels channel_ids description technique setting core")
PASSES = tuple(Pass(**row) for row in _PASSES)


def setting(name: str) -> Setting:
    """The row of setting ``name``; ValueError listing the names if there is none."""
    return SETTINGS[_setting_index(name)]


METHODS = tuple(item[0] for item in setting("method").items)
# The techniques in table order (the base path tracer's rows are no technique's).
TECHNIQUES = tuple(dict.fromkeys(s.technique for s in SETTINGS if s.technique != "base"))


def technique_switch(technique: str) -> Setting:
    """The row that switches ``technique`` on: the first of its table (``ic``, ``rrs``,
    ``guiding``), a bool or an enum with an item "off", as the core reads it (technique_on)."""
    for row in SETTINGS:
        if row.technique == technique and technique != "base":
            return row
    raise ValueError(f"unknown technique {technique!r} (techniques: {', '.join(TECHNIQUES)})")


def setting_on(name: str, value) -> bool:
    """Whether ``value`` of the switch ``name`` (a technique's, or the setting of a pass) turns
    on what it switches: a bool row's True, an enum row's any item but "off" (rrs: adrrs and
    ears), as the core reads a switch (not 0)."""
    return value != "off" if setting(name).type == "enum" else bool(value)


def setting_off(name: str):
    """The value of the switch ``name`` that turns it off: False, or an enum's "off"."""
    return "off" if setting(name).type == "enum" else False


# Settings by an older name, taken wherever settings come in by name (Session.set_params,
# --set for .npz and .blend scenes, the add-on's older .blend files) and never stored:
# name -> (the setting, {the old boolean: the setting's value}). adrrs was ADRRS' switch
# before rrs (off | adrrs | ears) replaced it (issue 34).
SYNONYMS = {"adrrs": ("rrs", {True: "adrrs", False: "off"})}


def _boolean(value):
    """``value`` as a bool where a bool row takes it (a bool, or the integers 0 and 1), else None."""
    if isinstance(value, (bool, numpy.bool_)):
        return bool(value)
    try:
        index = operator.index(value)
    except TypeError:
        return None
    return bool(index) if index in (0, 1) else None


def synonym(name: str, value):
    """(setting, value) that ``name=value`` sets: a synonym's setting and value (SYNONYMS), or
    ``(name, value)`` unchanged. ValueError naming the synonym for a value it does not take."""
    if name not in SYNONYMS:
        return name, value
    target, values = SYNONYMS[name]
    flag = _boolean(value)
    if flag is None:
        raise ValueError(f"{name} must be a boolean ({name}=1 sets {target}={values[True]}, {name}=0 sets "
                         f"{target}={values[False]}), got {value!r}")
    return target, values[flag]


def resolve_synonyms(changes: dict) -> dict:
    """``changes`` ({name: value}) with every synonym replaced by its setting (synonym); a
    synonym and its setting given together must agree (ValueError naming both)."""
    out = {}
    for name, value in changes.items():
        target, value = synonym(name, value)
        if target != name:
            if target in changes and changes[target] != value:
                raise ValueError(f"{name}={changes[name]!r} sets {target}={value!r}, which contradicts "
                                 f"{target}={changes[target]!r}")
            if target in out:
                continue
        out[target] = value
    return out


def adaptive_threshold(threshold: float, samples: int) -> float:
    """The noise threshold to give the core: ``threshold``, or for 0 (automatic) Cycles' choice
    from the sample target, max(0.001, 1 / samples) (the core alone, without a target, takes
    0.001). F12, the viewport and the CLI pass theirs through this."""
    if threshold > 0 or samples <= 0:
        return threshold
    return max(0.001, 1.0 / samples)
_TYPES = {"bool": bool, "int": int, "float": float, "enum": str}


def _validate(self) -> None:
    """Checks every value's type, range and enum name in the core (ValueError naming it)."""
    _make_params(dataclasses.asdict(self))


def _native_params(self):
    """The px::RenderParams these settings make, checked by the core."""
    return _make_params(dataclasses.asdict(self))


# Integrator settings: px::RenderParams (native/src/render/params.h), one field per core row
# of SETTINGS, at the row's default; enumerations by name (method="mis").
RenderParams = dataclasses.make_dataclass(
    "RenderParams",
    [(s.name, _TYPES[s.type], dataclasses.field(default=s.default)) for s in SETTINGS if s.core],
    namespace={"validate": _validate, "native": _native_params, "__module__": __name__,
               "__doc__": "Integrator settings, one field per core row of SETTINGS (see setting(name))."})


# The light-path settings under which a render estimates the scene's radiance without bias,
# through a one-pixel box filter: Max Bounces alone ends paths (no kind budget binds), no
# sample is clamped and no glossy lobe blurred. Cycles' defaults (Diffuse 4, Glossy 4, Clamp
# Indirect 10, Filter Glossy 1, Blackman-Harris 1.5 px), which are the table's, are biased:
# tests and benches that compare estimators or meet references pin these, as they pin Max Bounces.
UNBIASED_LIGHT_PATHS = {"diffuse_bounces": 1024, "glossy_bounces": 1024, "transmission_bounces": 1024,
                        "sample_clamp_direct": 0.0, "sample_clamp_indirect": 0.0, "blur_glossy": 0.0,
                        "pixel_filter_type": "BOX", "filter_width": 1.0}


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
        """Change integrator settings (RenderParams fields, or a synonym: ``adrrs=True`` sets
        ``rrs="adrrs"``, see SYNONYMS); resets accumulation if any differ."""
        changes = resolve_synonyms(changes)
        unknown = set(changes) - {f.name for f in dataclasses.fields(RenderParams)}
        if unknown:
            raise TypeError(f"unknown render parameter(s): {', '.join(sorted(unknown))}")
        params = dataclasses.replace(self._params, **changes)
        self._set_params(params.native())  # the core checks every value
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
        """Every pass the film holds (``passes``; not the engine's Noisy Image), by name."""
        return {name: self.read(name) for name in self.passes}

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
