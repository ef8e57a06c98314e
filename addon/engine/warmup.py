"""Warms the pipelines a scene needs before its first render (issue 32, item 5).

When a file is loaded or Parallax is picked as the render engine, the scene is exported at a
few pixels (its materials and lights decide the pipelines' scene features), and a worker
thread uploads it to a small session and starts compiling, on the core's own worker threads,
the pipelines the scene's settings need and their fallback with the techniques off
(``Session.warm``), then renders one frame of those pixels (lavapipe compiles a pipeline's code
at its first dispatch). Pipelines are shared by every session of the process, so the first F12
or viewport frame finds them compiled, or compiling already, instead of starting a 10-40 s
compile on lavapipe with a cold shader cache.
"""
import threading

import bpy

from .. import core, passes, sync
from .final import film_passes

WARM_PIXELS = 8
_thread = None  # the last warm-up's worker: one at a time
_owner = object()  # msgbus subscription owner


def _warm(data, params, device, film):
    try:
        parallax_core = core.load()
        session = parallax_core.Session(WARM_PIXELS, WARM_PIXELS, device)
        session.passes = sorted(film)  # F12's film: some passes have pipelines of their own
        session.set_params(**params)
        session.update(data)
        session.warm()
        # lavapipe compiles a pipeline's code at its first dispatch, shared by every session
        # (sun_room, cold: the first F12 frame took 6.9 s after warm() alone, 0.08 s after this).
        session.render(1)
    except Exception:  # noqa: BLE001 - the render that needs the scene reports what is wrong
        pass


def warm_scene(scene=None):
    """Starts warming the pipelines of ``scene`` (the context's by default) if its engine is
    Parallax; returns the worker thread, or None when nothing was started."""
    global _thread
    scene = scene or getattr(bpy.context, "scene", None)
    if scene is None or scene.render.engine != "PARALLAX" or (_thread is not None and _thread.is_alive()):
        return None
    try:
        depsgraph = bpy.context.evaluated_depsgraph_get()
        data, _ = sync.export_scene(depsgraph, WARM_PIXELS, WARM_PIXELS)
        settings = scene.parallax
        params = settings.render_params()
        film = film_passes({p.core for p in passes.enabled(scene, bpy.context.view_layer)},
                           settings.engine_values() if settings.use_denoising else None)
    except Exception:  # noqa: BLE001 - an export error is reported by the render itself
        return None
    # Not a daemon: the interpreter's exit waits for its upload rather than unwinding it
    # inside a native call.
    _thread = threading.Thread(target=_warm, args=(data, params, settings.device, film), name="parallax-warm")
    _thread.start()
    return _thread


def _warm_later():
    warm_scene()
    return None  # a one-shot timer


@bpy.app.handlers.persistent
def _on_load(_filepath=None):
    bpy.app.timers.register(_warm_later, first_interval=0.5)


def _on_engine_change():
    bpy.app.timers.register(_warm_later, first_interval=0.5)


def join(timeout=None):
    """Waits for the warm-up's upload and frame (compiles started for pipelines that frame does
    not use go on in the core; parallax_core waits for those at exit)."""
    if _thread is not None:
        _thread.join(timeout)


def register():
    bpy.app.handlers.load_post.append(_on_load)
    if bpy.app.timers is not None and not bpy.app.background:  # the add-on enabled in a running Blender
        bpy.app.timers.register(_warm_later, first_interval=1.0)
    bpy.msgbus.subscribe_rna(key=(bpy.types.RenderSettings, "engine"), owner=_owner, args=(),
                             notify=_on_engine_change)


def unregister():
    bpy.msgbus.clear_by_owner(_owner)
    if _on_load in bpy.app.handlers.load_post:
        bpy.app.handlers.load_post.remove(_on_load)
    join(10.0)
