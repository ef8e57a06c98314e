"""What the driver compiled: per pipeline a method creates, the stack size the driver reports for
each shader group (bytes) and, where the driver has VK_KHR_pipeline_executable_properties
(NVIDIA; not lavapipe), its statistics per executable (registers, spills, instructions: whatever
it reports). Issue 32's and issue 34's residual GPU costs come from the shape of the compiled
megakernel; this reads that shape instead of guessing.

    python -m bench.pipeline_stats [--npz DIR --scenes cornell_box,sun_room | --soup 1000]
        [--methods nee,mis,ears] [--device gpu] [--set NAME=VALUE ...] [--out FILE.json]

Each method gets a session on each scene that renders one frame (every pipeline the method's
frames use is created, and logged by the core through PARALLAX_PIPELINE_STATS). Against another
build, run it with that build first on PYTHONPATH (bench/regression.py's builds).
"""
import argparse
import json
import os
import sys
import tempfile

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.dirname(HERE))

PROGRAMS = {0: "camera", 1: "ic_hemisphere", 2: "preview"}  # PROGRAM_* (shared/techniques.h)


def collect(scene, device, params):
    """The core's PARALLAX_PIPELINE_STATS lines for the pipelines one frame of `params` creates."""
    import dataclasses

    import parallax_core as pc
    from bench.frame_cost import supported

    # As bench.frame_cost does: unbiased light paths where a build has them, and an older build
    # runs the technique-free methods without the settings it lacks.
    known = {f.name for f in dataclasses.fields(pc.RenderParams)}
    pins = {k: v for k, v in getattr(pc, "UNBIASED_LIGHT_PATHS", {}).items() if k in known}
    path = os.environ["PARALLAX_PIPELINE_STATS"]
    start = os.path.getsize(path) if os.path.exists(path) else 0
    session = pc.Session(scene.width, scene.height, device)
    session.set_params(samples_per_frame=1, seed=0, **{**pins, **supported(params, known)})
    session.update(scene)
    session.render(1)
    del session
    getattr(pc, "wait_for_background_compiles", lambda: None)()  # every pipeline logged
    with open(path) as f:
        f.seek(start)
        return [json.loads(line) for line in f if line.strip()]


def summary(entry):
    """One row's cells: program, techniques, the raygen's stack, then each executable's stats."""
    driver = entry["driver"]
    groups = driver["stack"] or [{}]
    stack = groups[0].get("general", 0)
    hits = max((g.get("closest_hit", 0) for g in groups[1:]), default=0)
    executables = driver.get("error", "") or "; ".join(
        f"{e['name']}: " + ", ".join(f"{k} {v}" for k, v in e["statistics"].items())
        for e in driver.get("executables", []))
    return (PROGRAMS.get(entry["program"], str(entry["program"])), entry["constants"]["techniques"],
            stack, hits, executables or "(no statistics from this driver)")


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--npz", help="folder of exported scenes (bench.converge --export-only)")
    ap.add_argument("--scenes", default="cornell_box")
    ap.add_argument("--soup", type=int, help="the throughput bench's triangle soup of this many triangles instead")
    ap.add_argument("--methods", default="pt,nee,mis")
    ap.add_argument("--device", default="gpu")
    ap.add_argument("--set", nargs="*", default=[], metavar="NAME=VALUE", help="settings for every method")
    ap.add_argument("--out", help="write the rows as JSON here")
    args = ap.parse_args(argv)
    if not args.npz and not args.soup:
        ap.error("give --npz (with --scenes) or --soup")
    # The device reads it when it is created: before the first session.
    log = os.environ.setdefault("PARALLAX_PIPELINE_STATS", os.path.join(tempfile.mkdtemp(), "stats.jsonl"))
    from bench.converge import load_scene, method_params
    from parallax_core.cli import parse_params
    from parallax_core import scenes

    overrides = parse_params(args.set)
    if args.soup:
        named = {f"soup{args.soup}": scenes.triangle_soup_scene(args.soup, 64, 64)}
    else:
        named = {name: load_scene(name, 0, args.npz) for name in args.scenes.split(",")}
    rows = []
    print(f"(log: {log})\n| scene | method | program | techniques | raygen stack B | closest-hit stack B | driver statistics |")
    print("|---|---|---|---:|---:|---:|---|")
    for name, scene in named.items():
        for method in args.methods.split(","):
            for entry in collect(scene, args.device, {**method_params(method), **overrides}):
                rows.append(dict(scene=name, method=method, **entry))
                print("| " + " | ".join(str(c) for c in (name, method) + summary(entry)) + " |", flush=True)
    if args.out:
        with open(args.out, "w") as f:
            json.dump(rows, f, indent=1)


if __name__ == "__main__":
    main()
