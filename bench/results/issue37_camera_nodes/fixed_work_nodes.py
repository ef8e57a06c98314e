# fixed_work.py with every material's colour and roughness from a node program (a ColorRamp of
# fract(3 u) times the constant colour, roughness from a Map Range): the evaluator's cost.
import dataclasses, sys
import numpy as np
import parallax_core as pc
from parallax_core import nodes
from parallax_core.scene import SceneData
scene = SceneData.load(sys.argv[1])
table = np.random.default_rng(1).random((256, 4))
for m in scene.materials:
    p = nodes.Program()
    u = p.math("FRACT", p.math("MULTIPLY", p.separate(p.uv(), 0), 3.0))
    p.store("base_color", p.mix("MULTIPLY", 1.0, p.ramp(u, table, True), m.base_color))
    p.store("roughness", p.map_range(u, 0.0, 1.0, 0.2, 0.6, True))
    m.node_program = tuple(p.finish())
known = {f.name for f in dataclasses.fields(pc.RenderParams)}
pins = {k: v for k, v in {**getattr(pc, "UNBIASED_LIGHT_PATHS", {}), "use_adaptive_sampling": False}.items() if k in known}
s = pc.Session(scene.width, scene.height, "cpu")
s.set_params(**pins, method=sys.argv[2], max_depth=8, depth_leeway=0, samples_per_frame=4, seed=0)
s.update(scene)
s.render(int(sys.argv[3]))
