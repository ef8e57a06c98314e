"""Issue 36's goal, time to a clean image: Parallax's F12 defaults against Cycles'.

    .venv/bin/python -m bench.clean_goal [RESULTS_JSON] [--out GOAL.md]

Reads a bench.converge results.json (default bench/results/cpu_clean/results.json) with the
rows of the method mis_clean and the peer cycles_clean (converge.CLEAN_ROWS) and writes
GOAL.md beside it: per scene and checkpoint both relMSEs, their ratio, both mean FLIPs and
whether the goal holds there (Parallax's relMSE <= Cycles'); then the samples and the
seconds each engine spent rendering and denoising.
"""
from __future__ import annotations

import argparse
import json
import os
import sys

HERE = os.path.dirname(os.path.abspath(__file__))
DEFAULT_RESULTS = os.path.join(HERE, "results", "cpu_clean", "results.json")


def _clean_rows():
    from bench.converge import CLEAN_ROWS

    return CLEAN_ROWS["mis_clean"], CLEAN_ROWS["cycles_clean"]


def goal_points(results):
    """[(scene, checkpoint, parallax point, cycles point)] of a results.json dict, for each
    scene with both clean rows, at the checkpoints both have. ValueError if there are none."""
    parallax_name, cycles_name = _clean_rows()
    points = []
    for scene, rows in results["scenes"].items():
        by_name = {r["renderer"]: r for r in rows}
        if parallax_name not in by_name or cycles_name not in by_name:
            continue
        ours = {p["checkpoint"]: p for p in by_name[parallax_name].get("checkpoints", [])}
        theirs = {p["checkpoint"]: p for p in by_name[cycles_name].get("checkpoints", [])}
        for mark in sorted(set(ours) & set(theirs)):
            points.append((scene, mark, ours[mark], theirs[mark]))
    if not points:
        raise ValueError(f"no scene has both rows {parallax_name!r} and {cycles_name!r} with checkpoints: "
                         "run bench.converge with --methods mis_clean --peers cycles_clean --checkpoints ...")
    return points


def _num(value, spec=".4g"):
    return "n/a" if value is None else format(value, spec)


def goal_holds(ours, theirs):
    """True where Parallax's relMSE is at most Cycles' (None if either is missing)."""
    if ours.get("rel_mse") is None or theirs.get("rel_mse") is None:
        return None
    return ours["rel_mse"] <= theirs["rel_mse"]


def goal_table(results):
    """GOAL.md's text for a results.json dict."""
    points = goal_points(results)
    held = [goal_holds(o, t) for _, _, o, t in points]
    lines = ["# Time to a clean image (issue 36)", "",
             "Parallax's F12 defaults (`mis_clean`: adaptive sampling, OIDN) against Cycles' "
             "(`cycles_clean`: noise threshold 0.01, OIDN on the CPU), both with Max Bounces "
             f"pinned, at equal time on {results.get('device', '?')}, {results.get('width', '?')} px wide. "
             "relMSE (Ruppert et al. 2020) and mean HDR-FLIP against a long undenoised, unbiased Parallax "
             "reference. Goal: Parallax's relMSE <= Cycles' at every point.", "",
             f"**Goal holds at {sum(h is True for h in held)} of {len(held)} points"
             + (": everywhere.**" if all(h is True for h in held) else ".**"), "",
             "| scene | checkpoint (s) | Parallax relMSE | Cycles relMSE | ratio P/C | Parallax FLIP | Cycles FLIP "
             "| goal holds |", "|---|---:|---:|---:|---:|---:|---:|:---:|"]
    for (scene, mark, ours, theirs), holds in zip(points, held):
        ratio = ours["rel_mse"] / theirs["rel_mse"] if holds is not None and theirs["rel_mse"] > 0 else None
        lines.append(f"| {scene} | {mark:g} | {_num(ours.get('rel_mse'))} | {_num(theirs.get('rel_mse'))} | "
                     f"{_num(ratio, '.3f')} | {_num(ours.get('flip'))} | {_num(theirs.get('flip'))} | "
                     f"{'n/a' if holds is None else 'y' if holds else 'n'} |")
    lines += ["", "Samples per pixel and seconds: Parallax's clock includes its start-up and leaves out the "
              "denoise; Cycles' is the render's wall time (scene sync and denoise included; its time limit "
              "counts neither). Denoise seconds: Parallax's measured around the denoiser, Cycles' from its "
              "status lines (last sample to Finished).", "",
              "| scene | checkpoint (s) | Parallax spp | Cycles spp | Parallax s | Cycles s | Parallax denoise s "
              "| Cycles denoise s |", "|---|---:|---:|---:|---:|---:|---:|---:|"]
    for scene, mark, ours, theirs in points:
        lines.append(f"| {scene} | {mark:g} | {ours['spp']} | {theirs['spp']} | {ours['seconds']:.1f} | "
                     f"{theirs['seconds']:.1f} | {_num(ours.get('denoise_seconds'), '.2f')} | "
                     f"{_num(theirs.get('denoise_seconds'), '.2f')} |")
    return "\n".join(lines) + "\n"


def write_goal(results_path, out=None):
    """Writes GOAL.md (default: beside `results_path`); returns its path."""
    with open(results_path) as f:
        results = json.load(f)
    out = out or os.path.join(os.path.dirname(os.path.abspath(results_path)), "GOAL.md")
    text = goal_table(results)
    with open(out, "w") as f:
        f.write(text)
    return out


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("results", nargs="?", default=DEFAULT_RESULTS, help="a bench.converge results.json")
    p.add_argument("--out", help="default: GOAL.md beside RESULTS")
    a = p.parse_args(argv)
    if not os.path.exists(a.results):
        p.error(f"{a.results}: no such file (run bench.converge first)")
    try:
        out = write_goal(a.results, a.out)
    except (ValueError, KeyError, json.JSONDecodeError) as e:
        p.error(f"{a.results}: {e}")
    print(out)
    return 0


if __name__ == "__main__":
    sys.exit(main())
