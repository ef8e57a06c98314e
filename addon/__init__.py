"""Parallax: a Vulkan path tracer as a Blender render engine.

Installs as a Blender 4.2+ extension (blender_manifest.toml, the native core as a bundled
wheel) and also as a legacy add-on (bl_info) for Blender 3.4 to 4.1.
"""
bl_info = {
    "name": "Parallax",
    "author": "Parallax developers",
    "version": (0, 1, 0),
    "blender": (3, 4, 0),
    "location": "Render Properties > Render Engine > Parallax",
    "description": "Research-grade Vulkan path tracer (NEE, MIS, irradiance cache, guiding)",
    "category": "Render",
}

from . import engine, properties, ui, versioning  # noqa: E402

_modules = (properties, versioning, engine, ui)


def register():
    for module in _modules:
        module.register()


def unregister():
    for module in reversed(_modules):
        module.unregister()
