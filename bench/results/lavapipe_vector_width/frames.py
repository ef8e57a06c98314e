"""MIS frames of 8 spp on lavapipe: argv[1] scenes (from bench/npz), argv[2] frames. Timed whole by farm-bench."""
import sys
from bench.converge import MAX_DEPTH, load_scene, method_params
import parallax_core as pc
for name in sys.argv[1].split(","):
    scene = load_scene(name, 0, "bench/npz")
    s = pc.Session(scene.width, scene.height, "cpu")
    s.set_params(samples_per_frame=8, max_depth=MAX_DEPTH, depth_leeway=0, seed=0, **method_params("mis"))
    s.update(scene); s.render(int(sys.argv[2]))
