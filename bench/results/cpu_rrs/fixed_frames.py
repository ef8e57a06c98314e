"""Fixed-work frame cost of MIS, ADRRS and EARS on one exported scene (lavapipe):
    PYTHONPATH=. python bench/results/cpu_rrs/fixed_frames.py SCENE FRAMES SPP [NAME=VALUE ...]
reads .wt/npz160/SCENE.npz (bench.converge --export-only --npz .wt/npz160 --width 160), renders
2 frames, then times FRAMES frames of SPP samples per method; NAME=VALUE settings apply to the
RRS methods (e.g. adrrs_splitting=0)."""
import sys
import time

import parallax_core as pc
from bench.converge import MAX_DEPTH, load_scene, method_params

scene_name, frames, spp = sys.argv[1], int(sys.argv[2]), int(sys.argv[3])
extra = dict(a.split("=") for a in sys.argv[4:])
scene = load_scene(scene_name, 160, ".wt/npz160")
for method in ("mis", "adrrs", "ears"):
    s = pc.Session(scene.width, scene.height, "cpu")
    p = dict(method_params(method), samples_per_frame=spp, seed=1, max_depth=MAX_DEPTH, depth_leeway=0)
    if method != "mis":
        p.update({k: (int(v) if v.isdigit() else v) for k, v in extra.items()})
    s.set_params(**p)
    s.update(scene)
    s.render(2)
    before = s.stats()
    start = time.perf_counter()
    s.render(frames)
    seconds = time.perf_counter() - start
    after = s.stats()
    rays = after["rays"] - before["rays"]
    samples = (after["samples"] - before["samples"]) * scene.width * scene.height
    print(f"{scene_name} {method}: {1000 * seconds / frames:.0f} ms/frame, rays/sample {rays / samples:.3f}, "
          f"Mrays/s {rays / seconds / 1e6:.2f}", flush=True)
