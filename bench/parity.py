"""Side-by-side Parallax | Cycles renders of the blender_scenes, with parity numbers.

    .venv/bin/python bench/parity.py [--size 256] [--samples 256] [--out bench/results/parity]
        [NAME ...]

Renders each scene with both engines (same .blend, same samples, Parallax with MIS and Cycles'
bounce counting) and writes NAME.png (Parallax left, Cycles right, Standard view: sRGB
clamp) plus a table: wall time of each render, image means, block relMSE (4x4 blocks) and
the share of pixels within 10%. Timings belong here, not in the tests.
"""
import argparse
import json
import os
import sys
import time

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
REPO = os.path.dirname(HERE)
SCENES = ("cornell_box", "veach_mis", "cornell_dielectric", "light_behind_glass", "atrium")


def render(bpy, cli, name, engine, size, samples, out_dir):
    path = os.path.join(REPO, "blender_scenes", name + ".blend")
    scene = cli.open_blend(path, engine, size)
    if engine == "PARALLAX":
        scene.parallax.samples, scene.parallax.samples_per_frame = samples, 8
        scene.parallax.max_depth, scene.parallax.depth_leeway = scene.cycles.max_bounces, 0
    else:
        scene.cycles.samples = samples
    start = time.perf_counter()
    cli._render(bpy, cli.engine_final())
    seconds = time.perf_counter() - start
    exr = os.path.join(out_dir, f"{name}_{engine.lower()}.exr")
    cli.set_exr_output(scene.render.image_settings)
    bpy.data.images["Render Result"].save_render(exr, scene=scene)
    import OpenEXR

    with OpenEXR.File(exr) as f:
        image = np.array(f.parts[0].channels["ViewLayer.Combined"].pixels)[..., :3]
    return image, seconds


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("names", nargs="*", default=list(SCENES))
    parser.add_argument("--size", type=int, default=256, help="image width (height keeps the aspect)")
    parser.add_argument("--samples", type=int, default=256)
    parser.add_argument("--out", default=os.path.join(HERE, "results", "parity"))
    args = parser.parse_args(argv)
    os.makedirs(args.out, exist_ok=True)

    import bpy
    from parallax_blender import cli
    from parallax_core.exr import write_png

    rows = []
    for name in args.names:
        ours, t_ours = render(bpy, cli, name, "PARALLAX", args.size, args.samples, args.out)
        theirs, t_theirs = render(bpy, cli, name, "CYCLES", args.size, args.samples, args.out)
        gap = np.ones((ours.shape[0], 4, 3), np.float32)
        write_png(os.path.join(args.out, f"{name}.png"), np.concatenate([ours, gap, theirs], axis=1))
        h, w = ours.shape[0] // 4 * 4, ours.shape[1] // 4 * 4
        a = ours[:h, :w].reshape(h // 4, 4, w // 4, 4, 3).mean((1, 3))
        b = theirs[:h, :w].reshape(h // 4, 4, w // 4, 4, 3).mean((1, 3))
        row = dict(scene=name, samples=args.samples, size=list(ours.shape[:2]),
                   parallax_seconds=round(t_ours, 2), cycles_seconds=round(t_theirs, 2),
                   parallax_mean=float(ours.mean()), cycles_mean=float(theirs.mean()),
                   block_rel_mse=float(((a - b) ** 2).sum() / (b ** 2).sum()),
                   within_10_percent=float((np.abs(a - b) <= 0.1 * b + 1e-3).mean()))
        rows.append(row)
        print(f"{name:20s} parallax {t_ours:6.1f} s  cycles {t_theirs:6.1f} s  mean "
              f"{row['parallax_mean']:.4f} / {row['cycles_mean']:.4f}  block relMSE "
              f"{row['block_rel_mse']:.5f}  blocks within 10%: {row['within_10_percent']:.0%}",
              flush=True)
    with open(os.path.join(args.out, "parity.json"), "w") as f:
        json.dump(rows, f, indent=1)


if __name__ == "__main__":
    sys.exit(main())
