"""Interactive viewport (Rendered shading): view_update / view_draw.

A worker thread owns the core sessions and renders progressively (``Session.render``
releases the GIL); Blender's thread only exports edits, hands them over and draws the
latest frame. An edit re-sends just the parts it touched (``Session.update(parts=...)``):
orbiting sends the camera, moving an object the instance transforms, a material slider the
materials. After each edit one frame of a smaller session (pixel size 2-8, chosen from the
measured frame time so it takes about ``PREVIEW_SECONDS``) is shown first, then the full
resolution refines. Full-size frames go in row bands (``final.band_rows``), so an edit
waits for one band, not a whole frame.

Start-up: before the path tracer's pipeline exists (compiling it takes seconds on lavapipe
with a cold shader cache), the first frame comes from the preview program (first-hit
shading, ``RenderParams.preview``, quick to compile) at the preview's pixel size, while the
path tracer compiles on a thread of its own (issue 9).

Denoising (Use Viewport Denoising): frames from Start Denoising on go to a denoise thread of
their own (``_DenoiseThread``), never Blender's or the render worker's: it denoises the newest
frame handed to it, dropping older ones, and shows the result if no edit came in meanwhile.
The coarse preview frame of an edit goes too, to a second denoise thread at normal priority
(small, so OIDN takes a fraction of a second of one core on it: the first denoised image comes
long before a full-size one, issue 36); the preview program's first-hit frame does not (it
has no noise). Within one scene state the image shown never gets coarser, and at a pixel size
showing denoised frames it shows no noisy ones again (as Cycles' viewport): a coarse denoised
frame gives way to the first full-size frame, noisy or not, and never replaces one. An edit
shows its new noisy frames at once and never waits for the denoiser.
"""
import dataclasses
import os
import threading
import time
import weakref

import numpy as np

from .. import core, properties, sync
from . import final

