"""A heavy procedural material's frame cost against Cycles' on this machine (issue 37, item 5).

    python bench/results/issue37_camera_nodes/procedural_vs_cycles.py [SAMPLES] [WIDTH HEIGHT]

One Blender scene, built with bpy 5.0.1: a floor and a wall whose shared material is a Principled
BSDF with its base colour from a 6-octave Noise (distorted) through a ColorRamp, roughness from
a fractal Voronoi (3 octaves), a Bump of a distorted Wave, under an area light and a grey world;
the same scene with a constant material as the baseline. Each engine renders it F12 (Parallax
with MIS, Cycles on the CPU with its default path tracing; denoising and adaptive sampling off
on both, the same bounces) once to warm up (pipelines, kernels), then three times: the median
wall time of the render call. Printed: seconds per render and the procedural/constant ratio of
each engine.
"""
import math
import os
import statistics
import sys
import time

REPO = os.path.dirname(os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__)))))
sys.path.insert(0, REPO)

import bpy  # noqa: E402


def material(procedural):
    m = bpy.data.materials.new("Procedural" if procedural else "Constant")
    tree = m.node_tree
    nodes, links = tree.nodes, tree.links
    nodes.clear()
    out = nodes.new("ShaderNodeOutputMaterial")
    bsdf = nodes.new("ShaderNodeBsdfPrincipled")
    bsdf.inputs["Base Color"].default_value = (0.6, 0.5, 0.4, 1.0)
    links.new(bsdf.outputs[0], out.inputs["Surface"])
    if not procedural:
        return m
    noise = nodes.new("ShaderNodeTexNoise")
    noise.inputs["Scale"].default_value, noise.inputs["Detail"].default_value = 4.0, 6.0
    noise.inputs["Distortion"].default_value = 0.5
    ramp = nodes.new("ShaderNodeValToRGB")
    ramp.color_ramp.elements[0].color = (0.1, 0.2, 0.5, 1.0)
    ramp.color_ramp.elements[1].color = (0.9, 0.6, 0.2, 1.0)
    links.new(next(s for s in noise.outputs if s.identifier == "Fac"), ramp.inputs["Fac"])
    links.new(ramp.outputs["Color"], bsdf.inputs["Base Color"])
    voronoi = nodes.new("ShaderNodeTexVoronoi")
    voronoi.inputs["Scale"].default_value, voronoi.inputs["Detail"].default_value = 6.0, 3.0
    links.new(voronoi.outputs["Distance"], bsdf.inputs["Roughness"])
    wave = nodes.new("ShaderNodeTexWave")
    wave.inputs["Scale"].default_value, wave.inputs["Distortion"].default_value = 3.0, 4.0
    bump = nodes.new("ShaderNodeBump")
    bump.inputs["Distance"].default_value = 0.02
    links.new(next(s for s in wave.outputs if s.identifier == "Fac"), bump.inputs["Height"])
    links.new(bump.outputs["Normal"], bsdf.inputs["Normal"])
    return m


def build(procedural, width, height):
    bpy.ops.wm.read_factory_settings(use_empty=True)
    scene = bpy.context.scene
    m = material(procedural)
    for name, location, rotation in (("Floor", (0, 0, 0), (0, 0, 0)), ("Wall", (0, 2, 2), (math.pi / 2, 0, 0))):
        mesh = bpy.data.meshes.new(name)
        mesh.from_pydata([(-2, -2, 0), (2, -2, 0), (2, 2, 0), (-2, 2, 0)], [], [(0, 1, 2, 3)])
        mesh.materials.append(m)
        obj = bpy.data.objects.new(name, mesh)
        obj.location, obj.rotation_euler = location, rotation
        scene.collection.objects.link(obj)
    light = bpy.data.objects.new("Key", bpy.data.lights.new("Key", "AREA"))
    light.data.energy, light.data.size = 300.0, 2.0
    light.location, light.rotation_euler = (1.5, -2.0, 3.0), (math.radians(40), 0, math.radians(30))
    scene.collection.objects.link(light)
    camera = bpy.data.objects.new("Camera", bpy.data.cameras.new("Camera"))
    camera.location, camera.rotation_euler = (0.0, -4.5, 1.6), (math.radians(80), 0, 0)
    scene.collection.objects.link(camera)
    scene.camera = camera
    world = bpy.data.worlds.new("World")
    world.color = (0.2, 0.2, 0.2)
    scene.world = world
    scene.render.resolution_x, scene.render.resolution_y, scene.render.resolution_percentage = width, height, 100
    return scene


def timed_render(scene, engine, samples):
    scene.render.engine = engine
    scene.cycles.use_denoising = scene.cycles.use_adaptive_sampling = False
    scene.cycles.device, scene.cycles.samples, scene.cycles.max_bounces = "CPU", samples, 8
    if engine == "PARALLAX":
        p = scene.parallax
        p.use_denoising = p.use_adaptive_sampling = False
        p.samples, p.method, p.max_depth, p.depth_leeway = samples, "mis", 8, 0
    bpy.ops.render.render()  # warm-up: pipelines and kernels
    times = []
    for _ in range(3):
        start = time.perf_counter()
        bpy.ops.render.render()
        times.append(time.perf_counter() - start)
    return statistics.median(times)


def main():
    samples = int(sys.argv[1]) if len(sys.argv) > 1 else 64
    width, height = (int(sys.argv[2]), int(sys.argv[3])) if len(sys.argv) > 3 else (160, 120)
    import addon

    addon.register()
    result = {}
    for procedural in (False, True):
        for engine in ("PARALLAX", "CYCLES"):
            scene = build(procedural, width, height)
            result[procedural, engine] = timed_render(scene, engine, samples)
    print(f"{width}x{height}, {samples} samples, seconds per render (median of 3 after a warm-up):")
    print("| material | Parallax (MIS) | Cycles | Parallax / Cycles |")
    print("|---|---:|---:|---:|")
    for procedural in (False, True):
        p, c = result[procedural, "PARALLAX"], result[procedural, "CYCLES"]
        print(f"| {'procedural' if procedural else 'constant'} | {p:.2f} | {c:.2f} | {p / c:.2f} |")
    print(f"| procedural / constant | {result[True, 'PARALLAX'] / result[False, 'PARALLAX']:.2f} | "
          f"{result[True, 'CYCLES'] / result[False, 'CYCLES']:.2f} | |")


if __name__ == "__main__":
    main()
