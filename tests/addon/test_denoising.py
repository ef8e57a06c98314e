"""Denoising in the add-on (issue 36): F12 through bpy gives the denoised Combined and the Noisy
Image pass (Cycles' name) and carries on undenoised without OIDN; the viewport worker denoises
on its own thread and an edit shows its noisy frame without waiting; the Denoising panel says
which OIDN runs, or that none was found."""
import dataclasses
import os
import time
import types

import numpy as np
import pytest
from blender_helpers import open_scene, render

import parallax_core
from parallax_core import denoise


def _smoothness(image):
    """Mean difference between horizontal neighbours (noise raises it)."""
    return float(np.abs(np.diff(image[..., :3], axis=1)).mean())


def test_f12_denoises_combined_and_keeps_the_noisy_image(bpy, tmp_path):
    from addon.engine import final

    scene = open_scene(bpy, "cornell_box", 48, 36)
    settings = scene.parallax
    settings.samples, settings.samples_per_frame, settings.seed = 4, 4, 1
    settings.use_denoising = True  # (open_scene pins it off, as the other F12 tests compare images)
    layers = render(bpy, tmp_path / "denoised.exr")
    report = final.last_report
    assert report.denoised and "Denoised (cpu" in report.denoise_message and not report.errors
    combined, noisy = layers["Combined"], layers["Noisy Image"]
    assert combined.shape == noisy.shape == (36, 48, 4)
    assert _smoothness(combined) < 0.6 * _smoothness(noisy)
    # Against a long render, the denoised image is the closer one.
    settings.use_denoising, settings.samples, settings.samples_per_frame = False, 256, 16
    reference = render(bpy, tmp_path / "reference.exr")
    assert "Noisy Image" not in reference and not final.last_report.denoised
    ref = reference["Combined"][..., :3]

    def error(image):
        return float(np.mean((image[..., :3] - ref) ** 2 / (ref ** 2 + 1e-2)))

    assert error(combined) < 0.5 * error(noisy), (error(combined), error(noisy))
    # The film is the same with denoising off: Noisy Image is Combined as rendered.
    settings.samples, settings.samples_per_frame = 4, 4
    undenoised = render(bpy, tmp_path / "off.exr")
    np.testing.assert_allclose(undenoised["Combined"], noisy, atol=1e-6)


def test_f12_without_oidn_renders_undenoised_with_a_warning(bpy, tmp_path, monkeypatch):
    from addon.engine import final

    monkeypatch.setenv(denoise.ENV_LIBRARY, str(tmp_path / "missing.so"))
    scene = open_scene(bpy, "cornell_box", 24, 16)
    scene.parallax.samples, scene.parallax.use_denoising = 2, True
    layers = render(bpy, tmp_path / "no_oidn.exr")
    report = final.last_report
    assert not report.errors and report.samples == 2 and not report.denoised
    assert any("OpenImageDenoise not found" in w and "not denoised" in w for w in report.warnings)
    np.testing.assert_array_equal(layers["Combined"], layers["Noisy Image"])


def test_denoising_panel_says_which_oidn(bpy, monkeypatch, tmp_path):
    from addon import ui

    monkeypatch.setattr(ui, "_denoiser_line", None)
    ((line, icon),) = ui.denoiser_status()
    assert icon == "INFO" and line == "OpenImageDenoise from Blender (bpy)"  # bpy 5.0.1 ships OIDN 2.3.3
    monkeypatch.setattr(ui, "_denoiser_line", None)
    monkeypatch.setenv(denoise.ENV_LIBRARY, str(tmp_path / "missing.so"))
    lines = ui.denoiser_status()
    assert lines[0] == ("OpenImageDenoise not found: renders are not denoised", "ERROR")
    assert any("missing.so" in text for text, _ in lines[1:])
    # The panel draws it above its rows.
    drawn = []
    layout = types.SimpleNamespace(label=lambda text, icon: drawn.append(text), prop=lambda *a, **k: None,
                                   use_property_split=False, use_property_decorate=False, active=True)
    panel = types.SimpleNamespace(layout=layout, bl_idname="PARALLAX_PT_denoising", switches=(), rows=())
    ui._SettingsPanel.draw(panel, types.SimpleNamespace(scene=bpy.context.scene))
    assert drawn == [text for text, _ in lines]
    monkeypatch.setattr(ui, "_denoiser_line", None)


