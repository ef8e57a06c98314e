"""F12 and background (``blender -b -f``) renders: progressive, cancellable.

A worker thread drives the core (its calls release the GIL) and keeps the latest snapshot
of the passes; Blender's thread copies snapshots into the render result about twice a second
and polls ``test_break``, so a cancel returns within ``POLL_SECONDS`` with the last snapshot
as the partial image. The worker traces each frame in row bands of about ``BAND_SECONDS``
and stops between them; a cancel also calls ``Session.cancel()``, which stops the band in
progress at its next dispatch, so no long dispatch keeps the CPU busy after a cancel.
"""
import threading
import time

import numpy as np

from .. import core, passes, sync

UPDATE_SECONDS = 0.5
POLL_SECONDS = 0.05
BAND_SECONDS = 0.1
JOIN_SECONDS = 10.0  # the longest render() waits for a cancelled worker's band to stop


class RenderReport:
    """What the latest render reported. Background renders have no other way to hand it to
    the caller (bpy.ops.render.render returns FINISHED either way); the CLI and tests read it."""

    def __init__(self):
        self.errors, self.warnings = [], []
        self.samples, self.cancelled = 0, False
        self.denoised, self.denoise_message = False, None  # Combined denoised; how, or why not
        self.rendering_at = None  # time.time() when the first band of samples was in (compiled)
        self.finished_at = None  # time.time() when render() returned to Blender
        self.worker_running = False  # the worker thread still ran when render() returned


last_report = RenderReport()

# parallax export: when set, render() hands (SceneData, warnings) to it instead of rendering,
# so the exported file is exactly what an F12 render would upload.
scene_hook = None

# parallax render: a stream (stderr) that also gets the progress line; Blender as a Python
# module prints no render stats of its own.
progress_stream = None


def stop_requested(engine):
    return engine.test_break()


def render_size(render):
    scale = render.resolution_percentage / 100.0
    return max(1, int(render.resolution_x * scale)), max(1, int(render.resolution_y * scale))


def border_region(render, width, height):
    """(x, y, w, h) of the border in pixels (y from the bottom), or None for the whole frame.
    Truncates like Blender's own render rectangle (``disprect``), which sizes the result."""
    if not render.use_border:
        return None
    x0, x1 = int(render.border_min_x * width), int(render.border_max_x * width)
    y0, y1 = int(render.border_min_y * height), int(render.border_max_y * height)
    if x1 <= x0 or y1 <= y0 or (x1 - x0, y1 - y0) == (width, height):
        return None
    return x0, y0, x1 - x0, y1 - y0


def band_rows(rows, seconds, height):
    """Rows for the next band so it takes about BAND_SECONDS, given that ``rows`` took
    ``seconds`` (growing at most 4x a step: a band that compiled the pipeline was slow)."""
    scale = min(4.0, BAND_SECONDS / max(seconds, 1e-4))
    return max(1, min(height, int(rows * scale)))


def film_passes(core_passes, denoise=None):
    """The passes an F12 keeps in its film: the core passes of the enabled Blender passes
    (Noisy Image is the film's Combined) and the denoiser's inputs. They decide some
    pipelines too (the Guiding Lobes pass has its own), so the warm-up asks for the same."""
    film = set(core_passes) - {"noisy_image"}
    if denoise:
        film |= set(core.load().denoise.film_passes(denoise))
    return film


