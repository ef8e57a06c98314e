"""Samples per second against samples per pixel per frame (the thesis' figure 5.2).

    .venv/bin/python -m bench.spp_per_frame [--scenes cornell_box,atrium] [--width 320]
        [--seconds 4] [--device auto] [--npz DIR] [--out bench/results/<device>]

One frame is one dispatch of `samples_per_frame` samples for every pixel: more per frame
amortises the per-dispatch cost and keeps the device busier, fewer updates the image more
often. For 1, 2, 4, 8, 16 and 32 spp per frame: pixel samples per second (wall), after a
warm-up frame. Writes spp_per_frame.md, .png and .json.
"""
import argparse
import json
import os
import sys
import time

from bench.converge import HERE, MAX_DEPTH, Progress, device_kind, load_scene

SPP = (1, 2, 4, 8, 16, 32)


def measure(scene, device, seconds, label):
    import parallax_core as pc

    session = pc.Session(scene.width, scene.height, device)
    session.set_params(method="mis", max_depth=MAX_DEPTH, depth_leeway=0)
    session.update(scene)
    bar = Progress(label, len(SPP))
    rates = {}
    for i, spp in enumerate(SPP):
        session.set_params(method="mis", max_depth=MAX_DEPTH, depth_leeway=0, samples_per_frame=spp)
        session.render(1)  # warm-up (and the compile, the first time)
        start, frames = time.perf_counter(), 0
        while time.perf_counter() - start < seconds or frames < 2:
            session.render(1)
            frames += 1
        rates[spp] = scene.width * scene.height * spp * frames / (time.perf_counter() - start)
        bar.update(i + 1, f"{spp} spp/frame")
    bar.close()
    return rates, session.device


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--scenes", default="cornell_box,atrium")
    p.add_argument("--width", type=int, default=320)
    p.add_argument("--seconds", type=float, default=4.0)
    p.add_argument("--device", default="auto")
    p.add_argument("--npz")
    p.add_argument("--out")
    a = p.parse_args(argv)
    results, device = {}, None
    for name in a.scenes.split(","):
        scene = load_scene(name, a.width, a.npz)
        results[name], device = measure(scene, a.device, a.seconds, f"{name}: spp per frame")
    kind, _ = device_kind(a.device)
    out = a.out or os.path.join(HERE, "results", kind)
    os.makedirs(out, exist_ok=True)
    lines = ["| spp per frame | " + " | ".join(f"{n} (M samples/s)" for n in results) + " |",
             "|---:|" + "---:|" * len(results)]
    for spp in SPP:
        lines.append(f"| {spp} | " + " | ".join(f"{r[spp] / 1e6:.2f}" for r in results.values()) + " |")
    table = "\n".join(lines) + "\n"
    print(table)
    with open(os.path.join(out, "spp_per_frame.md"), "w") as f:
        f.write(f"Device: {device}, width {a.width}, MIS, 8 bounces.\n\n" + table)
    with open(os.path.join(out, "spp_per_frame.json"), "w") as f:
        json.dump({"device": device, "width": a.width, "rates": results}, f, indent=1)
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(5, 3.5))
    for name, r in results.items():
        ax.plot(SPP, [r[s] / 1e6 for s in SPP], marker="o", label=name)
    ax.set_xscale("log", base=2)
    ax.set_xlabel("samples per pixel per frame")
    ax.set_ylabel("M samples / s")
    ax.set_title(f"{device}")
    ax.grid(True, alpha=0.3)
    ax.legend()
    fig.tight_layout()
    fig.savefig(os.path.join(out, "spp_per_frame.png"), dpi=110)
    return 0


if __name__ == "__main__":
    sys.exit(main())
