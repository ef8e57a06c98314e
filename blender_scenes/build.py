"""Build the Parallax test scenes as .blend files, from scratch, with bpy.

    .venv/bin/python blender_scenes/build.py [NAME ...] [--out DIR]   # default: every scene
    blender -b --python blender_scenes/build.py -- [NAME ...] --out DIR  # e.g. Blender 3.4

Each scene is saved as blender_scenes/NAME.blend. Units are metres, Z is up.
Materials use only nodes that Cycles and Parallax render identically: Diffuse BSDF
(roughness 0), Glossy and Glass BSDF (GGX), Emission, Image Texture -> Diffuse Color.
"""

import math
import os
import sys

import bpy
import bmesh
import numpy as np
from mathutils import Matrix, Vector

HERE = os.path.dirname(os.path.abspath(__file__))
REPO_ROOT = os.path.dirname(HERE)

WHITE = (0.725, 0.71, 0.68)  # Bitterli's Cornell box reflectances
RED = (0.63, 0.065, 0.05)
GREEN = (0.14, 0.45, 0.091)
STONE = (0.72, 0.66, 0.55)


# --------------------------------------------------------------------------- materials

def use_nodes(id_block):
    """Blender < 5 makes materials and worlds without node trees unless asked."""
    if bpy.app.version < (5, 0, 0):
        id_block.use_nodes = True


def _material(name, shader_type, **inputs):
    """A material whose surface is one shader node with the given input values."""
    mat = bpy.data.materials.new(name)
    use_nodes(mat)
    nodes, links = mat.node_tree.nodes, mat.node_tree.links
    nodes.clear()
    shader = nodes.new(shader_type)
    out = nodes.new("ShaderNodeOutputMaterial")
    out.location = (300, 0)
    links.new(shader.outputs[0], out.inputs["Surface"])
    for key, value in inputs.items():
        shader.inputs[key].default_value = (*value, 1.0) if key == "Color" else value
    if "Color" in inputs:
        mat.diffuse_color = (*inputs["Color"], 1.0)  # viewport colour only
    return mat, shader


def diffuse(name, color):
    return _material(name, "ShaderNodeBsdfDiffuse", Color=color, Roughness=0.0)[0]


def textured_diffuse(name, image):
    mat, bsdf = _material(name, "ShaderNodeBsdfDiffuse", Roughness=0.0)
    tex = mat.node_tree.nodes.new("ShaderNodeTexImage")
    tex.image = image
    tex.location = (-300, 0)
    mat.node_tree.links.new(tex.outputs["Color"], bsdf.inputs["Color"])
    return mat


def glossy(name, color, roughness):
    """GGX conductor; Blender roughness r means alpha = r^2."""
    mat, bsdf = _material(name, "ShaderNodeBsdfGlossy", Color=color, Roughness=roughness)
    bsdf.distribution = "GGX"
    return mat


def glass(name, ior=1.5):
    mat, bsdf = _material(name, "ShaderNodeBsdfGlass", Color=(1.0, 1.0, 1.0),
                          Roughness=0.0, IOR=ior)
    bsdf.distribution = "GGX"
    return mat


def emission(name, color, strength):
    """Radiance = color * strength; Cycles emits it from both sides of each face."""
    return _material(name, "ShaderNodeEmission", Color=color, Strength=strength)[0]


# --------------------------------------------------------------------------- textures

def packed_image(name, rgb):
    """An 8-bit sRGB image from an (H, W, 3) array in [0, 1], row 0 at the top; packed as PNG."""
    h, w, _ = rgb.shape
    rgba = np.ones((h, w, 4), np.float32)
    rgba[..., :3] = np.clip(rgb[::-1], 0.0, 1.0)  # Blender stores the bottom row first
    img = bpy.data.images.new(name, w, h, alpha=False)
    img.pixels.foreach_set(rgba.ravel())
    img.pack()
    return img


