"""Sessions of 4-spp frames on lavapipe: arguments scene:method:frames (scenes from bench/npz). Timed whole by farm-bench."""
import sys
from bench.converge import MAX_DEPTH, load_scene, method_params
import parallax_core as pc
for spec in sys.argv[1:]:
    name, method, frames = spec.split(":")
    scene = load_scene(name, 0, "bench/npz")
    s = pc.Session(scene.width, scene.height, "cpu")
    s.set_params(samples_per_frame=4, max_depth=MAX_DEPTH, depth_leeway=0, seed=0, **method_params(method))
    s.update(scene); s.render(int(frames))
