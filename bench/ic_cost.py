"""What the irradiance cache costs: frame time, prepare phase, creation, lookup grid builds, memory.

    .venv/bin/python -m bench.ic_cost [--scenes cornell_box,sun_room] [--width 320]
        [--device auto] [--frames 8] [--npz DIR | --procedural] [--big-capacity 4000000]
        [--json bench/results/ic_cost.json] [--md bench/results/ic_cost.md]

Per scene (blender_scenes/NAME.blend exported at --width as bench.converge does; --npz DIR
reads DIR/NAME.npz; --procedural uses parallax_core.scenes' twins), MIS, 8 bounces, 1 spp
per frame, default IC settings otherwise:

- frame time (median of --frames render(1) calls) with the cache off, and with it on after
  its prepare frames (a frame with the cache includes its share of the host steps: the
  creation jobs of the requests, refreshes, and the lookup grid's build; in consistent mode a
  step follows several frames);
- the prepare phase: `ic_prepare_frames` calls of render_rows(height), each running one
  prepare frame (camera rays to the first diffuse hit, queued entries, hemisphere + finish
  dispatch, lookup grid build), after the pipelines were compiled by a throw-away session;
- the creation dispatch per job: stats' ic_job_milliseconds / ic_jobs (200 rays per job),
  during the prepare phase and during the later frames;
- lookup grid build time per frame: stats' ic_build_milliseconds, per prepare frame and per
  later frame; and the later frames again with ic_capacity = --big-capacity (the grid lists
  the used slots only, so that should change nothing);
- memory per entry: no binding reports the cache's buffers, so it is measured as the growth
  of the process (CPU devices: lavapipe keeps every buffer in host memory, VmRSS) or of the
  GPU's used memory (nvidia-smi) when a session with a scene switches the cache on, for
  ic_capacity 65536 and --big-capacity, in fresh processes; per entry = the difference over
  the difference of capacities. Compare sizeof(IcEntry), 80 B per slot.

Rows are kept in --json by (device kind, scene) (so CPU and GPU runs add up, the GPU's run on
the device machine) and the Markdown table of all rows is written to --md.
"""
from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import time

HERE = os.path.dirname(os.path.abspath(__file__))
REPO = os.path.dirname(HERE)
SCENES = ("cornell_box", "sun_room")
MAX_DEPTH = 8
SMALL_CAPACITY = 65536


def load(name, width, npz_dir, procedural):
    if procedural:
        from parallax_core import scenes

        builder = scenes.SCENES[name]
        probe = builder()
        return builder(width, max(1, round(width * probe.height / probe.width)))
    from bench.converge import load_scene

    return load_scene(name, width, npz_dir)


def _ic_stats(session):
    st = session.stats()
    return {k: st[k] for k in ("ic_entries", "ic_jobs", "ic_job_milliseconds", "ic_build_milliseconds",
                               "ic_dropped", "ic_deferred", "ic_merged", "frames") if k in st}


def _delta(a, b):
    return {k: b[k] - a[k] for k in a}


def _timed_frames(session, frames):
    times = []
    for _ in range(frames):
        t = time.perf_counter()
        session.render(1)
        times.append(time.perf_counter() - t)
    return times


