"""What one guiding training iteration costs with guiding_fit = cpu and = device (issue 13).

    .venv/bin/python -m bench.guiding_fit_cost [--scenes light_behind_glass] [--width 320]
        [--device auto] [--frames 16] [--region-splits 8] [--npz DIR | --procedural]
        [--synthetic-width 1280 --synthetic-height 720] [--skip-synthetic]
        [--json bench/results/guiding_fit_cost.json] [--md bench/results/guiding_fit_cost.md]

Two measurements per device (rows kept in --json by (device kind, what), so CPU and GPU runs
add up; the Markdown table of all rows goes to --md):

- scene: per scene (blender_scenes/NAME.blend exported at --width as bench.converge does;
  --npz DIR reads DIR/NAME.npz; --procedural uses parallax_core.scenes' lamp_in_glass), MIS,
  guiding with 2^--region-splits regions and --frames training frames, once per fit. Per
  training iteration: the sample slots recorded, the samples that reached the fit, the
  training frame's GPU time, and the frame loop's stall after it: readback + fit + upload
  (cpu) or the fit's compute passes, submit to fence (device). Pipelines are compiled by a
  throw-away session first.
- synthetic: the fit alone on GuidingSample records as the trace loop writes them for a
  --synthetic-width x --synthetic-height image (GUIDING_PATH_VERTICES slots per recording
  path, at most GUIDING_MAX_RECORD_PATHS paths), spread over 2^--region-splits regions of a
  unit box with three lights: the host field's add_samples + fit (all threads) against
  DeviceFit.fit (upload excluded: the samples are on the device already in a render). Median
  of 5 iterations after 2 warm-up ones. On a GPU a frame of a Cornell box at the same size is
  rendered before each device fit, as in the training loop: a GPU left idle for a second drops
  its clocks (an H200 from 1980 to 345-600 MHz, `nvidia-smi --query-gpu=clocks.sm`), and fits
  timed on an idle GPU took 3.7-7 ms instead of 1.3 ms.
"""
from __future__ import annotations

import argparse
import json
import os
import statistics
import time

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
SCENES = ("light_behind_glass",)
FITS = ("cpu", "device")
PATH_VERTICES, MAX_RECORD_PATHS = 4, 1 << 18  # shaders/shared/guiding.h


def load(name, width, npz_dir, procedural):
    if procedural:
        from parallax_core import scenes

        return scenes.lamp_in_glass(width, max(1, round(width * 0.75)))
    from bench.converge import load_scene

    return load_scene(name, width, npz_dir)


