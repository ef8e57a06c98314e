"""Older .blend files: settings the add-on no longer has, read back as the settings that
replaced them.

A file keeps the value of a property the add-on has since removed (the ID property stays in
``scene.parallax``'s storage, invisible to RNA). After every file load, a removed setting
that is a synonym of a current one (``parallax_core.SYNONYMS``: ADRRS' switch ``adrrs``,
whose True is ``rrs = 'adrrs'``) sets that setting, unless the file set it itself, and is
dropped, so that saving the file leaves only the current setting.
"""
import bpy

from . import core


def _stored(settings):
    """The ID properties stored for ``settings`` (a PropertyGroup): Blender 5's system
    properties, or the group itself before (where ``get`` reads them)."""
    get = getattr(settings, "bl_system_properties_get", None)
    group = get() if get is not None else None
    return group if group is not None else settings


def migrate_scene(scene):
    """Moves ``scene``'s removed synonym settings to their settings; returns the names moved."""
    settings = getattr(scene, "parallax", None)
    if settings is None:
        return []
    pc = core.load()
    stored = _stored(settings)
    moved = []
    for name in pc.SYNONYMS:
        if name in settings.bl_rna.properties or stored.get(name) is None:
            continue
        value = stored[name]
        del stored[name]
        try:
            target, value = pc.synonym(name, value)
        except ValueError:  # not a value the old setting could hold: dropped
            continue
        if not settings.is_property_set(target):
            setattr(settings, target, value)
            moved.append(name)
    return moved


def migrate_all():
    for scene in bpy.data.scenes:
        migrate_scene(scene)


@bpy.app.handlers.persistent
def _on_load(_filepath=None):
    migrate_all()


def register():
    bpy.app.handlers.load_post.append(_on_load)
    try:  # the add-on enabled with a file open (at Blender's start bpy.data is not readable yet)
        migrate_all()
    except AttributeError:
        pass


def unregister():
    if _on_load in bpy.app.handlers.load_post:
        bpy.app.handlers.load_post.remove(_on_load)