def _recording_worker(*args, **kwargs):
    """A viewport worker that records every frame it shows, from either thread, as
    (generation, pixel size, denoised) in ``shown``."""
    from addon.engine import viewport

    class Recording(viewport._Worker):
        @property
        def frame(self):
            return self.__dict__.get("_frame")

        @frame.setter
        def frame(self, frame):
            self.__dict__["_frame"] = frame
            if frame is not None:
                self.__dict__.setdefault("shown", []).append((frame[3], frame[2], frame[4]))

    return Recording(*args, **kwargs)


def _assert_never_coarser(shown):
    """Within a scene state (generation) the image shown never gets coarser, and once it is
    denoised at a pixel size no noisy frame of that size (or coarser) comes back."""
    finest, denoised_at = {}, {}
    for generation, pixel_size, denoised in shown:
        assert pixel_size <= finest.get(generation, pixel_size), shown
        assert denoised or pixel_size < denoised_at.get(generation, float("inf")), shown
        finest[generation] = pixel_size
        if denoised:
            denoised_at[generation] = pixel_size


def test_viewport_denoises_on_its_own_thread_and_edits_do_not_wait():
    """The worker shows noisy frames until the denoise thread's frame of the same scene state
    is ready; after an edit its next frame is that edit's noisy one, not an old denoised one."""
    from addon.engine import viewport
    from parallax_core import scenes

    params = {**dataclasses.asdict(parallax_core.RenderParams()), "method": "mis", "samples_per_frame": 2}
    values = {s.name: s.default for s in parallax_core.SETTINGS if not s.core}
    values.update(use_preview_denoising=True, preview_denoising_start_sample=4)
    scene = scenes.cornell_box(32, 24)
    worker = _recording_worker("auto", params, 8, 1, denoise=values)
    worker.submit(scene, parts={"geometry"}, size=(32, 24))
    worker.start()

    def wait(condition, what):  # events, not rates
        deadline = time.monotonic() + 300
        while not condition():
            assert worker.error is None and worker.denoise_message is None, (worker.error, worker.denoise_message)
            assert time.monotonic() < deadline, what
            time.sleep(0.02)

    try:
        wait(lambda: worker.frame is not None and worker.frame[4], "a denoised frame")
        image, samples, pixel_size, generation, _ = worker.frame
        assert samples >= 4 and pixel_size == 1 and worker.denoised_frames >= 1
        assert worker._denoiser.name == "parallax-viewport-denoise" and worker._denoiser.is_alive()
        scene.camera.camera_to_world = np.array(scene.camera.camera_to_world, np.float64)
        scene.camera.camera_to_world[0, 3] += 0.05
        edit = worker.submit(scene, parts={"camera"})
        wait(lambda: worker.frame[3] >= edit, "the edit's first frame")
        first = next(f for f in worker.shown if f[0] == edit)
        assert not first[2]  # the edit's own (noisy) frame came first
        wait(lambda: worker.frame[3] == edit and worker.frame[4], "the edit's denoised frame")
        wait(lambda: worker.done and not worker.denoise_pending(), "the sample target")
        image, samples, _, _, denoised = worker.frame
        assert denoised and samples == 8
        noisy = worker._full.read("combined")
        assert _smoothness(image) < _smoothness(noisy)
        # Noisy Image in the viewport's pass menu: the film's Combined, never denoised.
        worker.submit(display="noisy_image")
        wait(lambda: worker.done and worker.frame[4] is False, "the noisy image")
        np.testing.assert_array_equal(worker.frame[0], noisy)
        _assert_never_coarser(worker.shown)
    finally:
        worker.stop(wait=300)
    worker._denoiser.join(10)
    assert not worker._denoiser.is_alive()  # stop() ends the denoise thread too


