#!/usr/bin/env python3
"""Ray throughput of the Parallax core on triangle-soup scenes of 1k, 100k and 1M triangles.

    python bench/throughput.py [--sizes 1k,100k,1M] [--resolution 512] [--method nee]
                               [--max-depth 4] [--seconds 10] [--device auto]
                               [--no-unordered] [--orders coherent+sort,...] [--json OUT.json]

For every size it measures three primitive orders of the same geometry
(scenes.triangle_soup_scene, a noise-displaced sphere on a floor under an area light):

  coherent+sort   the mesh as generated (already coherent), core's Morton ordering on
  shuffled        triangles randomly permuted, core ordering off (spatial_order=False):
                  the worst case a user's exported mesh can be; on lavapipe this traces
                  orders of magnitude slower, so it is measured at a reduced resolution
                  (--unordered-resolution) when a full-resolution frame would take too long
  shuffled+sort   triangles randomly permuted, core ordering on: shows the core repairs it

and reports scene upload time (Session.update: validation, flattening, ordering, BVH build;
the JSON's flatten_s is SceneData.flatten alone, timed apart),
time to the first frame after the upload, then renders for about --seconds and reports rays/s
(wall clock, every ray including shadow rays, from Session.stats()), rays per CPU-second
(time.process_time(): all threads of this process, which is where lavapipe renders) and pixel
samples per wall second. Russian roulette is off so every path does the same work.

Targets (the issue): with nee at 4 bounces, at least 80 % of the minimal tracer's
2.1 / 1.05 / 0.55 M rays per CPU-second on lavapipe, at least 70 % of its 3.0 / 1.9 / 1.4 G
rays/s at 1024x1024 on the H100/H200, and scene upload + first frame under 1 s for 100k
triangles. The table's "% target" column is measured / minimal tracer (per CPU-second on CPU
devices, per wall second on GPUs); the goal line is 80 % (CPU) or 70 % (GPU).

`run(...)` is importable (tests/unit/test_bench_smoke.py calls it with tiny settings).
"""
from __future__ import annotations

import argparse
import dataclasses
import json
import os
import platform
import sys
import time

# The minimal tracer's throughput, by triangle count: rays per CPU-second on lavapipe,
# rays per second on the H100/H200 at 1024x1024.
MINIMAL_CPU = {1_000: 2.1e6, 100_000: 1.05e6, 1_000_000: 0.55e6}
MINIMAL_GPU = {1_000: 3.0e9, 100_000: 1.9e9, 1_000_000: 1.4e9}
GOAL_CPU, GOAL_GPU = 0.80, 0.70
FIRST_FRAME_GOAL_S = 1.0  # upload + first frame, 100k triangles

ORDERS = (  # label, shuffle, spatial_order
    ("coherent+sort", False, True),
    ("shuffled", True, False),
    ("shuffled+sort", True, True),
)


def parse_size(text: str) -> int:
    t = text.strip().lower().replace("_", "")
    scale = {"k": 1_000, "m": 1_000_000}.get(t[-1:], 1)
    value = float(t[:-1] if scale != 1 else t)
    if value <= 0:
        raise ValueError(f"size must be positive: {text!r}")
    return int(round(value * scale))


def size_label(n: int) -> str:
    if n >= 1_000_000 and n % 1_000_000 == 0:
        return f"{n // 1_000_000}M"
    if n >= 1_000 and n % 1_000 == 0:
        return f"{n // 1_000}k"
    return str(n)


def _log(msg: str) -> None:
    print(msg, file=sys.stderr, flush=True)


def _device_arg(value):
    return int(value) if isinstance(value, str) and value.isdigit() else value


def _busy_cpu_s():
    """Machine-wide busy CPU time (s) from /proc/stat, or None off Linux."""
    try:
        with open("/proc/stat") as f:
            fields = [int(x) for x in f.readline().split()[1:]]
        idle = fields[3] + (fields[4] if len(fields) > 4 else 0)  # idle + iowait
        return (sum(fields[:8]) - idle) / os.sysconf("SC_CLK_TCK")
    except (OSError, ValueError, IndexError, AttributeError):
        return None