def measure_scene(scene, device, frames, big_capacity):
    import parallax_core as pc

    base = dict(method="mis", samples_per_frame=1, max_depth=MAX_DEPTH, depth_leeway=0, seed=0)
    # Compile every pipeline (camera with and without the cache, hemisphere, finish) first:
    # they are shared process-wide, so the sessions below do not pay for them.
    t = time.perf_counter()
    warm = pc.Session(scene.width, scene.height, device)
    warm.set_params(**base)
    warm.update(scene)
    warm.render(1)
    warm.set_params(**base, ic=True, ic_prepare_frames=1)
    warm.render(1)
    compile_s = time.perf_counter() - t
    del warm

    row = {"compile_and_warm_up_s": compile_s}
    session = pc.Session(scene.width, scene.height, device)
    session.set_params(**base)
    session.update(scene)
    session.render(1)
    off = _timed_frames(session, frames)
    row["frame_off_ms"] = 1e3 * statistics.median(off)

    session.set_params(**base, ic=True)  # resets the cache: the prepare frames are due
    s0 = s1 = _ic_stats(session)
    per_prepare = []
    while True:  # one prepare frame per call; the prepare phase may end early (coverage)
        t = time.perf_counter()
        done = session.render_rows(scene.height)  # after the prepare frames: the first frame
        if done:
            break
        per_prepare.append(time.perf_counter() - t)
        s1 = _ic_stats(session)
    prepare_frames = len(per_prepare)
    row["prepare_s"] = sum(per_prepare)
    d = _delta(s0, s1)
    row.update(prepare_frames=prepare_frames, prepare_frames_setting=session.params.ic_prepare_frames,
               prepare_frame_ms_first=1e3 * per_prepare[0] if per_prepare else 0,
               prepare_frame_ms_median=1e3 * statistics.median(per_prepare) if per_prepare else 0,
               entries_after_prepare=s1["ic_entries"], prepare_jobs=d["ic_jobs"],
               prepare_job_ms=d["ic_job_milliseconds"], prepare_build_ms=d["ic_build_milliseconds"],
               prepare_deferred=d["ic_deferred"], prepare_merged=d.get("ic_merged"))
    row["prepare_job_ms_per_job"] = d["ic_job_milliseconds"] / d["ic_jobs"] if d["ic_jobs"] else None
    row["prepare_build_ms_per_frame"] = d["ic_build_milliseconds"] / max(1, prepare_frames)

    s2 = _ic_stats(session)
    on = _timed_frames(session, frames)
    s3 = _ic_stats(session)
    d = _delta(s2, s3)
    row["frame_on_ms"] = 1e3 * statistics.median(on)
    row.update(entries_after=s3["ic_entries"], frame_jobs=d["ic_jobs"] / frames,
               frame_job_ms=d["ic_job_milliseconds"] / frames, frame_build_ms=d["ic_build_milliseconds"] / frames,
               dropped=s3["ic_dropped"])
    row["frame_job_ms_per_job"] = d["ic_job_milliseconds"] / d["ic_jobs"] if d["ic_jobs"] else None
    del session

    # The same cache frozen: capacity = the entries the prepare frames made and no refreshes, so
    # later frames queue requests that are dropped: no jobs, no builds. What is left of the
    # frame is tracing (paths ending at covered diffuse vertices) and the host's queue step.

    session = pc.Session(scene.width, scene.height, device)
    session.set_params(**base, ic=True, ic_capacity=max(1, row["entries_after_prepare"]), ic_update_prob=0.0)
    session.update(scene)
    session.render(1)
    s4 = _ic_stats(session)
    frozen = _timed_frames(session, frames)
    d = _delta(s4, _ic_stats(session))
    row["frame_frozen_ms"] = 1e3 * statistics.median(frozen)
    row["frozen_jobs"] = d["ic_jobs"]
    irradiance = session.read("ic_irradiance")
    row["covered_pixels"] = float((irradiance.max(axis=-1) > 0).mean())  # some sample's first diffuse hit was cached
    del session

    if big_capacity:
        session = pc.Session(scene.width, scene.height, device)
        session.set_params(**base, ic=True, ic_capacity=big_capacity)
        session.update(scene)
        t = time.perf_counter()
        session.render(1)
        row["big_prepare_s"] = time.perf_counter() - t  # prepare frames + one frame
        s2 = _ic_stats(session)
        on = _timed_frames(session, frames)
        d = _delta(s2, _ic_stats(session))
        row.update(big_capacity=big_capacity, big_frame_on_ms=1e3 * statistics.median(on),
                   big_frame_build_ms=d["ic_build_milliseconds"] / frames)
        del session
    return row


# ---- memory: fresh processes ---------------------------------------------------------------

