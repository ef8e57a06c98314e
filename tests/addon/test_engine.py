"""F12 behaviour: progressive updates, cancel, limits, border and resolution, bad scenes."""
import time

import numpy as np
import OpenEXR
import pytest
from addon.engine import final
from blender_helpers import open_scene, render


def test_cancel_returns_within_a_second_with_a_partial_image(bpy, tmp_path, monkeypatch):
    scene = open_scene(bpy, "cornell_box", 96, 96)
    # Frames of 64 spp take seconds on a CPU: the cancel must not wait for the one in flight.
    scene.parallax.samples, scene.parallax.samples_per_frame = 4096, 64
    scene.parallax.samples_per_frame = 8
    asked = []

    def stop_after_first_update(engine):
        if final_snapshot_shown():
            asked.append(time.perf_counter())
            return True
        return False

    shown = []
    real_write = final._write_result
    monkeypatch.setattr(final, "_write_result", lambda *a: (shown.append(1), real_write(*a)))
    final_snapshot_shown = lambda: bool(shown)  # noqa: E731
    monkeypatch.setattr(final, "stop_requested", stop_after_first_update)
    passes = render(bpy, tmp_path / "cancelled.exr")
    returned = time.perf_counter()
    assert asked and returned - asked[0] < 1.0
    report = final.last_report
    assert report.cancelled and not report.errors
    assert not report.worker_running  # Blender may quit or free the session right after
    assert 0 < report.samples < 4096
    assert passes["Combined"][..., :3].mean() > 0.01  # the partial image, not black


def test_f12_and_viewport_workers_stop_a_heavy_band_with_session_cancel(bpy):
    """One band of these settings runs for minutes on lavapipe (the closed emitter box of albedo
    1 without roulette): stopping either worker must not wait for it (Session.cancel)."""
    import dataclasses

    import parallax_core as pc
    from addon.engine import viewport
    from parallax_core import scenes

    heavy = {**dataclasses.asdict(pc.RenderParams()), "samples_per_frame": 4096, "max_depth": 1024,
             "depth_leeway": 1024, "rr_start_depth": 0}
    box = scenes.closed_emitter_box(1.0, 1.0, 8, 8)
    session = pc.Session(8, 8)
    session.set_params(**heavy)
    session.update(box)
    worker = final._Worker(session, 1000, 0, {"combined"})
    worker.start()
    time.sleep(1.0)
    worker.stop()
    worker.join(300)
    assert not worker.is_alive() and worker.error is None and session.samples < 1000 * 4096

    view = viewport._Worker("auto", heavy, 0, 1)
    view.submit(box, parts={"geometry"}, size=(8, 8))
    time.sleep(1.0)
    view.stop(wait=300)
    assert not view.is_alive() and view.error is None


def test_samples_end_the_render_and_time_limit_stops_early(bpy, tmp_path):
    scene = open_scene(bpy, "cornell_box", 32, 32)
    scene.parallax.samples, scene.parallax.samples_per_frame = 12, 4
    render(bpy, tmp_path / "a.exr")
    assert final.last_report.samples == 12 and not final.last_report.cancelled
    scene.parallax.samples, scene.parallax.samples_per_frame = 100000, 1
    scene.parallax.time_limit = 1.0
    start = time.perf_counter()
    render(bpy, tmp_path / "b.exr")
    assert time.perf_counter() - start < 30.0
    assert 0 < final.last_report.samples < 100000


def test_resolution_percentage_and_border(bpy, tmp_path):
    scene = open_scene(bpy, "cornell_box", 64, 48)
    scene.parallax.samples = 8
    scene.render.resolution_percentage = 50
    full = render(bpy, tmp_path / "full.exr")
    assert full["Combined"].shape == (24, 32, 4)

    scene.render.use_border, scene.render.use_crop_to_border = True, True
    scene.render.border_min_x, scene.render.border_max_x = 0.25, 0.75
    scene.render.border_min_y, scene.render.border_max_y = 0.5, 1.0
    cropped = render(bpy, tmp_path / "crop.exr")
    assert cropped["Combined"].shape == (12, 16, 4)
    # The border shows the same part of the picture as the full frame (top half, middle).
    a, b = cropped["Combined"][..., :3].mean((0, 1)), full["Combined"][:12, 8:24, :3].mean((0, 1))
    np.testing.assert_allclose(a, b, rtol=0.25)

    scene.render.use_crop_to_border = False
    uncropped = render(bpy, tmp_path / "border.exr")["Combined"]
    assert uncropped.shape == (24, 32, 4)
    assert uncropped[12:, :, :3].max() == 0.0 and uncropped[:12, 8:24, :3].mean() > 0.01


