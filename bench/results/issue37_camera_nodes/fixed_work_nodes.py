"""fixed_work.py with every material's colour and roughness from a node program (a ColorRamp of
fract(3 u) times the constant colour, roughness from a Map Range): the evaluator's cost."""
import os
import sys

import numpy as np
from parallax_core import nodes
from parallax_core.scene import SceneData

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from fixed_work import render  # noqa: E402

scene = SceneData.load(sys.argv[1])
table = np.random.default_rng(1).random((256, 4))
for m in scene.materials:
    p = nodes.Program()
    u = p.math("FRACT", p.math("MULTIPLY", p.separate(p.uv(), 0), 3.0))
    p.store("base_color", p.mix("MULTIPLY", 1.0, p.ramp(u, table, True), m.base_color))
    p.store("roughness", p.map_range(u, 0.0, 1.0, 0.2, 0.6, True))
    m.node_program = tuple(p.finish())
render(scene, sys.argv[2], int(sys.argv[3]))
