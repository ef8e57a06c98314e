"""Runs inside Blender's GUI (blender FILE.blend --python gui_driver.py -- OUT_DIR MODE).

MODE "viewport": switches the biggest 3D viewport to Rendered shading with Parallax, looking
through the scene camera with overlays off, and takes `xwd -root` screenshots: after the
first full-resolution frames, after more samples, after moving the tall box, and after
orbiting the view. MODE "cancel": starts an F12 render and waits for the test to press Esc.
MODE "denoise": the Rendered viewport with Use Viewport Denoising until a denoised frame
shows, then an F12 render with denoising (the default). PX_DENOISE=1 turns viewport denoising
on in the other modes (bench/viewport_latency.py --denoise).
Steps run from timers so Blender's event loop (and its drawing) goes on; results go to
OUT_DIR/result.json, and Blender quits at the end.
"""
import json
import math
import os
import subprocess
import sys
import time
import traceback

import addon_utils
import bpy
import mathutils

OUT, MODE = sys.argv[sys.argv.index("--") + 1:][:2]
result = {"mode": MODE, "errors": [], "shots": {}}
TIMEOUT = 900.0  # a generous bound: every step waits on an event, never on a rate
start = time.perf_counter()


def save_result():
    with open(os.path.join(OUT, "result.json"), "w") as f:
        json.dump(result, f, indent=1)


def screenshot(name):
    path = os.path.join(OUT, name + ".xwd")
    subprocess.run(["xwd", "-root", "-silent", "-out", path], check=True, timeout=30)
    result["shots"][name] = path


def view3d():
    screen = bpy.context.window.screen
    areas = [a for a in screen.areas if a.type == "VIEW_3D"]
    return max(areas, key=lambda a: a.width * a.height)


def worker():
    from parallax.engine import viewport

    workers = [w for w in viewport._workers if w.is_alive()]
    return workers[0] if workers else None


def run_steps(steps):
    """Runs generator `steps`: each yield is a condition (callable) to wait for."""
    state = {"wait": None}

    def tick():
        try:
            if time.perf_counter() - start > TIMEOUT:
                raise TimeoutError(f"gui driver timed out in mode {MODE}")
            if state["wait"] is not None and not state["wait"]():
                return 0.05
            state["wait"] = next(steps)
            return 0.05
        except StopIteration:
            save_result()
            bpy.ops.wm.quit_blender()
        except Exception:
            result["errors"].append(traceback.format_exc())
            save_result()
            bpy.ops.wm.quit_blender()
        return None

    bpy.app.timers.register(tick, first_interval=0.5)


def samples_at_least(n, generation=0):
    """A full-resolution frame with n samples of a scene handed over after `generation`."""
    def ready():
        w = worker()
        return w is not None and w.frame is not None and w.frame[1] >= n and w.frame[2] == 1 \
            and w.frame[3] > generation
    return ready


def after(seconds):
    until = time.perf_counter() + seconds
    return lambda: time.perf_counter() >= until


def rendered_camera_view():
    """Steps: the biggest 3D viewport fills the window, looks through the scene camera with
    overlays off, and switches to Rendered shading. Returns its space at the end."""
    area = view3d()
    with bpy.context.temp_override(area=area):
        bpy.ops.screen.screen_full_area(use_hide_panels=True)
    yield after(1.0)
    area = view3d()
    space = area.spaces.active
    space.overlay.show_overlays = False
    space.show_gizmo = False
    space.region_3d.view_perspective = "CAMERA"
    region = next(r for r in area.regions if r.type == "WINDOW")
    with bpy.context.temp_override(area=area, region=region):
        bpy.ops.view3d.view_center_camera()
    if os.environ.get("PX_DENOISE") == "1":
        bpy.context.scene.parallax.use_preview_denoising = True
    result["rendered_at"] = time.perf_counter()
    space.shading.type = "RENDERED"
    result["region"] = [region.x, region.y, region.width, region.height]
    result["window"] = [bpy.context.window.width, bpy.context.window.height]
    return space


