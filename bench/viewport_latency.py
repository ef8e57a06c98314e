"""Viewport responsiveness in a real Blender window (Debian's Blender 3.4 under Xvfb,
lavapipe): time from an edit to the first new frame, and samples/s while refining; with
--startup, time from switching to Rendered to the first image, cold and warm.

    .venv/bin/python bench/viewport_latency.py [--scenes cornell_box atrium] [--size 1280x720]
    .venv/bin/python bench/viewport_latency.py --startup [--runs 2] [--scenes cornell_box]
    .venv/bin/python bench/viewport_latency.py --denoise     # with Use Viewport Denoising on

--denoise (issue 36): the same edits with the viewport's denoiser on (its own thread); written
to bench/results/viewport_latency_denoise.json. The edit latency must not grow with it.

--startup --denoise (issue 36): time from switching to Rendered (Use Viewport Denoising on) to
the first denoised image (a coarse preview frame's) and to the first full-resolution denoised
one. Per scene one Blender run fills a fresh Mesa shader cache ("cold"), then --runs runs use
it ("warm"); written to --out (default bench/results/viewport_denoise_startup.json), with the
load average before each run.

--startup (issue 9): each run is a new Blender process (mode "startup" of gui_driver.py);
"cold" runs get an empty Mesa shader cache (MESA_SHADER_CACHE_DIR), "warm" runs the cache the
cold run filled. It measures the viewport as built ("quick": the preview program's first
frame while the path tracer compiles) and without that first frame (PX_NO_QUICK_FRAME=1,
the viewport before issue 9), and writes them to bench/results/viewport_latency.json
("startup") and viewport_latency.md.

Per scene, tests/viewport/gui_driver.py (mode "bench") shows the camera view Rendered,
then makes each kind of edit three times: orbit (camera), move an object (instances), change
a diffuse colour (materials), move a light. Latency runs from the moment the edit reaches
the render thread to the first image of the edited scene it publishes (a preview at pixel
size 2-8 when a full frame is slow), i.e. what the next redraw shows. Writes
bench/results/viewport_latency.json.
"""
import argparse
import glob
import json
import os
import statistics
import subprocess
import sys
import tempfile

HERE = os.path.dirname(os.path.abspath(__file__))
REPO = os.path.dirname(HERE)
sys.path.insert(0, os.path.join(REPO, "tests", "viewport"))
import gui  # noqa: E402


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scenes", nargs="+", default=["cornell_box", "atrium"])
    parser.add_argument("--size", default="1280x720")
    parser.add_argument("--out", default=os.path.join(HERE, "results", "viewport_latency.json"))
    parser.add_argument("--startup", action="store_true", help="measure start-up instead of edits")
    parser.add_argument("--runs", type=int, default=2, help="--startup: cold/warm pairs per variant")
    parser.add_argument("--denoise", action="store_true", help="with Use Viewport Denoising on")
    args = parser.parse_args(argv)
    if args.denoise and args.out == parser.get_default("out"):
        args.out = os.path.join(HERE, "results", "viewport_denoise_startup.json" if args.startup
                                else "viewport_latency_denoise.json")
    size = tuple(int(v) for v in args.size.split("x"))
    if args.startup:
        return startup_denoise(args, size) if args.denoise else startup(args, size)
    with tempfile.TemporaryDirectory() as tmp:
        subprocess.run([sys.executable, "-m", "pip", "wheel", "-q", "--no-build-isolation", "--no-deps",
                        "-w", tmp, REPO], check=True)
        (wheel,) = glob.glob(os.path.join(tmp, "parallax_core-*-cp311-*.whl"))
        session = gui.BlenderGui(os.path.join(tmp, "gui"), wheel, size, scenes=args.scenes)
        session.env["PX_DENOISE"] = "1" if args.denoise else "0"
        rows = {}
        try:
            for scene in args.scenes:
                load = os.getloadavg()
                proc, out = session.start(scene, "bench")
                log, _ = proc.communicate(timeout=900)
                with open(os.path.join(out, "result.json")) as f:
                    result = json.load(f)
                if result["errors"]:
                    raise RuntimeError("\n".join(result["errors"]) + log[-2000:])
                result["loadavg_before"], result["loadavg_after"] = load, os.getloadavg()
                rows[scene] = result
        finally:
            session.close()
    print(f"{'scene':14s} {'edit':9s} {'edit -> first new frame (ms)':>30s}")
    for scene, result in rows.items():
        for edit, runs in result["edits"].items():
            ms = ", ".join(f"{seconds * 1000:.0f}" for _, seconds in runs)
            parts = "+".join(runs[0][0])
            print(f"{scene:14s} {edit:9s} {ms:>30s}   (parts sent: {parts})")
        h, w = result["size"]
        print(f"{scene:14s} refining at {w}x{h}: {result['samples_per_second']:.1f} samples/s")
        every = sorted(seconds for runs in result["edits"].values() for _, seconds in runs)
        print(f"{scene:14s} median edit -> first new frame: {1000 * statistics.median(every):.0f} ms "
              f"(load average before {result['loadavg_before'][0]:.2f}, after {result['loadavg_after'][0]:.2f})")
    os.makedirs(os.path.dirname(args.out), exist_ok=True)
    if os.path.exists(args.out) and not args.denoise:  # keep the start-up figures of --startup
        with open(args.out) as f:
            rows.setdefault("startup", json.load(f).get("startup", []))
    with open(args.out, "w") as f:
        json.dump(rows, f, indent=1)


