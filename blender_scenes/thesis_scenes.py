"""The thesis' own scenes (shared/scenes/thesis_*) as .blend files, for Cycles and Parallax alike.

    .venv/bin/python blender_scenes/thesis_scenes.py [NAME ...] [--out DIR] [--width 320]

NAME is thesis_veach_mis or thesis_irradiance_cache (default: both). The Mitsuba 0.6 scenes
are read by bench/shared_scenes.py (whose notes list the approximations: Beckmann plates as
GGX, sphere emitters as Blender sphere lights) and rebuilt in Blender from that SceneData, so
the .blend renders what a Parallax render of the SceneData renders. They are derived from the
shared folder's files and are written to blender_scenes/generated/ (ignored by git), never
committed; `python -m bench.converge --suite thesis` builds them when missing.
"""
import os
import sys

import bpy
import numpy as np
from mathutils import Matrix

HERE = os.path.dirname(os.path.abspath(__file__))
REPO_ROOT = os.path.dirname(HERE)
GENERATED = os.path.join(HERE, "generated")
sys.path.insert(0, HERE)
sys.path.insert(0, REPO_ROOT)

import build  # noqa: E402  (blender_scenes/build.py: materials, lights, render settings)

from bench.shared_scenes import THESIS_SCENES, available  # noqa: E402


def blender_material(m):
    """A node material rendering like the Parallax Material `m` (diffuse, conductor,
    dielectric; emission as an Emission shader, added to the BSDF where the base is not black)."""
    if m.type == "conductor":
        mat = build.glossy(m.name, tuple(m.base_color), m.roughness)
    elif m.type == "dielectric":
        mat = build.glass(m.name, m.ior)
        mat.node_tree.nodes["Glass BSDF"].inputs["Roughness"].default_value = m.roughness
    elif m.type == "diffuse":
        mat = build.diffuse(m.name, tuple(m.base_color))
    else:
        raise NotImplementedError(f"material {m.name!r}: type {m.type!r} is not converted")
    emission = np.asarray(m.emission, float) * m.emission_strength
    if emission.max() > 0:
        nodes, links = mat.node_tree.nodes, mat.node_tree.links
        out = nodes["Material Output"]
        bsdf = out.inputs["Surface"].links[0].from_node
        emit = nodes.new("ShaderNodeEmission")
        emit.inputs["Color"].default_value = (*(emission / emission.max()), 1.0)
        emit.inputs["Strength"].default_value = float(emission.max())
        if max(m.base_color) > 0:
            add = nodes.new("ShaderNodeAddShader")
            links.new(bsdf.outputs[0], add.inputs[0])
            links.new(emit.outputs[0], add.inputs[1])
            links.new(add.outputs[0], out.inputs["Surface"])
        else:
            links.new(emit.outputs[0], out.inputs["Surface"])
    return mat


def blender_mesh(mesh, materials, transform):
    """A Blender mesh object of a Parallax Mesh, its corner normals as custom normals."""
    data = bpy.data.meshes.new(mesh.name or "mesh")
    data.from_pydata([tuple(map(float, p)) for p in mesh.positions], [],
                     [tuple(map(int, t)) for t in mesh.indices])
    used = sorted(set(mesh.material_indices.tolist())) if mesh.material_indices is not None else [0]
    for index in used:
        data.materials.append(materials[index])
    if mesh.material_indices is not None:
        slot = {index: i for i, index in enumerate(used)}
        data.polygons.foreach_set("material_index", [slot[int(i)] for i in mesh.material_indices])
    data.validate()
    if mesh.normals is not None:
        data.polygons.foreach_set("use_smooth", [True] * len(data.polygons))
        data.normals_split_custom_set([tuple(map(float, n)) for n in mesh.normals.reshape(-1, 3)])
    data.update()
    obj = bpy.data.objects.new(data.name, data)
    obj.matrix_world = Matrix([list(row) for row in np.asarray(transform, float)])
    bpy.context.scene.collection.objects.link(obj)
    return obj


def blender_light(light):
    if light.type != "point":
        raise NotImplementedError(f"light {light.name!r}: type {light.type!r} is not converted")
    obj = build.add_point_light(light.name or "Light", tuple(light.position), light.radius,
                                light.power, tuple(light.color))
    obj.visible_camera = light.camera_visible
    return obj


def blender_camera(camera, width):
    """A Blender camera whose view plane is the Camera's window (Camera.from_blender inverted:
    horizontal sensor fit, extent = sensor / lens = right - left, shift in that extent)."""
    left, right, bottom, top = camera.window
    extent = right - left
    cam = bpy.data.cameras.new("Camera")
    cam.sensor_fit, cam.sensor_width = "HORIZONTAL", 36.0
    cam.lens = cam.sensor_width / extent
    cam.shift_x, cam.shift_y = 0.5 * (left + right) / extent, 0.5 * (bottom + top) / extent
    cam.clip_start, cam.clip_end = camera.clip_start, camera.clip_end
    obj = bpy.data.objects.new("Camera", cam)
    obj.matrix_world = Matrix([list(row) for row in np.vstack([camera.camera_to_world, [0, 0, 0, 1]])])
    bpy.context.scene.collection.objects.link(obj)
    bpy.context.scene.camera = obj
    return obj


def build_scene(name, width=320, out_dir=GENERATED):
    """Writes out_dir/NAME.blend from the shared scene; returns its path."""
    data = THESIS_SCENES[name][1](width)
    bpy.ops.wm.read_factory_settings(use_empty=True)
    scene = bpy.context.scene
    scene.name = name
    scene.render.engine = "CYCLES"
    materials = [blender_material(m) for m in data.materials]
    for instance in data.effective_instances():
        blender_mesh(data.meshes[instance.mesh], materials, instance.transform)
    for light in data.lights:
        blender_light(light)
    build.set_world(tuple(data.world.color), data.world.strength)
    blender_camera(data.camera, data.width)
    build.configure_render(scene, data.width, data.height)
    if build.parallax_registered():
        scene.render.engine = "PARALLAX"
    os.makedirs(out_dir, exist_ok=True)
    path = os.path.join(out_dir, f"{name}.blend")
    bpy.context.preferences.filepaths.save_version = 0
    bpy.ops.wm.save_as_mainfile(filepath=path, compress=True)
    return path


def main(argv):
    import argparse

    parser = argparse.ArgumentParser(description="Convert the thesis' scenes to .blend.")
    parser.add_argument("names", nargs="*", metavar="NAME",
                        help=f"default: all of {', '.join(THESIS_SCENES)}")
    parser.add_argument("--out", default=GENERATED)
    parser.add_argument("--width", type=int, default=320)
    args = parser.parse_args(argv)
    for name in args.names or list(THESIS_SCENES):
        if name not in THESIS_SCENES:
            parser.error(f"unknown scene {name!r} (scenes: {', '.join(THESIS_SCENES)})")
        if not available(THESIS_SCENES[name][0]):
            print(f"{name}: the shared scene {THESIS_SCENES[name][0]} is missing; skipped")
            continue
        print(build_scene(name, args.width, args.out))


if __name__ == "__main__":
    main(sys.argv[sys.argv.index("--") + 1:] if "--" in sys.argv else sys.argv[1:])
