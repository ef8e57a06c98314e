"""Parallax settings: ``scene.parallax`` (render) and ``view_layer.parallax`` (passes).

The render settings mirror ``parallax_core.RenderParams`` one to one (see ``render_params``);
sampling limits and the device are the engine's.
"""
import bpy
from bpy.props import BoolProperty, EnumProperty, FloatProperty, IntProperty, PointerProperty

METHOD_ITEMS = (
    ("mis", "MIS", "Next event estimation and BSDF sampling, combined with multiple importance "
                   "sampling (Veach 1997): robust on every material and light size"),
    ("nee", "Next Event Estimation", "Sample a light at every vertex; emission hit by BSDF "
                                     "sampling is ignored except on delta bounces"),
    ("pt", "Path Tracing", "BSDF sampling only: lights are found by chance (the reference)"),
)
HEURISTIC_ITEMS = (
    ("power", "Power", "Power heuristic, exponent 2 (Veach 1997, eq. 9.13)"),
    ("balance", "Balance", "Balance heuristic (Veach 1997, eq. 9.10)"),
)
DEVICE_ITEMS = (
    ("auto", "Automatic", "An NVIDIA or other ray-tracing GPU if present, else the CPU (lavapipe)"),
    ("cpu", "CPU", "Mesa lavapipe: Vulkan on the CPU"),
    ("gpu", "GPU", "The first GPU with Vulkan ray tracing; fails if there is none"),
)


class ParallaxRenderSettings(bpy.types.PropertyGroup):
    # Sampling
    samples: IntProperty(
        name="Samples", description="Samples per pixel to render", default=128, min=1,
        soft_max=4096, max=2**24)
    time_limit: FloatProperty(
        name="Time Limit", description="Stop after this many seconds, even if fewer samples "
        "are done (0 = no limit)", default=0.0, min=0.0, subtype="TIME_ABSOLUTE", unit="TIME_ABSOLUTE")
    samples_per_frame: IntProperty(
        name="Samples per Frame", description="Samples per pixel in one GPU submission: more is "
        "faster overall, fewer updates the image more often", default=1, min=1, max=64)
    seed: IntProperty(
        name="Seed", description="Random seed; the same seed gives the same image on the same "
        "device", default=0, min=0)
    viewport_samples: IntProperty(
        name="Viewport Samples", description="Samples per pixel the viewport renders before it "
        "stops (0 = until something changes)", default=1024, min=0, max=2**24)
    viewport_start_pixel_size: EnumProperty(
        name="Start Pixel Size", description="After an edit the viewport first shows a frame "
        "with pixels this large, then refines; Automatic picks 1 to 8 from the measured frame "
        "time", items=(("AUTO", "Automatic", "From the measured frame time"),
                       ("1", "1", "Full resolution at once"), ("2", "2", "2x2 pixels"),
                       ("4", "4", "4x4 pixels"), ("8", "8", "8x8 pixels")), default="AUTO")
    # Light paths
    max_depth: IntProperty(
        name="Max Bounces", description="Maximum number of non-specular bounces (Cycles' Max "
        "Bounces)", default=8, min=0, max=1024)
    depth_leeway: IntProperty(
        name="Discrete Leeway", description="Specular (delta) bounces that do not count towards "
        "Max Bounces, so light through glass and mirrors is not cut short (thesis, sec. 3.1)",
        default=4, min=0, max=64)
    use_russian_roulette: BoolProperty(
        name="Russian Roulette", description="Terminate low-throughput paths at random, "
        "reweighting the survivors (unbiased)", default=True)
    rr_start_depth: IntProperty(
        name="Start Bounce", description="First bounce at which Russian roulette may end a path",
        default=3, min=1, max=1024)
    # Lights
    method: EnumProperty(
        name="Method", description="How paths find the lights", items=METHOD_ITEMS, default="mis")
    light_samples: IntProperty(
        name="Light Samples", description="Light samples (shadow rays) per path vertex",
        default=1, min=1, max=64)
    mis_heuristic: EnumProperty(
        name="MIS Heuristic", description="How MIS weighs light and BSDF samples",
        items=HEURISTIC_ITEMS, default="power")
    # Device
    device: EnumProperty(
        name="Device", description="Vulkan device to render on", items=DEVICE_ITEMS, default="auto")

    def render_params(self):
        """Keyword arguments for ``parallax_core.Session.set_params``."""
        return dict(
            method=self.method, mis_heuristic=self.mis_heuristic,
            samples_per_frame=self.samples_per_frame, max_depth=self.max_depth,
            depth_leeway=self.depth_leeway,
            rr_start_depth=self.rr_start_depth if self.use_russian_roulette else 0,
            light_samples=self.light_samples, seed=self.seed)


class ParallaxViewLayerSettings(bpy.types.PropertyGroup):
    use_pass_denoising_data: BoolProperty(
        name="Denoising Data", description="Denoising Albedo and Denoising Normal passes, for "
        "the compositor's Denoise node", default=True, update=lambda self, ctx: _update_passes(ctx))
    use_pass_ray_depth: BoolProperty(
        name="Ray Depth", description="Mean number of path segments traced per pixel",
        default=False, update=lambda self, ctx: _update_passes(ctx))


def _update_passes(context):
    # The compositor's Render Layers node picks up pass changes on this call.
    view_layer = getattr(context, "view_layer", None)
    if view_layer is not None:
        view_layer.update_render_passes()


classes = (ParallaxRenderSettings, ParallaxViewLayerSettings)


def register():
    for cls in classes:
        bpy.utils.register_class(cls)
    bpy.types.Scene.parallax = PointerProperty(type=ParallaxRenderSettings)
    bpy.types.ViewLayer.parallax = PointerProperty(type=ParallaxViewLayerSettings)


def unregister():
    del bpy.types.ViewLayer.parallax
    del bpy.types.Scene.parallax
    for cls in reversed(classes):
        bpy.utils.unregister_class(cls)
