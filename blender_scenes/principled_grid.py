"""The Principled BSDF material grid (issue 14): 21 patches, roughness x metallic x IOR Level x
transmission, plus coat, sheen, an F82-tinted metal and smooth (roughness 0) dielectric and
glass patches, each a quad in the plane z = 0 under a uniform world and a sun, seen at 45
degrees by an orthographic camera (so every pixel of a patch sees it at the same angle, and a
patch maps to a rectangle of pixels); nothing lies below them, so transmitted rays see the
world. Used by tests/addon/test_parity_principled.py and bench/parity.py (inside Blender or
bpy: `build(bpy)` makes the scene, `patch_means(image)` reads one value per patch).
"""
import importlib.util
import math
import os

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))


def _builder():
    """blender_scenes/build.py as a module (its helpers build scenes with bpy)."""
    spec = importlib.util.spec_from_file_location("parallax_scene_build", os.path.join(HERE, "build.py"))
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


W, H, ORTHO = 90, 32, 9.0        # pixel = 0.1 m across; rows see y / sqrt(2)
BASE = (0.8, 0.5, 0.25)
COLUMNS, PITCH, INSIDE = 7, 1.25, 0.35  # patch centres PITCH apart; pixels within INSIDE of one


def patches():
    """[(label, Principled inputs)]: the 16 grid patches, then the others."""
    out = []
    for roughness in (0.2, 0.5):
        for metallic in (0.0, 1.0):
            for level in (0.5, 1.0):
                for transmission in (0.0, 1.0):
                    out.append((f"r{roughness} m{metallic:g} s{level} t{transmission:g}",
                                {"Roughness": roughness, "Metallic": metallic,
                                 "Specular IOR Level": level, "Transmission Weight": transmission}))
    out.append(("coat", {"Roughness": 0.5, "Coat Weight": 1.0, "Coat Roughness": 0.1,
                         "Coat Tint": (0.9, 0.95, 1.0, 1.0)}))
    out.append(("sheen", {"Base Color": (0.1, 0.15, 0.4, 1.0), "Roughness": 0.5, "Sheen Weight": 1.0,
                          "Sheen Roughness": 0.5}))
    out.append(("metal f82", {"Roughness": 0.3, "Metallic": 1.0, "Specular Tint": (0.5, 0.8, 1.0, 1.0)}))
    out.append(("r0 dielectric", {"Roughness": 0.0}))
    out.append(("r0 glass", {"Roughness": 0.0, "Transmission Weight": 1.0}))
    return out


def centre(k):
    return ((k % COLUMNS - (COLUMNS - 1) / 2) * PITCH, (1 - k // COLUMNS) * PITCH)


def build(bpy):
    from mathutils import Vector

    bpy.ops.wm.read_factory_settings(use_empty=True)
    scene = bpy.context.scene
    scene.render.engine = "CYCLES"
    b = _builder()
    for k, (label, inputs) in enumerate(patches()):
        mat, bsdf = b._material(label, "ShaderNodeBsdfPrincipled", **{"Base Color": (*BASE, 1.0), **inputs})
        b.add_rect(label, 1.0, 1.0, mat, (*centre(k), 0.0))
    b.add_sun_light("Sun", (0.25, -0.8, -0.6), 2.0, 5.0)
    b.set_world((1.0, 1.0, 1.0), 0.5)
    cam = bpy.data.cameras.new("Camera")
    cam.type, cam.ortho_scale, cam.sensor_fit = "ORTHO", ORTHO, "AUTO"
    rotation = Vector((0.0, 1.0, -1.0)).to_track_quat("-Z", "Y").to_euler()
    scene.camera = b.add_object("Camera", cam, (0.0, -10.0, 10.0), rotation)
    b.configure_render(scene, W, H)
    return scene


def patch_means(image):
    """(patches, 3) mean radiance over the pixels well inside each patch."""
    u = ((np.arange(W) + 0.5) / W - 0.5) * ORTHO
    v = (0.5 - (np.arange(H) + 0.5) / H) * ORTHO * H / W
    x, y = np.meshgrid(u, v * math.sqrt(2.0))  # rows: image top first
    out = []
    for k in range(len(patches())):
        cx, cy = centre(k)
        mask = (np.abs(x - cx) < INSIDE) & (np.abs(y - cy) < INSIDE)
        assert mask.sum() >= 20
        out.append(image[mask].mean(axis=0))
    return np.array(out)
