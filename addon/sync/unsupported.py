"""Scene features Parallax does not render, each named in one warning rather than dropped
silently: motion blur, holdout, indirect only, volume shaders, hair (curves objects and
hair particle systems) and point clouds."""
from .materials import node_tree
from .meshes import GEOMETRY_TYPES


def warn_unsupported(depsgraph, warnings):
    """Adds one warning per unsupported feature used by the evaluated ``depsgraph``."""
    scene = depsgraph.scene
    if getattr(scene.render, "use_motion_blur", False):
        warnings.add("motion blur is not supported: the scene renders as if it were off")

    holdout, indirect = [], []
    _flagged_collections(depsgraph.view_layer.layer_collection, holdout, indirect)
    hair, points = [], []
    objects, materials = set(), {}
    for inst in depsgraph.object_instances:
        obj = inst.object
        key = (obj.name_full, obj.type)  # an object's geometry nodes may also output hair
        if key in objects:
            continue
        objects.add(key)
        if inst.show_particles:
            hair += [f"hair particles '{name}' on object '{obj.name}'"
                     for name in _hair_particles(obj, depsgraph.mode)]
        if not (inst.is_instance or inst.show_self):
            continue
        if getattr(obj, "is_holdout", False):  # Blender 5.0's object-level holdout
            holdout.append(f"object '{obj.name}'")
        if obj.type == "CURVES" and len(obj.data.curves):  # empty when modifiers made a mesh
            hair.append(f"curves object '{obj.name}'")
        if obj.type == "POINTCLOUD" and len(obj.data.points):
            points.append(f"object '{obj.name}'")
        if obj.type in GEOMETRY_TYPES or obj.type == "VOLUME":
            materials.update((slot.material.name_full, slot.material)
                             for slot in obj.material_slots if slot.material is not None)
    volumes = [f"material '{m.name}'" for m in materials.values() if _has_volume(m)]
    if scene.world is not None and _has_volume(scene.world):
        volumes.append(f"world '{scene.world.name}'")

    if holdout:
        warnings.add(f"holdout is not supported: {_some(holdout)} rendered as if holdout "
                     "were off")
    if indirect:
        warnings.add(f"indirect only is not supported: {_some(indirect)} rendered as if "
                     "indirect only were off (directly visible)")
    if volumes:
        warnings.add(f"volume shaders are not supported: {_some(volumes)} rendered as "
                     "if the Volume output were unlinked")
    if hair:
        warnings.add(f"hair curves are not supported: {_some(hair)} not rendered")
    if points:
        warnings.add(f"point clouds are not supported: {_some(points)} not rendered")


def _some(items):
    """The first item, and how many more."""
    return items[0] if len(items) == 1 else f"{items[0]} and {len(items) - 1} more"


def _flagged_collections(layer_collection, holdout, indirect):
    """Appends the view layer's collections flagged holdout / indirect only that hold
    objects; excluded collections (and their children) are not rendered anyway."""
    for child in layer_collection.children:
        if child.exclude:
            continue
        if len(child.collection.all_objects):
            if child.holdout:
                holdout.append(f"collection '{child.name}'")
            if child.indirect_only:
                indirect.append(f"collection '{child.name}'")
        _flagged_collections(child, holdout, indirect)


def _hair_particles(obj, mode):
    """Names of the object's hair particle systems that Cycles would render as strands."""
    names = []
    for modifier in obj.modifiers:
        if modifier.type != "PARTICLE_SYSTEM":
            continue
        enabled = modifier.show_render if mode == "RENDER" else modifier.show_viewport
        settings = modifier.particle_system.settings
        if enabled and settings.type == "HAIR" and settings.render_type == "PATH":
            names.append(modifier.particle_system.name)
    return names


def _has_volume(id_block):
    """Whether the material's/world's active Cycles output has its Volume input linked."""
    tree = node_tree(id_block)
    output = tree.get_output_node("CYCLES") if tree is not None else None
    volume = output.inputs.get("Volume") if output is not None else None
    return volume is not None and volume.is_linked
