"""Render passes: what Parallax registers with Blender, from the core's pass table.

Each row of ``parallax_core.PASSES`` becomes a Blender pass named by its label, with its
channel ids; a row with a ``setting`` is there only while that setting is on. The engine's
passes (``core`` False: Noisy Image) are filled by engine/final.py, not read from the film. The view layer
chooses among them: Blender's own toggles for its own passes, Cycles' Denoising Data for the
denoising passes, and one ``use_pass_<name>`` toggle (properties.py) for each of the others.
"""
import functools
from collections import namedtuple

from . import core

# Blender's own passes: Combined is always there; Depth and Normal have the view layer's toggles.
BLENDER_TOGGLES = {"Combined": None, "Depth": "use_pass_z", "Normal": "use_pass_normal"}
# Cycles' Denoising Data: these core passes under Cycles' names, which the compositor's Denoise
# node is linked to.
DENOISING_DATA = {"normal": "Denoising Normal", "albedo": "Denoising Albedo"}
DENOISING_TOGGLE = "use_pass_denoising_data"

# A Blender pass: its name, channels, Blender's chan_id and type, the core pass that fills it,
# and enabled(scene, view_layer).
Pass = namedtuple("Pass", "name channels chan_id type core enabled")


def blender_type(channel_ids):
    return {"RGBA": "COLOR", "RGB": "COLOR", "XYZ": "VECTOR"}.get(channel_ids, "VALUE")


def toggle_name(row):
    """The view-layer toggle (on ``view_layer.parallax``) of a pass row that has one."""
    return f"use_pass_{row.name}"


def has_own_toggle(row):
    """A row that Blender's toggles and Denoising Data do not cover gets ``use_pass_<name>``;
    the engine's passes (Noisy Image) have none: they are there while their setting is on, as
    Cycles' Noisy Image is while Use Denoising is."""
    return row.core and row.label not in BLENDER_TOGGLES and DENOISING_DATA.get(row.name) != row.label


def _enabled(row, layer_on):
    def enabled(scene, view_layer):
        return ((not row.setting or core.load().setting_on(row.setting, getattr(scene.parallax, row.setting)))
                and layer_on(view_layer))
    return enabled


@functools.lru_cache(maxsize=None)
def blender_passes():
    """Every pass Parallax can give Blender, in film order."""
    found = []
    for row in core.load().PASSES:
        def add(name, layer_on):
            found.append(Pass(name, row.channels, row.channel_ids, blender_type(row.channel_ids), row.name,
                              _enabled(row, layer_on)))

        if row.name in DENOISING_DATA:
            add(DENOISING_DATA[row.name], lambda layer: getattr(layer.parallax, DENOISING_TOGGLE))
        if row.label in BLENDER_TOGGLES:
            toggle = BLENDER_TOGGLES[row.label]
            add(row.label, (lambda layer: True) if toggle is None else
                (lambda layer, toggle=toggle: getattr(layer, toggle)))
        elif has_own_toggle(row):
            add(row.label, lambda layer, name=toggle_name(row): getattr(layer.parallax, name))
        elif not row.core:
            add(row.label, lambda layer: True)
    return tuple(found)


def by_name():
    return {p.name: p for p in blender_passes()}


def enabled(scene, view_layer):
    return [p for p in blender_passes() if p.enabled(scene, view_layer)]


def register_passes(engine, scene, view_layer):
    """RenderEngine.update_render_passes: tells Blender (and the compositor) our passes."""
    for p in enabled(scene, view_layer):
        engine.register_pass(scene, view_layer, p.name, p.channels, p.chan_id, p.type)
