"""The add-on registers, unregisters and re-registers cleanly; its settings live in the .blend."""
import addon


def engines(bpy):
    """bl_idnames of the registered render engines."""
    return {getattr(e, "bl_idname", None) for e in bpy.types.RenderEngine.__subclasses__()
            if e.is_registered}


def test_register_unregister_register(bpy):
    for _ in range(2):
        addon.unregister()
        assert not hasattr(bpy.types.Scene, "parallax")
        assert "PARALLAX" not in engines(bpy)
        addon.register()
        assert hasattr(bpy.types.Scene, "parallax")
        assert "PARALLAX" in engines(bpy)
    # Shared Blender panels (dimensions, output, Cycles' material nodes) show for Parallax.
    assert "PARALLAX" in bpy.types.RENDER_PT_format.COMPAT_ENGINES


def test_engine_identity(bpy):
    from addon.engine import ParallaxRenderEngine

    assert ParallaxRenderEngine.bl_idname == "PARALLAX"
    assert ParallaxRenderEngine.bl_label == "Parallax"
    assert ParallaxRenderEngine.bl_use_shading_nodes_custom is False


def test_every_setting_has_a_description(bpy):
    from addon.properties import ParallaxRenderSettings, ParallaxViewLayerSettings

    for group in (ParallaxRenderSettings, ParallaxViewLayerSettings):
        for prop in group.bl_rna.properties:
            if prop.identifier not in ("rna_type", "name"):
                assert prop.description, f"{group.__name__}.{prop.identifier} has no description"


def test_settings_survive_save_and_load(fresh, bpy, tmp_path):
    settings = fresh.parallax
    settings.samples, settings.method, settings.mis_heuristic = 77, "pt", "balance"
    settings.max_depth, settings.rr_start_depth, settings.time_limit = 5, 0, 12.5
    settings.device = "cpu"
    fresh.view_layers[0].parallax.use_pass_ray_depth = True
    path = str(tmp_path / "settings.blend")
    bpy.ops.wm.save_as_mainfile(filepath=path)
    bpy.ops.wm.read_factory_settings(use_empty=True)
    assert bpy.context.scene.parallax.samples == 128  # defaults in a new file
    bpy.ops.wm.open_mainfile(filepath=path)
    scene = bpy.context.scene
    assert scene.render.engine == "PARALLAX"
    loaded = scene.parallax
    assert (loaded.samples, loaded.method, loaded.mis_heuristic) == (77, "pt", "balance")
    assert (loaded.max_depth, loaded.rr_start_depth, loaded.time_limit) == (5, 0, 12.5)
    assert loaded.device == "cpu" and scene.view_layers[0].parallax.use_pass_ray_depth
    params = loaded.render_params()
    assert params["rr_start_depth"] == 0 and params["method"] == "pt" and params["max_depth"] == 5


def test_render_params_match_the_core(bpy):
    import dataclasses

    from parallax_core import RenderParams
    from addon.properties import ParallaxRenderSettings

    scene = bpy.context.scene
    assert isinstance(scene.parallax, ParallaxRenderSettings)
    # preview (the viewport's quick first frame) is the engine's choice, not a scene setting.
    fields = {f.name for f in dataclasses.fields(RenderParams)} - {"preview"}
    params = set(scene.parallax.render_params())
    assert params == fields


def test_a_scene_renders_with_its_cycles_light_paths(fresh):
    # Values set in Cycles are used where Parallax's were never set: a scene made with Cycles
    # keeps its bounces, clamps and filter when a user switches engine.
    settings, cycles = fresh.parallax, fresh.cycles
    params = settings.render_params()
    assert (params["max_depth"], params["depth_leeway"], params["diffuse_bounces"]) == (12, 4, 4)  # Parallax's defaults
    cycles.max_bounces, cycles.diffuse_bounces, cycles.sample_clamp_indirect = 6, 2, 3.0
    cycles.pixel_filter_type, cycles.filter_width, cycles.blur_glossy = "GAUSSIAN", 2.0, 0.5
    params = settings.render_params()
    assert (params["max_depth"], params["diffuse_bounces"], params["sample_clamp_indirect"]) == (6, 2, 3.0)
    assert params["blur_glossy"] == 0.5
    assert (params["pixel_filter_type"], params["filter_width"]) == ("GAUSSIAN", 2.0)
    assert params["depth_leeway"] == 0  # Cycles' Total counts every bounce
    assert params["glossy_bounces"] == 4  # never set in Cycles: Parallax's (the same default)
    # Parallax's own values win once set.
    settings.diffuse_bounces, settings.depth_leeway = 3, 2
    params = settings.render_params()
    assert (params["diffuse_bounces"], params["depth_leeway"], params["max_depth"]) == (3, 2, 6)