def _gpu_used_mib():
    try:
        out = subprocess.run(["nvidia-smi", "--query-gpu=memory.used", "--format=csv,noheader,nounits"],
                             capture_output=True, text=True, timeout=30).stdout
        return float(out.split()[0])
    except (OSError, ValueError, IndexError, subprocess.SubprocessError):
        return None


def _rss_bytes():
    with open("/proc/self/status") as f:
        for line in f:
            if line.startswith("VmRSS:"):
                return int(line.split()[1]) * 1024
    return 0


def memory_probe(scene, device, capacity):
    """Growth of RSS and GPU memory when the cache (of `capacity` slots) is switched on."""
    import parallax_core as pc

    session = pc.Session(scene.width, scene.height, device)
    session.set_params(method="mis", max_depth=MAX_DEPTH)
    session.update(scene)
    session.render(1)
    time.sleep(0.5)
    rss0, gpu0 = _rss_bytes(), _gpu_used_mib()
    session.set_params(method="mis", max_depth=MAX_DEPTH, ic=True, ic_capacity=capacity, ic_prepare_frames=0)
    session.render(1)  # buffers are allocated at set_params; one frame touches them
    time.sleep(0.5)
    rss1, gpu1 = _rss_bytes(), _gpu_used_mib()
    return {"capacity": capacity, "rss_growth": rss1 - rss0,
            "gpu_growth_mib": (gpu1 - gpu0) if gpu0 is not None and gpu1 is not None else None}


def memory_per_entry(name, width, device, npz_dir, procedural, big_capacity):
    probes = []
    for capacity in (SMALL_CAPACITY, big_capacity):
        args = [sys.executable, "-m", "bench.ic_cost", "--_memory-probe", str(capacity), "--scenes", name,
                "--width", str(width), "--device", device]
        if npz_dir:
            args += ["--npz", npz_dir]
        if procedural:
            args.append("--procedural")
        out = subprocess.run(args, capture_output=True, text=True, cwd=REPO,
                             env={**os.environ, "PYTHONPATH": os.pathsep.join(
                                 [REPO] + [p for p in os.environ.get("PYTHONPATH", "").split(os.pathsep) if p])})
        if out.returncode:
            sys.stderr.write(out.stderr[-2000:])
            return None
        probes.append(json.loads(out.stdout.strip().splitlines()[-1]))
    small, big = probes
    slots = big["capacity"] - small["capacity"]
    result = {"probes": probes, "rss_bytes_per_entry": (big["rss_growth"] - small["rss_growth"]) / slots}
    if small["gpu_growth_mib"] is not None:
        result["gpu_bytes_per_entry"] = (big["gpu_growth_mib"] - small["gpu_growth_mib"]) * 2**20 / slots
    return result


# ---- output --------------------------------------------------------------------------------

def _f(v, fmt):
    return "–" if v is None else format(v, fmt)


