"""What OIDN costs (issue 36): seconds per denoise at 160x120 and 1280x720, with F12's and the
viewport's default settings, on the CPU device (or CUDA on a GPU machine with --device gpu).

    .venv/bin/python -m bench.denoise_cost [--sizes 160x120,1280x720] [--runs 3] [--device cpu]
        [--library bpy|pyoidn] [--json bench/results/denoise_cost.json]

The images are Combined, Denoising Albedo and Normal of a 4-spp cornell_box render at that
size (the content barely changes OIDN's time). "first" is the first call of a Denoiser (it
builds the filters: OIDN's weights and buffers for that size), "warm" the median of --runs
later calls on the same image, as F12 (one call) and the viewport (many) see them.
--library bpy imports bpy first, so Blender's OIDN 2.3.3 is used; else pyoidn's 2.5.1.
"""
import argparse
import json
import os
import statistics
import sys
import time

HERE = os.path.dirname(os.path.abspath(__file__))

MODES = {"F12 (RGB_ALBEDO_NORMAL, ACCURATE, HIGH)": ("RGB_ALBEDO_NORMAL", "ACCURATE", "HIGH"),
         "viewport (RGB_ALBEDO, FAST, BALANCED)": ("RGB_ALBEDO", "FAST", "BALANCED")}


def film(width, height, device):
    from parallax_core import Session, scenes

    session = Session(width, height, device)
    session.set_params(samples_per_frame=4)
    session.update(scenes.cornell_box(width, height))
    session.render(1)
    return {name: session.read(name) for name in ("combined", "albedo", "normal")}, session.device_type


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sizes", default="160x120,1280x720")
    parser.add_argument("--runs", type=int, default=3)
    parser.add_argument("--device", default="cpu", help="the render's device (its type picks OIDN's)")
    parser.add_argument("--library", choices=("bpy", "pyoidn"), default="pyoidn")
    parser.add_argument("--json", default=os.path.join(HERE, "results", "denoise_cost.json"))
    args = parser.parse_args(argv)
    if args.library == "bpy":
        import bpy  # noqa: F401  (Blender's OIDN comes first while bpy is loaded)
    from parallax_core import denoise

    rows = []
    for size in args.sizes.split(","):
        width, height = (int(v) for v in size.split("x"))
        images, device_type = film(width, height, args.device)
        for label, (inputs, prefilter, quality) in MODES.items():
            denoiser = denoise.Denoiser(device_type)
            times = []
            for _ in range(1 + args.runs):
                start = time.perf_counter()
                denoiser.denoise(images["combined"], images["albedo"], images["normal"], inputs, prefilter, quality)
                times.append(time.perf_counter() - start)
            rows.append({"size": size, "mode": label, "first_s": times[0], "warm_s": statistics.median(times[1:]),
                         "oidn": denoiser.version, "library": denoiser.source, "oidn_device": denoiser.device_kind,
                         "cpus": os.cpu_count()})
            denoiser.close()
            print(f"{size:>9s}  {label:40s} first {times[0]:6.2f} s  warm {rows[-1]['warm_s']:6.2f} s  "
                  f"(OIDN {denoiser.version} from {denoiser.source}, {denoiser.device_kind})", flush=True)
    os.makedirs(os.path.dirname(args.json), exist_ok=True)
    with open(args.json, "w") as f:
        json.dump(rows, f, indent=1)


if __name__ == "__main__":
    sys.exit(main())
