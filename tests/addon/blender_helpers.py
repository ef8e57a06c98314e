"""bpy helpers for the add-on tests: open a scene, render it, read every pass back."""
import os

import numpy as np
import OpenEXR

REPO = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
SCENES = os.path.join(REPO, "blender_scenes")


def open_scene(bpy, name, width, height, engine="PARALLAX"):
    bpy.ops.wm.open_mainfile(filepath=os.path.join(SCENES, name + ".blend"), load_ui=False)
    scene = bpy.context.scene
    scene.render.engine = engine
    scene.render.resolution_x, scene.render.resolution_y = width, height
    scene.render.resolution_percentage = 100
    pin_denoising_off(scene)
    return scene


def pin_denoising_off(scene):
    """Denoising and adaptive sampling off on both engines (both default to on): the tests
    compare F12 images numerically, every pixel with the same samples; tests/addon/
    test_denoising.py and tests/render/test_adaptive_sampling.py turn them on."""
    scene.cycles.use_denoising = scene.cycles.use_adaptive_sampling = False
    if hasattr(scene, "parallax"):
        scene.parallax.use_denoising = scene.parallax.use_adaptive_sampling = False


def render(bpy, path):
    """F12-renders the current scene and saves the result as a multilayer EXR at ``path``;
    returns {pass name: float32 (H, W, C), row 0 at the top}."""
    from addon.cli import set_exr_output

    bpy.ops.render.render()
    scene = bpy.context.scene
    set_exr_output(scene.render.image_settings)
    bpy.data.images["Render Result"].save_render(str(path), scene=scene)
    return read_layers(path)


def render_engine(bpy, tmp_path, scene, engine, seed, samples):
    """The Combined RGB of `scene` rendered by `engine` ("PARALLAX" with MIS and Cycles' bounce
    count, or "CYCLES") with `samples` and `seed`: the parity tests' one render, denoising
    and adaptive sampling off on both engines."""
    scene.render.engine = engine
    pin_denoising_off(scene)
    if engine == "PARALLAX":
        settings = scene.parallax
        settings.samples, settings.samples_per_frame, settings.seed = samples, 16, seed
        settings.max_depth, settings.depth_leeway = scene.cycles.max_bounces, 0
        settings.method = "mis"
    else:
        scene.cycles.samples, scene.cycles.seed = samples, seed
    image = render(bpy, tmp_path / f"{scene.name}_{engine}_{seed}.exr")["Combined"][..., :3]
    assert np.isfinite(image).all()
    return image


def read_layers(path):
    passes = {}
    with OpenEXR.File(str(path)) as f:
        for part in f.parts:
            for name, channel in part.channels.items():
                # "ViewLayer.Normal.X" -> pass "Normal", component "X"; RGBA come grouped.
                layer_pass = name.split(".")
                pass_name = layer_pass[1] if len(layer_pass) > 1 else layer_pass[0]
                pixels = np.asarray(channel.pixels, dtype=np.float32)
                if pixels.ndim == 2:
                    pixels = pixels[..., None]
                passes.setdefault(pass_name, []).append((layer_pass[-1], pixels))
    order = {c: i for i, c in enumerate("RGBAXYZV")}
    return {name: np.concatenate([p for _, p in sorted(parts, key=lambda cp: order.get(cp[0], 9))], axis=2)
            for name, parts in passes.items()}