def _is_cpu(session) -> bool:
    return session.device_type == "cpu"


def _warm_up(session, params: dict) -> float:
    """Compile the pipeline on a tiny scene; returns the compile time estimate (s): the
    first render's time minus a second render's."""
    from parallax_core import scenes

    session.set_params(**params)
    session.update(scenes.triangle_soup_scene(16, session.width, session.height))
    t0 = time.perf_counter()
    session.render(1)
    first = time.perf_counter() - t0
    t0 = time.perf_counter()
    session.render(1)
    second = time.perf_counter() - t0
    return max(0.0, first - second)


def _measure(session, scene, spatial_order: bool, seconds: float) -> dict:
    """Upload, first frame, then render for about ``seconds``; raw numbers."""
    # The Python share of the upload (SceneData.flatten), timed apart; update() flattens again.
    t0 = time.perf_counter()
    scene.flatten()
    flatten_s = time.perf_counter() - t0
    t0 = time.perf_counter()
    warnings = session.update(scene, spatial_order=spatial_order)
    upload_s = time.perf_counter() - t0

    # Latency: the first one-sample frame after the upload (what a viewport shows first).
    spp = session.params.samples_per_frame
    session.set_params(samples_per_frame=1)
    t0 = time.perf_counter()
    session.render(1)
    latency_s = time.perf_counter() - t0
    session.set_params(samples_per_frame=spp)  # resets the accumulation

    c0, t0 = time.process_time(), time.perf_counter()
    session.render(1)
    first_s = time.perf_counter() - t0
    first_cpu = time.process_time() - c0
    st = session.stats()
    rays0, samples0 = st["rays"], st["samples"]

    busy0 = _busy_cpu_s()
    if first_s >= seconds:
        # One frame is all the time we have: it is the measurement.
        frames, rays, samples, wall, cpu = 1, rays0, samples0, first_s, first_cpu
    else:
        target_call = max(0.02, min(0.25, seconds / 8))  # GPUs: batch frames per submit
        per_frame = first_s
        frames = 0
        wall = cpu = 0.0
        while wall < seconds - 0.5 * per_frame or frames == 0:
            n = max(1, min(1000, int(target_call / max(per_frame, 1e-6))))
            c0, t0 = time.process_time(), time.perf_counter()
            session.render(n)
            dt = time.perf_counter() - t0
            cpu += time.process_time() - c0
            wall += dt
            frames += n
            per_frame = dt / n
        st = session.stats()
        rays, samples = st["rays"] - rays0, st["samples"] - samples0

    busy1 = _busy_cpu_s()
    if first_s >= seconds:
        busy0 = None  # the first frame was not bracketed by /proc/stat reads
    # CPU time other processes used while we measured: they compete with lavapipe's threads,
    # so rays/s (wall) drops; rays per CPU-second is less affected.
    other = max(0.0, busy1 - busy0 - cpu) if busy0 is not None and busy1 is not None else None
    image = session.read("combined")
    pixel_samples = samples * session.width * session.height
    return {
        "upload_s": upload_s,
        "flatten_s": flatten_s,
        "first_frame_s": latency_s,
        "frame_s": first_s,
        "frames": frames,
        "samples_per_pixel": samples,
        "rays": rays,
        "wall_s": wall,
        "cpu_s": cpu,
        "rays_per_s": rays / wall if wall > 0 else 0.0,
        "rays_per_cpu_s": rays / cpu if cpu > 0 else 0.0,
        "samples_per_s": pixel_samples / wall if wall > 0 else 0.0,
        "other_cpu_s": other,
        "other_cpu_share": (other / (wall * (os.cpu_count() or 1))) if other is not None and wall > 0 else None,
        "image_mean": float(image[..., :3].mean()),
        "warnings": list(warnings),
    }


