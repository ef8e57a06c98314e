"""``parallax render FILE.blend`` and ``parallax export FILE.blend``: bpy in the background,
through the same engine code as F12 (see parallax_core.cli for the command line)."""
import ast
import os
import sys


class CommandError(Exception):
    pass


def _bpy():
    try:
        import bpy
    except ImportError as e:
        raise CommandError(f"rendering .blend files needs Blender's Python module: "
                           f"pip install bpy==5.0.1 ({e})") from e
    return bpy


def open_blend(path, engine="PARALLAX", width=None):
    """Registers the add-on (once) and opens ``path``; returns the scene. ``width`` sets the
    render width (100%), the height keeping the file's aspect."""
    bpy = _bpy()
    if not os.path.isfile(path):
        raise CommandError(f"{path}: no such file")
    if not hasattr(bpy.types.Scene, "parallax"):
        from . import register
        register()
    bpy.ops.wm.open_mainfile(filepath=os.path.abspath(path), load_ui=False)
    scene = bpy.context.scene
    scene.render.engine = engine
    if width:
        render = scene.render
        aspect = render.resolution_y / render.resolution_x
        render.resolution_x, render.resolution_y = width, max(1, round(width * aspect))
        render.resolution_percentage = 100
    return scene


def apply_settings(scene, assignments):
    """``PROP=VALUE`` pairs: PROP is a Parallax setting (``samples``) or a path from the
    scene (``render.resolution_x``, ``cycles.samples``). A setting of the core's table is
    parsed by its row's type, as ``--set`` for .npz scenes parses it (parallax_core.cli);
    any other VALUE is a Python literal or a word (for a boolean: 1/0, true/false, on/off,
    yes/no). PROP may be a synonym of a setting (``adrrs=1``: ``rrs=adrrs``,
    parallax_core.SYNONYMS)."""
    from . import properties

    table = {row.name for row in properties.table_rows()}  # (loads the core)
    from parallax_core import SYNONYMS
    from parallax_core.cli import BOOL_WORDS, parse_params

    for item in assignments:
        name, sep, text = item.partition("=")
        if not sep:
            raise CommandError(f"--set {item!r}: expected PROP=VALUE")
        name = name.strip()
        if name in SYNONYMS:  # its setting, as for .npz scenes (parse_params gives the setting's value)
            name = SYNONYMS[name][0]
        path = name if "." in name else f"parallax.{name}"
        owner_path, _, attr = path.rpartition(".")
        try:
            owner = scene.path_resolve(owner_path)
        except ValueError as e:
            raise CommandError(f"--set {item!r}: scene has no '{owner_path}'") from e
        if not hasattr(owner, attr):
            raise CommandError(f"--set {item!r}: '{owner_path}' has no property '{attr}'")
        prop = owner.bl_rna.properties.get(attr) if hasattr(owner, "bl_rna") else None
        if name in table:
            try:
                value = parse_params([item.strip()])[name]
            except ValueError as e:
                raise CommandError(str(e)) from e
        elif prop is not None and prop.type == "BOOLEAN" and not prop.is_array:
            value = BOOL_WORDS.get(text.strip().lower())
            if value is None:
                raise CommandError(f"--set {item!r}: expected one of {', '.join(BOOL_WORDS)}")
        else:
            try:
                value = ast.literal_eval(text.strip())
            except (ValueError, SyntaxError):
                value = text.strip()
        try:
            setattr(owner, attr, value)
        except (TypeError, ValueError, AttributeError) as e:
            raise CommandError(f"--set {item!r}: {e}") from e


def set_exr_output(image_settings):
    if hasattr(image_settings, "media_type"):  # Blender 5: the media type decides the formats
        image_settings.media_type = "MULTI_LAYER_IMAGE"
    image_settings.file_format = "OPEN_EXR_MULTILAYER"
    image_settings.color_depth = "32"


def set_png_output(image_settings):
    if hasattr(image_settings, "media_type"):
        image_settings.media_type = "IMAGE"
    image_settings.file_format = "PNG"
    image_settings.color_mode = "RGB"
    image_settings.color_depth = "8"


def engine_final():
    """The ``engine.final`` module of the Parallax engine Blender has registered: this
    package's, or another copy's (an installed extension, the repository's add-on)."""
    import importlib

    import bpy

    for cls in bpy.types.RenderEngine.__subclasses__():
        if getattr(cls, "bl_idname", None) == "PARALLAX" and cls.is_registered:
            return importlib.import_module(cls.__module__ + ".final")
    from .engine import final
    return final


def _render(bpy, final):
    """Runs the render operator; Parallax's errors become CommandError."""
    final.last_report = final.RenderReport()
    final.progress_stream = sys.stderr
    try:
        bpy.ops.render.render()
    except RuntimeError as e:  # Blender raises when the engine reported an error
        raise CommandError("; ".join(final.last_report.errors) or str(e)) from e
    finally:
        final.progress_stream = None
    if bpy.context.scene.render.engine == "PARALLAX" and final.last_report.errors:
        raise CommandError("; ".join(final.last_report.errors))


def render(path, output, engine="PARALLAX", samples=None, device=None, assignments=(), png=None):
    """Renders a .blend's active scene to a multilayer EXR (and a colour-managed PNG)."""
    bpy = _bpy()
    scene = open_blend(path, engine)
    if samples is not None:
        (scene.parallax if engine == "PARALLAX" else scene.cycles).samples = samples
    if device is not None:
        if engine == "PARALLAX":
            scene.parallax.device = device
        else:
            scene.cycles.device = device.upper()
    apply_settings(scene, assignments)
    final = engine_final()

    _render(bpy, final)
    result = bpy.data.images["Render Result"]
    set_exr_output(scene.render.image_settings)
    result.save_render(os.path.abspath(output), scene=scene)
    if png:
        set_png_output(scene.render.image_settings)
        result.save_render(os.path.abspath(png), scene=scene)
    return scene


def export(path, output=None, width=None):
    """(SceneData, warnings) the core would receive for an F12 render of ``path`` (at
    ``width``, the height keeping the aspect, if given); saved to ``output`` if given."""
    bpy = _bpy()
    open_blend(path, width=width)
    final = engine_final()

    captured = []
    final.scene_hook = lambda data, warnings: captured.append((data, warnings))
    try:
        _render(bpy, final)
    finally:
        final.scene_hook = None
    if not captured:
        raise CommandError(f"{path}: the scene was not exported (no view layer rendered)")
    data, warnings = captured[0]
    if output:
        data.save(output)
    return data, warnings