def block_means(image, block):
    h, w = image.shape[0] // block * block, image.shape[1] // block * block
    c = image.shape[2]
    return image[:h, :w].reshape(h // block, block, w // block, block, c).mean(axis=(1, 3))


def export_current(bpy):
    """(SceneData, warnings) that an F12 render of the current scene would upload."""
    from addon.engine import final

    captured = []
    final.scene_hook = lambda data, warnings: captured.append((data, warnings))
    try:
        bpy.ops.render.render()
    finally:
        final.scene_hook = None
    assert captured, final.last_report.errors
    return captured[0]


def build_scene(bpy, builder, width, height):
    """An empty file with the scene ``builder(b)`` makes with blender_scenes/build.py's helpers
    (``b``), rendered at width x height with Cycles set up as those scenes are."""
    bpy.ops.wm.read_factory_settings(use_empty=True)
    scene = bpy.context.scene
    scene.render.engine = "CYCLES"
    b = load_scene_builder()
    builder(b)
    b.configure_render(scene, width, height)
    return scene


def render_seed_pairs(bpy, tmp_path, scene, samples):
    """(p0, p1, c0, c1): the Combined RGB of Parallax and of Cycles, seeds 0 and 1 each."""
    p0, p1 = (render_engine(bpy, tmp_path, scene, "PARALLAX", seed, samples) for seed in (0, 1))
    c0, c1 = (render_engine(bpy, tmp_path, scene, "CYCLES", seed, samples) for seed in (0, 1))
    return p0, p1, c0, c1


def parity_figures(bpy, tmp_path, name, scene, samples, block):
    """(R, block relMSE, our mean, Cycles' mean) of ``scene`` rendered by both engines with seeds
    0 and 1 (parity_ratio), printed and the two engines' mean images saved as NAME.npy."""
    p0, p1, c0, c1 = render_seed_pairs(bpy, tmp_path, scene, samples)
    ratio, rel_mse = parity_ratio(p0, p1, c0, c1, block)
    ours, theirs = float((p0 + p1).mean() / 2), float((c0 + c1).mean() / 2)
    print(f"{name}: mean {ours:.4f} vs Cycles {theirs:.4f}, block relMSE {rel_mse:.5f}, "
          f"difference / noise {ratio:.2f}")
    np.save(tmp_path / f"{name}.npy", np.stack([p0 + p1, c0 + c1]) / 2)
    return ratio, rel_mse, ours, theirs


def parity_ratio(p0, p1, c0, c1, block):
    """(difference / noise ratio R, block relMSE) of two seed pairs (test_parity.py explains R:
    about 1 without a systematic difference)."""
    P0, P1, C0, C1 = (block_means(x, block) for x in (p0, p1, c0, c1))
    difference = (((P0 + P1) - (C0 + C1)) / 2) ** 2
    noise = ((P0 - P1) ** 2 + (C0 - C1) ** 2) / 4
    rel_mse = float(difference.sum() / max((((C0 + C1) / 2) ** 2).sum(), 1e-30))
    return float(difference.sum() / max(noise.sum(), 1e-30)), rel_mse


def load_scene_module(name):
    """blender_scenes/NAME.py as a module (the scene scripts there build scenes with bpy)."""
    import importlib.util

    spec = importlib.util.spec_from_file_location(f"parallax_scene_{name}", os.path.join(SCENES, name + ".py"))
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def load_scene_builder():
    """blender_scenes/build.py (its helpers build scenes with bpy)."""
    return load_scene_module("build")


def assert_params(params, expected):
    """Every expected setting is in `params` with the same type and value (floats to 1e-6)."""
    import pytest

    for name, value in expected.items():
        assert type(params[name]) is type(value), name
        assert params[name] == (pytest.approx(value, rel=1e-6) if isinstance(value, float) else value), name


def save_and_reopen(bpy, path):
    """Saves the open file to `path`, forgets it, opens it again; returns its scene."""
    bpy.ops.wm.save_as_mainfile(filepath=str(path))
    bpy.ops.wm.read_factory_settings(use_empty=True)
    bpy.ops.wm.open_mainfile(filepath=str(path))
    return bpy.context.scene


class FakeWorker:
    """Stands in for the viewport's worker: records what ViewportRender.update hands over."""
    device = "auto"
    error = None  # a worker stopped by an error would be replaced
    display = "combined"

    def __init__(self):
        self.submitted = []

    def submit(self, scene=None, parts=(), **changes):
        self.submitted.append(changes)


class FakeDepsgraph:
    def __init__(self, scene):
        self.scene, self.updates = scene, []
