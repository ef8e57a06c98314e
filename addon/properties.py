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


IC_SETTINGS = ("ic", "ic_accuracy", "ic_min_radius", "ic_create_prob", "ic_update_prob",
               "ic_nee_samples", "ic_gradients", "ic_gradient_max", "ic_visibility_check",
               "ic_prepare_frames", "ic_capacity", "ic_rebuild_interval", "ic_highlight")
ADRRS_SETTINGS = ("adrrs", "adrrs_splitting", "adrrs_window", "adrrs_rr_min", "adrrs_max_splits",
                  "adrrs_estimate_spp", "adrrs_estimate", "adrrs_ic_glossy")
GUIDING_SETTINGS = ("guiding", "guiding_prob", "guiding_parallax", "guiding_training_spp",
                    "guiding_min_samples", "guiding_max_components", "guiding_split_merge",
                    "guiding_region_splits", "guiding_region_threshold", "guiding_max_regions",
                    "guiding_probe_x", "guiding_probe_y", "guiding_fit")
LOBES_LOOP_FRAMES = 48  # Animate Lobes: frames per loop of the spheres through their regions (2 s at 24 fps)
GUIDING_FIT_ITEMS = (
    ("auto", "Automatic", "Device on a GPU, CPU on lavapipe: where each was measured faster"),
    ("cpu", "CPU", "Fit the mixtures on the CPU: the samples are read back after each training "
                   "frame, kept per region until there are enough, and regions refine"),
    ("device", "Device", "Fit the mixtures in compute shaders where the samples are: no sample "
                         "readback; regions refine as with the CPU fit (a few bytes per region read back)"),
)
# What the Rendered viewport can show (as Cycles' viewport Render Pass): the combined image or
# one of the technique's visualisation passes, read from the same session (passes.py).
VIEWPORT_PASS_ITEMS = (
    ("combined", "Combined", "The rendered image"),
    ("normal", "Normal", "First-hit shading normal"),
    ("albedo", "Albedo", "First-hit albedo (the denoising albedo)"),
    ("depth", "Depth", "Distance to the first hit"),
    ("ray_depth", "Ray Depth", "Mean path length"),
    ("ic_irradiance", "IC Irradiance", "Irradiance cache: interpolated irradiance (cache on)"),
    ("ic_gradients", "IC Gradients", "Irradiance cache: gradient magnitudes (cache on)"),
    ("adrrs_estimate", "ADRRS Estimate", "ADRRS: the adjoint estimate (ADRRS on)"),
    ("adrrs_splits", "ADRRS Splits", "ADRRS: splits per pixel sample (ADRRS on)"),
    ("guiding_regions", "Guiding Regions", "Path guiding: a colour per region (guiding on)"),
    ("guiding_components", "Guiding Components", "Path guiding: active lobes / max (guiding on)"),
    ("guiding_lobes", "Guiding Lobes", "Path guiding: the probe pixel's mixture as an inset, and "
                                        "a sphere per trained region coloured by its pdf (guiding on)"),
)
ADRRS_ESTIMATE_ITEMS = (
    ("ic", "Irradiance Cache", "Estimate frames after the cache's prepare frames: paths to the "
                               "first non-specular hit, lit by NEE and the cache (thesis 4.5)"),
    ("image", "Image", "The image rendered so far, blurred; refreshed each time the samples "
                       "double (the alternative the thesis names in 4.5)"),
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
    viewport_pass: EnumProperty(
        name="Viewport Pass", description="What the Rendered viewport shows: the image or a "
        "visualisation pass, live (switching keeps the samples and the trained guiding field)",
        items=VIEWPORT_PASS_ITEMS, default="combined")
    # Light paths
    max_depth: IntProperty(
        name="Max Bounces", description="Maximum number of non-specular bounces (Cycles' Max "
        "Bounces)", default=8, min=0, max=1024)
    depth_leeway: IntProperty(
        name="Discrete Leeway", description="Specular (delta) bounces that do not count towards "
        "Max Bounces, so light through glass and mirrors is not cut short (thesis, sec. 3.1)",
        default=4, min=0, max=64)
    use_russian_roulette: BoolProperty(
        name="Russian Roulette", description="Terminate low-throughput paths at random "
        "(survival probability the square root of the throughput, as Cycles), reweighting the "
        "survivors (unbiased)", default=True)
    rr_start_depth: IntProperty(
        name="Start Bounce", description="First bounce at which Russian roulette may end a path",
        default=3, min=1, max=1024)
    # Lights
    method: EnumProperty(
        name="Method", description="How paths find the lights", items=METHOD_ITEMS, default="mis")
    light_samples: IntProperty(
        name="Light Samples", description="Light samples (shadow rays) per path vertex",
        default=1, min=1, max=64)
    light_tree: BoolProperty(
        name="Light Tree", description="Pick among the local lights (lamps, emissive meshes) "
        "by their estimated contribution at the shading point, through a tree over them "
        "(Conty Estevez & Kulla 2018), as Cycles' Light Tree; off: by emitted power alone",
        default=True)
    mis_heuristic: EnumProperty(
        name="MIS Heuristic", description="How MIS weighs light and BSDF samples",
        items=HEURISTIC_ITEMS, default="power")
    # Irradiance cache (thesis, sec. 3.2.3 and 4.4; Ward, Rubinstein & Clear 1988; Ward & Heckbert 1992)
    ic: BoolProperty(
        name="Irradiance Cache", description="Reuse indirect diffuse irradiance from sparse cache "
        "entries, each the mean of a hemisphere of paths, interpolated between nearby entries "
        "(Ward, Rubinstein & Clear 1988; thesis, sec. 4.4). Biased but smooth",
        default=False, update=lambda self, ctx: _update_scene_passes(self))
    ic_accuracy: FloatProperty(
        name="Accuracy", description="Ward's accuracy a: an entry is used where its error "
        "estimate is below a, i.e. within a times its radius and for normals close to its own. "
        "Smaller is more accurate and needs more entries (Ward et al. 1988)",
        default=0.2, min=0.001, max=2.0, soft_min=0.05, precision=3)
    ic_min_radius: FloatProperty(
        name="Min Radius", description="Lower limit of an entry's radius, the harmonic mean "
        "distance of its hemisphere paths, in scene units: keeps corners and contact regions "
        "from needing unbounded numbers of entries", default=0.1, min=0.0001, soft_max=10.0,
        precision=4, subtype="DISTANCE", unit="LENGTH")
    ic_visibility_check: BoolProperty(
        name="Visibility Check", description="Skip entries that lie in front of the shaded "
        "point (Ward et al. 1988's 'in front' test), so light does not leak across creases",
        default=True)
    ic_create_prob: FloatProperty(
        name="Creation Probability", description="Probability that a path vertex without a "
        "valid cache entry queues the creation of one (thesis, sec. 4.4)", default=0.01,
        min=0.0, max=1.0, precision=4, subtype="FACTOR")
    ic_update_prob: FloatProperty(
        name="Update Probability", description="Probability per pixel and frame of refreshing "
        "a cache entry with new hemisphere paths, so early noisy entries improve over time",
        default=1e-5, min=0.0, max=1.0, precision=6, subtype="FACTOR")
    ic_nee_samples: IntProperty(
        name="Entry Light Samples", description="Light samples per vertex of the hemisphere "
        "paths that compute a cache entry", default=1, min=1, max=64)
    ic_prepare_frames: IntProperty(
        name="Prepare Frames", description="Frames that only fill the cache before the image "
        "starts to accumulate", default=50, min=0, max=10000)
    ic_capacity: IntProperty(
        name="Capacity", description="Maximum number of cache entries; creations beyond it are "
        "dropped (and counted in the render stats)", default=65536, min=1, max=4_000_000)
    ic_rebuild_interval: IntProperty(
        name="Rebuild Interval", description="Rebuild the cache's acceleration structure from "
        "scratch, in Morton order, every this many frames (in between, frames that add entries "
        "only refit it; on lavapipe a refit tree traces several times slower, hence 1)",
        default=1, min=1, max=100000)
    ic_gradients: BoolProperty(
        name="Gradients", description="Extrapolate each entry with its rotational and "
        "translational irradiance gradients (Ward & Heckbert 1992) for smoother interpolation",
        default=False)
    ic_gradient_max: FloatProperty(
        name="Max Gradient Length", description="Clamp of the gradients' length relative to the "
        "entry's irradiance, against extrapolating noisy gradients",
        default=5.0, min=0.0, soft_max=20.0)
    ic_highlight: BoolProperty(
        name="Colour Highlight", description="The IC Irradiance pass shows only the colour "
        "(the thesis' colour-highlight mode, fig. 4.13)", default=False)
    # Adjoint-driven Russian roulette and splitting (thesis 3.2.4, 4.5; Vorba & Krivanek 2016)
    adrrs: BoolProperty(
        name="ADRRS", description="Adjoint-driven Russian roulette and splitting: end paths whose "
        "continuation matters little and split those that matter much, judged by the irradiance "
        "cache and a pixel estimate (Vorba & Krivanek 2016; thesis, sec. 4.5). Unbiased; builds "
        "the irradiance cache for its estimates even with the cache off",
        default=False, update=lambda self, ctx: _update_scene_passes(self))
    adrrs_splitting: BoolProperty(
        name="Splitting", description="Split paths whose weight lies above the window (else "
        "only roulette below it)", default=True)
    adrrs_window: FloatProperty(
        name="Window Width", description="s: the weight window spans 2C/(1+s) to 2sC/(1+s) "
        "around the ideal weight C (Vorba & Krivanek recommend 5)", default=5.0, min=1.0,
        soft_max=20.0, max=1e6)
    adrrs_rr_min: FloatProperty(
        name="Min Survival", description="Lowest survival probability of Russian roulette below "
        "the window (against fireflies)", default=0.1, min=0.001, max=1.0, subtype="FACTOR")
    adrrs_max_splits: IntProperty(
        name="Max Splits", description="Most extra paths split off per pixel sample",
        default=10, min=0, max=64)
    adrrs_estimate: EnumProperty(
        name="Estimate", description="Where the pixel estimate comes from", items=ADRRS_ESTIMATE_ITEMS,
        default="ic")
    adrrs_estimate_spp: IntProperty(
        name="Estimate Samples", description="Irradiance Cache: estimate frames (1 sample per "
        "pixel each); Image: samples before the first estimate", default=4, min=1, max=65536)
    adrrs_ic_glossy: BoolProperty(
        name="Cache on Glossy", description="The Irradiance Cache estimate reads the cache at "
        "glossy surfaces too (thesis, sec. 4.4)", default=True)
    # Path guiding (thesis 3.2.5-3.2.8, 4.6; Ruppert, Herholz & Lensch 2020)
    guiding: BoolProperty(
        name="Path Guiding", description="Sample directions from a von Mises-Fisher mixture of the "
        "incident light, learnt per region of the scene from the paths traced so far, mixed with "
        "BSDF sampling (Ruppert, Herholz & Lensch 2020; thesis, sec. 4.6). Unbiased",
        default=False, update=lambda self, ctx: _update_scene_passes(self))
    guiding_prob: FloatProperty(
        name="Guiding Probability", description="Probability of sampling the mixture rather than "
        "the BSDF at a guided vertex (one-sample MIS of the two)", default=0.5, min=0.0, max=1.0,
        subtype="FACTOR")
    guiding_parallax: BoolProperty(
        name="Parallax", description="Each lobe aims at the point its light came from, so one "
        "region's mixture points the right way from anywhere in it (Ruppert et al. 2020)",
        default=True)
    guiding_training_spp: IntProperty(
        name="Training Samples", description="Samples per pixel (1 per training frame) spent "
        "training before the image accumulates; 0 = keep training while the image accumulates",
        default=32, min=0, max=65536)
    guiding_min_samples: IntProperty(
        name="Min Samples", description="A region fits its mixture once it has accumulated this "
        "many lit samples (across frames, so rarely lit regions train too)", default=64, min=1,
        max=2**24)
    guiding_max_components: IntProperty(
        name="Max Components", description="Most lobes per region's mixture", default=16, min=1,
        max=16)
    guiding_split_merge: BoolProperty(
        name="Split and Merge", description="Split lobes that fit their samples badly and merge "
        "lobes that say the same (Ruppert et al. 2020)", default=True)
    guiding_region_splits: IntProperty(
        name="Region Splits", description="The scene box is halved this many times along its "
        "longest axis: 2^n regions to start with, split further as they gather light", default=3, min=0, max=20)
    guiding_region_threshold: IntProperty(
        name="Region Threshold", description="A region that received this many lit samples (paths "
        "that found light) splits in two, both halves keeping its mixture (0 = never)", default=10000, min=0, max=2**31 - 1)
    guiding_max_regions: IntProperty(
        name="Max Regions", description="Adaptive refinement stops at this many regions",
        default=4096, min=1, max=2**22)
    guiding_fit: EnumProperty(
        name="Fit On", description="Where the guiding mixtures are fitted", items=GUIDING_FIT_ITEMS,
        default="auto")
    guiding_probe_x: IntProperty(
        name="Probe X", description="Pixel column whose first hit's mixture the Guiding Lobes "
        "pass plots (-1 = the image centre)", default=-1, min=-1, max=16383)
    guiding_probe_y: IntProperty(
        name="Probe Y", description="Pixel row (from the top) whose first hit's mixture the Guiding "
        "Lobes pass plots (-1 = the image centre)", default=-1, min=-1, max=16383)
    guiding_animate_lobes: BoolProperty(
        name="Animate Lobes", description="Guiding Lobes pass: the spheres move through their "
        f"regions with the timeline (a loop every {LOBES_LOOP_FRAMES} frames) and show the mixture "
        "where they are, so parallax-aware lobes turn to keep aiming at their lights (thesis fig. 4.20)",
        default=False)
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
            light_samples=self.light_samples, light_tree=self.light_tree, seed=self.seed,
            guiding_lobes_phase=self.guiding_lobes_phase(),
            **{name: getattr(self, name) for name in IC_SETTINGS + ADRRS_SETTINGS + GUIDING_SETTINGS})

    def guiding_lobes_phase(self):
        """Where the Guiding Lobes spheres are: -1 at their regions' centres, or with Animate
        Lobes the scene's frame along their loop, in [0, 1)."""
        if not self.guiding_animate_lobes:
            return -1.0
        return (self.id_data.frame_current % LOBES_LOOP_FRAMES) / LOBES_LOOP_FRAMES


