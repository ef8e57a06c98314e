"""Side-by-side Parallax | Cycles renders of the blender_scenes and the Principled material
grid, with parity numbers and each engine's speed on this machine.

    .venv/bin/python bench/parity.py [--size 256] [--samples 256] [--out bench/results/parity]
        [NAME ...]          (NAME: a blender_scenes .blend, or principled_grid)

Renders each scene with both engines (same .blend, same samples, Parallax with MIS and Cycles'
bounce counting) and writes NAME.png (Parallax left, Cycles right, Standard view: sRGB
clamp), parity.json and parity.md: the wall time of each render, the mean ratio, block relMSE
(4x4 blocks; for the grid, the patches' means) and the share of blocks within 10%, and
samples per second. Samples per second are marginal, measured side by side in one run: each
engine first renders 1 sample (Parallax compiles its pipelines) and SAMPLES/8 samples, and
the rate is the extra samples over the extra time, so scene loading, BVH builds and
compiles (start-up, which a longer render pays once) drop out. Timings belong here, not in the tests.
"""
import argparse
import importlib.util
import json
import os
import sys
import time

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
REPO = os.path.dirname(HERE)
SCENES = ("cornell_box", "veach_mis", "cornell_dielectric", "light_behind_glass", "atrium", "principled_grid")
GRID_SCALE = 3  # the grid renders at 3x its 90x32 and is pooled back for its patch means


def _grid():
    spec = importlib.util.spec_from_file_location("principled_grid",
                                                  os.path.join(REPO, "blender_scenes", "principled_grid.py"))
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def open_scene(bpy, cli, name, engine, size):
    if name != "principled_grid":
        return cli.open_blend(os.path.join(REPO, "blender_scenes", name + ".blend"), engine, size)
    cli.open_blend(os.path.join(REPO, "blender_scenes", "cornell_box.blend"), engine)  # registers
    grid = _grid()
    scene = grid.build(bpy)
    scene.render.engine = engine
    scene.render.resolution_x, scene.render.resolution_y = grid.W * GRID_SCALE, grid.H * GRID_SCALE
    return scene


def render(bpy, cli, name, engine, size, samples, out_dir, tag=""):
    scene = open_scene(bpy, cli, name, engine, size)
    # Denoising and adaptive sampling off on both engines: parity compares the estimators, every
    # pixel with the same samples (both default to on).
    scene.cycles.use_denoising = scene.cycles.use_adaptive_sampling = False
    if engine == "PARALLAX":
        scene.parallax.use_denoising = scene.parallax.use_adaptive_sampling = False
        scene.parallax.samples, scene.parallax.samples_per_frame = samples, 8
        scene.parallax.max_depth, scene.parallax.depth_leeway = scene.cycles.max_bounces, 0
        scene.parallax.method = "mis"
    else:
        scene.cycles.samples = samples
    start = time.perf_counter()
    cli._render(bpy, cli.engine_final())
    seconds = time.perf_counter() - start
    exr = os.path.join(out_dir, f"{name}_{engine.lower()}{tag}.exr")
    cli.set_exr_output(scene.render.image_settings)
    bpy.data.images["Render Result"].save_render(exr, scene=scene)
    import OpenEXR

    with OpenEXR.File(exr) as f:
        image = np.array(f.parts[0].channels["ViewLayer.Combined"].pixels)[..., :3]
    return image, seconds


def blocks(image, name):
    """What is compared: the grid's patch means, else 4x4-pixel block means."""
    if name == "principled_grid":
        h, w = image.shape[0] // GRID_SCALE, image.shape[1] // GRID_SCALE
        pooled = image[:h * GRID_SCALE, :w * GRID_SCALE].reshape(h, GRID_SCALE, w, GRID_SCALE, 3).mean((1, 3))
        return _grid().patch_means(pooled)
    h, w = image.shape[0] // 4 * 4, image.shape[1] // 4 * 4
    return image[:h, :w].reshape(h // 4, 4, w // 4, 4, 3).mean((1, 3)).reshape(-1, 3)


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

    few = max(1, args.samples // 8)
    rows = []
    for name in args.names:
        timing = {}
        for engine in ("PARALLAX", "CYCLES"):
            render(bpy, cli, name, engine, args.size, 1, args.out, "_few")  # compiles the pipelines
            _, t_few = render(bpy, cli, name, engine, args.size, few, args.out, "_few")
            image, t_all = render(bpy, cli, name, engine, args.size, args.samples, args.out)
            timing[engine] = (image, t_all, (args.samples - few) / max(t_all - t_few, 1e-6))
        (ours, t_ours, rate_ours), (theirs, t_theirs, rate_theirs) = timing["PARALLAX"], timing["CYCLES"]
        gap = np.ones((ours.shape[0], 4, 3), np.float32)
        write_png(os.path.join(args.out, f"{name}.png"), np.concatenate([ours, gap, theirs], axis=1))
        a, b = blocks(ours, name), blocks(theirs, name)
        row = dict(scene=name, samples=args.samples, size=list(ours.shape[:2]),
                   parallax_seconds=round(t_ours, 2), cycles_seconds=round(t_theirs, 2),
                   parallax_samples_per_second=round(rate_ours, 2), cycles_samples_per_second=round(rate_theirs, 2),
                   parallax_mean=float(ours.mean()), cycles_mean=float(theirs.mean()),
                   mean_ratio=float(ours.mean() / theirs.mean()),
                   block_rel_mse=float(((a - b) ** 2).sum() / (b ** 2).sum()),
                   within_10_percent=float((np.abs(a - b) <= 0.1 * b + 1e-3).mean()))
        rows.append(row)
        print(f"{name:20s} mean ratio {row['mean_ratio']:.4f}  block relMSE {row['block_rel_mse']:.5f}  "
              f"within 10%: {row['within_10_percent']:.0%}  spp/s parallax {rate_ours:.1f} cycles "
              f"{rate_theirs:.1f} ({rate_ours / rate_theirs:.2f}x)", flush=True)
    with open(os.path.join(args.out, "parity.json"), "w") as f:
        json.dump(rows, f, indent=1)
    lines = [f"Parallax (MIS) vs Cycles, {args.samples} spp at {args.size} px wide (the grid at "
             f"{GRID_SCALE}x 90x32, its 21 patches compared), `python bench/parity.py`.", "",
             "| scene | mean ratio | block relMSE | blocks within 10% | Parallax spp/s | Cycles spp/s | ratio |",
             "|---|---:|---:|---:|---:|---:|---:|"]
    for r in rows:
        lines.append(f"| {r['scene']} | {r['mean_ratio']:.3f} | {r['block_rel_mse']:.2g} | "
                     f"{r['within_10_percent']:.0%} | {r['parallax_samples_per_second']:.1f} | "
                     f"{r['cycles_samples_per_second']:.1f} | "
                     f"{r['parallax_samples_per_second'] / r['cycles_samples_per_second']:.2f} |")
    with open(os.path.join(args.out, "parity.md"), "w") as f:
        f.write("\n".join(lines) + "\n")


if __name__ == "__main__":
    sys.exit(main())
