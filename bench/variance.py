"""Variance per sample of Parallax (MIS) and Cycles on one blender_scenes .blend, without a
reference: RUNS independent renders of SAMPLES each per engine (seeds differ), the per-pixel
variance across them, relative to the mean squared (+0.01, as relMSE), averaged over the
image and multiplied by SAMPLES. Run with the bounces limited to 1 (direct light only) and
to the full depth, it tells whether a gap in equal-time relMSE is in the direct or the
indirect light, and it does not depend on render speed. `--rr 3,5,7` renders Parallax once per
Russian-roulette start bounce, with its rays per path (shadow rays included) as the cost.

    .venv/bin/python -m bench.variance [--scene cornell_box] [--width 160] [--samples 32]
        [--runs 6] [--depths 1,8] [--rr 3] [--no-cycles]
"""
import argparse

import numpy as np

from bench.converge import blend_path, export_scene, render_result_rgb


def cycles_image(name, width, samples, depth, seed):
    import bpy

    from parallax_blender import cli

    scene = cli.open_blend(blend_path(name), "CYCLES", width)
    c = scene.cycles
    c.samples, c.use_adaptive_sampling, c.seed, c.device, c.time_limit = samples, False, seed, "CPU", 0
    c.max_bounces = c.diffuse_bounces = c.glossy_bounces = c.transmission_bounces = depth
    c.use_denoising = False  # the variance of the estimator, not of a denoiser
    bpy.ops.render.render()
    return render_result_rgb(scene, name)


def parallax_image(scene, samples, depth, seed, rr_start_depth):
    """(image, rays per path) of one Parallax MIS render."""
    import parallax_core as pc

    session = pc.Session(scene.width, scene.height, "auto")
    session.set_params(method="mis", samples_per_frame=samples, max_depth=depth, depth_leeway=0, seed=seed,
                       ic=False, rrs="off", guiding=False, rr_start_depth=rr_start_depth)
    session.update(scene)
    session.render(1)
    rays = session.stats()["rays"] / (samples * scene.width * scene.height)
    return session.read("combined")[..., :3], rays


def relative_variance(images, samples):
    images = np.stack(images)
    mean, var = images.mean(0), images.var(0, ddof=1)
    return float((var / (mean ** 2 + 1e-2)).mean() * samples), float(mean.mean())


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--scene", default="cornell_box")
    p.add_argument("--width", type=int, default=160)
    p.add_argument("--samples", type=int, default=32)
    p.add_argument("--runs", type=int, default=6)
    p.add_argument("--depths", default="1,8", help="max bounces (both engines), comma-separated")
    p.add_argument("--rr", default="3", help="Parallax's rr_start_depth values, comma-separated")
    p.add_argument("--no-cycles", action="store_true")
    a = p.parse_args(argv)
    scene = export_scene(a.scene, a.width)
    print(f"{a.scene}, {a.width} px, {a.runs} renders of {a.samples} spp per engine\n")
    print("| bounces | engine | mean | relative variance x spp | rays per path |\n|---:|---|---:|---:|---:|")
    for depth in (int(d) for d in a.depths.split(",")):
        if not a.no_cycles:
            rel, mean = relative_variance([cycles_image(a.scene, a.width, a.samples, depth, 1000 + k)
                                           for k in range(a.runs)], a.samples)
            print(f"| {depth} | Cycles | {mean:.4f} | {rel:.4f} | |", flush=True)
        for rr in (int(r) for r in a.rr.split(",")):
            images, rays = zip(*(parallax_image(scene, a.samples, depth, 1000 + k, rr) for k in range(a.runs)))
            rel, mean = relative_variance(images, a.samples)
            print(f"| {depth} | Parallax MIS, roulette from bounce {rr} | {mean:.4f} | {rel:.4f} | "
                  f"{np.mean(rays):.2f} |", flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
