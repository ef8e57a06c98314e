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
    return scene


def render(bpy, path):
    """F12-renders the current scene and saves the result as a multilayer EXR at ``path``;
    returns {pass name: float32 (H, W, C), row 0 at the top}."""
    from addon.cli import set_exr_output

    bpy.ops.render.render()
    scene = bpy.context.scene
    set_exr_output(scene.render.image_settings)
    bpy.data.images["Render Result"].save_render(str(path), scene=scene)
    return read_layers(path)


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
