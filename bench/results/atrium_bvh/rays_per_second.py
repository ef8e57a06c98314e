"""Samples and rays per second of MIS (or argv[2]) frames of 8 spp on lavapipe, 4 frames after one.

    PYTHONPATH=. .venv/bin/python bench/results/atrium_bvh/rays_per_second.py atrium,cornell_box pt bench/npz
"""
import sys, time
from bench.converge import MAX_DEPTH, load_scene, method_params
import parallax_core as pc
import numpy as np
for name in sys.argv[1].split(","):
    scene = load_scene(name, 0, sys.argv[3] if len(sys.argv) > 3 else "bench/npz")
    s = pc.Session(scene.width, scene.height, "cpu")
    s.set_params(samples_per_frame=8, max_depth=MAX_DEPTH, depth_leeway=0, seed=0, **method_params(sys.argv[2] if len(sys.argv) > 2 else "mis"))
    s.update(scene); s.render(1)
    r0 = s.stats()["rays"]; t = time.perf_counter(); s.render(4); dt = time.perf_counter() - t
    rays = s.stats()["rays"] - r0
    print(f"{name}: {4*8/dt:.1f} spp/s, {rays/dt/1e6:.2f} Mrays/s, {rays/(4*8*scene.width*scene.height):.2f} rays/path", flush=True)