def measure_scene(scene, device, frames, region_splits):
    import parallax_core as pc

    rows = []
    for fit in FITS:
        params = dict(method="mis", samples_per_frame=1, guiding=True, guiding_fit=fit, guiding_training_spp=frames,
                      guiding_region_splits=region_splits, guiding_min_samples=128, guiding_region_threshold=0)
        warm = pc.Session(scene.width, scene.height, device)  # compiles the pipelines
        warm.update(scene)
        warm.set_params(**dict(params, guiding_training_spp=2))
        warm.render(1)
        del warm
        session = pc.Session(scene.width, scene.height, device)
        session.update(scene)
        session.set_params(**params)
        t = time.perf_counter()
        session.render(1)  # the training frames, then one frame
        wall = time.perf_counter() - t
        st = session.stats()
        n = max(1, st["guiding_training_frames"])
        stall = st["guiding_readback_milliseconds"] + st["guiding_fit_milliseconds"] + st["guiding_upload_milliseconds"]
        pixels = scene.width * scene.height
        stride = -(-pixels // MAX_RECORD_PATHS)
        rows.append(dict(what=f"scene {scene.width}x{scene.height}", fit=fit, regions=st["guiding_regions"],
                         slots_per_iteration=-(-pixels // stride) * PATH_VERTICES,
                         samples_per_iteration=st["guiding_samples"] / n,
                         frame_ms=st["guiding_frame_milliseconds"] / n,
                         readback_ms=st["guiding_readback_milliseconds"] / n,
                         fit_ms=st["guiding_fit_milliseconds"] / n, upload_ms=st["guiding_upload_milliseconds"] / n,
                         stall_ms=stall / n, trained_regions=st["guiding_trained_regions"], lobes=st["guiding_lobes"],
                         wall_s=wall))
    return rows


def synthetic_records(width, height, region_splits, seed=0):
    """GuidingSample records of a unit box lit by three point lights; each record's region is
    the field's lookup of its position (as the trace loop's region query gives it)."""
    from parallax_core import _native

    g = _native.guiding
    rng = np.random.default_rng(seed)
    paths = min(width * height, MAX_RECORD_PATHS)
    n = paths * PATH_VERTICES
    x = rng.random((n, 3))
    lights = np.array([[0.5, 0.5, 1.5], [-0.5, 0.2, 0.5], [0.5, 1.8, 0.3]])
    light = lights[rng.integers(0, 3, n)]
    to = light - x
    dist = np.linalg.norm(to, axis=1)
    d = to / dist[:, None]
    w = rng.exponential(1.0, n) * (rng.random(n) < 0.7)  # 30% unlit
    params = g.GuidingParams()
    params.region_splits, params.region_threshold = region_splits, 0
    field = g.GuidingField(np.zeros(3), np.ones(3), params)
    regions = field.region_of(x)
    return g.make_samples(x, d, np.full(n, 1 / (4 * np.pi)), w, dist, regions), params


def measure_synthetic(device, width, height, region_splits, iterations=5, warm_up=2):
    from parallax_core import _native

    g = _native.guiding
    records, params = synthetic_records(width, height, region_splits)
    rows = []
    host = g.GuidingField(np.zeros(3), np.ones(3), params)
    times = []
    for i in range(warm_up + iterations):
        t = time.perf_counter()
        host.add_samples(records)
        host.fit()
        times.append(1e3 * (time.perf_counter() - t))
    rows.append(dict(what=f"synthetic {width}x{height}", fit="cpu", regions=host.region_count,
                     slots_per_iteration=len(records), fit_ms=statistics.median(times[warm_up:]),
                     stall_ms=statistics.median(times[warm_up:])))
    o = g.FitOptions()
    fitter = g.DeviceFit(1 << region_splits, o, parallax=True, device=device)
    import parallax_core as pc
    from parallax_core import scenes

    busy = pc.Session(width, height, device)  # keeps a GPU's clocks up, as the frames of a render do
    if busy.device_type == "cpu":
        busy = None
    else:
        busy.update(scenes.cornell_box(width, height))
    times = []
    for _ in range(warm_up + iterations):
        if busy is not None:
            busy.render(1)
        times.append(fitter.fit(records))
    rows.append(dict(what=f"synthetic {width}x{height}", fit="device", regions=fitter.region_count,
                     slots_per_iteration=len(records), fit_ms=statistics.median(times[warm_up:]),
                     stall_ms=statistics.median(times[warm_up:])))
    return rows


COLUMNS = ("device", "what", "fit", "regions", "slots_per_iteration", "samples_per_iteration", "frame_ms",
           "readback_ms", "fit_ms", "upload_ms", "stall_ms", "trained_regions", "lobes")


def markdown(rows):
    out = ["| " + " | ".join(COLUMNS) + " |", "|" + "---|" * len(COLUMNS)]
    for r in rows:
        cells = []
        for c in COLUMNS:
            v = r.get(c, "")
            cells.append(f"{v:.2f}" if isinstance(v, float) else str(v))
        out.append("| " + " | ".join(cells) + " |")
    return "\n".join(out) + "\n"


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scenes", default=",".join(SCENES))
    ap.add_argument("--width", type=int, default=320)
    ap.add_argument("--device", default="auto")
    ap.add_argument("--frames", type=int, default=16, help="training frames (iterations) per fit")
    ap.add_argument("--region-splits", type=int, default=8, help="2^n regions (8: 256)")
    src = ap.add_mutually_exclusive_group()
    src.add_argument("--npz", metavar="DIR")
    src.add_argument("--procedural", action="store_true")
    ap.add_argument("--synthetic-width", type=int, default=1280)
    ap.add_argument("--synthetic-height", type=int, default=720)
    ap.add_argument("--skip-synthetic", action="store_true")
    ap.add_argument("--skip-scenes", action="store_true")
    ap.add_argument("--json", default=os.path.join(HERE, "results", "guiding_fit_cost.json"))
    ap.add_argument("--md", default=os.path.join(HERE, "results", "guiding_fit_cost.md"))
    args = ap.parse_args(argv)

    import parallax_core as pc

    kind = pc.Session(8, 8, args.device).device_type
    rows = []
    if not args.skip_scenes:
        for name in args.scenes.split(","):
            scene = load(name, args.width, args.npz, args.procedural)
            for r in measure_scene(scene, args.device, args.frames, args.region_splits):
                rows.append(dict(r, what=f"{name} {r['what']}"))
    if not args.skip_synthetic:
        rows += measure_synthetic(args.device, args.synthetic_width, args.synthetic_height, args.region_splits)
    kept = {}
    if args.json and os.path.exists(args.json):
        with open(args.json) as f:
            kept = {(r["device"], r["what"], r["fit"]): r for r in json.load(f)}
    for r in rows:
        r["device"] = kind
        kept[(kind, r["what"], r["fit"])] = r
        print(json.dumps(r))
    all_rows = sorted(kept.values(), key=lambda r: (r["device"], r["what"], r["fit"]))
    if args.json:
        os.makedirs(os.path.dirname(args.json), exist_ok=True)
        with open(args.json, "w") as f:
            json.dump(all_rows, f, indent=1)
    if args.md:
        with open(args.md, "w") as f:
            f.write(markdown(all_rows))


if __name__ == "__main__":
    main()