def run(sizes=(1_000, 100_000, 1_000_000), resolution=None, seconds=10.0, method="nee",
        max_depth=4, device="auto", unordered=True, unordered_resolution=64,
        samples_per_frame=None, seed=0, progress=_log, info=None, orders=None, passes=None) -> list[dict]:
    """Measure every (size, order); returns one dict per row (see _measure for the raw
    fields, plus scene/order/resolution/target fields). ``resolution`` None: 512 on CPU
    devices, 1024 on GPUs. ``samples_per_frame`` None: 8 on CPU devices, 16 on GPUs (more
    work per dispatch; the thesis' figure 5.2). ``info``, if a dict, receives device and
    pipeline details. ``orders``: the ORDERS labels to measure (default all; ``unordered``
    False drops "shuffled"). ``passes``: the film's passes (Session.passes; None: every pass;
    a build older than Session.passes writes every pass regardless)."""
    import parallax_core
    from parallax_core import Session, scenes

    known = [label for label, _, _ in ORDERS]
    orders = list(known if orders is None else orders)
    for label in orders:
        if label not in known:
            raise ValueError(f"unknown order {label!r} (orders: {', '.join(known)})")

    sizes = [parse_size(s) if isinstance(s, str) else int(s) for s in sizes]
    device = _device_arg(device)
    probe = Session(8, 8, device)  # to learn the device type before picking the resolution
    cpu_device = _is_cpu(probe)
    del probe
    res = int(resolution or (512 if cpu_device else 1024))
    samples_per_frame = int(samples_per_frame or (8 if cpu_device else 16))
    # Like for like across builds: unbiased light paths (no kind budget, no clamp, a one-pixel box
    # filter) and no adaptive sampling, in every build that has those settings.
    known = {f.name for f in dataclasses.fields(parallax_core.RenderParams)}
    pins = {**getattr(parallax_core, "UNBIASED_LIGHT_PATHS", {}), "use_adaptive_sampling": False}
    params = dict({k: v for k, v in pins.items() if k in known}, method=method, max_depth=max_depth,
                  rr_start_depth=0, samples_per_frame=samples_per_frame, seed=seed)
    main = Session(res, res, device)
    if passes is not None and hasattr(main, "passes"):
        main.passes = list(passes)
    compile_s = _warm_up(main, params)
    progress(f"device: {main.device} ({main.device_type}), {res}x{res}, {method} "
             f"max_depth={max_depth}, pipeline compile {compile_s:.2f} s")
    small_res = min(int(unordered_resolution), res)
    small = None  # reduced-resolution session for the unordered case, made when needed

    if isinstance(info, dict):
        info.update(device=main.device, device_type=main.device_type, resolution=res,
                    method=method, max_depth=max_depth, rr_start_depth=0,
                    samples_per_frame=samples_per_frame, seconds=seconds,
                    pipeline_compile_s=compile_s, unordered_resolution=small_res,
                    cpu_count=os.cpu_count(), lp_num_threads=os.environ.get("LP_NUM_THREADS"),
                    platform=platform.platform(), python=platform.python_version(),
                    core=os.path.dirname(parallax_core.__file__))

    minimal = MINIMAL_CPU if cpu_device else MINIMAL_GPU
    rows = []
    for n in sizes:
        built = {}
        for label, shuffle, spatial_order in ORDERS:
            if (not spatial_order and not unordered) or label not in orders:
                continue
            if shuffle not in built:
                t0 = time.perf_counter()
                built[shuffle] = scenes.triangle_soup_scene(n, res, res, shuffle=shuffle, seed=seed)
                built[f"{shuffle}_s"] = time.perf_counter() - t0
            scene = built[shuffle]
            session, row_res, note = main, res, ""
            if not spatial_order and small_res < res:
                # Probe one frame at the reduced resolution; go to full resolution only if a
                # full frame is predicted to take at most half the time budget.
                if small is None:
                    small = Session(small_res, small_res, device)
                    if passes is not None and hasattr(small, "passes"):
                        small.passes = list(passes)
                    c = _warm_up(small, params)
                    progress(f"  ({small_res}x{small_res} session for the unordered case: "
                             f"pipeline compile {c:.2f} s)")
                small_scene = scene.with_resolution(small_res, small_res)
                m = _measure(small, small_scene, spatial_order, seconds)
                predicted = m["frame_s"] * (res * res) / (small_res * small_res)
                if predicted <= 0.5 * seconds:
                    m = _measure(main, scene, spatial_order, seconds)
                else:
                    session, row_res = small, small_res
                    note = (f"measured at {small_res}x{small_res}; full-resolution frame "
                            f"~{predicted:.0f} s")
            else:
                m = _measure(main, scene, spatial_order, seconds)
            if small is not None and session is small:
                triangles = small.triangle_count
            else:
                triangles = main.triangle_count
            target = minimal.get(n)
            achieved = m["rays_per_cpu_s"] if cpu_device else m["rays_per_s"]
            row = dict(scene="triangle_soup", size=size_label(n), n_requested=n,
                       triangles=int(triangles), order=label, shuffle=shuffle,
                       spatial_order=spatial_order, resolution=row_res,
                       scene_build_s=built[f"{shuffle}_s"], note=note,
                       target=target, target_metric="rays_per_cpu_s" if cpu_device else "rays_per_s",
                       fraction_of_target=(achieved / target) if target else None, **m)
            rows.append(row)
            pct = f"{_pct(row['fraction_of_target'])} of target" if target else "no target"
            busy = (f", other processes {100 * m['other_cpu_share']:.0f}% of the CPUs"
                    if m["other_cpu_share"] is not None else "")
            progress(f"{row['size']:>5} {label:<14} {row_res}x{row_res}: upload {m['upload_s']:.3f} s, "
                     f"first frame {m['first_frame_s']:.3f} s, {m['frames']} frames in {m['wall_s']:.1f} s, "
                     f"{m['rays_per_s'] / 1e6:.3f} Mrays/s, {m['rays_per_cpu_s'] / 1e6:.3f} Mrays/CPU-s, {pct}{busy}"
                     + (f"  [{note}]" if note else ""))
    return rows


