#!/usr/bin/env python3
"""Interactive edit latency: Session.update(scene, parts=...) plus the next 1-spp frame.

    python bench/update_latency.py [--resolution 1280x720] [--triangles 100k] [--repeats 3]
                                   [--method mis] [--max-depth 8] [--device auto]
                                   [--json OUT.json]

A viewport edit changes one part of the scene: the camera (orbiting), an object's transform
(instances), a material, a light or the world (lights), or a mesh (geometry). For
scenes.cornell_box and scenes.triangle_soup_scene (about --triangles triangles), this
applies a small edit of each part and measures the wall time of
``update(scene, parts={part})`` and of the ``render(1)`` (1 sample per pixel) after it,
against ``update(scene)`` of the whole scene (after the same kind of camera edit). Each row
is the median of --repeats edits; "flatten" is SceneData.flatten(parts=...) alone
(validation and flattening in Python, measured separately, part of "update"); "BLASes" is
how many BLASes the update built (Session.stats()["blas_builds"]).

`run(...)` is importable and returns one dict per row.
"""
from __future__ import annotations

import argparse
import json
import math
import os
import statistics
import sys
import time

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from throughput import parse_size, size_label  # noqa: E402

ROWS = ("full", "camera", "instances", "materials", "lights", "geometry")


def _log(msg: str) -> None:
    print(msg, file=sys.stderr, flush=True)


def _parse_resolution(text: str) -> tuple[int, int]:
    w, _, h = text.lower().partition("x")
    return int(w), int(h or w)


def _edit(scene, part: str, k: int, mover: int) -> None:
    """A small edit of ``part`` (the k-th one: every edit differs from the last).
    ``mover``: the instance (and its mesh) to move or reshape."""
    import numpy as np

    from parallax_core.scene import Instance, World

    if part in ("camera", "full"):  # orbit about the world Z axis
        a = math.radians(2.0 * (k + 1))
        c, s = math.cos(a), math.sin(a)
        rz = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
        m = np.asarray(scene.camera.camera_to_world, dtype=np.float64)[:3].copy()
        scene.camera.camera_to_world = rz @ m
    elif part == "instances":
        if not scene.instances:
            scene.instances = [Instance(i) for i in range(len(scene.meshes))]
        t = np.eye(4)
        t[0, 3] = 0.01 * ((k % 2) * 2 - 1)
        scene.instances[mover].transform = t @ np.asarray(scene.instances[mover].transform)
    elif part == "materials":
        mat = scene.materials[0]
        mat.base_color = tuple(min(1.0, 0.2 + 0.1 * ((k + i) % 7)) for i in range(3))
    elif part == "lights":
        w = scene.world
        scene.world = World(tuple(0.02 * ((k + i) % 5) for i in range(3)), w.strength, w.map)
        for light in scene.lights:
            light.position = tuple(np.asarray(light.position, float) + (0.01 * ((k % 2) * 2 - 1), 0, 0))
    elif part == "geometry":
        mesh = scene.meshes[scene.effective_instances()[mover].mesh]
        p = np.asarray(mesh.positions, dtype=np.float64)
        mesh.positions = p.mean(axis=0) + (p - p.mean(axis=0)) * (1.0 + 0.001 * ((k % 2) * 2 - 1))
    else:
        raise ValueError(part)


