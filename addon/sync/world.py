"""Blender world -> Parallax World: Background colour x strength, or an equirectangular
Environment Texture x strength (importance-sampled by the core)."""
import numpy as np

from .images import image_rgb, srgb_to_linear
from .materials import node_tree


def export_world(world, data, warnings):
    from ..core import load

    World = load().scene.World
    if world is None:
        data.world = World(color=(0.0, 0.0, 0.0), strength=0.0)
        return
    tree = node_tree(world)
    output = tree.get_output_node("CYCLES") if tree is not None else None
    if output is None:
        data.world = World(color=tuple(world.color), strength=1.0)
        return
    background = _linked_node(output.inputs.get("Surface"))
    if background is None:
        data.world = World(color=(0.0, 0.0, 0.0), strength=0.0)
        return
    if background.type != "BACKGROUND":
        warnings.add(f"world '{world.name}': '{background.bl_label}' as the world surface is not "
                     "supported; rendered black")
        data.world = World(color=(0.0, 0.0, 0.0), strength=0.0)
        return
    strength = background.inputs["Strength"]
    if strength.is_linked:
        warnings.add(f"world '{world.name}': a linked Strength is not supported; using its value")
    color_socket = background.inputs["Color"]
    color = tuple(color_socket.default_value[:3])
    env_map = None
    source = _linked_node(color_socket)
    if source is not None:
        if source.type == "TEX_ENVIRONMENT" and source.image is not None:
            env_map = _environment_map(source, world.name, warnings)
            color = (1.0, 1.0, 1.0)
        else:
            warnings.add(f"world '{world.name}': '{source.bl_label}' into the Background colour is "
                         "not supported; using the colour value")
    data.world = World(color=color, strength=float(strength.default_value), map=env_map)


def is_black(world):
    return world.map is None and (world.strength == 0.0 or not np.any(np.asarray(world.color) > 0))


def _linked_node(socket):
    while socket is not None and socket.is_linked:
        node = socket.links[0].from_node
        if node.type != "REROUTE":
            return node
        socket = node.inputs[0]
    return None


def _environment_map(node, world_name, warnings):
    """The image as linear float (H, W, 3), row 0 at the top (the zenith); None if empty."""
    image = node.image
    label = f"world '{world_name}'"
    if node.projection != "EQUIRECTANGULAR":
        warnings.add(f"{label}: {node.projection} projection is rendered as equirectangular")
    if node.inputs["Vector"].is_linked:
        warnings.add(f"{label}: a mapped Vector input of the Environment Texture is ignored")
    loaded = image_rgb(image)
    if loaded is None:
        warnings.add(f"{label}: image '{image.name}' has no pixels (missing file?); using white")
        return None
    pixels, stored_as_srgb = loaded
    return np.ascontiguousarray(srgb_to_linear(pixels) if stored_as_srgb else pixels, dtype=np.float32)