def _pct(fraction: float) -> str:
    p = 100 * fraction
    return f"{p:.0f}%" if p >= 9.5 else f"{p:.2g}%"


def _fmt(x: float, digits: int = 3) -> str:
    if x == 0:
        return "0"
    if abs(x) >= 10 ** digits:
        return f"{x:.0f}"
    return f"{x:.{digits}g}"


def markdown_table(rows: list[dict], info: dict) -> str:
    cpu = info.get("device_type") == "cpu"
    goal = GOAL_CPU if cpu else GOAL_GPU
    head = ("| scene | triangles | order | res | upload s | first frame s | Mrays/s | Mrays/CPU-s "
            f"| % target ({'per CPU-s' if cpu else 'per s'}) | Msamples/s | others' CPU |")
    lines = [head, "|" + "---|" * 11]
    for r in rows:
        pct = _pct(r["fraction_of_target"]) if r["fraction_of_target"] is not None else "—"
        other = f"{100 * r['other_cpu_share']:.0f}%" if r.get("other_cpu_share") is not None else "—"
        if r["fraction_of_target"] is not None and r["order"] != "shuffled":
            pct += " ✓" if r["fraction_of_target"] >= goal else " ✗"
        lines.append(
            f"| soup {r['size']} | {r['triangles']} | {r['order']} | {r['resolution']}² "
            f"| {r['upload_s']:.3f} | {r['first_frame_s']:.3f} | {_fmt(r['rays_per_s'] / 1e6)} "
            f"| {_fmt(r['rays_per_cpu_s'] / 1e6)} | {pct} | {_fmt(r['samples_per_s'] / 1e6)} | {other} |")
    return "\n".join(lines)