def _measure_scene(name, scene, mover, width, height, params, repeats, device, progress):
    from parallax_core import Session

    s = Session(width, height, device)
    s.set_params(**params)
    t0 = time.perf_counter()
    s.update(scene)
    s.render(1)  # compiles the pipeline
    warm_s = time.perf_counter() - t0
    progress(f"{name}: first update + frame {warm_s:.2f} s (pipeline compile included)")
    tri = s.triangle_count
    rows = []
    for row in ROWS:
        parts = None if row == "full" else {row}
        updates, renders, flattens, builds = [], [], [], []
        for k in range(repeats):
            _edit(scene, row, k, mover)
            t0 = time.perf_counter()
            scene.flatten(parts=parts)
            flattens.append(time.perf_counter() - t0)
            b0 = s.stats()["blas_builds"]
            t0 = time.perf_counter()
            s.update(scene, parts=parts)
            t1 = time.perf_counter()
            s.render(1)
            t2 = time.perf_counter()
            updates.append(t1 - t0)
            renders.append(t2 - t1)
            builds.append(s.stats()["blas_builds"] - b0)
        r = {
            "scene": name, "triangles": tri, "width": width, "height": height, "row": row,
            "update_ms": 1e3 * statistics.median(updates),
            "flatten_ms": 1e3 * statistics.median(flattens),
            "render_ms": 1e3 * statistics.median(renders),
            "total_ms": 1e3 * statistics.median(u + r for u, r in zip(updates, renders)),
            "blas_builds": max(builds),
            "updates_ms": [1e3 * u for u in updates], "renders_ms": [1e3 * r for r in renders],
        }
        rows.append(r)
        progress(f"{name} {row:9s} update {r['update_ms']:8.2f} ms  render {r['render_ms']:8.1f} ms")
    full = rows[0]
    for r in rows:
        r["update_speedup"] = full["update_ms"] / r["update_ms"] if r["update_ms"] > 0 else float("inf")
        r["total_speedup"] = full["total_ms"] / r["total_ms"] if r["total_ms"] > 0 else float("inf")
    return rows, s.device, s.device_type


def run(resolution=(1280, 720), triangles=100_000, repeats=3, method="mis", max_depth=8,
        device="auto", progress=_log, info=None) -> list[dict]:
    """Every (scene, row); ``info``, if a dict, receives the device name and type."""
    from parallax_core import scenes

    width, height = resolution
    device = int(device) if isinstance(device, str) and device.isdigit() else device
    params = dict(method=method, max_depth=max_depth, samples_per_frame=1, seed=0)
    rows = []
    for name, scene, mover in (
        ("cornell_box", scenes.cornell_box(width, height), 6),  # the tall box
        (f"triangle_soup {size_label(triangles)}",
         scenes.triangle_soup_scene(triangles, width, height), 1),  # the displaced sphere
    ):
        r, dev, dev_type = _measure_scene(name, scene, mover, width, height, params, repeats, device,
                                          progress)
        rows += r
        if info is not None:
            info.update(device=dev, device_type=dev_type)
    return rows


def table(rows) -> str:
    lines = ["| scene | triangles | update | update ms | of which flatten ms | render(1) ms | "
             "update + render ms | update speed-up | total speed-up | BLASes built |",
             "|---|---:|---|---:|---:|---:|---:|---:|---:|---:|"]
    for r in rows:
        what = "full `update(scene)`" if r["row"] == "full" else f"`parts={{'{r['row']}'}}`"
        lines.append(
            f"| {r['scene']} | {r['triangles']:,} | {what} | {r['update_ms']:.2f} | {r['flatten_ms']:.2f} | "
            f"{r['render_ms']:.0f} | {r['total_ms']:.0f} | {r['update_speedup']:.1f}x | "
            f"{r['total_speedup']:.2f}x | {r['blas_builds']} |")
    return "\n".join(lines)


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--resolution", default="1280x720", help="WxH (default 1280x720)")
    p.add_argument("--triangles", default="100k", help="triangle_soup size (default 100k)")
    p.add_argument("--repeats", type=int, default=3, help="edits per row; the median is shown")
    p.add_argument("--method", choices=("pt", "nee", "mis"), default="mis")
    p.add_argument("--max-depth", type=int, default=8)
    p.add_argument("--device", default="auto", help="auto, cpu, gpu or a device index")
    p.add_argument("--json", metavar="OUT.json", help="also write the raw numbers as JSON")
    a = p.parse_args(argv)
    info = {}
    t0 = time.perf_counter()
    rows = run(_parse_resolution(a.resolution), parse_size(a.triangles), a.repeats, a.method,
               a.max_depth, a.device, info=info)
    w, h = _parse_resolution(a.resolution)
    print(f"Device: {info.get('device')} ({info.get('device_type')}); {w}x{h}, 1 spp, "
          f"{a.method}, max_depth {a.max_depth}; median of {a.repeats} edits per row\n")
    print(table(rows))
    print(f"\n({time.perf_counter() - t0:.0f} s)")
    if a.json:
        with open(a.json, "w") as f:
            json.dump({"info": info, "rows": rows}, f, indent=1)
    return 0


if __name__ == "__main__":
    sys.exit(main())
