"""Render passes: what Parallax registers with Blender and which core pass fills each."""
from collections import namedtuple

# enabled(scene, view_layer): whether the pass is on for that view layer of that scene.
Pass = namedtuple("Pass", "name channels chan_id type core enabled")

PASSES = (
    Pass("Combined", 4, "RGBA", "COLOR", "combined", lambda scene, layer: True),
    Pass("Depth", 1, "Z", "VALUE", "depth", lambda scene, layer: layer.use_pass_z),
    Pass("Normal", 3, "XYZ", "VECTOR", "normal", lambda scene, layer: layer.use_pass_normal),
    Pass("Denoising Normal", 3, "XYZ", "VECTOR", "normal",
         lambda scene, layer: layer.parallax.use_pass_denoising_data),
    Pass("Denoising Albedo", 3, "RGB", "COLOR", "albedo",
         lambda scene, layer: layer.parallax.use_pass_denoising_data),
    Pass("Ray Depth", 1, "X", "VALUE", "ray_depth",
         lambda scene, layer: layer.parallax.use_pass_ray_depth),
    Pass("IC Irradiance", 3, "RGB", "COLOR", "ic_irradiance",
         lambda scene, layer: scene.parallax.ic and layer.parallax.use_pass_ic_irradiance),
    Pass("IC Gradients", 3, "RGB", "COLOR", "ic_gradients",
         lambda scene, layer: scene.parallax.ic and layer.parallax.use_pass_ic_gradients),
    Pass("ADRRS Estimate", 3, "RGB", "COLOR", "adrrs_estimate",
         lambda scene, layer: scene.parallax.adrrs and layer.parallax.use_pass_adrrs_estimate),
    Pass("ADRRS Splits", 1, "X", "VALUE", "adrrs_splits",
         lambda scene, layer: scene.parallax.adrrs and layer.parallax.use_pass_adrrs_splits),
    Pass("Guiding Regions", 3, "RGB", "COLOR", "guiding_regions",
         lambda scene, layer: scene.parallax.guiding and layer.parallax.use_pass_guiding_regions),
    Pass("Guiding Components", 1, "X", "VALUE", "guiding_components",
         lambda scene, layer: scene.parallax.guiding and layer.parallax.use_pass_guiding_components),
    Pass("Guiding Lobes", 3, "RGB", "COLOR", "guiding_lobes",
         lambda scene, layer: scene.parallax.guiding and layer.parallax.use_pass_guiding_lobes),
)
BY_NAME = {p.name: p for p in PASSES}


def enabled(scene, view_layer):
    return [p for p in PASSES if p.enabled(scene, view_layer)]


def register_passes(engine, scene, view_layer):
    """RenderEngine.update_render_passes: tells Blender (and the compositor) our passes."""
    for p in enabled(scene, view_layer):
        engine.register_pass(scene, view_layer, p.name, p.channels, p.chan_id, p.type)