class ParallaxViewLayerSettings(bpy.types.PropertyGroup):
    use_pass_denoising_data: BoolProperty(
        name="Denoising Data", description="Denoising Albedo and Denoising Normal passes, for "
        "the compositor's Denoise node", default=True, update=lambda self, ctx: _update_passes(ctx))
    use_pass_ray_depth: BoolProperty(
        name="Ray Depth", description="Mean number of path segments traced per pixel",
        default=False, update=lambda self, ctx: _update_passes(ctx))
    use_pass_ic_irradiance: BoolProperty(
        name="IC Irradiance", description="Irradiance cache: the cached indirect irradiance at "
        "the first diffuse hit, without the surface colour (with the Irradiance Cache on)",
        default=True, update=lambda self, ctx: _update_passes(ctx))
    use_pass_ic_gradients: BoolProperty(
        name="IC Gradients", description="Irradiance cache: R = length of the translational "
        "gradient, G = of the rotational gradient (with the Irradiance Cache on)",
        default=True, update=lambda self, ctx: _update_passes(ctx))
    use_pass_adrrs_estimate: BoolProperty(
        name="ADRRS Estimate", description="ADRRS: the pixel estimate its weight window is "
        "centred on (with ADRRS on)", default=True, update=lambda self, ctx: _update_passes(ctx))
    use_pass_adrrs_splits: BoolProperty(
        name="ADRRS Splits", description="ADRRS: extra paths split off per pixel sample (with "
        "ADRRS on)", default=True, update=lambda self, ctx: _update_passes(ctx))
    use_pass_guiding_regions: BoolProperty(
        name="Guiding Regions", description="Path guiding: a colour per guiding region at the "
        "first hit (with Path Guiding on)", default=True, update=lambda self, ctx: _update_passes(ctx))
    use_pass_guiding_components: BoolProperty(
        name="Guiding Components", description="Path guiding: active lobes of the first hit's "
        "region / Max Components (with Path Guiding on)", default=True,
        update=lambda self, ctx: _update_passes(ctx))
    use_pass_guiding_lobes: BoolProperty(
        name="Guiding Lobes", description="Path guiding: a lat-long plot of the probe pixel's "
        "mixture (inset, bottom left) and a sphere per trained region coloured by its mixture's "
        "density (with Path Guiding on)", default=True, update=lambda self, ctx: _update_passes(ctx))


def _update_scene_passes(settings):
    # A scene setting that adds or removes passes: every view layer of the scene.
    for view_layer in settings.id_data.view_layers:
        view_layer.update_render_passes()


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
