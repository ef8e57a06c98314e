"""The combined pass of four scene/method pairs after 3 frames of 2 spp, saved to argv[1] (.npz), to compare vector widths."""
import sys, numpy as np
from bench.converge import MAX_DEPTH, load_scene, method_params
import parallax_core as pc
out = {}
for spec in ["cornell_box:mis", "atrium:mis", "light_behind_glass:guiding_device", "cornell_dielectric:ic"]:
    name, method = spec.split(":")
    scene = load_scene(name, 0, "bench/npz")
    s = pc.Session(scene.width, scene.height, "cpu")
    s.set_params(samples_per_frame=2, max_depth=MAX_DEPTH, depth_leeway=0, seed=0, **method_params(method))
    s.update(scene); s.render(3)
    out[spec] = s.read("combined")
np.savez(sys.argv[1], **out)
