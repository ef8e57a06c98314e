import dataclasses, sys
import parallax_core as pc
from parallax_core.scene import SceneData
scene = SceneData.load(sys.argv[1])
known = {f.name for f in dataclasses.fields(pc.RenderParams)}
pins = {k: v for k, v in {**getattr(pc, "UNBIASED_LIGHT_PATHS", {}), "use_adaptive_sampling": False}.items() if k in known}
s = pc.Session(scene.width, scene.height, "cpu")
s.set_params(**pins, method=sys.argv[2], max_depth=8, depth_leeway=0, samples_per_frame=4, seed=0)
s.update(scene)
s.render(int(sys.argv[3]))
