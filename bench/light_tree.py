#!/usr/bin/env python3
"""Light tree against picking lights by power, side by side on the same session.

    python bench/light_tree.py [--resolution 48] [--rounds 3] [--frames 4] [--json OUT.json]

For each scene (many_emitters: 1000 emissive triangles; cornell_box: 2; veach_mis: 4 sphere
lights) and each mode it renders, alternating the modes
round by round so both see the same machine load: samples per CPU-second (time.process_time,
where lavapipe renders) and per wall second, and the relMSE at equal samples estimated from
8 seeded batches (mean of se^2 / (mean^2 + 1e-3), unbiased estimators: no reference needed).
The mode is switched with parallax_core.set_light_tree_min_lights (0: tree, 2**32-1: power).
"""
from __future__ import annotations

import argparse
import dataclasses
import json
import time

import numpy as np

import parallax_core as pc
from parallax_core import scenes

MODES = {"tree": 0, "power": 2**32 - 1}


def _params(spp, seed, method, depth):
    d = dataclasses.asdict(pc.RenderParams())
    return {**d, "method": method, "samples_per_frame": spp, "seed": seed, "max_depth": depth}


def measure(scene, res, rounds, frames, spp, method, depth):
    s = pc.Session(res, res)
    sc = scene.with_resolution(res, res)
    out = {m: {"cpu": 0.0, "wall": 0.0, "samples": 0} for m in MODES}
    for m, thr in MODES.items():  # warm-up: compile once, outside the timing
        pc.set_light_tree_min_lights(thr)
        s.update(sc)
        s.set_params(**_params(spp, 0, method, depth))
        s.reset()
        s.render(1)
        s.read("combined")
    for r in range(rounds):
        for m, thr in MODES.items():
            pc.set_light_tree_min_lights(thr)
            s.update(sc)
            s.set_params(**_params(spp, r + 1, method, depth))
            s.reset()
            c0, w0 = time.process_time(), time.perf_counter()
            s.render(frames)
            s.read("combined")
            out[m]["cpu"] += time.process_time() - c0
            out[m]["wall"] += time.perf_counter() - w0
            out[m]["samples"] += frames * spp * res * res
    for m, thr in MODES.items():  # noise at equal samples
        pc.set_light_tree_min_lights(thr)
        s.update(sc)
        imgs = []
        for b in range(8):
            s.set_params(**_params(spp, 1000 + b, method, depth))
            s.reset()
            s.render(frames)
            imgs.append(s.read("combined")[..., :3])
        st = np.stack(imgs)
        mean, se = st.mean(0), st.std(0, ddof=1) / np.sqrt(len(imgs))
        out[m]["relmse"] = float((se**2 / (mean**2 + 1e-3)).mean())
        out[m]["mean"] = float(mean.mean())
        out[m]["samples_per_cpu_s"] = out[m]["samples"] / out[m]["cpu"]
        out[m]["samples_per_wall_s"] = out[m]["samples"] / out[m]["wall"]
    return out


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--resolution", type=int, default=48)
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--frames", type=int, default=4)
    ap.add_argument("--spp", type=int, default=4, help="samples per frame")
    ap.add_argument("--method", default="mis")
    ap.add_argument("--max-depth", type=int, default=4)
    ap.add_argument("--scenes", default="many_emitters,cornell_box,veach_mis")
    ap.add_argument("--json")
    a = ap.parse_args()
    builders = {"many_emitters": lambda: scenes.many_emitters(1000), "cornell_box": scenes.cornell_box,
                "veach_mis": scenes.veach_mis}
    before = pc.light_tree_min_lights()
    results = {}
    try:
        print(f"{'scene':15s} {'mode':6s} {'spp/cpu-s':>10s} {'spp/wall-s':>10s} {'relMSE':>10s} {'mean':>8s}")
        for name in a.scenes.split(","):
            r = measure(builders[name](), a.resolution, a.rounds, a.frames, a.spp, a.method, a.max_depth)
            results[name] = r
            for m in MODES:
                x = r[m]
                print(f"{name:15s} {m:6s} {x['samples_per_cpu_s']:10.0f} {x['samples_per_wall_s']:10.0f} "
                      f"{x['relmse']:10.3g} {x['mean']:8.4f}")
            t, p = r["tree"], r["power"]
            print(f"{name:15s} tree/power: speed (cpu) {t['samples_per_cpu_s'] / p['samples_per_cpu_s']:.3f}, "
                  f"relMSE at equal spp {t['relmse'] / p['relmse']:.3f}, efficiency "
                  f"{(p['relmse'] / t['relmse']) * (t['samples_per_cpu_s'] / p['samples_per_cpu_s']):.2f}x")
    finally:
        pc.set_light_tree_min_lights(before)
    if a.json:
        with open(a.json, "w") as f:
            json.dump(results, f, indent=1)


if __name__ == "__main__":
    main()
