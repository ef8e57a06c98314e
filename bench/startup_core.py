"""The viewport's start-up steps without Blender: CPU and wall seconds from importing the core
to the first image and to the first full-resolution frame, as addon/engine/viewport.py's
worker takes them (a 960x600 session and a quarter-size preview session of the Cornell box).

    .venv/bin/python bench/startup_core.py            # cold (empty Mesa cache) and warm, quick and before

"quick": the preview program's frame first while Session.compile() builds the path tracer on
another thread (the viewport since issue 9); "before": the preview session renders with the
path tracer at once. CPU seconds count every thread of the process.
"""
import os
import subprocess
import sys
import tempfile

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


def main():
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
