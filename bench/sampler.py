"""Per-sample noise of the path sampler: relMSE against the cached reference after a fixed
number of samples, for a few sample counts; the image mean over the reference's (a bias
shows there); samples per second.

    .venv/bin/python -m bench.sampler [--scenes cornell_box,veach_mis] [--width 160]
        [--spp 16,64,256] [--seeds 4] [--npz DIR] [--reference-seconds 120] [--device auto]

Run it with two builds of the core (PYTHONPATH) to compare samplers at equal samples: the
relMSE is the mean over --seeds renders, MIS, the scene's blender_scenes file exported as
bench.converge does, against bench.converge's reference (rendered there if missing).
"""
from __future__ import annotations

import argparse
import time

import numpy as np


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scenes", default="cornell_box,veach_mis")
    ap.add_argument("--width", type=int, default=160)
    ap.add_argument("--spp", default="16,64,256")
    ap.add_argument("--seeds", type=int, default=4)
    ap.add_argument("--npz", help="read DIR/NAME.npz (bench.converge --export-only) instead of exporting")
    ap.add_argument("--reference-seconds", type=float, default=120.0)
    ap.add_argument("--device", default="auto")
    args = ap.parse_args(argv)

    import parallax_core as pc
    from bench.converge import MAX_DEPTH, load_scene, reference_image, rel_mse

    for name in args.scenes.split(","):
        scene = load_scene(name, args.width, args.npz)
        reference = reference_image(name, scene, args.reference_seconds, args.device)
        s = pc.Session(scene.width, scene.height, args.device)
        s.update(scene)
        for spp in (int(x) for x in args.spp.split(",")):
            errors, ratios, seconds = [], [], 0.0
            for seed in range(args.seeds):
                s.set_params(method="mis", samples_per_frame=1, max_depth=MAX_DEPTH, depth_leeway=0, seed=seed + 1)
                s.reset()
                t = time.perf_counter()
                s.render(spp)
                seconds += time.perf_counter() - t
                image = s.read("combined")[..., :3]
                errors.append(rel_mse(image, reference))
                ratios.append(image.mean() / reference[..., :3].mean())
            print(f"{name} {spp:5d} spp: relMSE {np.mean(errors):.6f} (seeds {min(errors):.6f}..{max(errors):.6f}), "
                  f"mean ratio {np.mean(ratios):.4f}, {spp * args.seeds / seconds:.2f} spp/s", flush=True)


if __name__ == "__main__":
    main()
