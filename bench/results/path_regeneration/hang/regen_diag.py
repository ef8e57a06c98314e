"""The H200 hang sequence (bench.frame_cost clocks,light_behind_glass with pt,nee,mis,gpt,gmis),
each step logged with a timestamp; faulthandler prints the Python stack of a hung step."""
import faulthandler, sys, time, json
from bench.converge import MAX_DEPTH, load_scene, method_params
import parallax_core as pc

npz = sys.argv[1]
plan = [(a.split(":")[0], a.split(":")[1].split(",")) for a in sys.argv[2:]]
extra = {}
t0 = time.perf_counter()
def log(*a):
    print(f"[{time.perf_counter()-t0:7.2f}]", *a, flush=True)
for name, methods in plan:
    scene = load_scene(name, 0, npz)
    for m in methods:
        faulthandler.dump_traceback_later(40, exit=True)
        s = pc.Session(scene.width, scene.height, __import__("os").environ.get("PX_DEVICE", "gpu"))
        s.set_params(samples_per_frame=int(__import__("os").environ.get("PX_SPP", "64")), max_depth=MAX_DEPTH, depth_leeway=0, seed=0, **method_params(m), **extra)
        try:
            log(name, m, "update"); s.update(scene)
            log(name, m, "compile"); s.compile()
            s.render(2)
            log(name, m, "rays after 2", s.stats().get("rays"))
            i, start = 0, time.perf_counter()
            while time.perf_counter() - start < 1.0:
                log(name, m, "frame", i); s.render(1); i += 1
        except Exception as e:
            log(name, m, "ERROR", e)
            faulthandler.cancel_dump_traceback_later()
            if __import__("os").environ.get("PX_EXIT_NORMALLY"):
                del s; __import__("gc").collect(); log(name, m, "session deleted"); sys.exit(3)
            if not __import__("os").environ.get("PX_PRIVATE_CONTEXT"): __import__("os")._exit(3)
            continue
        log(name, m, "ms", round(1e3 * (time.perf_counter() - start) / i, 2))
        st = s.stats()
        log(name, m, "done", {k: st[k] for k in ("rays",) if k in st})
        faulthandler.cancel_dump_traceback_later()
        del s