def viewport_steps():
    space = yield from rendered_camera_view()
    yield samples_at_least(2)
    screenshot("early")
    yield samples_at_least(16)
    screenshot("converged")
    before = worker().generation
    bpy.data.objects["TallBox"].location.x += 0.6  # an object transform: instances only
    yield samples_at_least(4, before)
    screenshot("moved")
    before = worker().generation
    space.region_3d.view_perspective = "PERSP"  # orbit: the camera only
    space.region_3d.view_rotation.rotate(mathutils.Euler((0.0, 0.0, math.radians(25))))
    yield samples_at_least(4, before)
    screenshot("orbited")
    w = worker()
    result["latencies"] = w.latencies
    t0, s0, generation = time.perf_counter(), w.frame[1], w.generation
    yield after(3.0)
    assert worker().generation == generation, "the view changed while counting samples"
    result["samples_per_second"] = (worker().frame[1] - s0) / (time.perf_counter() - t0)
    space.shading.type = "SOLID"  # frees the viewport engine and its worker
    yield after(1.0)
    from parallax.engine import viewport
    result["workers_alive_after_solid"] = sum(w.is_alive() for w in viewport._workers)
    space.shading.type = "RENDERED"  # and quit while it renders: Blender must exit cleanly
    yield lambda: worker() is not None and worker().frame is not None


def bench_steps():
    """Edit -> first new frame latency for each kind of edit (3 times each), then samples/s."""
    space = yield from rendered_camera_view()
    yield samples_at_least(4)
    objects = bpy.data.objects
    mover = next((objects[n] for n in ("TallBox", "Fountain") if n in objects),
                 next(o for o in objects if o.type == "MESH"))
    light = next((o for o in objects if o.type == "LIGHT"), objects.get("Light"))
    material = next(m for m in bpy.data.materials if m.node_tree and any(
        n.type == "BSDF_DIFFUSE" for n in m.node_tree.nodes))
    diffuse = next(n for n in material.node_tree.nodes if n.type == "BSDF_DIFFUSE")
    space.region_3d.view_perspective = "PERSP"
    yield samples_at_least(4, worker().generation)
    edits = {
        "camera": lambda i: space.region_3d.view_rotation.rotate(
            mathutils.Euler((0.0, 0.0, math.radians(4 if i % 2 else -4)))),
        "object": lambda i: setattr(mover.location, "x", mover.location.x + (0.1 if i % 2 else -0.1)),
        "material": lambda i: diffuse.inputs["Color"].default_value.__setitem__(0, 0.5 + 0.1 * (i % 2)),
        "light": lambda i: setattr(light.location, "z", light.location.z + (0.05 if i % 2 else -0.05)),
    }
    result["edits"] = {}
    for name, edit in edits.items():
        for i in range(3):
            w = worker()
            before, count = w.generation, len(w.latencies)
            edit(i)
            yield lambda: len(worker().latencies) > count and worker().latencies[-1] is not None
            result["edits"].setdefault(name, []).append(worker().latencies[-1])
            yield samples_at_least(2, before)
    w = worker()
    t0, s0, generation = time.perf_counter(), w.frame[1], w.generation
    yield after(5.0)
    assert worker().generation == generation, "the view changed while counting samples"
    result["samples_per_second"] = (worker().frame[1] - s0) / (time.perf_counter() - t0)
    result["size"] = list(worker().frame[0].shape[:2])
    result["denoised_frames"] = worker().denoised_frames  # with PX_DENOISE=1: the denoiser ran


