"""The thesis' evaluation numbers (Scholl 2020, tables 5.1-5.4) beside ours.

    .venv/bin/python -m bench.thesis [--out bench/results/SUMMARY.md]

The thesis rendered 1280x720 on an RTX 2080 Ti for 2 minutes (Clocks: 10 minutes), start-up
(~22 s) included, Mitsuba on a 4-core i5 6600k. `python -m bench.converge --suite thesis`
writes bench/results/<cpu|gpu>_thesis/results.json; this module puts those rows beside the
thesis' for the same method and scene class and writes SUMMARY.md. Our runs are shorter and
smaller than the thesis' (see each results.json), so spp are compared as samples per pixel per
second scaled to 1280x720 (pixel samples per second / 921600), a rate that does not depend on
the resolution or the time chosen.
"""
from __future__ import annotations

import argparse
import json
import os
import sys

HERE = os.path.dirname(os.path.abspath(__file__))
RESULTS = os.path.join(HERE, "results")
THESIS_PIXELS = 1280 * 720

# Our method names (bench.converge.METHODS) for the thesis' columns.
THESIS_METHOD_NAMES = {
    "pt": "Path Tracer", "nee": "NEE", "mis": "NEE + MIS", "ic_noupdate": "IC no updates",
    "ic_thesis": "Irradiance Cache", "ic": "Irradiance Cache, consistent", "adrrs": "ADRRS",
    "guiding_pt": "Guiding Parallax",
    "guiding": "Guiding Parallax + NEE", "guiding_device": "Guiding Parallax + NEE, device fit",
    "guiding_pt_device": "Guiding Parallax, device fit",
}

# Table -> (our scene of the same class, seconds, {method: (relMSE, spp)}). Mitsuba's columns
# are its 2-minute run. The thesis' Veach MIS and Cornell box ran IC and guiding with NEE
# but without MIS; Clocks' two guiding runs differ in training frames (64 and 32).
THESIS_TABLES = {
    "5.1 Sponza": ("atrium", 120, {
        "mitsuba": (0.217, 72), "pt": (31.131, 3712), "nee": (0.017, 1408), "mis": (0.028, 800),
        "ic_noupdate": (0.37, 864), "ic_thesis": (0.222, 800), "adrrs": (0.216, 62),
        "guiding_pt": (78.807, 976), "guiding": (0.046, 604)}),
    "5.2 Veach MIS": ("thesis_veach_mis", 120, {
        "mitsuba": (0.0182, 500), "pt": (0.1206, 50944), "nee": (0.0058, 12128), "mis": (0.0017, 5888),
        "ic_thesis": (0.0225, 4416), "adrrs": (0.0349, 1376), "guiding": (0.035, 1344)}),
    "5.3 Cornell Box Dielectric": ("cornell_dielectric", 120, {
        "mitsuba": (0.449, 200), "pt": (0.0078, 11872), "nee": (0.0078, 5152), "mis": (0.0123, 3136),
        "ic_thesis": (0.0551, 992), "adrrs": (0.1549, 304), "guiding_pt": (0.0466, 976), "guiding": (0.0479, 860)}),
    "5.4 Clocks": ("clocks", 600, {
        "mitsuba": (28713, 2550), "pt": (347, 493312), "nee": (636, 196736), "guiding_pt": (1351, 16640)}),
}


def our_method(renderer):
    """bench.converge's renderer label -> the thesis' method key ('mitsuba', 'pt', ...)."""
    if renderer.startswith("Parallax "):
        return renderer.split(" ", 1)[1]
    if renderer.startswith("Mitsuba"):
        return "mitsuba"
    return None  # Cycles: no thesis column


def rate(spp, seconds, pixels=THESIS_PIXELS):
    """Samples per pixel per second at 1280x720 from spp over `seconds` at `pixels`."""
    return spp * pixels / THESIS_PIXELS / seconds if seconds else 0.0


def summary_rows(results, table):
    """Rows (method, thesis relMSE, thesis spp/s, ours relMSE, ours spp/s at 720p) of one table
    from a results.json dict; None where a side has no number."""
    scene, seconds, thesis = THESIS_TABLES[table]
    ours = {}
    for row in results.get("scenes", {}).get(scene, []):
        key = our_method(row["renderer"]) or row["renderer"]
        ours[key] = (row["rel_mse"], rate(row["spp"], row["seconds"], row["pixels"]))
    keys = list(thesis) + [k for k in ours if k not in thesis]
    return [(k, *((thesis[k][0], thesis[k][1] / seconds) if k in thesis else (None, None)),
             *ours.get(k, (None, None))) for k in keys]


def _fmt(x, digits=4):
    return "—" if x is None else f"{x:.{digits}g}"


def write_summary(out=os.path.join(RESULTS, "SUMMARY.md"), dirs=("gpu_thesis", "cpu_thesis"), results_dir=RESULTS):
    """SUMMARY.md from results_dir/<dir>/results.json; returns its path."""
    lines = ["# Parallax beside the thesis (Scholl 2020, chapter 5)", "",
             "Made by `python -m bench.thesis` from `python -m bench.converge --suite thesis` runs. "
             "The thesis: 1280x720, RTX 2080 Ti, 2 min (Clocks 10 min). Ours: each run's device, "
             "size and time are given per section; relMSE is Ruppert et al.'s (largest 0.1 % of "
             "pixels dropped) against each side's own reference, so relMSE compares methods within "
             "a column, not the two renderers' scenes (ours are the same class, not the same files, "
             "except Veach MIS). *spp/s* is samples per pixel per second at 1280x720.", ""]
    for d in dirs:
        path = os.path.join(results_dir, d, "results.json")
        if not os.path.exists(path):
            lines += [f"## {d}", "", f"No run yet (`{path}` is missing).", ""]
            continue
        with open(path) as f:
            results = json.load(f)
        lines += [f"## {results.get('device', d)} ({d}): {results.get('seconds', 0):g} s per renderer, "
                  f"{results.get('width')} px wide"
                  + (", pipelines compiled before the timed runs" if results.get("warm_pipelines") else ""), ""]
        for table in THESIS_TABLES:
            rows = summary_rows(results, table)
            if all(r[3] is None for r in rows):
                continue
            lines += [f"### Table {table} (ours: `{THESIS_TABLES[table][0]}`)", "",
                      "| method | thesis relMSE | thesis spp/s | ours relMSE | ours spp/s | spp/s ours ÷ thesis |",
                      "|---|---:|---:|---:|---:|---:|"]
            for key, t_err, t_rate, o_err, o_rate in rows:
                ratio = o_rate / t_rate if o_rate and t_rate else None
                lines.append(f"| {THESIS_METHOD_NAMES.get(key, key)} | {_fmt(t_err)} | {_fmt(t_rate, 3)} | "
                             f"{_fmt(o_err)} | {_fmt(o_rate, 3)} | {_fmt(ratio, 3)} |")
            lines.append("")
    with open(out, "w") as f:
        f.write("\n".join(lines))
    return out


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--out", default=os.path.join(RESULTS, "SUMMARY.md"))
    a = p.parse_args(argv)
    print(write_summary(a.out))
    return 0


if __name__ == "__main__":
    sys.exit(main())
