"""Blender world -> Parallax World: Background colour x strength, an equirectangular
Environment Texture x strength (importance-sampled by the core), or any other graph into the
Background's Colour and Strength (Sky Texture, gradients, mapped or tinted images, ...) baked
on the host into an equirectangular map (parallax_core.node_fields), as Cycles bakes its
world for importance sampling. A Sky Texture's sun disc becomes a sun light."""
import numpy as np

from .images import image_rgb, srgb_to_linear
from .materials import node_tree
from .node_graph import GraphCompiler, Unsupported, _tree_nodes, vector_linked

# Baked maps (2:1): this width unless an image in the graph is wider, up to the maximum. The
# Rendered viewport bakes on Blender's thread at every world edit: a quarter of the texels.
BAKE_WIDTHS = (1024, 4096)
PREVIEW_BAKE_WIDTHS = (512, 1024)


def export_world(world, data, warnings, bake_widths=BAKE_WIDTHS):
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
    color_socket = background.inputs["Color"]
    color = tuple(color_socket.default_value[:3])
    source = _linked_node(color_socket)
    if source is None and not strength.is_linked:
        data.world = World(color=color, strength=float(strength.default_value))
    elif _plain_environment(source) and not strength.is_linked:  # the image itself, unresampled
        env_map = _environment_map(source, world.name, warnings)
        data.world = World(color=(1.0, 1.0, 1.0) if env_map is not None else color,
                           strength=float(strength.default_value), map=env_map)
    else:
        _bake(world, background, data, warnings, bake_widths)


def is_black(world):
    return world.map is None and (world.strength == 0.0 or not np.any(np.asarray(world.color) > 0))


def _linked_node(socket):
    while socket is not None and socket.is_linked:
        node = socket.links[0].from_node
        if node.type != "REROUTE":
            return node
        socket = node.inputs[0]
    return None


def _plain_environment(node):
    return (node is not None and node.type == "TEX_ENVIRONMENT" and node.image is not None and
            node.projection == "EQUIRECTANGULAR" and not vector_linked(node))


def _texel_directions(width, height, rows=None):
    """World directions at the texel centres of a (height, width) equirectangular map laid
    out as parallax_core.scene.World's (row 0 at the top): (N, 3), row by row, of ``rows``
    (a range; all by default)."""
    rows = range(height) if rows is None else rows
    u = (np.arange(width) + 0.5) / width
    v = 1.0 - (np.asarray(rows) + 0.5) / height
    phi, latitude = np.meshgrid((0.5 - u) * 2.0 * np.pi, (v - 0.5) * np.pi)
    return np.stack([np.cos(latitude) * np.cos(phi), np.cos(latitude) * np.sin(phi), np.sin(latitude)],
                    -1).reshape(-1, 3)


def _background_program(world, background, directions, images, warnings):
    """(FieldProgram, colour, strength): the Background's graph over ``directions`` (Cycles'
    background shading point: P = the direction, N = I = -direction, UV 0). Raises Unsupported
    (or ValueError) for a graph the host cannot evaluate. ``images`` caches the host images."""
    from ..core import load

    label = f"world '{world.name}'"
    back = -directions
    program = load().node_fields.FieldProgram(len(directions), {
        "position": directions, "generated": directions, "object": directions, "normal": back,
        "true_normal": back, "incoming": back, "object_normal": back,
        "uv": np.broadcast_to(np.zeros(3), directions.shape)})

    def image(image, node_label, interpolation):
        key = (image.name_full, interpolation)
        if key not in images:
            images[key] = _host_image(image, label, interpolation, warnings)
        return images[key]

    compiler = GraphCompiler(program, image, label)
    return (program, compiler.socket(background.inputs["Color"], "color"),
            compiler.socket(background.inputs["Strength"], "float"))


# Texels a bake evaluates at once: the fields stay some tens of MB whatever the map's size.
BAKE_BLOCK = 1 << 18


