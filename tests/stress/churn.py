"""Session churn and viewport-style partial updates (issue 9), measuring host RSS and the
device memory the core holds. Run by tests/stress/test_churn.py in a process of its own (so
other tests' allocations do not blur the figures); prints one JSON line.

    python tests/stress/churn.py cycles [--cycles 100] [--seed 9]
    python tests/stress/churn.py updates [--edits 1000] [--seed 9]
"""
from __future__ import annotations

import argparse
import copy
import gc
import json
import os
import random
import threading

import numpy as np

import parallax_core as pc
from parallax_core import scenes
from parallax_core.scene import Instance, Light

W = H = 24


def rss_bytes() -> int:
    with open("/proc/self/statm") as f:
        return int(f.read().split()[1]) * os.sysconf("SC_PAGE_SIZE")


def memory() -> dict:
    gc.collect()
    return {"rss": rss_bytes(), "device": pc.memory()["allocated"]}


def scene_for(cycle: int, light: bool = False):
    sc = scenes.cornell_box(W, H)
    sc.instances = [Instance(i) for i in range(len(sc.meshes))]
    sc.instances[5].transform = np.eye(4)
    sc.instances[5].transform[0, 3] = 0.05 * (cycle % 7)  # the short box moves per cycle
    if light:
        sc.lights.append(Light("point", color=(1.0, 0.9, 0.8), power=20.0, position=(0.3, -0.4, 1.5),
                               radius=0.05, name="bulb"))
    return sc


def cancel_at_random(session: pc.Session, rng: random.Random) -> str:
    """Render a few frames and cancel at a random moment: before the call, from another thread
    during it (after a random delay), between row bands, or not at all."""
    how = rng.choice(["before", "during", "rows", "none"])
    if how == "before":
        session.cancel()
        session.render(3)
    elif how == "during":
        worker = threading.Thread(target=session.render, args=(50,))
        worker.start()
        threading.Event().wait(rng.uniform(0.0, 0.05))
        session.cancel()
        worker.join(timeout=600)
        assert not worker.is_alive(), "cancel() did not stop render()"
    elif how == "rows":
        for _ in range(rng.randint(1, 3 * H)):
            session.render_rows(rng.randint(1, 8))
        session.cancel()
    else:
        session.render(rng.randint(1, 3))
    return how


def cycles(n: int, seed: int) -> dict:
    rng = random.Random(seed)
    after, kinds = {}, []
    for cycle in range(n):
        # Settings and scene features repeat every 8 cycles, so the first 10 cycles compile
        # every pipeline variant the loop uses (pipelines are kept for the process).
        variant = cycle % 8
        s = pc.Session(W, H)
        s.set_params(method="nee" if variant & 2 else "mis", samples_per_frame=rng.randint(1, 2), seed=cycle,
                     ic=variant >= 6, ic_capacity=1024, ic_prepare_frames=2)  # 1 in 4 makes a cache
        s.update(scene_for(cycle, light=bool(variant & 1)))
        s.update(scene_for(cycle + 1, light=bool(variant & 1)), parts={"instances"})
        # Pipelines are compiled on first render and kept: the first 8 cycles render to the
        # end, so every variant exists before the measurement after cycle 10.
        kinds.append(cancel_at_random(s, rng) if cycle >= 8 else (s.render(2), "none")[1])
        assert np.isfinite(s.read("combined")).all()
        del s
        if cycle + 1 in (10, n):
            after[cycle + 1] = memory()
    return {"after_10": after[10], "after_all": after[n], "cancels": {k: kinds.count(k) for k in set(kinds)}}


def updates(n: int, seed: int) -> dict:
    """One session, edited like a viewport: each edit re-sends one part, then a few row bands
    are traced (the viewport's quick frame), sometimes a whole frame."""
    rng = random.Random(seed)
    base = scene_for(0, light=True)
    s = pc.Session(W, H)
    s.set_params(method="mis", samples_per_frame=1)
    s.update(base)
    after = {}
    for edit in range(n):
        sc = copy.deepcopy(base)
        part = rng.choice(["camera", "instances", "materials", "lights", "geometry"])
        t = edit * 0.01
        if part == "camera":
            sc.camera = copy.deepcopy(base.camera)
            sc.camera.camera_to_world = sc.camera.camera_to_world.copy()
            sc.camera.camera_to_world[0, 3] += 0.2 * np.sin(t)
        elif part == "instances":
            sc.instances[6].transform = np.eye(4)
            sc.instances[6].transform[1, 3] = 0.1 * np.sin(t)
        elif part == "materials":
            sc.materials[0].base_color = (0.5 + 0.2 * np.sin(t), 0.7, 0.6)
        elif part == "lights":
            sc.lights[0].power = 20.0 + 5 * np.sin(t)
        else:
            sc.meshes[5] = scenes.box((0.33, -0.35, 0.3), 0.6 + 0.1 * np.sin(t), 0.3, 0, "short_box")
        s.update(sc, parts={part})
        for _ in range(rng.randint(1, 4)):
            s.render_rows(8)
        if rng.random() < 0.2:
            s.render(1)
        if edit + 1 in (n // 10, n):
            after[edit + 1] = memory()
    assert np.isfinite(s.read("combined")).all()
    return {"after_10pct": after[n // 10], "after_all": after[n]}


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("mode", choices=["cycles", "updates"])
    ap.add_argument("--cycles", type=int, default=100)
    ap.add_argument("--edits", type=int, default=1000)
    ap.add_argument("--seed", type=int, default=9)
    a = ap.parse_args()
    result = cycles(a.cycles, a.seed) if a.mode == "cycles" else updates(a.edits, a.seed)
    result["validation_messages"] = len(pc.validation_messages())
    print(json.dumps(result))


if __name__ == "__main__":
    main()
