"""Issue 35's goal, path guiding that never loses: guiding_auto (MIS + guiding at every default)
against the best of Parallax's unguided methods, at equal time, the median over seeds.

    .venv/bin/python -m bench.guiding_goal RESULTS_JSON [RESULTS_JSON ...] [--out GOAL.md]

Each RESULTS_JSON is a bench.converge run (one per `--seed`) holding the method guiding_auto
and some of pt, nee and mis on the same scenes. Per scene: each method's median relMSE over the
runs that have it, the best unguided one, guiding_auto's ratio to it and whether the goal holds
there: "never loses" (ratio <= 1.1) everywhere, and ">= 4x below" on the glass-lit scenes
(clocks, light_behind_glass). Also whether guiding_auto left the guided pipeline
(stats guiding_pipeline 0: no region paid for it).
"""
from __future__ import annotations

import argparse
import json
import statistics
import sys

UNGUIDED = ("pt", "nee", "mis")
GLASS_LIT = ("clocks", "light_behind_glass")
NEVER_LOSES, GLASS_WIN = 1.1, 4.0


def goal_rows(runs):
    """[(scene, {method: [relMSE per run]}, [guiding_pipeline per run])] of results.json dicts."""
    scenes = {}
    for results in runs:
        for scene, rows in results["scenes"].items():
            errors, pipelines = scenes.setdefault(scene, ({}, []))
            for row in rows:
                method = row["renderer"].removeprefix("Parallax ")
                if method in UNGUIDED + ("guiding_auto",):
                    errors.setdefault(method, []).append(row["rel_mse"])
                if method == "guiding_auto":
                    pipelines.append(row.get("info", {}).get("guiding_pipeline"))
    return [(scene, errors, pipelines) for scene, (errors, pipelines) in scenes.items()]


def table(runs):
    lines = ["| scene | guiding_auto | best unguided | ratio | goal | guided pipeline | runs |",
             "|---|---:|---|---:|---|---|---:|"]
    for scene, errors, pipelines in goal_rows(runs):
        if "guiding_auto" not in errors or not any(m in errors for m in UNGUIDED):
            continue
        medians = {m: statistics.median(v) for m, v in errors.items()}
        best = min((m for m in UNGUIDED if m in medians), key=medians.get)
        ratio = medians["guiding_auto"] / medians[best]
        bound = 1.0 / GLASS_WIN if scene in GLASS_LIT else NEVER_LOSES
        held = "holds" if ratio <= bound else f"misses (<= {bound:g})"
        kept = "/".join("on" if p else "off" for p in pipelines)
        lines.append(f"| {scene} | {medians['guiding_auto']:.4g} | {best} {medians[best]:.4g} | {ratio:.2f} | {held} | "
                     f"{kept} | {len(errors['guiding_auto'])} |")
    return "\n".join(lines) + "\n"


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("results", nargs="+", help="bench.converge results.json files, one per seed")
    p.add_argument("--out", help="write the table here too")
    a = p.parse_args(argv)
    runs = []
    for path in a.results:
        with open(path) as f:
            runs.append(json.load(f))
    text = table(runs)
    sys.stdout.write(text)
    if a.out:
        with open(a.out, "w") as f:
            f.write(text)
    return 0


if __name__ == "__main__":
    sys.exit(main())