def _add_mesh(bpy, scene, name, vertices, faces, material=None):
    mesh = bpy.data.meshes.new(name)
    mesh.from_pydata(vertices, [], faces)
    if material is not None:
        mesh.materials.append(material)
    obj = bpy.data.objects.new(name, mesh)
    scene.collection.objects.link(obj)
    return obj


def _add_light(bpy, scene, kind="POINT", power=500.0, location=(0.0, -3.0, 2.0)):
    light = bpy.data.objects.new("Lamp", bpy.data.lights.new("Lamp", kind))
    light.data.energy = power
    light.location = location
    scene.collection.objects.link(light)
    return light


QUAD = [(-1, 0, -1), (1, 0, -1), (1, 0, 1), (-1, 0, 1)]


def test_unsupported_node_renders_with_one_warning(fresh, bpy, tmp_path):
    material = bpy.data.materials.new("Velvet")
    nodes = material.node_tree.nodes
    nodes.clear()
    sheen = nodes.new("ShaderNodeBsdfSheen")
    out = nodes.new("ShaderNodeOutputMaterial")
    material.node_tree.links.new(sheen.outputs[0], out.inputs["Surface"])
    _add_mesh(bpy, fresh, "Quad", QUAD, [(0, 1, 2, 3)], material)
    _add_mesh(bpy, fresh, "Quad2", [(x, 0.5, z) for x, _, z in QUAD], [(0, 1, 2, 3)], material)
    _add_light(bpy, fresh)
    passes = render(bpy, tmp_path / "velvet.exr")
    report = final.last_report
    assert not report.errors
    about_sheen = [w for w in report.warnings if "Sheen" in w]
    assert len(about_sheen) == 1 and "Velvet" in about_sheen[0]
    assert passes["Combined"][..., :3].mean() > 0.0


def test_no_lights_renders_black_with_a_warning(fresh, bpy, tmp_path):
    fresh.world = None
    _add_mesh(bpy, fresh, "Quad", QUAD, [(0, 1, 2, 3)])
    passes = render(bpy, tmp_path / "dark.exr")
    assert not final.last_report.errors
    assert any("no lights" in w for w in final.last_report.warnings)
    assert passes["Combined"][..., :3].max() == 0.0


def test_nan_vertex_and_empty_mesh_render_with_warnings(fresh, bpy, tmp_path):
    nan = float("nan")
    _add_mesh(bpy, fresh, "Broken", QUAD + [(nan, 0, 0)], [(0, 1, 2, 3), (0, 1, 4)])
    _add_mesh(bpy, fresh, "Empty", [], [])
    _add_light(bpy, fresh)
    passes = render(bpy, tmp_path / "broken.exr")
    report = final.last_report
    assert not report.errors, report.errors
    assert any("'Broken'" in w and "NaN" in w for w in report.warnings)
    assert any("'Empty'" in w for w in report.warnings)
    assert np.isfinite(passes["Combined"]).all() and passes["Combined"][..., :3].mean() > 0.0


def test_unsupported_camera_is_a_clear_error_and_bpy_goes_on(fresh, bpy, tmp_path):
    _add_mesh(bpy, fresh, "Quad", QUAD, [(0, 1, 2, 3)])
    _add_light(bpy, fresh)
    fresh.camera.data.type = "CUSTOM"  # an OSL camera (Blender 5)
    # Blender turns the engine's error report into an exception of the render operator.
    with pytest.raises(RuntimeError, match="custom cameras are not supported"):
        bpy.ops.render.render()
    assert final.last_report.errors == [
        "camera 'Camera': custom cameras are not supported (perspective, orthographic and panoramic are)"]
    fresh.camera.data.type = "PERSP"
    render(bpy, tmp_path / "again.exr")
    assert not final.last_report.errors and final.last_report.samples == fresh.parallax.samples


def test_bad_device_is_reported(fresh, bpy, monkeypatch):
    _add_mesh(bpy, fresh, "Quad", QUAD, [(0, 1, 2, 3)])
    fresh.parallax.device = "gpu"
    import parallax_core

    has_gpu = any(d.get("type") == "discrete" and d.get("ray_tracing") for d in parallax_core.devices())
    if has_gpu:
        pytest.skip("this machine has a ray-tracing GPU")
    with pytest.raises(RuntimeError, match="Parallax"):
        bpy.ops.render.render()
    assert final.last_report.errors and "gpu" in final.last_report.errors[0].lower()


