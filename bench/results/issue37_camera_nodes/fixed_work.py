"""A fixed amount of work for paired whole-process timings: the .npz scene argv[1] with method
argv[2], argv[3] frames of 4 samples, max depth 8, unbiased light paths, no adaptive sampling."""
import dataclasses
import sys

import parallax_core as pc
from parallax_core.scene import SceneData


def render(scene, method, frames):
    known = {f.name for f in dataclasses.fields(pc.RenderParams)}
    pins = {k: v for k, v in {**getattr(pc, "UNBIASED_LIGHT_PATHS", {}), "use_adaptive_sampling": False}.items()
            if k in known}
    s = pc.Session(scene.width, scene.height, "cpu")
    s.set_params(**pins, method=method, max_depth=8, depth_leeway=0, samples_per_frame=4, seed=0)
    s.update(scene)
    s.render(frames)


if __name__ == "__main__":
    render(SceneData.load(sys.argv[1]), sys.argv[2], int(sys.argv[3]))
