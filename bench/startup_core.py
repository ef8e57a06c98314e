"""The viewport's start-up steps without Blender: CPU and wall seconds from importing the core
to the first image and to the first full-resolution frame, as addon/engine/viewport.py's
worker takes them (a 960x600 session and a quarter-size preview session of the Cornell box).

    .venv/bin/python bench/startup_core.py            # cold (empty Mesa cache) and warm, quick and before
    .venv/bin/python bench/startup_core.py --switch ic [--npz SCENE.npz] [--size 960x600]

"quick": the preview program's frame first while Session.compile() builds the path tracer on
another thread (the viewport since issue 9); "before": the preview session renders with the
path tracer at once. CPU seconds count every thread of the process.

--switch METHOD: switching a technique on in a Rendered viewport that shows MIS (issue 33: the
cache's image within 5 s on lavapipe, no black frame while it prepares). The full-size session
renders MIS frames as the viewport does (background compilation on), then takes METHOD's
settings (a bench.converge method: ic, guiding, ears, ...) and renders until a frame holds the
technique's own samples (not the fallback's). Per Mesa cache state: seconds to that frame, the
frames before it that showed the fallback, and those that showed nothing (black).
"""
import argparse
import os
import subprocess
import sys
import tempfile
import time

STEPS = r"""
import sys, threading, time
c0, w0 = time.process_time(), time.perf_counter()
import parallax_core as pc
from parallax_core import scenes
W, H = 960, 600
full, prev = pc.Session(W, H), pc.Session(W // 4, H // 4)
sc = scenes.cornell_box(W, H)
for s in (full, prev):
    s.update(sc)
if sys.argv[1] == "quick" and not full.pipeline_ready:
    threading.Thread(target=full.compile, daemon=True).start()
    prev.set_params(preview=True)
prev.render(1); prev.read("combined")
first = (time.process_time() - c0, time.perf_counter() - w0)
prev.set_params(preview=False)
full.render(1); full.read("combined")
print(*first, time.process_time() - c0, time.perf_counter() - w0)
"""


def switch_frames(method: str, npz: str = "", width: int = 960, height: int = 600,
                  limit: float = 600.0) -> tuple[float, int, int]:
    """The viewport's full-size session (background compilation on) renders MIS frames, then
    takes `method`'s settings and renders frames until one holds the technique's own samples.
    Returns the seconds to that frame, and the frames before it that showed the fallback's
    samples and that showed nothing (black)."""
    import numpy as np
    import parallax_core as pc
    from parallax_core import scenes
    from parallax_core.scene import SceneData
    from bench import converge

    scene = SceneData.load(npz) if npz else scenes.cornell_box(width, height)
    session = pc.Session(scene.width, scene.height)
    session.background_compile = True
    # The viewport's full-size film while it shows Combined (viewport.py, _film_passes).
    session.passes = [p.name for p in pc.PASSES if p.core and p.name != "guiding_lobes"]
    session.update(scene)
    session.set_params(**{**converge.method_params("mis"), "samples_per_frame": 1, "seed": 0})
    for _ in range(3):
        session.render(1)
    # As the viewport: guiding trains while the image accumulates (addon/engine/viewport.py).
    session.set_params(**{**converge.method_params(method), "samples_per_frame": 1, "seed": 0,
                          "guiding_training_spp": 0})
    start = time.perf_counter()
    fallback = black = 0
    while True:
        session.render(1)
        if not np.any(session.read("combined")[..., :3]):
            black += 1
        elif session.fallback_film:
            fallback += 1
        else:
            return time.perf_counter() - start, fallback, black
        if time.perf_counter() - start > limit:
            raise RuntimeError(f"no frame of {method} within {limit:.0f} s")


SWITCH = """
import sys
from bench.startup_core import switch_frames
print(*switch_frames(sys.argv[1], sys.argv[2], int(sys.argv[3]), int(sys.argv[4])))
"""


def switch(method: str, npz: str, size: str) -> None:
    width, height = (int(v) for v in size.split("x"))
    root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    print(f"| switch to {method} | Mesa cache | s to its first frame | fallback frames | black frames |")
    print("|---|---|---|---|---|")
    with tempfile.TemporaryDirectory() as cache:
        env = {**os.environ, "MESA_SHADER_CACHE_DIR": cache, "PARALLAX_VALIDATION": "0",
               "PYTHONPATH": os.pathsep.join(p for p in (root, os.environ.get("PYTHONPATH")) if p)}
        for state in ("cold", "warm"):
            out = subprocess.run([sys.executable, "-c", SWITCH, method, npz, str(width), str(height)],
                                 env=env, check=True, capture_output=True, text=True).stdout.split()
            seconds, fallback, black = float(out[0]), int(out[1]), int(out[2])
            print(f"| {npz or 'cornell_box'} | {state} | {seconds:.2f} | {fallback} | {black} |", flush=True)


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--switch", metavar="METHOD", help="measure switching to this bench.converge method")
    parser.add_argument("--npz", default="", help="--switch: the scene (default: the Cornell box)")
    parser.add_argument("--size", default="960x600", help="--switch: the Cornell box's size (default 960x600)")
    args = parser.parse_args()
    if args.switch:
        switch(args.switch, args.npz, args.size)
        return
    print("| viewport | Mesa cache | first image: CPU s | wall s | first full frame: CPU s | wall s |")
    print("|---|---|---|---|---|---|")
    for variant in ("quick", "before"):
        with tempfile.TemporaryDirectory() as cache:
            env = {**os.environ, "MESA_SHADER_CACHE_DIR": cache, "PARALLAX_VALIDATION": "0"}
            for state in ("cold", "warm"):
                out = subprocess.run([sys.executable, "-c", STEPS, variant], env=env, check=True,
                                     capture_output=True, text=True).stdout.split()
                cpu1, wall1, cpu2, wall2 = (float(v) for v in out)
                print(f"| {variant} | {state} | {cpu1:.2f} | {wall1:.2f} | {cpu2:.2f} | {wall2:.2f} |", flush=True)


if __name__ == "__main__":
    main()
