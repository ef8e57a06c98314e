import sys, time
import parallax_core as pc
from parallax_core.scene import SceneData
scene = SceneData.load("/tmp/npz160/sun_room.npz")
mode = sys.argv[1]
params = dict(method="mis", guiding=True)
t0 = time.perf_counter()
if mode != "none":
    w = pc.Session(8, 8, "cpu"); w.passes = ["combined"]; w.set_params(**params); w.update(scene); w.warm()
    if mode == "render":
        w.render(1)
    pc.wait_for_background_compiles()
t1 = time.perf_counter()
s = pc.Session(scene.width, scene.height, "cpu"); s.passes = ["combined"]; s.background_compile = True
s.set_params(**params); s.update(scene)
t2 = time.perf_counter()
s.render(1)
t3 = time.perf_counter()
print(mode, f"warm-up {t1-t0:.1f} s, F12's first frame {t3-t2:.2f} s, fallback samples {s.stats()['fallback_samples']}")