def startup_steps():
    """Seconds from switching the viewport to Rendered to its first image, and to its first
    full-resolution path-traced frame. PX_NO_QUICK_FRAME=1: without the preview program's
    first frame (the viewport before issue 9), for comparison. PX_DENOISE=1 (issue 36): also
    to the first denoised image (any pixel size) and to the first full-resolution denoised one."""
    if os.environ.get("PX_NO_QUICK_FRAME") == "1":
        from parallax.engine import viewport
        viewport._Worker._quick_frame = lambda self, params: None
    denoise = os.environ.get("PX_DENOISE") == "1"
    if denoise:  # when (and at which pixel size) the first frame went to the denoiser
        from parallax.engine import viewport
        submit = viewport._DenoiseThread.submit

        def recording_submit(self, job):
            result.setdefault("first_handover", (time.perf_counter(), job[2]))
            submit(self, job)
        viewport._DenoiseThread.submit = recording_submit
    yield from rendered_camera_view()
    yield lambda: worker() is not None and worker().first_full_frame_at is not None
    w = worker()
    result["first_image_seconds"] = w.first_frame_at - result["rendered_at"]
    result["first_full_frame_seconds"] = w.first_full_frame_at - result["rendered_at"]
    result["size"] = list(w.frame[0].shape[:2])
    if denoise:
        yield lambda: worker().first_full_denoised_at is not None or worker().denoise_message is not None
        w = worker()
        assert w.denoise_message is None, w.denoise_message
        result["first_denoised_seconds"] = w.first_denoised_at - result["rendered_at"]
        result["first_full_denoised_seconds"] = w.first_full_denoised_at - result["rendered_at"]
        at, result["first_handover_pixel_size"] = result.pop("first_handover")
        result["first_handover_seconds"] = at - result["rendered_at"]


def denoise_steps():
    """The viewport's denoise thread and F12's denoiser in Blender 3.4, which has no OIDN of its
    own: both must find the pyoidn the add-on bundles."""
    from parallax import ui
    from parallax.engine import final

    scene = bpy.context.scene
    result["denoiser"] = [list(line) for line in ui.denoiser_status()]
    scene.parallax.use_preview_denoising, scene.parallax.preview_denoising_start_sample = True, 2
    space = yield from rendered_camera_view()
    yield lambda: worker() is not None and (worker().frame is not None and worker().frame[4]
                                            or worker().denoise_message is not None)
    w = worker()
    result["viewport"] = {"denoised_frames": w.denoised_frames, "message": w.denoise_message,
                          "samples": w.frame[1], "first_denoised_s": (w.first_denoised_at or 0) - result["rendered_at"]}
    yield after(0.5)  # drawn
    screenshot("denoised")
    space.shading.type = "SOLID"
    yield after(1.0)
    scene.parallax.samples, scene.render.resolution_x, scene.render.resolution_y = 4, 64, 48
    bpy.ops.render.render("INVOKE_DEFAULT")
    yield lambda: final.last_report.finished_at is not None
    report = final.last_report
    result["f12"] = {"denoised": report.denoised, "message": report.denoise_message,
                     "errors": report.errors, "samples": report.samples}


def cancel_steps():
    scene = bpy.context.scene
    scene.parallax.samples, scene.parallax.samples_per_frame = 100000, int(os.environ.get("PX_SPF", 64))
    # A 64-spp frame of some seconds on lavapipe: the Esc lands inside one.
    scene.render.resolution_x, scene.render.resolution_y, scene.render.resolution_percentage = 320, 240, 100
    bpy.ops.render.render("INVOKE_DEFAULT")
    from parallax.engine import final
    # Its first band of samples is in: the pipelines are compiled (a cold compile, 2-40 s on
    # lavapipe, is not cancelled); then a 64-spp frame is in flight.
    yield lambda: final.last_report.rendering_at is not None
    yield after(0.5)
    open(os.path.join(OUT, "rendering"), "w").close()
    escape = os.path.join(OUT, "escape_sent")
    yield lambda: os.path.exists(escape)
    sent = float(open(escape).read() or time.time())
    yield lambda: not bpy.app.is_job_running("RENDER") or time.time() - sent > 10.0
    result["job_seconds"] = time.time() - sent  # until Blender's render job ended
    report = final.last_report
    result["cancel_seconds"] = (report.finished_at or float("inf")) - sent  # our engine stopped
    result["cancelled"] = report.cancelled
    result["still_rendering"] = bpy.app.is_job_running("RENDER")
    yield after(0.5)
    result["responsive"] = True  # timers still run after the cancel


try:
    assert addon_utils.enable("parallax", default_set=True) is not None, "the add-on did not enable"
    bpy.context.scene.render.engine = "PARALLAX"
    run_steps({"viewport": viewport_steps, "bench": bench_steps, "cancel": cancel_steps,
               "startup": startup_steps, "denoise": denoise_steps}[MODE]())
except Exception:
    result["errors"].append(traceback.format_exc())
    save_result()
    bpy.ops.wm.quit_blender()