def _bake(world, background, data, warnings, bake_widths):
    """The Background's Colour x Strength evaluated in every direction of an equirectangular
    map, as wide as the widest image in the graph within ``bake_widths`` (least, most), a
    block of rows at a time."""
    from ..core import load

    core = load()
    widths = [n.image.size[0] for n in _tree_nodes(world.node_tree)
              if n.type in ("TEX_ENVIRONMENT", "TEX_IMAGE") and n.image is not None]
    width = int(min(max([bake_widths[0]] + widths), bake_widths[1]))
    height = max(width // 2, 1)
    rows_per_block = max(1, BAKE_BLOCK // width)
    radiance, images, program = None, {}, None
    for first in range(0, height, rows_per_block):
        rows = range(first, min(first + rows_per_block, height))
        try:
            program, color, strength = _background_program(world, background, _texel_directions(width, height, rows),
                                                            images, warnings)
        except (Unsupported, ValueError) as e:
            warnings.add(f"world '{world.name}': the Background is driven by {e}, which is not supported; using "
                         "its colour and strength values")
            data.world = core.scene.World(color=tuple(background.inputs["Color"].default_value[:3]),
                                          strength=float(background.inputs["Strength"].default_value))
            return
        if program.is_constant(color) and program.is_constant(strength):
            data.world = core.scene.World(color=tuple(float(x) for x in core.nodes._vec4(color)[:3]),
                                          strength=float(core.nodes._vec4(strength)[0]))
            break
        if radiance is None:
            radiance = np.empty((height, width, 3), np.float32)
        block = program.evaluate(color, "color")[:, :3] * program.evaluate(strength, "float")[:, None]
        radiance[rows.start:rows.stop] = np.nan_to_num(np.maximum(block, 0.0), nan=0.0, posinf=0.0).reshape(
            len(rows), width, 3)
    if radiance is not None:
        data.world = core.scene.World(color=(1.0, 1.0, 1.0), strength=1.0, map=radiance)
    _sun_discs(world, background, program.skies, images, data, warnings)


def _sun_discs(world, background, skies, images, data, warnings):
    """The sun disc of a Sky Texture straight into the Background's Colour as a sun light of
    the disc's angular diameter and mean radiance (x the Strength in its direction). The disc of
    a sky whose colour passes through other nodes is left out, with a warning."""
    from ..core import load

    core = load()
    source = _linked_node(background.inputs["Color"])
    direct = source is not None and source.type == "TEX_SKY" and not vector_linked(source)
    for name, params in skies:
        sun = core.node_fields.sky_model(params).sun()
        if sun is None:
            continue
        if not (direct and name == source.name):
            warnings.add(f"world '{world.name}': the sun disc of Sky Texture '{name}' is left out (only a "
                         "Sky Texture straight into the Background's Colour gives its sun)")
            continue
        direction, diameter, radiance = sun
        program, _, strength = _background_program(world, background, np.asarray(direction, np.float64)[None],
                                                    images, warnings)
        scale = float(program.evaluate(strength, "float")[0])
        half = 0.5 * diameter  # the core turns power into radiance: power / (pi sin^2 half)
        data.lights.append(core.scene.Light(
            type="sun", power=float(scale * np.pi * np.sin(half) ** 2), color=tuple(float(x) for x in radiance),
            direction=tuple(float(x) for x in -np.asarray(direction)), angle=float(diameter),
            name=f"{world.name} sun", camera_visible=True))


def _host_image(image, label, interpolation, warnings):
    """A node's image for the host bake (node_fields.HostImage), None without pixels."""
    from ..core import load

    loaded = image_rgb(image)
    if loaded is None:
        warnings.add(f"{label}: image '{image.name}' has no pixels (missing file?)")
        return None
    pixels, stored_as_srgb = loaded
    return load().node_fields.HostImage(np.nan_to_num(pixels, nan=0.0, posinf=0.0), stored_as_srgb, interpolation)


def _environment_map(node, world_name, warnings):
    """The image as linear float (H, W, 3), row 0 at the top (the zenith); None if empty."""
    image = node.image
    label = f"world '{world_name}'"
    loaded = image_rgb(image)
    if loaded is None:
        warnings.add(f"{label}: image '{image.name}' has no pixels (missing file?); using white")
        return None
    pixels, stored_as_srgb = loaded
    return np.ascontiguousarray(srgb_to_linear(pixels) if stored_as_srgb else pixels, dtype=np.float32)