PREVIEW_SECONDS = 0.03
# OIDN's CPU threads in the viewport: a quarter of the cores (one on this 2-core machine), on
# the denoise thread at nice +10, so the render keeps the cores edits need (issue 36).
VIEWPORT_DENOISE_THREADS = max(1, (os.cpu_count() or 1) // 4)
# The coarse preview frames' denoise thread keeps the render's priority: at nice +10 a
# 0.2-CPU-second denoise waits seconds behind the render's threads (and a loaded machine's).
COARSE_DENOISE_NICE, FULL_DENOISE_NICE = 0, 10
PUBLISH_SECONDS = 0.05  # at most this often a new image for the viewport

_workers = weakref.WeakSet()  # live workers, stopped on unregister


def _region_size(context):
    return max(1, context.region.width), max(1, context.region.height)


def _camera_key(camera):
    """What a viewport camera is made of, rounded: a change of it is a camera update."""
    values = (getattr(camera, f.name) for f in dataclasses.fields(camera))
    return tuple(v if isinstance(v, str) else np.round(np.asarray(v, dtype=np.float64), 7).tobytes() for v in values)


def changed_parts(depsgraph):
    """The SceneData parts an evaluated depsgraph's updates touch."""
    import bpy

    parts = set()
    for update in depsgraph.updates:
        data = update.id
        if isinstance(data, bpy.types.Object):
            if data.type == "LIGHT":
                parts.add("lights")
            elif data.type == "CAMERA":
                continue  # the viewport's own view is checked on every draw
            else:
                if update.is_updated_geometry:
                    parts.add("geometry")
                if update.is_updated_transform:
                    parts.add("instances")
                if update.is_updated_shading:
                    parts.add("materials")
        elif isinstance(data, bpy.types.Material):
            parts.add("materials")  # not the world: its bake costs a fraction of a second
        elif isinstance(data, (bpy.types.ShaderNodeTree, bpy.types.Image)):
            parts.update(("materials", "lights"))  # node groups and images may be the world's too
        elif isinstance(data, (bpy.types.Light, bpy.types.World)):
            parts.add("lights")
        elif isinstance(data, (bpy.types.Mesh, bpy.types.Curve, bpy.types.MetaBall, bpy.types.Collection)):
            parts.add("geometry")
    return parts


class _Worker(threading.Thread):
    """Renders the viewport image; takes scene, camera, size and settings changes at any time."""

    def __init__(self, device, params, target_samples, pixel_size, display="combined", denoise=None):
        super().__init__(name="parallax-viewport", daemon=True)
        self.device = device
        # latest (image (H, W, 4), samples, pixel size, generation, denoised)
        self.frame = None
        self._denoise = denoise  # the denoising settings {name: value} with use_preview_denoising on, or None
        # _DenoiseThread of the full-size frames, and of the coarse ones: made with their first frame
        self._denoiser = self._coarse_denoiser = None
        self.denoised_frames = 0  # frames the denoiser showed (tests, bench/)
        self.first_denoised_at = None  # perf_counter() of the first (bench/)
        self.first_full_denoised_at = None  # ... of the first at pixel size 1 (bench/)
        self.denoise_message = None  # why frames are not denoised (no OIDN), or None
        self.error = None
        self.done = False      # the sample target is reached and nothing is pending
        self._lock = threading.Condition()
        self._scene, self._parts, self._size, self._params = None, set(), None, params
        self._target, self._pixel_size = target_samples, pixel_size
        self._display, self._display_changed = display, False  # the core pass shown (viewport_pass)
        self._stopped = False
        self._full = self._preview = None  # sessions: full size, and pixel size 2-8 (or none)
        self._preview_factor = 1
        self._frame_seconds = None  # measured frame time at full size
        self._band_rows = 16
        self._published = 0.0
        self.generation = 0    # counts the hand-overs; a frame shows the scene of its generation
        self._submitted = {}   # generation -> when it was handed over
        self._rendering = 0    # generation the sessions hold now
        self.latencies = []    # (parts, seconds from the hand-over to its first image)
        self.first_frame_at = self.first_full_frame_at = None  # perf_counter() (bench/)
        _workers.add(self)

    # -- Blender's thread --

    @property
    def display(self):
        return self._display

    def submit(self, scene=None, parts=(), size=None, params=None, target=None, pixel_size=None,
               display=None, denoise=False):
        """``denoise``: new denoising settings (a dict, or None for off); False: unchanged."""
        with self._lock:
            if denoise is not False:
                self._denoise = denoise
            if display is not None and display != self._display:
                # Another pass of the same session: shown from the next frame on, samples kept
                # (Guiding Lobes aside: _film_passes).
                self._display, self._display_changed = display, True
            if scene is not None:
                self._scene = scene
                self._parts |= set(parts)
            if size is not None:
                self._size = size
            if params is not None:
                self._params = params
            if target is not None:
                self._target = target
            if pixel_size is not None:
                self._pixel_size = pixel_size
            self.generation += 1
            self._submitted[self.generation] = (tuple(sorted(parts)), time.perf_counter())
            self.done = False
            if (scene is not None and parts) or size is not None:
                self._cancel()  # an edit does not wait for the band in progress
            self._lock.notify()
            return self.generation

    def _cancel(self):
        """Stops the worker's render call in progress at its next dispatch (as F12 does)."""
        for session in (self._full, self._preview):
            if session is not None:
                session.cancel()

    def stop(self, wait=2.0):
        with self._lock:
            self._stopped = True
            self._cancel()
            self._lock.notify()
        for denoiser in (self._denoiser, self._coarse_denoiser):
            if denoiser is not None:
                denoiser.stop()
        if self.is_alive() and threading.current_thread() is not self:
            self.join(wait)

    def edited_since(self, generation):
        """Something was handed over after ``generation`` (its frames are outdated)."""
        return self.generation != generation or self._stopped

    def denoise_pending(self):
        """A frame is with the denoiser (view_draw keeps redrawing until it is shown)."""
        return any(d is not None and d.pending() for d in (self._denoiser, self._coarse_denoiser))

    def _show_denoised(self, generation, samples, pixel_size, image):
        """The denoise thread's result: shown if no edit came in since its frame, nothing finer
        of the same scene state is shown (a full-size frame, noisy or not, over a coarse denoised
        one) and nothing newer at its pixel size is shown denoised."""
        with self._lock:
            if self._stopped or generation != self._rendering or generation != self.generation:
                return
            shown = self.frame
            if shown is not None and shown[3] == generation and (
                    shown[2] < pixel_size or shown[2] == pixel_size and shown[4] and shown[1] >= samples):
                return
            if self._display != "combined":
                return
            self.frame = (image, samples, pixel_size, generation, True)
            self.denoised_frames += 1
            now = time.perf_counter()
            self.first_denoised_at = self.first_denoised_at or now
            if pixel_size == 1:
                self.first_full_denoised_at = self.first_full_denoised_at or now

    # -- worker thread --

    def run(self):
        try:
            while self._step():
                pass
        except Exception as e:  # shown by view_draw
            self.error = e
            self.done = True

    def _take_changes(self):
        """Waits until there is something to do; returns the pending changes (None: stop)."""
        with self._lock:
            while not self._stopped and (self._full is None and self._size is None or
                                         self.done and not self._parts and self._size is None):
                self._lock.wait()
            if self._stopped:
                return None
            changes = (self._scene, self._parts, self._size, self._params, self._target, self._pixel_size)
            self._parts, self._size = set(), None
            self._rendering = self.generation
            return changes

    def _step(self):
        changes = self._take_changes()
        if changes is None:
            return False
        scene, parts, size, params, target, pixel_size = changes
        edited = bool(parts) or size is not None
        Session = core.load().Session
        if size is not None:  # a new viewport size: new sessions, which need the whole scene
            self._full, self._preview, self._preview_factor = Session(*size, self.device), None, 1
            # A technique switched on renders its fallback (techniques off) while it compiles.
            self._full.background_compile = True
            self._frame_seconds, parts = None, None
        factor = pixel_size or self._auto_pixel_size()
        preview_parts = parts
        if edited and factor != self._preview_factor:
            width, height = self._full.width, self._full.height
            self._preview = Session(max(1, width // factor), max(1, height // factor),
                                    self.device) if factor > 1 else None
            self._preview_factor, preview_parts = factor, None
        for session, session_parts in ((self._full, parts), (self._preview, preview_parts)):
            if session is not None:
                # The quick preview frame skips the irradiance cache, ADRRS and guiding: their
                # prepare, estimate and training frames would cost many frames; the full-size
                # session shows them. There guiding keeps training while the image accumulates
                # (training frames would leave the viewport empty), and its field survives
                # camera moves (Session keeps it; edits to geometry or lights restart it).
                session.set_params(**({**params, "guiding_training_spp": 0} if session is self._full
                                      else _without_techniques(params)))
                if edited:
                    session.update(scene, parts=None if session_parts is None else sorted(session_parts))
        self._full.passes = self._film_passes()  # a change starts the film over
        with self._lock:  # a stop() before this returns here; one after it cancels these sessions
            if self._stopped:
                return False
        if edited and self._preview is not None:
            # Combined, and the passes the viewport's denoiser reads of its frames (albedo and
            # normal add nothing measurable to its frame time).
            self._preview.passes = list(self._denoise_passes()) or ["combined"]
            if not self._full.pipeline_ready:
                self._quick_frame(params)
            self._preview.render(1)
            self._publish(self._preview, self._preview_factor)
        samples = self._full.samples
        # Done at the sample target, or once adaptive sampling found every pixel converged.
        if (target and samples >= target or self._full.converged) and not self._full.fallback_film:
            shown = self.frame
            denoising = bool(self._denoise) and self._display == "combined" and self.denoise_message is None
            if (self._display_changed or shown is None or shown[1] != samples or shown[2] != 1
                    or shown[4] != denoising):
                # The last frame may have come too soon to publish, or to go to the busy denoiser
                # (shown noisy, an older denoised frame would replace it), or denoising was
                # switched since.
                self._publish(self._full, 1, last=True)
            self.done = True
            return True
        seconds = self._render_frame()
        if seconds is None:
            return True  # an edit came in: the frame is dropped, the edit handled first
        if samples > 0 or parts is not None:  # not the first frame of a new scene (compiles)
            previous = self._frame_seconds
            self._frame_seconds = seconds if previous is None else 0.5 * (previous + seconds)
        if edited or time.perf_counter() - self._published >= PUBLISH_SECONDS:
            self._publish(self._full, 1)
        return True

    def _quick_frame(self, params):
        """Publishes a frame of the preview program while the path tracer compiles (on the
        core's worker thread; a failed compile is raised by the render that needs it)."""
        self._full.warm()
        self._preview.set_params(**_without_techniques(params), preview=True)
        self._preview.render(1)
        self._publish(self._preview, self._preview_factor, denoise=False)  # first-hit: no noise
        self._preview.set_params(**_without_techniques(params), preview=False)

    def _render_frame(self):
        """One full-size frame in row bands of about BAND_SECONDS; its duration, or None if
        an edit arrived in between."""
        full, total = self._full, 0.0
        while True:
            start = time.perf_counter()
            done = full.render_rows(self._band_rows)
            seconds = time.perf_counter() - start
            total += seconds
            self._band_rows = final.band_rows(self._band_rows, seconds, full.height)
            if done or full.converged:  # converged: adaptive sampling has no pixel left to sample
                return total
            with self._lock:
                if self._stopped or self._parts or self._size is not None:
                    return None

    def _auto_pixel_size(self):
        """Smallest of 1, 2, 4, 8 whose preview frame takes about PREVIEW_SECONDS, from the
        measured full-size frame time (4 before there is one)."""
        if self._frame_seconds is None:
            return 4
        for factor in (1, 2, 4, 8):
            if self._frame_seconds / (factor * factor) <= PREVIEW_SECONDS:
                return factor
        return 8

    def _film_passes(self):
        """The full-size session's film: every pass, so that another Viewport Pass shows at
        once with the samples kept, but Guiding Lobes only while it is shown. That pass has
        pipelines of its own (TECH_GUIDING_LOBES: a ray into the regions' TLAS per pixel),
        which every guided frame would pay for (lavapipe: twice the cold compile, frames
        1.2x); showing it starts the film over, the trained field kept."""
        display = self._display
        return [p.name for p in core.load().PASSES
                if p.core and (p.name != "guiding_lobes" or display == "guiding_lobes")]

    def _denoise_passes(self):
        """The film passes the viewport's denoiser reads (none with denoising off)."""
        denoise = self._denoise
        return core.load().denoise.film_passes(denoise, preview=True) if denoise else ()

    def _publish(self, session, pixel_size, last=False, denoise=True):
        """Shows ``session``'s image; with denoising, hands it to the denoise thread: a coarse
        preview frame always (the first of its scene state; small, so its passes read fast), a
        full-size one when the thread is idle (reading the auxiliary passes for a frame it
        would drop costs frame time) or when it is the ``last`` before the sample target.
        ``denoise``: False for the preview program's first-hit frame."""
        display = self._display
        if display != "combined" and session is not self._full:
            return  # the quick preview renders without the techniques whose passes these are
        self._display_changed = False
        # Noisy Image: Combined as the film has it, never denoised.
        image = _as_rgba(session.read("combined" if display == "noisy_image" else display))
        samples = session.samples
        frame = (image, samples, pixel_size, self._rendering, False)
        values = self._denoise
        denoising = bool(values) and display == "combined" and self.denoise_message is None
        with self._lock:  # shown before the denoiser has it: an edit's noisy frame comes first
            shown = self.frame
            # This scene state shows a denoised frame at least as fine: the next comes from the denoiser.
            if not (denoising and shown is not None and shown[3] == self._rendering and shown[4]
                    and shown[2] <= pixel_size):
                self.frame = frame
        if (denoising and denoise and not session.fallback_film
                and samples >= max(1, values["preview_denoising_start_sample"])
                and (last or pixel_size > 1 or self._denoiser is None or not self._denoiser.pending())):
            images = {"combined": image}
            for name in self._denoise_passes()[1:]:
                images[name] = session.read(name)
            if pixel_size > 1:
                if self._coarse_denoiser is None:
                    self._coarse_denoiser = _DenoiseThread(self, session.device_type, COARSE_DENOISE_NICE,
                                                          "parallax-viewport-denoise-coarse")
                    self._coarse_denoiser.start()
                denoiser = self._coarse_denoiser
            else:
                if self._denoiser is None:
                    self._denoiser = _DenoiseThread(self, session.device_type, FULL_DENOISE_NICE)
                    self._denoiser.start()
                denoiser = self._denoiser
            denoiser.submit((self._rendering, samples, pixel_size, images, values))
        self._published = time.perf_counter()
        self.first_frame_at = self.first_frame_at or self._published
        if pixel_size == 1:
            self.first_full_frame_at = self.first_full_frame_at or self._published
        with self._lock:
            for generation in [g for g in self._submitted if g <= self._rendering]:
                parts, handed_over = self._submitted.pop(generation)
                if generation == self._rendering:
                    self.latencies.append((parts, self._published - handed_over))


class _DenoiseThread(threading.Thread):
    """Denoises the newest frame handed to it (older ones are dropped) with one OIDN device
    of its own, and hands the result to the worker. OIDN's call releases the GIL (ctypes).
    It runs at ``nice`` (+10 for full-size frames: a lower CPU priority than the render) on
    VIEWPORT_DENOISE_THREADS threads, and an edit cancels the denoise in progress (OIDN's
    progress monitor), so the edit's frames get the cores at once."""

    def __init__(self, worker, device_type, nice, name="parallax-viewport-denoise"):
        super().__init__(name=name, daemon=True)
        self._worker = weakref.ref(worker)
        self._device_type, self._nice = device_type, nice
        self._cond = threading.Condition()
        self._job, self._busy, self._stopped = None, False, False

    def submit(self, job):
        with self._cond:
            self._job = job
            self._cond.notify()

    def pending(self):
        with self._cond:
            return self._busy or self._job is not None

    def stop(self):
        with self._cond:
            self._stopped = True
            self._cond.notify()

    def run(self):
        denoise = core.load().denoise
        denoiser = None
        try:
            if self._nice:
                os.setpriority(os.PRIO_PROCESS, threading.get_native_id(), self._nice)  # this thread (Linux)
        except (AttributeError, OSError):
            pass
        try:
            while True:
                with self._cond:
                    while self._job is None and not self._stopped:
                        self._cond.wait()
                    if self._stopped:
                        return
                    job, self._job, self._busy = self._job, None, True
                worker = self._worker()
                if worker is None:
                    return
                generation, samples, pixel_size, images, values = job
                try:
                    if generation == worker.generation:  # not already edited away
                        denoiser = denoiser or denoise.Denoiser(self._device_type, threads=VIEWPORT_DENOISE_THREADS)
                        out = denoise.denoise_images(
                            images, values, denoiser, preview=True,
                            cancel=lambda: self._stopped or worker.edited_since(generation))
                        worker._show_denoised(generation, samples, pixel_size, out["combined"])
                except denoise.DenoiseCancelled:
                    pass  # an edit came in: its frames come next
                except (denoise.DenoiserUnavailable, denoise.DenoiseError) as e:
                    worker.denoise_message = f"{e}; the viewport is not denoised"
                    return
                finally:
                    del worker
                    with self._cond:
                        self._busy = False
        finally:
            with self._cond:
                self._busy, self._job = False, None
            if denoiser is not None:
                denoiser.close()


def _without_techniques(params):
    """``params`` with every technique switched off (the quick preview frames)."""
    return {**params, **{row.name: core.load().setting_off(row.name) for row in properties.technique_switches()}}


def _as_rgba(image):
    """A pass as the float RGBA image view_draw shows: one channel as grey, alpha 1."""
    image = np.asarray(image, dtype=np.float32)
    if image.shape[2] == 4:
        return image
    rgb = np.repeat(image[..., :1], 3, axis=2) if image.shape[2] == 1 else image[..., :3]
    return np.concatenate([rgb, np.ones_like(rgb[..., :1])], axis=2)


class ViewportRender:
    """One 3D viewport's Parallax state (kept on its RenderEngine instance)."""

    def __init__(self):
        self.exporter = sync.SceneExporter(sync.world.PREVIEW_BAKE_WIDTHS)
        self.worker = None
        self._camera_key = None
        self._size = None
        self._settings = None
        self._texture = None  # (frame it shows, GPUTexture)
        self._reported = set()

    def _settings_of(self, scene):
        s = scene.parallax
        params = s.render_params()
        # The viewport's adaptive sampling (Cycles' preview settings) in the core's fields.
        params["use_adaptive_sampling"] = s.use_preview_adaptive_sampling
        params["adaptive_threshold"] = core.load().adaptive_threshold(s.preview_adaptive_threshold,
                                                                      s.viewport_samples)
        pixel_size = 0 if s.viewport_start_pixel_size == "AUTO" else int(s.viewport_start_pixel_size)
        # The viewport's denoising rows (use_preview_denoising, preview_denoising_*), not F12's.
        denoise = {name: value for name, value in s.engine_values().items()
                   if name.startswith("preview_denois") or name == "use_preview_denoising"} \
            if s.use_preview_denoising else None
        return params, s.viewport_samples, pixel_size, s.device, s.viewport_pass, denoise

    def update(self, engine, context, depsgraph):
        """view_update: the scene changed (or this is the first call)."""
        scene = depsgraph.scene
        params, target, pixel_size, device, display, denoise = self._settings_of(scene)
        try:
            # A worker stopped by an error (a scene past the memory budget) starts over on
            # the next edit, which may have fixed it.
            if self.worker is None or device != self.worker.device or self.worker.error is not None:
                self.free()
                width, height = _region_size(context)
                camera = sync.camera.viewport_camera(context, depsgraph)
                data, warnings = self.exporter.full(depsgraph, width, height, view_camera=camera)
                self.worker = _Worker(device, params, target, pixel_size, display, denoise)
                self.worker.submit(data, parts={"geometry"}, size=(width, height))
                self.worker.start()
                self._camera_key, self._size = _camera_key(camera), (width, height)
            else:
                parts = changed_parts(depsgraph)
                warnings = []
                if parts:
                    parts, warnings = self.exporter.update(depsgraph, parts)
                if parts or (params, target, pixel_size, denoise) != self._settings:
                    self.worker.submit(self.exporter.data, parts=parts, params=params,
                                       target=target, pixel_size=pixel_size, display=display,
                                       denoise=denoise)
                elif display != self.worker.display:
                    self.worker.submit(display=display)
        except (ImportError, ValueError, RuntimeError, MemoryError) as e:
            engine.update_stats("", f"Parallax: {e}")
            engine.report({"ERROR"}, f"Parallax: {e}")
            return
        self._settings = (params, target, pixel_size, denoise)
        for message in warnings:
            if message not in self._reported:  # once per viewport, not on every edit
                self._reported.add(message)
                engine.report({"WARNING"}, f"Parallax: {message}")

    def draw(self, engine, context, depsgraph):
        """view_draw: hand over view changes, draw the newest frame, ask for more."""
        worker = self.worker
        if worker is None:
            return
        size = _region_size(context)
        camera = sync.camera.viewport_camera(context, depsgraph)
        key = _camera_key(camera)
        if size != self._size or key != self._camera_key:
            data = self.exporter.data
            data.camera, data.width, data.height = camera, size[0], size[1]
            if size != self._size:
                worker.submit(data, parts={"camera"}, size=size)
            else:
                worker.submit(data, parts={"camera"})
            self._size, self._camera_key = size, key
        if worker.error is not None:
            engine.update_stats("", f"Parallax error: {worker.error}")
            if f"error: {worker.error}" not in self._reported:  # once, not on every redraw
                self._reported.add(f"error: {worker.error}")
                engine.report({"ERROR"}, f"Parallax: {worker.error}")
            return
        frame = worker.frame
        if frame is not None:
            self._draw_frame(engine, depsgraph.scene, frame, size)
            image, samples, pixel_size, _, denoised = frame
            target = self._settings[1] if self._settings else 0
            status = f"Sample {samples}" + (f"/{target}" if target else "")
            if denoised:
                status += " (denoised)"
            elif worker.denoise_message:
                status += " | not denoised: no OpenImageDenoise"
            engine.update_stats("", status if pixel_size == 1 else f"{status} (preview)")
        if not worker.done or worker.denoise_pending():
            engine.tag_redraw()

    def _draw_frame(self, engine, scene, frame, size):
        import gpu
        from gpu_extras.presets import draw_texture_2d

        if self._texture is None or self._texture[0] is not frame:
            image = np.ascontiguousarray(frame[0][::-1], dtype=np.float32)  # GPU rows go bottom-up
            height, width = image.shape[:2]
            buffer = gpu.types.Buffer("FLOAT", width * height * 4, image.ravel())
            self._texture = (frame, gpu.types.GPUTexture((width, height), format="RGBA16F", data=buffer))
        gpu.state.blend_set("ALPHA_PREMULT")
        engine.bind_display_space_shader(scene)
        draw_texture_2d(self._texture[1], (0, 0), size[0], size[1])
        engine.unbind_display_space_shader()
        gpu.state.blend_set("NONE")

    def free(self):
        if self.worker is not None:
            self.worker.stop()
            self.worker = None
        self._texture = None


def stop_all():
    """Stops every viewport worker (add-on unregistration, Blender quitting)."""
    for worker in list(_workers):
        worker.stop()