def tiles_image(size=256, cells=2, grout=3):
    """1 m x 1 m of floor: 0.5 m cream/terracotta tiles with grout lines."""
    rng = np.random.default_rng(1)
    cell = np.arange(size) * cells // size
    checker = ((cell[:, None] + cell[None, :]) % 2).astype(bool)
    rgb = np.where(checker[..., None], (0.80, 0.74, 0.62), (0.62, 0.30, 0.20))
    rgb = rgb * rng.uniform(0.92, 1.0, (size, size, 1))  # mottling
    line = np.arange(size) % (size // cells) < grout
    rgb[line[:, None] | line[None, :]] = (0.35, 0.33, 0.30)
    return packed_image("Tiles", rgb)


def bricks_image(size=256, rows=16, per_row=4, mortar=2):
    """1 m x 1 m of running-bond brickwork (0.25 m x 0.0625 m bricks), each brick tinted."""
    rng = np.random.default_rng(2)
    bh, bw = size // rows, size // per_row
    y, x = np.mgrid[0:size, 0:size]
    row = y // bh
    xs = x + (row % 2) * (bw // 2)  # half-brick offset on every other row
    brick = row * (per_row + 1) + xs // bw
    tint = rng.uniform(0.75, 1.05, brick.max() + 1)[brick]
    rgb = np.multiply.outer(tint, (0.60, 0.28, 0.18))
    rgb[(y % bh < mortar) | (xs % bw < mortar)] = (0.70, 0.68, 0.62)
    return packed_image("Bricks", rgb)


# --------------------------------------------------------------------------- geometry

# Box corner i lies at -/+ half size along x, y, z as bits 0, 1, 2 of i are 0/1. Each side
# is a quad wound counter-clockwise seen from outside, so its normal points out of the box.
BOX_SIDES = {
    "-x": (0, 4, 6, 2), "+x": (1, 3, 7, 5),
    "-y": (0, 1, 5, 4), "+y": (2, 6, 7, 3),
    "-z": (0, 2, 3, 1), "+z": (4, 5, 7, 6),
}


def box_geometry(size, matrix=Matrix(), sides=tuple(BOX_SIDES), inward=False):
    """(verts, faces) of a box of `size` centred on the origin and moved by `matrix`."""
    corners = [matrix @ Vector([s / 2 if i >> axis & 1 else -s / 2 for axis, s in enumerate(size)])
               for i in range(8)]
    faces = [BOX_SIDES[side][::-1] if inward else BOX_SIDES[side] for side in sides]
    return corners, faces


def merge(parts):
    """Concatenate several (verts, faces) into one."""
    verts, faces = [], []
    for part_verts, part_faces in parts:
        faces += [tuple(i + len(verts) for i in face) for face in part_faces]
        verts += list(part_verts)
    return verts, faces


def make_mesh(name, geometry, materials, material_indices=None):
    verts, faces = geometry
    mesh = bpy.data.meshes.new(name)
    mesh.from_pydata([tuple(v) for v in verts], [], faces)
    for mat in materials:
        mesh.materials.append(mat)
    if material_indices:
        mesh.polygons.foreach_set("material_index", material_indices)
    mesh.validate()
    mesh.update()
    return mesh


def add_object(name, data, location=(0, 0, 0), rotation=(0, 0, 0)):
    obj = bpy.data.objects.new(name, data)
    obj.location = location
    obj.rotation_euler = rotation
    bpy.context.scene.collection.objects.link(obj)
    return obj


def add_box(name, size, material, location, rot_z=0.0):
    mesh = make_mesh(name, box_geometry(size), [material])
    return add_object(name, mesh, location, (0, 0, rot_z))


def add_rect(name, width, height, material, location, rotation=(0, 0, 0)):
    """A width x height quad in its local XY plane, facing its local +Z."""
    w, h = width / 2, height / 2
    geometry = ([(-w, -h, 0), (w, -h, 0), (w, h, 0), (-w, h, 0)], [(0, 1, 2, 3)])
    return add_object(name, make_mesh(name, geometry, [material]), location, rotation)


def add_room(name, lo, hi, side_materials):
    """Inward-facing walls of the box lo..hi; side_materials maps each side kept to a material."""
    lo, hi = Vector(lo), Vector(hi)
    materials = list(dict.fromkeys(side_materials.values()))
    mesh = make_mesh(name, box_geometry(hi - lo, sides=side_materials, inward=True), materials,
                     [materials.index(m) for m in side_materials.values()])
    return add_object(name, mesh, (lo + hi) / 2)


def add_uv_sphere(name, radius, location, material, segments=48, rings=24):
    bm = bmesh.new()
    bmesh.ops.create_uvsphere(bm, u_segments=segments, v_segments=rings, radius=radius)
    mesh = bpy.data.meshes.new(name)
    bm.to_mesh(mesh)
    bm.free()
    mesh.materials.append(material)
    if hasattr(mesh, "shade_smooth"):
        mesh.shade_smooth()
    else:  # Blender < 4.1
        mesh.polygons.foreach_set("use_smooth", [True] * len(mesh.polygons))
    return add_object(name, mesh, location)


def box_project_uvs(mesh, metres_per_uv=1.0):
    """UVs from object-space positions, projected along each face's dominant normal axis."""
    uv = mesh.uv_layers.new(name="UVMap")
    for poly in mesh.polygons:
        axis = max(range(3), key=lambda a: abs(poly.normal[a]))
        a, b = [(1, 2), (0, 2), (0, 1)][axis]
        for li in poly.loop_indices:
            co = mesh.vertices[mesh.loops[li].vertex_index].co
            uv.data[li].uv = (co[a] / metres_per_uv, co[b] / metres_per_uv)


# --------------------------------------------------------------------------- lights, camera, world

def add_point_light(name, location, radius, power, color=(1.0, 1.0, 1.0)):
    """Cycles sphere light: `power` W, radiance power / (4 pi^2 radius^2) * color."""
    light = bpy.data.lights.new(name, "POINT")
    light.energy = power
    light.color = color
    light.shadow_soft_size = radius
    if hasattr(light, "use_soft_falloff"):  # Blender 4.0+: a true sphere light
        light.use_soft_falloff = False
    obj = add_object(name, light, location)
    obj.visible_camera = True  # off by default for lights; Veach's spheres are seen directly
    return obj


def add_sun_light(name, direction, strength, angle_degrees, color=(1.0, 1.0, 1.0)):
    """Cycles sun: `strength` W/m^2 arriving along `direction` (where the light travels), of
    angular diameter `angle_degrees`. Not seen by camera rays."""
    light = bpy.data.lights.new(name, "SUN")
    light.energy = strength
    light.color = color
    light.angle = math.radians(angle_degrees)
    rotation = Vector(direction).to_track_quat("-Z", "Y").to_euler()
    obj = add_object(name, light, (0, 0, 10), rotation)
    obj.visible_camera = False
    return obj


def add_camera(location, target, fov_degrees):
    """Perspective camera looking at `target`; the FOV spans the image's larger side."""
    cam = bpy.data.cameras.new("Camera")
    cam.sensor_fit = "AUTO"
    cam.lens_unit = "FOV"
    cam.angle = math.radians(fov_degrees)
    direction = Vector(target) - Vector(location)
    obj = add_object("Camera", cam, location, direction.to_track_quat("-Z", "Y").to_euler())
    bpy.context.scene.camera = obj
    return obj


def set_world(color=(0.0, 0.0, 0.0), strength=0.0):
    """A uniform world (black and off by default)."""
    world = bpy.data.worlds.new("World")
    use_nodes(world)
    background = world.node_tree.nodes["Background"]
    background.inputs["Color"].default_value = (*color, 1.0)
    background.inputs["Strength"].default_value = strength
    bpy.context.scene.world = world


def configure_render(scene, width, height):
    """Output, colour management and Cycles settings shared by every scene."""
    render = scene.render
    render.resolution_x, render.resolution_y, render.resolution_percentage = width, height, 100
    scene.display_settings.display_device = "sRGB"
    view = scene.view_settings
    view.view_transform, view.look, view.exposure, view.gamma = "Standard", "None", 0.0, 1.0
    cycles = scene.cycles
    cycles.device = "CPU"
    cycles.samples = 128
    cycles.use_adaptive_sampling = False
    cycles.use_denoising = False
    cycles.seed = 0
    cycles.use_animated_seed = False
    for bounces in ("max_bounces", "diffuse_bounces", "glossy_bounces",
                    "transmission_bounces", "transparent_max_bounces"):
        setattr(cycles, bounces, 8)
    cycles.volume_bounces = 0
    cycles.sample_clamp_direct = 0.0
    cycles.sample_clamp_indirect = 0.0
    cycles.blur_glossy = 0.0
    cycles.caustics_reflective = True
    cycles.caustics_refractive = True
    cycles.pixel_filter_type = "BOX"
    cycles.filter_width = 1.0


# --------------------------------------------------------------------------- scenes

def cornell_room():
    """Bitterli's Cornell box without its boxes: 2 m cube, open at -y, quad light, camera."""
    white = diffuse("White", WHITE)
    add_room("CornellBox", (-1, -1, 0), (1, 1, 2), {
        "-z": white, "+z": white, "+y": white,
        "-x": diffuse("Red", RED), "+x": diffuse("Green", GREEN),
    })
    # Bitterli's light: radiance (17, 12, 4); here 1 mm below the ceiling, facing down.
    add_rect("Light", 0.47, 0.38, emission("Light", (1.0, 12 / 17, 4 / 17), 17.0),
             (-0.005, 0.03, 1.999), (math.pi, 0, 0))
    add_camera((0, -6.8, 1), (0, 0, 1), 19.5)
    set_world()
    return white


def build_cornell_box():
    white = cornell_room()
    # Bitterli's box transforms converted to Z up: size, centre, rotation about Z.
    add_box("ShortBox", (0.6044, 0.5948, 0.6), white, (0.3286, -0.3746, 0.3), math.radians(-16.64))
    add_box("TallBox", (0.6073, 0.5977, 1.2), white, (-0.3354, 0.2914, 0.6), math.radians(19.19))


def build_cornell_dielectric():
    cornell_room()
    centre = (0.1, -0.15, 0.501)  # resting on the floor
    add_uv_sphere("GlassSphere", 0.5, centre, glass("Glass"))
    add_uv_sphere("InnerBall", 0.2, centre, diffuse("Yellow", (0.8, 0.6, 0.1)), 32, 16)


# Veach's plates (Mitsuba thesis_veachMIS, converted to Z up): Blender roughness, and the
# (y, z) of the plate's near and far edges; each spans x = -4..4.
VEACH_PLATES = [
    (0.5, (-4.0667, -3.99615), (-3.08221, -3.82069)),
    (0.3, (-2.70046, -3.73096), (-1.74564, -3.43378)),
    (0.15, (-1.36972, -3.28825), (-0.476536, -2.83856)),
    (0.05, (-0.25609, -2.70651), (0.526323, -2.08375)),
]
# Sphere lights along x: (x, radius, colour). Veach's lights all emit the same power, so
# the blurred highlights on the rough plates match; radiance grows as 1 / radius^2.
VEACH_LIGHTS = [
    (-3.75, 0.0333, (1.0, 0.35, 0.25)),
    (-1.25, 0.1, (1.0, 0.85, 0.3)),
    (1.0, 0.3, (0.35, 1.0, 0.4)),
    (3.75, 0.9, (0.35, 0.55, 1.0)),
]
VEACH_LIGHT_POWER = 40.0  # W; Veach: radiance 100 on the r = 0.1 sphere is 39.5 W


def build_veach_mis():
    for i, (roughness, near, far) in enumerate(VEACH_PLATES, 1):
        (y0, z0), (y1, z1) = near, far
        tilt = math.atan2(z1 - z0, y1 - y0)
        add_rect(f"Plate{i}", 8.0, math.hypot(y1 - y0, z1 - z0),
                 glossy(f"Glossy{roughness}", (0.8, 0.8, 0.8), roughness),
                 (0, (y0 + y1) / 2, (z0 + z1) / 2), (tilt, 0, 0))
    dark = diffuse("Dark", (0.1, 0.1, 0.1))
    floor_z, back_y = -4.14615, 2.0
    add_rect("Floor", 20.0, 12.0, dark, (0, back_y - 6.0, floor_z))
    add_rect("Backdrop", 20.0, 14.0, dark, (0, back_y, floor_z + 7.0), (math.pi / 2, 0, 0))
    for i, (x, radius, color) in enumerate(VEACH_LIGHTS, 1):
        add_point_light(f"Light{i}", (x, 0, 0), radius, VEACH_LIGHT_POWER, color)
    add_camera((0, -15, 2), (0, -2.5, -2), 40.0)
    set_world()


def build_light_behind_glass():
    white = diffuse("White", (0.8, 0.8, 0.8))
    add_room("Room", (-2, -2, 0), (2, 2, 2.5), {
        "-z": diffuse("Floor", (0.5, 0.45, 0.4)),
        "+z": white, "-x": white, "+x": white, "-y": white, "+y": white,
    })
    add_box("Block", (0.6, 0.6, 0.8), white, (0.3, 0.2, 0.4), math.radians(20))
    # The lamp: an emissive cube inside a hollow glass cube (1 cm walls) near the ceiling.
    # Shadow rays cannot pass the glass, so the room is lit by caustic paths only.
    lamp = (1.55, 1.55, 2.1)
    shell = merge([box_geometry((0.3, 0.3, 0.3)), box_geometry((0.28, 0.28, 0.28), inward=True)])
    add_object("GlassBox", make_mesh("GlassBox", shell, [glass("Glass")]), lamp)
    add_box("Emitter", (0.1, 0.1, 0.1), emission("Lamp", (1.0, 0.9, 0.75), 100.0), lamp)
    add_camera((-1.8, -1.2, 1.2), (0.0, 1.3, 1.2), 75.0)
    set_world()


def add_glass_shell(name, outer, inner, location, material, segments=48, rings=24):
    """A hollow glass ball: an outward UV sphere of radius `outer` and an inward one of
    radius `inner` in one mesh (the walls a closed solid of thickness outer - inner)."""
    bm = bmesh.new()
    bmesh.ops.create_uvsphere(bm, u_segments=segments, v_segments=rings, radius=outer)
    inner_verts = bmesh.ops.create_uvsphere(bm, u_segments=segments, v_segments=rings, radius=inner)["verts"]
    bmesh.ops.reverse_faces(bm, faces=list({f for v in inner_verts for f in v.link_faces}))
    mesh = bpy.data.meshes.new(name)
    bm.to_mesh(mesh)
    bm.free()
    mesh.materials.append(material)
    mesh.polygons.foreach_set("use_smooth", [True] * len(mesh.polygons))
    return add_object(name, mesh, location)


def build_clocks():
    """In the spirit of the thesis' clocks scene (sec. 5.3.4), harder than light_behind_glass:
    a closed room split by a 2 m wall with a 1.6 m gap; the only light is a small emitter
    inside a glass ball on the far side, so the camera's side is lit by caustic light that
    bounced off the far side's walls and came over the wall or through the gap."""
    white = diffuse("White", (0.78, 0.78, 0.76))
    add_room("Room", (-2.5, -2, 0), (2.5, 2, 2.6), {
        "-z": diffuse("Floor", (0.55, 0.45, 0.35)),
        "+z": white, "-x": white, "+x": white, "-y": white, "+y": white,
    })
    # The divider at x = 0.6 from the -y wall to y = 0.4: a 1.6 m gap along the +y wall.
    add_box("Divider", (0.1, 2.4, 2.0), white, (0.6, -0.8, 1.0))
    add_box("Table", (1.0, 0.6, 0.75), diffuse("Table", (0.45, 0.30, 0.20)), (-1.2, 0.6, 0.375),
            math.radians(10))
    # The "clocks": three dials on the +y wall of the camera's side.
    dial = diffuse("Dial", (0.85, 0.82, 0.70))
    for i, x in enumerate((-2.0, -1.3, -0.6)):
        add_box(f"Clock{i + 1}", (0.3, 0.04, 0.3), dial, (x, 1.98, 1.6))
    # The lamp: a 5 cm emissive ball inside a glass ball (15 cm, 1 cm walls): no shadow ray
    # reaches it, every path to it is a caustic.
    lamp = (1.8, -1.2, 1.9)
    add_glass_shell("GlassBall", 0.15, 0.14, lamp, glass("Glass"))
    add_uv_sphere("Emitter", 0.05, lamp, emission("Lamp", (1.0, 0.9, 0.75), 400.0), 24, 12)
    add_camera((-2.3, -1.8, 1.4), (0.4, 1.3, 1.0), 70.0)
    set_world()


def arch_geometry(span, thickness, depth, stones=7):
    """A semicircular arch of `stones` boxes over `span`, springing from the origin level."""
    inner = span / 2
    length = 2 * (inner + thickness) * math.tan(math.pi / (2 * stones))  # closes the outer joints
    mid = inner + thickness / 2
    parts = []
    for k in range(stones):
        phi = math.pi * (k + 0.5) / stones
        place = (Matrix.Translation((mid * math.cos(phi), 0, mid * math.sin(phi)))
                 @ Matrix.Rotation(math.pi / 2 - phi, 4, "Y"))
        parts.append(box_geometry((length, depth, thickness), place))
    return merge(parts)


def stack(*bounds):
    """Merged axis-aligned boxes, each given by two opposite corners."""
    parts = []
    for lo, hi in bounds:
        lo, hi = Vector(lo), Vector(hi)
        size = [abs(v) for v in hi - lo]
        parts.append(box_geometry(size, Matrix.Translation((lo + hi) / 2)))
    return merge(parts)


def build_atrium():
    half_x, half_y, height = 8.0, 5.0, 8.0    # courtyard walls
    arcade_y, bays_x = 3.0, [-7.0 + 2.0 * i for i in range(8)]  # pillar lines at y = +-3
    spring, span = 2.65, 1.6                    # arches between the pillars' capitals
    gallery, roof = 4.25, 7.0                   # tops of the gallery floor and roof
    stone = diffuse("Stone", STONE)

    # Floor and walls, open to the sky; both textures cover 1 m x 1 m.
    bricks = textured_diffuse("Bricks", bricks_image())
    room = add_room("Courtyard", (-half_x, -half_y, 0), (half_x, half_y, height), {
        "-z": textured_diffuse("Tiles", tiles_image()),
        "-x": bricks, "+x": bricks, "-y": bricks, "+y": bricks,
    })
    box_project_uvs(room.data)

    # Two-storey arcades along both long walls; pillars and arches share meshes (instances).
    pillar = make_mesh("Pillar", stack(((-0.3, -0.3, 0), (0.3, 0.3, 0.2)),        # base
                                       ((-0.2, -0.2, 0.2), (0.2, 0.2, 2.5)),      # shaft
                                       ((-0.3, -0.3, 2.5), (0.3, 0.3, spring))),  # capital
                       [stone])
    upper_height = roof - 0.4 - gallery  # up to the upper beam
    upper_pillar = make_mesh("UpperPillar", stack(((-0.15, -0.15, 0), (0.15, 0.15, upper_height))),
                             [stone])
    arch = make_mesh("Arch", arch_geometry(span, 0.2, 0.4), [stone])
    galleries = []
    for side in (-1, 1):
        y, back = side * arcade_y, side * (arcade_y + 0.2)
        for i, x in enumerate(bays_x):
            add_object(f"Pillar.{side:+d}.{i}", pillar, (x, y, 0))
            add_object(f"UpperPillar.{side:+d}.{i}", upper_pillar, (x, y, gallery))
        for i, (x0, x1) in enumerate(zip(bays_x, bays_x[1:])):
            add_object(f"Arch.{side:+d}.{i}", arch, ((x0 + x1) / 2, y, spring))
        galleries += [
            ((-half_x, y - 0.2, spring + span / 2), (half_x, y + 0.2, gallery)),  # on the arches
            ((-half_x, back, gallery - 0.25), (half_x, side * half_y, gallery)),   # gallery floor
            ((-half_x, y - 0.2, roof - 0.4), (half_x, y + 0.2, roof)),             # upper beam
            ((-half_x, back, roof - 0.2), (half_x, side * half_y, roof)),          # gallery roof
        ]
    add_object("Galleries", make_mesh("Galleries", stack(*galleries), [stone]))
    add_object("Fountain", make_mesh("Fountain", stack(
        ((-1.2, -1.2, 0), (1.2, -1.0, 0.5)), ((-1.2, 1.0, 0), (1.2, 1.2, 0.5)),
        ((-1.2, -1.0, 0), (-1.0, 1.0, 0.5)), ((1.0, -1.0, 0), (1.2, 1.0, 0.5)),
        ((-0.15, -0.15, 0), (0.15, 0.15, 1.2))), [stone]))

    add_point_light("Sun", (2.5, -3.5, 15.0), 0.2, 10000.0, (1.0, 0.95, 0.85))
    set_world((0.012, 0.018, 0.03), 1.0)
    add_camera((-7.2, -1.6, 1.7), (4.0, 1.5, 3.0), 75.0)


# Sun room, as parallax_core.scenes.sun_room: room size, window (centre y, centre z, width,
# height) in the +X wall, sun elevation and azimuth (degrees), strength (W/m^2), angle.
SUN_ROOM_SIZE = (4.0, 5.0, 2.8)
SUN_ROOM_WINDOW = (0.6, 1.55, 1.2, 1.0)
SUN_ROOM_SUN = (36.6, 20.0, 5.0, 0.5)


def wall_with_hole_geometry(x, y_range, z_range, hole):
    """Quads of the wall plane x = `x` around the rectangular `hole` (y0, y1, z0, z1), facing
    -X (counter-clockwise seen from -X, where the viewer's right is -Y)."""
    (ya, yb), (za, zb) = y_range, z_range
    y0, y1, z0, z1 = hole
    verts, faces = [], []
    for lo_y, hi_y, lo_z, hi_z in ((ya, yb, za, z0), (ya, yb, z1, zb),
                                   (ya, y0, z0, z1), (y1, yb, z0, z1)):
        faces.append(tuple(range(len(verts), len(verts) + 4)))
        verts += [Vector((x, hi_y, lo_z)), Vector((x, lo_y, lo_z)),
                  Vector((x, lo_y, hi_z)), Vector((x, hi_y, hi_z))]
    return verts, faces


def build_sun_room():
    """A closed room lit by a sun through one window: mostly indirect light."""
    sx, sy, sz = SUN_ROOM_SIZE
    wy, wz, ww, wh = SUN_ROOM_WINDOW
    floor = diffuse("Floor", (0.60, 0.45, 0.32))
    ceiling = diffuse("Ceiling", (0.80, 0.80, 0.78))
    cream = diffuse("WallCream", (0.78, 0.74, 0.62))
    blue = diffuse("WallBlue", (0.62, 0.70, 0.78))
    green = diffuse("WallGreen", (0.66, 0.76, 0.62))
    # One mesh (watertight shared edges): five inward sides and the +X wall around the window.
    sides = {"-z": floor, "+z": ceiling, "-x": cream, "+y": blue, "-y": green}
    shell = box_geometry((sx, sy, sz), Matrix.Translation((0, 0, sz / 2)), sides, inward=True)
    hole = (wy - ww / 2, wy + ww / 2, wz - wh / 2, wz + wh / 2)
    window_wall = wall_with_hole_geometry(sx / 2, (-sy / 2, sy / 2), (0.0, sz), hole)
    materials = [floor, ceiling, cream, blue, green]
    indices = ([materials.index(m) for m in sides.values()]
               + [materials.index(cream)] * len(window_wall[1]))
    add_object("Room", make_mesh("Room", merge([shell, window_wall]), materials, indices))
    add_box("Cabinet", (1.4, 0.6, 0.9), diffuse("Cabinet", (0.62, 0.30, 0.24)), (-0.4, 2.1, 0.45))
    add_box("Bench", (1.2, 0.5, 0.5), diffuse("Bench", (0.30, 0.38, 0.55)), (0.25, 0.55, 0.25),
            math.radians(15.0))
    elevation, azimuth, strength, angle = SUN_ROOM_SUN
    el, az = math.radians(elevation), math.radians(azimuth)
    to_sun = Vector((math.cos(el) * math.cos(az), math.cos(el) * math.sin(az), math.sin(el)))
    add_sun_light("Sun", -to_sun, strength, angle, (1.0, 0.95, 0.88))
    set_world((0.02, 0.025, 0.035), 1.0)
    add_camera((-1.8, -2.3, 1.6), (1.2, 1.0, 0.9), 65.0)


SCENES = {  # name: (builder, resolution)
    "cornell_box": (build_cornell_box, (512, 512)),
    "veach_mis": (build_veach_mis, (512, 512)),
    "cornell_dielectric": (build_cornell_dielectric, (512, 512)),
    "light_behind_glass": (build_light_behind_glass, (512, 512)),
    "atrium": (build_atrium, (640, 480)),
    "sun_room": (build_sun_room, (512, 512)),
    "clocks": (build_clocks, (640, 480)),
}


# --------------------------------------------------------------------------- main

_parallax_registered = None


def parallax_registered():
    """Register the Parallax add-on once per process; False if it is missing or fails."""
    global _parallax_registered
    if _parallax_registered is None:
        try:
            sys.path.insert(0, REPO_ROOT)
            import addon
            addon.register()
            _parallax_registered = True
        except Exception as exc:  # the add-on may not exist yet
            print(f"note: Parallax add-on not registered ({exc!r}); scenes keep CYCLES")
            _parallax_registered = False
    return _parallax_registered


def triangle_count(scene):
    return sum(sum(len(p.vertices) - 2 for p in obj.data.polygons)
               for obj in scene.objects if obj.type == "MESH")


def build(name, out_dir=HERE):
    builder, (width, height) = SCENES[name]
    bpy.ops.wm.read_factory_settings(use_empty=True)
    scene = bpy.context.scene
    scene.name = name
    scene.render.engine = "CYCLES"
    builder()
    configure_render(scene, width, height)
    if parallax_registered():
        try:
            scene.render.engine = "PARALLAX"
        except TypeError as exc:
            print(f"note: {exc}; {name} keeps CYCLES")
    path = os.path.join(out_dir, f"{name}.blend")
    bpy.context.preferences.filepaths.save_version = 0  # no .blend1 backups
    bpy.ops.wm.save_as_mainfile(filepath=path, compress=True)
    print(f"{path}: {len(scene.objects)} objects, {triangle_count(scene)} triangles, "
          f"engine {scene.render.engine}, {os.path.getsize(path) / 1024:.0f} KiB")


def main(argv):
    import argparse

    parser = argparse.ArgumentParser(description="Build the Parallax test scenes.")
    parser.add_argument("names", nargs="*", choices=list(SCENES) + [[]], default=[],
                        metavar="NAME", help=f"scenes to build (default: all of {', '.join(SCENES)})")
    parser.add_argument("--out", default=HERE, help="folder for the .blend files "
                        "(default: blender_scenes/)")
    args = parser.parse_args(argv)
    os.makedirs(args.out, exist_ok=True)
    for name in args.names or list(SCENES):
        build(name, args.out)


if __name__ == "__main__":
    # Inside Blender (blender -b --python build.py -- NAME ...) the arguments follow "--".
    main(sys.argv[sys.argv.index("--") + 1:] if "--" in sys.argv else sys.argv[1:])