def test_compositor_denoise_node_uses_our_passes(bpy, tmp_path):
    """Render Layers exposes Denoising Normal/Albedo, and Blender's Denoise node (OIDN) turns
    a 4-spp render smooth while keeping its brightness."""
    scene = open_scene(bpy, "cornell_box", 64, 64)
    scene.parallax.samples = 4
    tree = bpy.data.node_groups.new("Compositor", "CompositorNodeTree")
    scene.compositing_node_group = tree
    scene.render.use_compositing = True
    layers = tree.nodes.new("CompositorNodeRLayers")
    denoise = tree.nodes.new("CompositorNodeDenoise")
    output = tree.nodes.new("NodeGroupOutput")
    tree.interface.new_socket("Image", in_out="OUTPUT", socket_type="NodeSocketColor")
    tree.links.new(layers.outputs["Image"], denoise.inputs["Image"])
    tree.links.new(layers.outputs["Denoising Normal"], denoise.inputs["Normal"])
    tree.links.new(layers.outputs["Denoising Albedo"], denoise.inputs["Albedo"])

    def composited(source, name):
        tree.links.new(source, output.inputs[0])
        bpy.ops.render.render()
        settings = scene.render.image_settings
        settings.media_type, settings.file_format, settings.color_depth = "IMAGE", "OPEN_EXR", "32"
        bpy.data.images["Render Result"].save_render(str(tmp_path / name), scene=scene)
        with OpenEXR.File(str(tmp_path / name)) as f:
            return np.array(f.parts[0].channels["RGBA"].pixels)[..., :3]

    noisy = composited(layers.outputs["Image"], "noisy.exr")
    clean = composited(denoise.outputs["Image"], "denoised.exr")
    roughness = lambda image: np.abs(np.diff(image, axis=1)).mean()  # noqa: E731
    assert roughness(clean) < 0.6 * roughness(noisy)
    assert clean.mean() == pytest.approx(noisy.mean(), rel=0.05)


def test_scene_past_the_memory_budget_is_an_error_report(fresh, bpy, tmp_path):
    """A texture past the device-memory budget: the render operator fails with the engine's
    error report (no crash), and the next render, within the budget, works."""
    import parallax_core

    material = bpy.data.materials.new("Huge")
    image = bpy.data.images.new("Huge", 2048, 2048)  # 16 MiB of texels on the device
    tex = material.node_tree.nodes.new("ShaderNodeTexImage")
    tex.image = image
    bsdf = material.node_tree.nodes["Principled BSDF"]
    material.node_tree.links.new(tex.outputs["Color"], bsdf.inputs["Base Color"])
    _add_mesh(bpy, fresh, "Quad", QUAD, [(0, 1, 2, 3)], material)
    _add_light(bpy, fresh)
    parallax_core.set_memory_budget(parallax_core.memory()["allocated"] + 8 * 2**20)
    try:
        with pytest.raises(RuntimeError, match="Parallax: the scene does not fit.*budget"):
            bpy.ops.render.render()
        assert len(final.last_report.errors) == 1 and "device memory budget" in final.last_report.errors[0]
    finally:
        parallax_core.set_memory_budget(0)
    image.scale(64, 64)
    render(bpy, tmp_path / "fits.exr")
    assert not final.last_report.errors and final.last_report.samples == fresh.parallax.samples


def test_warm_up_asks_for_the_film_of_f12(fresh, bpy, monkeypatch):
    """The warm-up compiles the pipelines of the film an F12 of the view layer keeps: some
    passes have pipelines of their own (Guiding Lobes), so warming another film would leave
    F12's guided pipeline cold."""
    from addon.engine import warmup

    films = []
    monkeypatch.setattr(warmup, "_warm", lambda data, params, device, film: films.append(film))
    scene = bpy.context.scene
    scene.parallax.guiding = True
    scene.parallax.use_denoising = False
    for lobes in (False, True):
        bpy.context.view_layer.parallax.use_pass_guiding_lobes = lobes
        warmup.warm_scene(scene).join()
    assert "combined" in films[0] and films[1] - films[0] == {"guiding_lobes"}
    scene.parallax.use_denoising = True  # F12 keeps the denoiser's inputs too
    warmup.warm_scene(scene).join()
    assert films[2] == final.film_passes(films[1], scene.parallax.engine_values())


def test_warm_up_renders_a_frame_after_its_compiles(fresh, bpy, monkeypatch):
    """lavapipe compiles a pipeline's code at its first dispatch: the warm-up session renders a
    frame after warm(), so that the first F12 finds the code made, not only the pipeline."""
    from addon import core
    from addon.engine import warmup

    calls, Session = [], core.load().Session

    class Recording:  # a Session that lists what is called or set on it
        def __init__(self, *args):
            self.session = Session(*args)

        def __getattr__(self, name):
            attr = getattr(self.session, name)
            if not callable(attr):
                return attr

            def call(*args, **kwargs):
                calls.append(name)
                return attr(*args, **kwargs)
            return call

        def __setattr__(self, name, value):
            if name == "session":
                object.__setattr__(self, name, value)
            else:
                calls.append(name)
                setattr(self.session, name, value)

    monkeypatch.setattr(core.load(), "Session", Recording)
    warmup.warm_scene(bpy.context.scene).join()
    assert calls[-2:] == ["warm", "render"], calls