def markdown(rows):
    lines = [
        "| device | scene | size | frame off (ms) | frame on (ms) | on/off | prepare (s) | prepare frame (ms, median) "
        "| entries after prepare | frame on, cache frozen (ms) | covered pixels "
        "| job ms/job (prepare, later) | build ms/frame (prepare, later) "
        "| later frame at big capacity: build ms / frame ms | bytes/entry |",
        "|---|---|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|",
    ]
    for key in sorted(rows):
        r = rows[key]
        mem = r.get("memory") or {}
        per_entry = mem.get("gpu_bytes_per_entry", mem.get("rss_bytes_per_entry"))
        big = (f"{_f(r.get('big_frame_build_ms'), '.1f')} / {_f(r.get('big_frame_on_ms'), '.1f')} "
               f"({r['big_capacity'] / 1e6:g}M)"
               if r.get("big_capacity") else "–")
        lines.append(
            f"| {r['kind']} ({r['device']}) | {r['scene']} | {r['size']} | {r['frame_off_ms']:.1f} | "
            f"{r['frame_on_ms']:.1f} | {r['frame_on_ms'] / r['frame_off_ms']:.2f} | {r['prepare_s']:.2f} "
            f"({r['prepare_frames']} frames) | "
            f"{r['prepare_frame_ms_median']:.1f} | {r['entries_after_prepare']} | "
            f"{_f(r.get('frame_frozen_ms'), '.1f')} | {_f(None if r.get('covered_pixels') is None else 100 * r['covered_pixels'], '.0f')}{'' if r.get('covered_pixels') is None else '%'} | "
            f"{_f(r['prepare_job_ms_per_job'], '.3f')}, {_f(r['frame_job_ms_per_job'], '.3f')} | "
            f"{r['prepare_build_ms_per_frame']:.2f}, {r['frame_build_ms']:.2f} | {big} | "
            f"{_f(per_entry, '.0f')} |")
    lines += [
        "",
        "MIS, 8 bounces, 1 spp per frame, default IC settings (accuracy 0.2, up to 50 prepare frames, capacity "
        "65536, rebuild interval 1). Frame times: median of the timed frames, the cache's host step included. "
        "Prepare: the prepare frames after the pipelines were compiled (the phase ends early once 98% of first "
        "diffuse hits are covered, 90% in consistent mode). Frozen: the cache the prepare frames "
        "made, with capacity = its entries and no refreshes (no jobs, no builds: tracing + the host's queue step); "
        "covered pixels: share of pixels whose first diffuse hit found entries. Job = one hemisphere estimate "
        "(200 rays) + its share of the finish dispatch. Build = the lookup grid (download, build, upload). bytes/entry: growth "
        "of the GPU's used memory (nvidia-smi) or the process RSS (lavapipe) between ic_capacity 65536 and the "
        "big capacity, "
        "per slot; sizeof(IcEntry) 80 B (lavapipe's RSS counts only "
        "touched pages: a lower bound). `bench/ic_cost.py`; core builds in ic_cost.json.",
    ]
    return "\n".join(lines) + "\n"


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--scenes", default=",".join(SCENES))
    p.add_argument("--width", type=int, default=320)
    p.add_argument("--device", default="auto")
    p.add_argument("--frames", type=int, default=8)
    p.add_argument("--npz")
    p.add_argument("--procedural", action="store_true")
    p.add_argument("--big-capacity", type=int, default=4_000_000)
    p.add_argument("--no-memory", action="store_true")
    p.add_argument("--json", default=os.path.join(HERE, "results", "ic_cost.json"))
    p.add_argument("--md", default=os.path.join(HERE, "results", "ic_cost.md"))
    p.add_argument("--md-only", action="store_true", help="only rewrite --md from --json")
    p.add_argument("--_memory-probe", type=int, dest="memory_probe", help=argparse.SUPPRESS)
    a = p.parse_args(argv)
    scenes = [s for s in a.scenes.split(",") if s]
    if a.memory_probe:
        scene = load(scenes[0], a.width, a.npz, a.procedural)
        print(json.dumps(memory_probe(scene, a.device, a.memory_probe)))
        return 0
    rows = {}
    if os.path.exists(a.json):
        with open(a.json) as f:
            rows = json.load(f)
    if not a.md_only:
        from bench.converge import core_identity, device_kind

        kind, device_name = device_kind(a.device)
        core = core_identity()
        for name in scenes:
            scene = load(name, a.width, a.npz, a.procedural)
            sys.stderr.write(f"ic_cost: {name} {scene.width}x{scene.height} on {device_name}\n")
            row = measure_scene(scene, a.device, a.frames, a.big_capacity)
            if not a.no_memory:
                row["memory"] = memory_per_entry(name, a.width, a.device, a.npz, a.procedural, a.big_capacity)
            row.update(kind=kind, device=device_name, scene=name, size=f"{scene.width}x{scene.height}",
                       procedural=a.procedural, core=core)
            rows[f"{kind}:{name}"] = row
            os.makedirs(os.path.dirname(os.path.abspath(a.json)), exist_ok=True)
            with open(a.json, "w") as f:
                json.dump(rows, f, indent=1)
    text = markdown(rows)
    with open(a.md, "w") as f:
        f.write(text)
    print(text)
    return 0


if __name__ == "__main__":
    sys.exit(main())