def summary(rows: list[dict], info: dict) -> str:
    cpu = info.get("device_type") == "cpu"
    out = [f"device: {info.get('device')} ({info.get('device_type')}), {info.get('cpu_count')} CPUs, "
           f"{info.get('method')} max_depth={info.get('max_depth')} rr off, "
           f"{info.get('resolution')}x{info.get('resolution')}, {info.get('samples_per_frame')} spp per frame, "
           f"~{info.get('seconds')} s per row, "
           f"pipeline compile {info.get('pipeline_compile_s', 0):.2f} s"]
    targets = "2.1 / 1.05 / 0.55 M rays per CPU-s" if cpu else "3.0 / 1.9 / 1.4 G rays/s"
    out.append(f"% target = measured / minimal tracer ({targets}); goal >= "
               f"{100 * (GOAL_CPU if cpu else GOAL_GPU):.0f}% (not applied to the 'shuffled' rows).")
    for r in rows:
        if r["n_requested"] == 100_000 and r["order"] == "coherent+sort":
            t = r["upload_s"] + r["first_frame_s"]
            ok = "✓" if t < FIRST_FRAME_GOAL_S else "✗"
            out.append(f"100k upload + first frame: {t:.3f} s (goal < {FIRST_FRAME_GOAL_S:.0f} s) {ok}")
    shares = [r["other_cpu_share"] for r in rows if r.get("other_cpu_share") is not None]
    if shares and max(shares) > 0.05:
        out.append(f"warning: other processes used up to {100 * max(shares):.0f}% of the machine's CPUs "
                   "during a measurement ('others' CPU' column): wall-clock rates are low there; "
                   "rays per CPU-second is less affected.")
    notes = [f"soup {r['size']} {r['order']}: {r['note']}" for r in rows if r["note"]]
    if notes:
        out.append("notes: " + "; ".join(notes))
    out.append("order: coherent+sort = mesh as generated, core Morton ordering on; shuffled = "
               "triangles permuted, ordering off (spatial_order=False); shuffled+sort = permuted, "
               "ordering on. First frame excludes pipeline compile (warmed up on a tiny scene).")
    return "\n".join(out)


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--sizes", default="1k,100k,1M", help="triangle counts (default 1k,100k,1M)")
    p.add_argument("--resolution", type=int, help="square image size (default 512 on CPU, 1024 on GPU)")
    p.add_argument("--method", choices=("pt", "nee", "mis"), default="nee")
    p.add_argument("--max-depth", type=int, default=4)
    p.add_argument("--seconds", type=float, default=10.0, help="render time per row (default 10)")
    p.add_argument("--device", default="auto", help="auto, cpu, gpu or a device index")
    p.add_argument("--no-unordered", action="store_true",
                   help="skip the shuffled mesh without spatial ordering (slow on lavapipe)")
    p.add_argument("--orders", default=",".join(label for label, _, _ in ORDERS),
                   help="triangle orders to measure (default all: coherent+sort,shuffled,shuffled+sort)")
    p.add_argument("--unordered-resolution", type=int, default=64,
                   help="resolution for the unordered case when full resolution is too slow (default 64)")
    p.add_argument("--spp-per-frame", type=int, default=None,
                   help="samples_per_frame (default 8 on CPU devices, 16 on GPUs)")
    p.add_argument("--passes", help="the film's passes, e.g. combined,depth (default: every pass)")
    p.add_argument("--json", metavar="OUT.json", help="also write the raw numbers as JSON")
    args = p.parse_args(argv)

    info: dict = {}
    t0 = time.perf_counter()
    try:
        rows = run(sizes=args.sizes.split(","), resolution=args.resolution, seconds=args.seconds,
                   method=args.method, max_depth=args.max_depth, device=args.device,
                   unordered=not args.no_unordered, unordered_resolution=args.unordered_resolution,
                   samples_per_frame=args.spp_per_frame, info=info, orders=args.orders.split(","),
                   passes=args.passes.split(",") if args.passes else None)
    except (ValueError, RuntimeError) as e:
        print(f"throughput: error: {e}", file=sys.stderr)
        return 2
    info["total_s"] = time.perf_counter() - t0
    print(markdown_table(rows, info))
    print()
    print(summary(rows, info))
    if args.json:
        with open(args.json, "w") as f:
            json.dump({"info": info, "rows": rows}, f, indent=2)
        _log(f"wrote {args.json}")
    _log(f"total {info['total_s']:.0f} s")
    return 0


if __name__ == "__main__":
    sys.exit(main())