class _Worker(threading.Thread):
    """Renders frames until the sample count, the time limit or ``stop()``; keeps snapshots.
    With ``denoise`` (the denoising settings {name: value}, use_denoising on) the last
    snapshot is denoised here, on this thread, as Cycles denoises F12 at the end: Combined gets
    the denoised image and Noisy Image the film's; the progressive ones show the noisy image in
    both. A cancelled render is not denoised."""

    def __init__(self, session, samples, time_limit, core_passes, denoise=None):
        super().__init__(name="parallax-render", daemon=True)
        self.session = session
        self.samples = samples  # the target (frames rendered while a technique compiled do not count)
        self.time_limit = time_limit
        self.denoise = denoise
        self.wanted_passes = set(core_passes) - {"noisy_image"}
        self.core_passes = film_passes(core_passes, denoise)
        self.denoising = False  # the denoiser runs now (the status line says so)
        self.denoised = False   # the last snapshot's Combined is denoised
        self.denoise_message = None  # why it is not (no OIDN, an OIDN error), or the denoiser used
        self.rows_per_band = max(1, session.height // 16)  # adapted to the measured band time
        self.rendering_at = None  # time.time() when the first band was in
        self.snapshot = None  # (samples, seconds, rays per second, {core pass: image}, stats)
        self.error = None
        self._stop_event = threading.Event()
        self.start_time = time.perf_counter()

    def stop(self):
        self._stop_event.set()
        self.session.cancel()  # the band in progress stops at its next dispatch

    def out_of_time(self):
        """Past the time limit, with a whole frame in the film (a limit shorter than the first
        frame still gives a whole image)."""
        if not self.time_limit or self.session.samples == 0:
            return False
        return time.perf_counter() - self.start_time >= self.time_limit

    def run(self):
        try:
            last_snapshot = 0.0
            while self.session.samples < self.samples or self.session.fallback_film:
                if self._stop_event.is_set() or self.out_of_time() or self.session.converged:
                    break  # converged: adaptive sampling found every pixel done
                if not self._render_frame():
                    break
                now = time.perf_counter()
                if now - last_snapshot >= UPDATE_SECONDS or self.session.samples >= self.samples:
                    self._take_snapshot()
                    last_snapshot = now
            if self.snapshot is None or self.snapshot[0] != self.session.samples:
                # Cancelled: not denoised, so not the denoiser's passes (Esc stays quick).
                self._take_snapshot(self.wanted_passes if self._stop_event.is_set() else None)
            if self.denoise and not self._stop_event.is_set():
                self._denoise()
        except Exception as e:  # reported by the Blender thread
            self.error = e

    def _denoise(self):
        """Replaces the last snapshot by its denoised version (a new tuple: Blender's thread
        shows it); with no OIDN the render stays as it is and ``denoise_message`` says why."""
        denoise = core.load().denoise
        samples, seconds, rate, images, stats = self.snapshot
        self.denoising = True
        try:
            start = time.perf_counter()
            denoiser = denoise.Denoiser(self.session.device_type)
            try:
                out = denoise.denoise_images(images, self.denoise, denoiser)
            finally:
                denoiser.close()
            self.denoised = True
            self.denoise_message = (f"Denoised ({denoiser.device_kind}, {time.perf_counter() - start:.1f} s, "
                                    f"OpenImageDenoise {denoiser.version} from {denoiser.source})")
        except (denoise.DenoiserUnavailable, denoise.DenoiseError) as e:
            out, self.denoise_message = {}, f"{e}; the image is not denoised"
        finally:
            self.denoising = False
        self.snapshot = (samples, seconds, rate, {**images, **out}, stats)

    def _render_frame(self):
        """One frame in row bands of about BAND_SECONDS; False if stopped or out of time in
        between (the partial frame's pixels count their own samples: the image stays exact)."""
        rows = self.rows_per_band
        while True:
            start = time.perf_counter()
            done = self.session.render_rows(rows)
            self.rendering_at = self.rendering_at or time.time()
            rows = band_rows(rows, time.perf_counter() - start, self.session.height)
            self.rows_per_band = rows
            if done or self.session.converged:  # converged: no pixel left to sample
                return True
            if self._stop_event.is_set() or self.out_of_time():
                return False

    def _take_snapshot(self, passes=None):
        stats = self.session.stats()
        images = {name: self.session.read(name) for name in (passes or self.core_passes)}
        if self.denoise:  # until the denoiser runs, Noisy Image is Combined
            images["noisy_image"] = images["combined"]
        render_seconds = stats.get("milliseconds", 0.0) / 1e3  # device time, without compiling
        rate = stats.get("rays", 0) / render_seconds if render_seconds > 0 else 0.0
        self.snapshot = (int(stats.get("samples", 0)), time.perf_counter() - self.start_time,
                         rate, images, stats)


def ic_status(stats):
    """The irradiance cache's part of the stats line."""
    return (f"IC {stats.get('ic_entries', 0)}/{stats.get('ic_capacity', 0)} entries, "
            f"{stats.get('ic_dropped', 0)} dropped")


def guiding_status(stats):
    """Path guiding's part of the stats line."""
    return (f"Guiding {stats.get('guiding_trained_regions', 0)}/{stats.get('guiding_regions', 0)} regions, "
            f"{stats.get('guiding_lobes', 0)} lobes, {stats.get('guiding_training_frames', 0)} training frames")


def _write_result(result, snapshot):
    images = snapshot[3]
    specs = passes.by_name()
    for render_pass in result.layers[0].passes:
        spec = specs.get(render_pass.name)
        if spec is None or spec.core not in images:
            continue
        image = images[spec.core][::-1, :, :render_pass.channels]  # Blender's rows go bottom-up
        flat = np.ascontiguousarray(image, dtype=np.float32).ravel()
        try:
            render_pass.rect.foreach_set(flat)
        except (AttributeError, TypeError):  # Blender < 4: rect only takes per-pixel rows
            render_pass.rect = flat.reshape(-1, render_pass.channels)


def render(engine, depsgraph):
    scene = depsgraph.scene
    settings = scene.parallax
    view_layer = depsgraph.view_layer
    global last_report
    last_report = report = RenderReport()

    width, height = render_size(scene.render)
    region = border_region(scene.render, width, height)
    _, _, w, h = region or (0, 0, width, height)
    try:
        parallax_core = core.load()
        data, warnings = sync.export_scene(depsgraph, width, height, region)
        if scene_hook is not None:
            scene_hook(data, warnings)
            return
        session = parallax_core.Session(w, h, settings.device)
        session.background_compile = True  # a technique compiling: its fallback renders meanwhile
        params = settings.render_params()
        params["adaptive_threshold"] = parallax_core.adaptive_threshold(params["adaptive_threshold"], settings.samples)
        session.set_params(**params)
        warnings += [m for m in session.update(data) if m not in warnings]
    except (ImportError, ValueError, RuntimeError, TypeError, MemoryError) as e:
        # MemoryError: parallax_core.DeviceMemoryError, a scene past the device-memory budget.
        report.errors.append(str(e))
        engine.report({"ERROR"}, f"Parallax: {e}")
        return
    report.warnings = list(warnings)
    for message in warnings:
        engine.report({"WARNING"}, f"Parallax: {message}")

    wanted = passes.enabled(scene, view_layer)
    per_frame = settings.samples_per_frame
    frames = -(-settings.samples // per_frame)
    total = frames * per_frame
    denoise = settings.engine_values() if settings.use_denoising else None
    worker = _Worker(session, total, settings.time_limit, {p.core for p in wanted}, denoise)
    # The film holds the passes this render reads only (less memory, fewer writes per sample).
    session.passes = sorted(worker.core_passes)
    # With a border, Blender's result covers just the border: its pixel (0, 0) is (x, y).
    result = engine.begin_result(0, 0, w, h, layer=view_layer.name)
    worker.start()
    shown = None
    cancelled = denoising_shown = False
    while True:
        finished = not worker.is_alive()
        report.rendering_at = worker.rendering_at
        snapshot = worker.snapshot
        if snapshot is not None and snapshot is not shown:
            shown = snapshot
            _write_result(result, snapshot)
            engine.update_result(result)
            samples, seconds, rate, _, stats = snapshot
            line = f"Sample {samples}/{total} | {rate / 1e6:.1f} M rays/s | {seconds:.1f} s"
            if stats.get("fallback_film"):  # the samples so far are the fallback's
                line += " | without the techniques while they compile"
            if stats.get("ic_capacity"):  # the cache was built: ic on, or for ADRRS' estimates
                line += f" | {ic_status(stats)}"
            if settings.guiding:
                line += f" | {guiding_status(stats)}"
            if worker.denoised:
                line += " | Denoised"
            engine.update_stats("", line)
            if progress_stream is not None:
                progress_stream.write(f"\rParallax: {line}  ")
                progress_stream.flush()
            progress = samples / total
            if settings.time_limit:
                progress = max(progress, min(1.0, seconds / settings.time_limit))
            engine.update_progress(progress)
        if finished:
            break
        if worker.denoising and shown is not None and not denoising_shown:
            denoising_shown = True
            engine.update_stats("", f"Sample {shown[0]}/{total} | Denoising")
        if stop_requested(engine):
            worker.stop()
            cancelled = True
            break
        time.sleep(POLL_SECONDS)
    # Wait for the cancelled worker: its band stops at the next dispatch. Returning while it is
    # still inside the core let Blender quit under it (Esc then exit: the daemon thread, unwound
    # at interpreter exit inside a native call, aborted Blender with "terminate called without
    # an active exception"). Bounded, so a stuck device cannot hang Blender.
    worker.join(JOIN_SECONDS)
    engine.end_result(result)
    if progress_stream is not None:
        progress_stream.write("\n")
        if worker.denoise_message:  # how it was denoised, or why not
            progress_stream.write(f"Parallax: {worker.denoise_message}\n")
    report.samples, report.cancelled = (shown[0] if shown else 0), cancelled
    report.worker_running = worker.is_alive()
    report.denoised, report.denoise_message = worker.denoised, worker.denoise_message
    if denoise and not worker.denoised and worker.denoise_message:
        report.warnings.append(worker.denoise_message)
        engine.report({"WARNING"}, f"Parallax: {worker.denoise_message}")
    if worker.error is not None:
        report.errors.append(str(worker.error))
        engine.report({"ERROR"}, f"Parallax: {worker.error}")
    elif cancelled:
        engine.update_stats("", f"Cancelled at sample {shown[0] if shown else 0}/{total}")
    report.finished_at = time.time()