def _gui_session(tmp, size, scenes):
    """A Blender GUI session under Xvfb with this tree's parallax_core wheel, built into tmp."""
    subprocess.run([sys.executable, "-m", "pip", "wheel", "-q", "--no-build-isolation", "--no-deps",
                    "-w", tmp, REPO], check=True)
    (wheel,) = glob.glob(os.path.join(tmp, "parallax_core-*-cp311-*.whl"))
    return gui.BlenderGui(os.path.join(tmp, "gui"), wheel, size, scenes=scenes)


def _startup_run(session, scene, name):
    """One Blender run of gui_driver's startup steps; its result.json (RuntimeError on errors)."""
    proc, out = session.start(scene, "startup", name)
    log, _ = proc.communicate(timeout=900)
    with open(os.path.join(out, "result.json")) as f:
        result = json.load(f)
    if result["errors"]:
        raise RuntimeError("\n".join(result["errors"]) + log[-2000:])
    return result


def startup(args, size):
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        session = _gui_session(tmp, size, args.scenes)
        try:
            for scene in args.scenes:
                for run in range(args.runs):
                    for variant, quick in (("quick", "0"), ("before", "1")):
                        cache = tempfile.mkdtemp(dir=tmp)
                        for cache_state in ("cold", "warm"):
                            session.env.update(MESA_SHADER_CACHE_DIR=cache, PX_NO_QUICK_FRAME=quick)
                            result = _startup_run(session, scene, f"startup-{variant}-{run}-{cache_state}")
                            rows.append({"scene": scene, "variant": variant, "cache": cache_state, "run": run,
                                         "first_image_s": result["first_image_seconds"],
                                         "first_full_frame_s": result["first_full_frame_seconds"],
                                         "size": result["size"]})
                            print(rows[-1], flush=True)
        finally:
            session.close()
    # Kept next to the edit latencies: viewport_latency.json["startup"], and a table in .md.
    out = os.path.join(HERE, "results", "viewport_latency")
    saved = {}
    if os.path.exists(out + ".json"):
        with open(out + ".json") as f:
            saved = json.load(f)
    saved["startup"] = rows
    with open(out + ".json", "w") as f:
        json.dump(saved, f, indent=1)
    lines = [f"Switching a {size[0]}x{size[1]} Blender window's viewport to Rendered (bench/viewport_latency.py "
             "--startup)", "",
             "| scene | viewport | Mesa cache | first image (s) | first full-resolution frame (s) |",
             "|---|---|---|---|---|"]
    for r in rows:
        lines.append(f"| {r['scene']} | {r['variant']} | {r['cache']} | {r['first_image_s']:.2f} | "
                     f"{r['first_full_frame_s']:.2f} |")
    with open(out + ".md", "w") as f:
        f.write("\n".join(lines) + "\n")
    print("\n".join(lines))


def startup_denoise(args, size):
    """--startup --denoise: per scene a cold run (fills a fresh Mesa cache), then args.runs warm."""
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        session = _gui_session(tmp, size, args.scenes)
        try:
            for scene in args.scenes:
                session.env.update(MESA_SHADER_CACHE_DIR=tempfile.mkdtemp(dir=tmp), PX_DENOISE="1",
                                   PX_NO_QUICK_FRAME="0")
                for run in range(args.runs + 1):
                    cache_state = "warm" if run else "cold"
                    load = os.getloadavg()
                    result = _startup_run(session, scene, f"startup-denoise-{run}")
                    rows.append({"scene": scene, "cache": cache_state, "run": run,
                                 "first_image_s": result["first_image_seconds"],
                                 "first_full_frame_s": result["first_full_frame_seconds"],
                                 "first_to_denoiser_s": result["first_handover_seconds"],
                                 "first_to_denoiser_pixel_size": result["first_handover_pixel_size"],
                                 "first_denoised_s": result["first_denoised_seconds"],
                                 "first_full_denoised_s": result["first_full_denoised_seconds"],
                                 "size": result["size"], "loadavg_before": load})
                    print(rows[-1], flush=True)
        finally:
            session.close()
    os.makedirs(os.path.dirname(args.out), exist_ok=True)
    with open(args.out, "w") as f:
        json.dump({"window": list(size), "runs": rows}, f, indent=1)
    print("| scene | Mesa cache | first image (s) | first to the denoiser (s, pixel size) | first denoised (s) | "
          "first full frame (s) | first full denoised (s) | load average (1 min) |")
    for r in rows:
        print(f"| {r['scene']} | {r['cache']} | {r['first_image_s']:.2f} | {r['first_to_denoiser_s']:.2f} "
              f"({r['first_to_denoiser_pixel_size']}) | {r['first_denoised_s']:.2f} | {r['first_full_frame_s']:.2f} | "
              f"{r['first_full_denoised_s']:.2f} | {r['loadavg_before'][0]:.2f} |")


if __name__ == "__main__":
    main()