def test_viewport_first_denoised_frame_is_the_coarse_preview(monkeypatch):
    """Issue 36: the coarse preview frame (pixel size 4 here) goes to the denoiser, so the first
    denoised image comes before any full-size frame; the first full-size frame (noisy) then
    replaces it, its denoised frame follows, and a late coarse denoised frame never replaces a
    finer one. The preview program's first-hit frame is not denoised."""
    from addon.engine import viewport
    from parallax_core import scenes

    jobs = []  # the frames handed to the denoiser
    submit, render_frame = viewport._DenoiseThread.submit, viewport._Worker._render_frame

    def held_render_frame(self):
        # The first full-size frame waits for the denoiser to finish what it was given (events,
        # not rates), so the test sees the order the frames come in on a slow machine.
        while not self._stopped and self.denoise_pending():
            time.sleep(0.01)
        monkeypatch.setattr(viewport._Worker, "_render_frame", render_frame)
        return render_frame(self)

    monkeypatch.setattr(viewport._DenoiseThread, "submit", lambda self, job: (jobs.append(job), submit(self, job)))
    monkeypatch.setattr(viewport._Worker, "_render_frame", held_render_frame)
    params = {**dataclasses.asdict(parallax_core.RenderParams()), "method": "mis", "samples_per_frame": 1}
    del params["preview"]  # the worker's to set (the add-on's render_params has no such row)
    values = {s.name: s.default for s in parallax_core.SETTINGS if not s.core}
    values.update(use_preview_denoising=True, preview_denoising_start_sample=1)
    worker = _recording_worker("auto", params, 4, 4, denoise=values)
    worker.submit(scenes.cornell_box(64, 48), parts={"geometry"}, size=(64, 48))
    worker.start()
    deadline = time.monotonic() + 300
    try:
        while not (worker.done and not worker.denoise_pending() and worker.first_full_denoised_at):
            assert worker.error is None and worker.denoise_message is None, (worker.error, worker.denoise_message)
            assert time.monotonic() < deadline, "the sample target, denoised"
            time.sleep(0.02)
        denoised = [pixel_size for _, pixel_size, denoised in worker.shown if denoised]
        assert denoised[0] == 4 and 1 in denoised, worker.shown
        # The preview session's frame went first, with the albedo pass the settings ask for.
        generation, samples, pixel_size, images, _ = jobs[0]
        assert pixel_size == 4 and images["combined"].shape[:2] == (12, 16) and "albedo" in images
        assert [job[2] for job in jobs].count(4) == 1  # not the preview program's frame too
        _assert_never_coarser(worker.shown)
        # After the coarse denoised frame, the first full-size one showed at once, noisy.
        after = worker.shown[worker.shown.index((1, 4, True)) + 1]
        assert after == (1, 1, False), worker.shown
        assert worker.first_denoised_at < worker.first_full_frame_at < worker.first_full_denoised_at
        image, samples, pixel_size, generation, denoised = worker.frame
        assert denoised and pixel_size == 1 and samples == 4 and image.shape[:2] == (48, 64)
        # Coarse frames denoise at the render's priority, full-size ones at nice +10.
        base = os.getpriority(os.PRIO_PROCESS, 0)
        assert os.getpriority(os.PRIO_PROCESS, worker._coarse_denoiser.native_id) == base
        assert os.getpriority(os.PRIO_PROCESS, worker._denoiser.native_id) == max(base, 10)
        # A coarse denoised frame coming late is dropped: the full-size one stays.
        frame = worker.frame
        worker._show_denoised(generation, 8, 4, np.zeros((12, 16, 4), np.float32))
        assert worker.frame is frame
    finally:
        worker.stop(wait=300)
