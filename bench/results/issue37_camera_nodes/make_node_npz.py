"""Scenes of .wt/npz with every material's colour and roughness from node programs:
npz_nodes (ColorRamp of fract(3u) x colour, roughness by Map Range), npz_noise (4-octave Noise
at scale 5 of Generated coordinates into a ColorRamp x colour)."""
import sys
import numpy as np
from parallax_core import nodes
from parallax_core.scene import SceneData

table = np.random.default_rng(1).random((256, 4))
for name in ("cornell_box", "veach_mis", "atrium", "light_behind_glass"):
    for kind in ("nodes", "noise"):
        scene = SceneData.load(f".wt/npz/{name}.npz")
        for m in scene.materials:
            p = nodes.Program()
            if kind == "nodes":
                u = p.math("FRACT", p.math("MULTIPLY", p.separate(p.uv(), 0), 3.0))
            else:
                v = p.affine(p.generated(), np.diag([5.0, 5.0, 5.0, 1.0])[:3])
                u = p.noise(v, 4.0, 0.5, 2.0, True)
            p.store("base_color", p.mix("MULTIPLY", 1.0, p.ramp(u, table, True), m.base_color))
            p.store("roughness", p.map_range(u, 0.0, 1.0, 0.2, 0.6, True))
            m.node_program = tuple(p.finish())
        scene.save(f".wt/npz_{kind}/{name}.npz")
