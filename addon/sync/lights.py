"""Blender lights -> Parallax lights, in Cycles' units (the core converts power to radiance).

Power is ``energy * 2^exposure``. Point/spot: in W, radius = ``shadow_soft_size``; with Soft
Falloff (Blender's default) a disk facing the shading point as in Cycles, else a true sphere. Sun: strength in W/m^2 and angular diameter. Area: power in W over the
shape scaled by the object (square, rectangle, disk, ellipse), one-sided along local -Z.
"""
import numpy as np

# Sizes are scaled per axis by the object, so squares and disks may stretch.
AREA_SHAPES = {"SQUARE": "rectangle", "RECTANGLE": "rectangle", "DISK": "ellipse", "ELLIPSE": "ellipse"}


def _node_emission(tree, label, warnings):
    """The factor a light's node tree puts on its colour x power: the Emission's Color x
    Strength at its Surface output, as Cycles multiplies them. The graph is folded on the host
    (parallax_core.node_fields); one that varies over the light (texture coordinates, IES,
    ...) or another shader is named in a warning, and its sockets' own values are used. Without
    a surface at the output the light is black, as in Cycles."""
    from ..core import load

    from .node_graph import GraphCompiler, Unsupported
    from .world import _linked_node

    core = load()
    output = tree.get_output_node("CYCLES")
    emission = _linked_node(output.inputs.get("Surface")) if output is not None else None
    if emission is None:  # Cycles' light then emits nothing
        warnings.add(f"{label}: its node tree has no surface at its output: it emits no light (as in Cycles)")
        return np.zeros(3)
    if emission.type != "EMISSION":
        warnings.add(f"{label}: '{emission.bl_label}' as the light's surface is not supported; colour x power is used")
        return np.ones(3)
    color, strength = emission.inputs["Color"], emission.inputs["Strength"]
    own = np.asarray(color.default_value[:3], np.float64) * float(strength.default_value)
    program = core.node_fields.FieldProgram(1, {})  # no coordinates: a light's graph must fold
    compiler = GraphCompiler(program, lambda *args: None, label)
    try:
        rgb, scale = compiler.socket(color, "color"), compiler.socket(strength, "float")
    except (Unsupported, ValueError) as e:
        warnings.add(f"{label}: the Emission is driven by {e}, which is not supported; using its values")
        return own
    return core.nodes._vec4(rgb)[:3] * float(core.nodes._vec4(scale)[0])


def export_lights(depsgraph, data, warnings):
    from ..core import load

    Light = load().scene.Light
    for inst in depsgraph.object_instances:
        obj = inst.object
        if obj.type != "LIGHT" or not (inst.is_instance or inst.show_self):
            continue
        light = obj.data
        label = f"light '{obj.name}'"
        m = np.array(inst.matrix_world, dtype=np.float64)
        axis_x, axis_y, axis_z = m[:3, 0], m[:3, 1], m[:3, 2]
        if np.linalg.norm(axis_z) == 0.0:
            warnings.add(f"{label}: zero scale, skipped")
            continue
        common = dict(color=tuple(light.color), position=tuple(m[:3, 3]),
                      direction=tuple(-axis_z / np.linalg.norm(axis_z)), name=obj.name,
                      camera_visible=bool(getattr(obj, "visible_camera", True)))
        power = float(light.energy) * 2.0 ** float(getattr(light, "exposure", 0.0))
        if not getattr(light, "normalize", True) and light.type != "AREA":
            warnings.add(f"{label}: Normalize off is ignored (power is used as if on)")
        if getattr(light, "use_nodes", False) and light.node_tree is not None:
            common["color"] = tuple(np.asarray(common["color"]) * _node_emission(light.node_tree, label, warnings))
        if light.type in ("POINT", "SPOT"):
            kind = "point" if light.type == "POINT" else "spot"
            extra = dict(radius=float(light.shadow_soft_size),
                         soft_falloff=bool(getattr(light, "use_soft_falloff", True)))
            if kind == "spot":
                extra.update(spot_size=float(light.spot_size), spot_blend=float(light.spot_blend))
            data.lights.append(Light(type=kind, power=power, **common, **extra))
        elif light.type == "SUN":
            data.lights.append(Light(type="sun", power=power,
                                     angle=float(light.angle), **common))
        elif light.type == "AREA":
            scale_x, scale_y = np.linalg.norm(axis_x), np.linalg.norm(axis_y)
            if scale_x == 0.0 or scale_y == 0.0:
                warnings.add(f"{label}: zero scale, skipped")
                continue
            if getattr(light, "spread", np.pi) < np.pi - 1e-6:
                warnings.add(f"{label}: Spread below 180 degrees is ignored")
            shape = AREA_SHAPES.get(light.shape, "rectangle")
            size_x = light.size * scale_x
            size_y = (light.size_y if light.shape in ("RECTANGLE", "ELLIPSE") else light.size) * scale_y
            if not getattr(light, "normalize", True):  # power is per unit area: undo the core's 1/A
                power *= size_x * size_y * (np.pi / 4.0 if shape == "ellipse" else 1.0)
            data.lights.append(Light(
                type="area", power=power, shape=shape, size=float(size_x), size_y=float(size_y),
                axis_u=tuple(axis_x / scale_x), axis_v=tuple(axis_y / scale_y), **common))
        else:
            warnings.add(f"{label}: {light.type} lights are not supported, skipped")
