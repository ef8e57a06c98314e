"""Equal-time convergence: every Parallax method and the peers on the blender_scenes.

    .venv/bin/python -m bench.converge [--scenes cornell_box,veach_mis,...,sun_room] [--seconds 120]
        [--device auto] [--methods pt,nee,mis,ic] [--peers cycles,cycles_guiding,mitsuba]
        [--width 320] [--reference-seconds 1200] [--checkpoints 5,20,60] [--npz DIR]
        [--out bench/results/<device>]

The thesis' evaluation (Scholl 2020, ch. 5): each renderer gets the same wall-clock time,
start-up included, on the same scene, and its image is compared with a reference by the
relMSE of Ruppert et al. 2020: per pixel (x - r)^2 / (r^2 + 0.001) averaged over colour, the
largest 0.1% of pixels dropped, the rest averaged.

- Scenes come from blender_scenes/NAME.blend through the add-on's export (what an F12
  render uploads), at --width (height keeps the aspect); --npz DIR instead reads DIR/NAME.npz
  (the GPU machine has no Blender): `python -m bench.converge --export-only --npz DIR` writes
  them.
- Parallax methods render progressively; the error is recorded along the way (convergence
  plot). `ic` is MIS with the irradiance cache at its default settings (RenderParams'
  defaults); its prepare frames run inside its time. `guiding` (MIS + path guiding),
  `guiding_pt` (without NEE) and `guiding_noparallax` keep training while the image
  accumulates, the fits inside their time (see method_params). Cycles (CPU, through bpy; also with
  its Open PGL path guiding) renders the same .blend at the same size with a time limit,
  once per checkpoint. Mitsuba 3 renders the same SceneData (bench/mitsuba_peer.py),
  progressively.
- Time to a clean image (issue 36): the method `mis_clean` is Parallax with F12's defaults
  (every row of parallax_core.SETTINGS at its default: adaptive sampling and OIDN denoising on)
  and the peer `cycles_clean` is Cycles with its own F12 defaults (adaptive sampling, OIDN on
  the CPU), both with the path length pinned to MAX_DEPTH and no sample cap. They are judged at
  --checkpoints (seconds): mis_clean in one progressive run whose film is denoised at each
  (parallax_core.cli.denoise_film, as the CLI; the denoise is not charged to its clock, as
  Cycles' time limit leaves its denoise out), cycles_clean once per checkpoint with that time
  limit. Every other Parallax method applies parallax_core.UNBIASED_LIGHT_PATHS (no clamps, no
  per-kind bounce limits, a 1-px box filter) and renders undenoised. bench/clean_goal.py
  tables the clean rows (GOAL.md).
- The reference is a long Parallax render (MIS; PT where every light is behind glass;
  undenoised, unbiased light paths, its own seed), cached in bench/references/ (not
  committed) with a JSON note of how it was made, and reused.
- Besides relMSE every row has the mean HDR-FLIP (Andersson et al. 2021, the flip-evaluator
  package) of its final image: relMSE punishes a denoiser's blur less than the eye does.
- Output in --out: NAME.md (table), NAME_convergence.png, NAME_images.jpg (final images and
  the reference), results.json (raw numbers), raw/ (final images; the clean rows' at every
  checkpoint).
"""
from __future__ import annotations

import argparse
import json
import math
import os
import sys
import time

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
REPO = os.path.dirname(HERE)
SCENES = ("cornell_box", "veach_mis", "cornell_dielectric", "light_behind_glass", "atrium")
EXTRA_SCENES = ("sun_room", "clocks")  # sun_room: indirect light through a window (the irradiance
# cache's case); clocks: caustic light through a doorway (path guiding's case, issue 12)
# --suite thesis: the scenes of the thesis' chapter 5 our repository can hold (bench/thesis.py
# pairs them with its tables); thesis_* are converted from ../shared/scenes on first use.
THESIS_SUITE = ("atrium", "thesis_veach_mis", "cornell_dielectric", "clocks", "thesis_irradiance_cache")
# ic: MIS + the irradiance cache (its default mode, consistent); ic_thesis: the thesis' mode
# (paths end at the cache) at its refresh rate; ic_noupdate: the thesis' mode, no refreshes;
# adrrs: MIS + ADRRS; guiding: MIS + path guiding (defaults);
# guiding_pt: guiding without NEE; guiding_noparallax: guiding with parallax off; guiding_device:
# guiding fitted by compute passes on the device (guiding_fit = device); guiding_pt_device: both;
# guiding_auto: MIS + path guiding at every guiding default (the row issue 35's goal is judged on).
# mis_adaptive: MIS with adaptive sampling at its defaults (Cycles'; every other method: off).
# mis_clean: F12's defaults (adaptive sampling and denoising on), the path length pinned.
# ears_rr: MIS + EARS' roulette alone (adrrs_splitting off): what EARS' splits add.
METHODS = ("pt", "nee", "mis", "ic", "ic_thesis", "ic_noupdate", "adrrs", "ears", "ears_rr", "guiding", "guiding_pt",
           "guiding_noparallax", "guiding_device", "guiding_pt_device", "guiding_auto", "mis_adaptive", "mis_clean")
# cycles_clean: Cycles with its F12 defaults (adaptive sampling, OIDN), the path length pinned.
PEERS = ("cycles", "cycles_guiding", "cycles_clean", "mitsuba")
# Every method row of the thesis' tables 5.1-5.4.
THESIS_METHODS = ("pt", "nee", "mis", "ic_noupdate", "ic_thesis", "adrrs", "guiding_pt", "guiding", "guiding_device",
                  "guiding_pt_device")
MAX_DEPTH = 8  # Cycles' Max Bounces in every scene; Parallax with no discrete leeway
# The reference's method per scene (default mis): where every light is behind glass, NEE's
# shadow rays all fail, and plain path tracing converges fastest to the same image.
REFERENCE_METHOD = {"clocks": "pt", "light_behind_glass": "pt"}
QUICK = dict(width=64, seconds=3.0, reference_seconds=20.0)  # --quick: a smoke run, numbers not meant
REFERENCE_SEED = 7919  # the compared runs use seed 0 (--seed)
# The rows of the clean method and peer (bench/clean_goal.py reads them by these names).
CLEAN_ROWS = {"mis_clean": "Parallax mis_clean", "cycles_clean": "Cycles (F12 defaults)"}
NO_SAMPLE_CAP = 1 << 20  # Cycles' samples for the timed runs: time decides
# The Cycles settings blender_scenes/build.py (configure_render) pins to unbiased values, and
# those of adaptive sampling and denoising: cycles_clean puts each back to Cycles' default.
CYCLES_F12 = ("use_adaptive_sampling", "adaptive_threshold", "adaptive_min_samples", "use_denoising",
              "denoising_input_passes", "denoising_prefilter", "denoising_quality", "denoising_use_gpu",
              "seed", "use_animated_seed", "max_bounces", "diffuse_bounces", "glossy_bounces",
              "transmission_bounces", "transparent_max_bounces", "volume_bounces", "sample_clamp_direct",
              "sample_clamp_indirect", "blur_glossy", "caustics_reflective", "caustics_refractive",
              "pixel_filter_type", "filter_width", "device")


# ---- metric ------------------------------------------------------------------------------

def rel_mse(image, reference, drop=0.001):
    """Ruppert et al. 2020: mean over pixels of mean over colour of (x - r)^2 / (r^2 + 0.001),
    without the largest `drop` fraction of pixels."""
    x, r = np.asarray(image, np.float64)[..., :3], np.asarray(reference, np.float64)[..., :3]
    per_pixel = ((x - r) ** 2 / (r * r + 1e-3)).mean(axis=-1).ravel()
    per_pixel = np.where(np.isfinite(per_pixel), per_pixel, np.inf)
    keep = per_pixel.size - int(per_pixel.size * drop)
    return float(np.partition(per_pixel, keep - 1)[:keep].mean())


_flip_missing = []


def mean_flip(image, reference):
    """Mean HDR-FLIP (Andersson et al. 2021) of `image` against `reference` (linear RGB), from
    the flip-evaluator package; None (said once) where it is not installed. Non-finite and
    negative values count as 0 (FLIP takes non-negative radiance)."""
    try:
        import flip_evaluator
    except ImportError as e:
        if not _flip_missing:
            _flip_missing.append(e)
            print(f"bench.converge: no FLIP ({e}; pip install -r scripts/requirements.txt)", file=sys.stderr)
        return None

    def rgb(x):
        x = np.nan_to_num(np.asarray(x, np.float32)[..., :3], nan=0.0, posinf=0.0, neginf=0.0)
        return np.ascontiguousarray(np.maximum(x, 0.0))

    _, mean, _ = flip_evaluator.evaluate(rgb(reference), rgb(image), "HDR", applyMagma=False)
    return float(mean)


def checkpoints(seconds):
    """Times at which the error is recorded: doubling up to `seconds`."""
    t, out = seconds, []
    while t >= 0.5 and len(out) < 8:
        out.append(t)
        t /= 2
    return sorted(out)


def parse_checkpoints(text):
    """"5,20,60" -> (5.0, 20.0, 60.0): positive, finite, distinct, sorted; ValueError otherwise."""
    try:
        marks = [float(x) for x in text.split(",") if x.strip()]
    except ValueError:
        raise ValueError(f"--checkpoints {text!r}: expected seconds separated by commas, e.g. 5,20,60") from None
    if not marks or not all(math.isfinite(m) and m > 0 for m in marks) or len(set(marks)) != len(marks):
        raise ValueError(f"--checkpoints {text!r}: expected distinct positive seconds, e.g. 5,20,60")
    return tuple(sorted(marks))


def due_checkpoints(pending, elapsed, next_seconds, finished=False):
    """The leading checkpoints of `pending` (sorted) to take now, at `elapsed` seconds: those
    the next step (`next_seconds` long) would pass, as a run with a time limit stops before
    the frame that would overrun it; all of them when the run is `finished` (adaptive
    sampling: every pixel converged, the image will not change)."""
    if finished:
        return list(pending)
    return [m for m in pending if elapsed + next_seconds > m]


def frames_per_call(frames, seconds, target=0.2, most=64):
    """Frames for the next render() call, and how long it should take, given that `frames`
    took `seconds`: about `target` seconds, at most 4x the last (its call may have compiled
    a pipeline) and within 1..`most`."""
    per_frame = max(seconds, 1e-6) / frames
    n = int(max(1, min(most, 4 * frames, target / per_frame)))
    return n, n * per_frame


class Progress:
    """A one-line progress bar on stderr for a step of known length."""

    def __init__(self, label, total):
        self.label, self.total, self.start = label, total, time.perf_counter()

    def update(self, done, note=""):
        frac = min(1.0, done / self.total) if self.total else 1.0
        bar = "#" * int(30 * frac) + " " * (30 - int(30 * frac))
        sys.stderr.write(f"\r{self.label:34s} [{bar}] {time.perf_counter() - self.start:6.1f} s {note:24s}")
        sys.stderr.flush()

    def close(self, note=""):
        self.update(self.total, note)
        sys.stderr.write("\n")


# ---- scenes ------------------------------------------------------------------------------

def blend_path(name):
    """blender_scenes/NAME.blend; a thesis_* scene is converted from the shared folder into
    blender_scenes/generated/ the first time (blender_scenes/thesis_scenes.py, in its own
    process: it resets Blender's file)."""
    if not name.startswith("thesis_"):
        return os.path.join(REPO, "blender_scenes", name + ".blend")
    path = os.path.join(REPO, "blender_scenes", "generated", name + ".blend")
    if not os.path.exists(path):
        import subprocess

        script = os.path.join(REPO, "blender_scenes", "thesis_scenes.py")
        done = subprocess.run([sys.executable, script, name], capture_output=True, text=True)
        if not os.path.exists(path):
            raise FileNotFoundError(f"{name}: could not convert the shared scene ({path} missing):\n"
                                    + (done.stdout + done.stderr)[-2000:])
    return path


def export_scene(name, width):
    """SceneData of NAME.blend (blend_path) at `width`, exactly as F12 would upload it."""
    from parallax_blender import cli

    return cli.export(blend_path(name), width=width)[0]


def load_scene(name, width, npz_dir):
    if npz_dir:
        from parallax_core.scene import SceneData

        return SceneData.load(os.path.join(npz_dir, name + ".npz"))
    return export_scene(name, width)


# ---- renderers ---------------------------------------------------------------------------

def unbiased_light_paths():
    """The settings that make Parallax's estimator unbiased and its film a 1-px box
    (parallax_core.UNBIASED_LIGHT_PATHS; none in a core without Cycles' light-path settings):
    every method but mis_clean, and the reference, apply them."""
    import parallax_core as pc

    return dict(getattr(pc, "UNBIASED_LIGHT_PATHS", {}))


def clean_settings():
    """(RenderParams fields, engine settings) of mis_clean: F12's defaults, every row of
    parallax_core.SETTINGS at its default (adaptive sampling at 0.01, OIDN with albedo and
    normal, ACCURATE prefilter, HIGH quality), but the path length pinned as every method's
    (MAX_DEPTH bounces, no specular leeway: Cycles' Max Bounces, which the reference uses).
    The engine's `samples` is not used: time decides (no sample cap)."""
    import dataclasses

    import parallax_core as pc

    params = dict(dataclasses.asdict(pc.RenderParams()), max_depth=MAX_DEPTH, depth_leeway=0)
    # As F12 (0 would be Cycles' automatic threshold, from the sample target: there is none).
    params["adaptive_threshold"] = pc.adaptive_threshold(params["adaptive_threshold"], 0)
    engine = {s.name: s.default for s in pc.SETTINGS if not s.core}
    return params, engine


def method_params(method):
    """RenderParams of a --methods name: pt, nee, mis, ic (MIS + the irradiance cache with
    its default settings) or adrrs (MIS + ADRRS, whose cache and estimate are built in the
    measured time; the throughput roulette stays where ADRRS has no adjoint); mis_clean:
    clean_settings()' RenderParams. Every method but mis_clean with unbiased_light_paths()."""
    if method not in METHODS:
        raise ValueError(f"unknown method {method!r} (methods: {', '.join(METHODS)})")
    if method == "mis_clean":
        return clean_settings()[0]
    return {**_method_params(method), **unbiased_light_paths()}


def _method_params(method):
    off = dict(ic=False, rrs="off", guiding=False, guiding_parallax=True, guiding_training_spp=32,
               use_adaptive_sampling=False)
    if method == "mis_adaptive":
        import parallax_core as pc

        defaults = pc.RenderParams()
        return dict(off, method="mis", use_adaptive_sampling=True, adaptive_threshold=defaults.adaptive_threshold,
                    adaptive_min_samples=defaults.adaptive_min_samples)
    if method in ("adrrs", "ears"):  # MIS with the RRS method of that name
        return dict(off, method="mis", rrs=method)
    if method == "ears_rr":
        return dict(off, method="mis", rrs="ears", adrrs_splitting=False)
    if method == "guiding_auto":  # exactly guiding's defaults (training, fit, probability)
        return dict({k: v for k, v in off.items() if not k.startswith("guiding_")}, method="mis", guiding=True)
    if method.startswith("guiding"):
        # Keep training (guiding_training_spp 0): every frame accumulates into the image and
        # trains the field, whose fits run inside the measured time. Training frames first (the
        # default, 32) would spend most of a short lavapipe budget (10-60 s at 1-3 spp/s) on
        # frames that are thrown away.
        return dict(off, method="pt" if method.startswith("guiding_pt") else "mis", guiding=True,
                    guiding_parallax=method != "guiding_noparallax", guiding_training_spp=0,
                    guiding_fit="device" if method.endswith("_device") else "cpu")
    if method == "ic":
        return dict(off, method="mis", ic=True)
    if method in ("ic_thesis", "ic_noupdate"):  # the thesis' refresh rate (TECHNIQUES.md), or none
        return dict(off, method="mis", ic=True, ic_mode="thesis",
                    ic_update_prob=0.0 if method == "ic_noupdate" else 1e-5)
    return dict(off, method=method)


def render_parallax(scene, method, seconds, device, reference, label, seed=0):
    """Progressive Parallax render for `seconds` (start-up included); (image, spp, seconds,
    [(t, relMSE)], info). 1-spp frames (the first compiles) size the frames to ~0.2 s.

    For `ic` the sizing frames are rendered with the cache off (MIS, the same session): any
    set_params resets the cache, so sizing with it on would run the prepare frames twice.
    The cache is switched on with the sized samples per frame; its prepare frames then run
    once, inside the measured time, one per render_rows() call so that the clock is checked
    between them. `info` holds the session's stats at the end (the cache's entries, jobs,
    ...) and, for ic, when the prepare phase ended (or that it did not)."""
    import parallax_core as pc

    bar = Progress(label, seconds)
    start = time.perf_counter()
    session = pc.Session(scene.width, scene.height, device)
    # As F12: while a technique's pipelines compile (a cold start), frames render without it;
    # the film starts over with its first frame, so `spp` and the image are the technique's
    # own, and info reports the fallback's samples apart.
    session.background_compile = True
    # As F12 with a default view layer: the film holds Combined (and the Ray Depth the info
    # reports, ADRRS' splits; mis_clean: what its denoiser reads as well). A technique that
    # shows no pass of its own may leave the pipeline once it stops paying.
    if method != "mis_clean":
        session.passes = ["combined", "ray_depth"] + (["adrrs_splits"] if method in ("adrrs", "ears", "ears_rr") else [])
    params = dict(method_params(method), samples_per_frame=1, max_depth=MAX_DEPTH, depth_leeway=0, seed=seed)
    # Cache prepare, ADRRS estimate and guiding training frames first.
    prepares = params["ic"] or params["rrs"] != "off" or params["guiding"]
    sizing = dict(params, method="mis", ic=False, rrs="off", guiding=False) if prepares else params
    session.set_params(**sizing)
    session.update(scene)
    session.render(1)
    # The fastest of up to 3 frames (while they take under 0.1 s in all): one frame's hiccup on
    # a GPU sized a run's frames to 27 spp instead of 64, and guiding's per-frame training cost
    # then came 2.4x as often (its equal-time relMSE varied 1.5x from run to run).
    frame_times = []
    while len(frame_times) < 3 and sum(frame_times) < 0.1:
        frame_start = time.perf_counter()
        session.render(1)
        frame_times.append(time.perf_counter() - frame_start)
    per_frame = int(min(64, max(1, 0.2 / max(min(frame_times), 1e-4))))
    session.set_params(**{**params, "samples_per_frame": per_frame})  # restarts accumulation (and the cache)
    marks, curve, info = checkpoints(seconds), [], {"samples_per_frame": per_frame}

    def record(elapsed):
        if marks and elapsed >= marks[0] and reference is not None:
            curve.append((elapsed, rel_mse(session.read("combined"), reference)))
            while marks and elapsed >= marks[0]:
                marks.pop(0)

    stop = False
    if prepares:
        # The prepare frames one per render_rows(height) call, so that the clock is checked
        # between them (render() would run all of them at once); the call after the last one
        # renders the first frame. Out of time before that: no samples (a black image).
        while True:
            frame_start = time.perf_counter()
            done = session.render_rows(scene.height)
            now = time.perf_counter()
            elapsed = now - start
            bar.update(elapsed, f"{session.samples} spp" if done else "preparing")
            if done:
                info["prepare_done_at"] = round(elapsed - (now - frame_start), 3)
                record(elapsed)
                break
            if elapsed + (now - frame_start) > seconds:
                info["prepare_unfinished"] = True
                break
        stop = info.get("prepare_unfinished") or elapsed + (now - frame_start) > seconds
    while not stop:
        frame_start = time.perf_counter()
        session.render(1)
        now = time.perf_counter()
        elapsed = now - start
        record(elapsed)
        bar.update(elapsed, f"{session.samples} spp")
        stop = elapsed + (now - frame_start) > seconds
    image = session.read("combined")[..., :3]
    stats = session.stats()
    spp = 0 if stats["fallback_film"] else stats["samples"]  # the technique's own samples
    info.update(fallback_samples=stats["fallback_samples"], fallback_film=stats["fallback_film"])
    used = time.perf_counter() - start
    bar.close(f"{spp} spp")
    if reference is not None and (not curve or curve[-1][0] < used - 1e-3):
        curve.append((used, rel_mse(image, reference)))
    info.update({k: (round(v, 3) if isinstance(v, float) else v) for k, v in stats.items()
                 if k.startswith(("ic_", "adrrs_", "ears_", "guiding_")) or k in ("frames", "rays")} if prepares else {})
    if params["rrs"] != "off":
        info["adrrs_splits_per_sample"] = round(float(session.read("adrrs_splits").mean()), 4)
    info["ray_depth"] = round(float(session.read("ray_depth").mean()), 3)
    return image, spp, used, curve, info


def render_parallax_clean(scene, marks, device, reference, label, seed=0):
    """mis_clean: one progressive Parallax render with F12's defaults (clean_settings), its
    film denoised at each checkpoint of `marks` (seconds) as the CLI denoises
    (parallax_core.cli.denoise_film). The clock includes start-up and leaves out the
    denoising and scoring at the checkpoints (Cycles' time limit leaves its denoise out).
    A checkpoint is taken before the render() call that would pass it (after the first frame
    at the earliest: F12 always gives a whole image), or as soon as every pixel converged.
    Returns (image, spp, seconds, curve, info, points): the last denoised image, and per
    checkpoint {checkpoint, seconds, spp, rel_mse, flip, noisy_rel_mse, denoise_seconds,
    fallback_film, image}."""
    import parallax_core as pc
    from parallax_core.cli import denoise_film

    if not marks:
        raise ValueError("mis_clean: no checkpoints")
    params, engine = clean_settings()
    settings = {**params, **engine}
    if not settings["use_denoising"]:
        raise ValueError("mis_clean: use_denoising is off by default; F12's defaults denoise")
    pending = sorted(marks)
    bar = Progress(label, pending[-1])
    start = time.perf_counter()
    paused = 0.0  # seconds spent denoising and scoring: not on the clock
    session = pc.Session(scene.width, scene.height, device)
    session.background_compile = True  # as F12
    session.set_params(**dict(params, seed=seed))
    session.update(scene)
    # As F12: the film holds the passes read (Combined and the denoiser's inputs) only.
    session.passes = sorted({"combined", *pc.denoise.film_passes(settings)})
    session.render(1)  # compiles the pipelines (inside the time, as every method's)
    frame_start = time.perf_counter()
    session.render(1)
    frames, next_seconds = frames_per_call(1, time.perf_counter() - frame_start)
    points = []
    while pending:
        elapsed = time.perf_counter() - start - paused
        due = due_checkpoints(pending, elapsed, next_seconds, session.converged)
        if due:
            pause = time.perf_counter()
            stats = session.stats()
            out, line = denoise_film(session, settings)
            denoise_seconds = time.perf_counter() - pause
            if "combined" not in out:  # denoise_film kept the noisy image: not a clean row
                raise RuntimeError(f"mis_clean: {line}")
            image = out["combined"][..., :3]
            point = dict(seconds=round(elapsed, 3), spp=int(stats["samples"]),
                         denoise_seconds=round(denoise_seconds, 3), fallback_film=bool(stats["fallback_film"]),
                         image=image)
            if reference is not None:
                point.update(rel_mse=rel_mse(image, reference), flip=mean_flip(image, reference),
                             noisy_rel_mse=rel_mse(out["noisy_image"], reference))
            points += [dict(point, checkpoint=m) for m in due]
            pending = pending[len(due):]
            paused += time.perf_counter() - pause
            bar.update(elapsed, f"{point['spp']} spp, denoised")
            continue
        frame_start = time.perf_counter()
        session.render(frames)
        frames, next_seconds = frames_per_call(frames, time.perf_counter() - frame_start)
        bar.update(time.perf_counter() - start - paused, f"{session.samples} spp")
    last = points[-1]
    bar.close(f"{last['spp']} spp")
    curve = [(p["seconds"], p["rel_mse"]) for p in points if "rel_mse" in p]
    info = {"converged": bool(session.converged), "denoiser": line}
    return last["image"], last["spp"], last["seconds"], curve, info, points


def cycles_clean_settings(scene):
    """Cycles' F12 defaults on a scene of blender_scenes (which pins Cycles unbiased):
    every setting of CYCLES_F12 back to its default as bpy's RNA gives it (adaptive sampling
    at 0.01, OIDN on the CPU with albedo and normal, clamps, per-kind bounces, Blackman-Harris
    1.5 px, ...), the view layers' denoising too, OIDN as the denoiser; but Max Bounces
    pinned to MAX_DEPTH and no sample cap (time decides)."""
    cycles = scene.cycles
    props = cycles.bl_rna.properties
    for name in CYCLES_F12:
        setattr(cycles, name, props[name].default)
    # Cycles' default denoiser is OIDN (its property's default is the enum value 4, which
    # bl_rna cannot name: the items are made at run time, by the devices found).
    cycles.denoiser = "OPENIMAGEDENOISE"
    for layer in scene.view_layers:
        layer.cycles.use_denoising = layer.cycles.bl_rna.properties["use_denoising"].default
    cycles.max_bounces = MAX_DEPTH
    cycles.samples = NO_SAMPLE_CAP


def cycles_denoise_seconds(timed_stats):
    """Seconds Cycles spent denoising, from its status lines [(time, text)]: from the last
    line with samples rendered ("Sample 39/1048576") to "Finished" (Cycles shows nothing else
    meanwhile; without denoising the two come together). None if either is missing."""
    sampled = [t for t, text in timed_stats if _last_sample_count([text]) > 0]
    finished = [t for t, text in timed_stats if "Finished" in text]
    if not sampled or not finished:
        return None
    return max(0.0, finished[-1] - sampled[-1])


def render_cycles(name, width, seconds, guiding, reference, label, clean=False, marks=None):
    """Cycles (CPU) on the same .blend at the same size, time-limited, once per checkpoint:
    `marks` (seconds; default: the doubling checkpoints from seconds / 4 to `seconds`).
    `clean`: with Cycles' F12 defaults (cycles_clean_settings), denoised; otherwise pinned
    unbiased, as the .blend has it, and undenoised. Returns (image, spp, seconds, curve,
    points): per checkpoint {checkpoint, seconds (the render's wall time, scene sync and
    denoise included), spp, rel_mse, flip, denoise_seconds, image}."""
    import bpy

    from parallax_blender import cli

    stats = []

    def on_stats(text, *args):  # render_stats handler: Cycles' status line
        if isinstance(text, str):
            stats.append((time.perf_counter(), text))

    curve, points, image, spp, used = [], [], None, 0, 0.0
    marks = sorted(marks) if marks else [t for t in checkpoints(seconds) if t >= seconds / 4]
    bar = Progress(label, sum(marks))
    done = 0.0
    for limit in marks:
        scene = cli.open_blend(blend_path(name), "CYCLES", width)
        cycles = scene.cycles
        if clean:
            cycles_clean_settings(scene)
        else:
            cycles.samples, cycles.use_adaptive_sampling = NO_SAMPLE_CAP, False
            cycles.device = "CPU"
            cycles.use_denoising = False  # pinned, as the Parallax methods' sessions
        cycles.time_limit = limit
        cycles.use_guiding = guiding
        if guiding:
            cycles.use_surface_guiding = cycles.use_volume_guiding = True
        stats.clear()
        bpy.app.handlers.render_stats.append(on_stats)
        start = time.perf_counter()
        try:
            bpy.ops.render.render()
        finally:
            bpy.app.handlers.render_stats.remove(on_stats)
        used = time.perf_counter() - start
        image = render_result_rgb(scene, name)
        spp = _last_sample_count([text for _, text in stats])
        point = dict(checkpoint=limit, seconds=round(used, 3), spp=spp, image=image,
                     denoise_seconds=cycles_denoise_seconds(stats) if clean else None)
        if reference is not None:
            curve.append((used, rel_mse(image, reference)))
            point.update(rel_mse=curve[-1][1], flip=mean_flip(image, reference) if clean else None)
        points.append(point)
        done += limit
        bar.update(done, f"{spp} spp")
    bar.close(f"{spp} spp")
    return image, spp, used, curve, points


def render_result_rgb(scene, name):
    """Blender's Render Result (the combined pass, RGB), read back through a temporary EXR."""
    import bpy
    import OpenEXR

    from parallax_blender import cli

    path = os.path.join(os.environ.get("TMPDIR", "/tmp"), f"parallax_bench_{name}.exr")
    cli.set_exr_output(scene.render.image_settings)
    bpy.data.images["Render Result"].save_render(path, scene=scene)
    with OpenEXR.File(path) as f:
        image = np.array(f.parts[0].channels["ViewLayer.Combined"].pixels)[..., :3]
    os.remove(path)
    return image


def _last_sample_count(stats):
    """The most samples Cycles' status lines reported ("Sample 257/1048576")."""
    counts = [int(part.split()[1].split("/")[0]) for text in stats for part in
              (p.strip() for p in text.split("|")) if part.startswith("Sample ")]
    return max(counts, default=0)


def render_mitsuba(scene, seconds, variant, reference, label):
    from bench import mitsuba_peer

    bar = Progress(label, seconds)
    curve = []

    def progress(image, spp, elapsed):
        if reference is not None:
            curve.append((elapsed, rel_mse(image, reference)))
        bar.update(elapsed, f"{spp} spp")

    image, spp, used = mitsuba_peer.render_for(scene, seconds, variant, max_depth=MAX_DEPTH, progress=progress)
    bar.close(f"{spp} spp")
    return image, spp, used, curve


def warm_pipelines(scene, methods, device):
    """Compiles the pipelines every method needs on this scene (they are shared process-wide,
    keyed by method, the scene's features and the techniques), so that no timed run pays for a
    compile another run (or the reference) already paid for."""
    import parallax_core as pc

    session = pc.Session(scene.width, scene.height, device)
    session.update(scene)
    for method in methods:
        session.set_params(**{**method_params(method), "max_depth": MAX_DEPTH, "depth_leeway": 0,
                              "ic_prepare_frames": 1})
        session.render(1)  # with ic: one prepare frame (camera + hemisphere + finish pipelines) and a frame
        session.warm()  # and the pipeline without techniques (guiding leaves for it where it does not pay)
        pc.wait_for_background_compiles()


def spin_up(scene, device, seconds=0.5):
    """Keeps the device busy for `seconds` before a timed run: a GPU left idle (a pipeline
    compile, writing results) drops its clocks (the H200 to 345-600 MHz within a second), and
    the run after it sized its frames on the slow clock (23 spp per frame instead of 64)."""
    import parallax_core as pc

    session = pc.Session(scene.width, scene.height, device)
    session.set_params(**{**unbiased_light_paths(), "method": "pt", "samples_per_frame": 1, "max_depth": MAX_DEPTH,
                          "depth_leeway": 0})
    session.update(scene)
    start = time.perf_counter()
    while time.perf_counter() - start < seconds:
        session.render(1)


def core_identity():
    """Which parallax_core build is loaded: the native module's file, size, mtime and SHA-1
    prefix (read from disk: call it right after the import)."""
    import glob
    import hashlib

    import parallax_core as pc

    so = sorted(glob.glob(os.path.join(os.path.dirname(pc.__file__), "_native*")))
    if not so:
        return {}
    with open(so[0], "rb") as f:
        digest = hashlib.sha1(f.read()).hexdigest()[:12]
    st = os.stat(so[0])
    return {"native": os.path.basename(so[0]), "sha1": digest, "bytes": st.st_size,
            "mtime": time.strftime("%Y-%m-%d %H:%M:%S", time.gmtime(st.st_mtime))}


# ---- reference ---------------------------------------------------------------------------

def reference_image(name, scene, seconds, device, folder=os.path.join(HERE, "references")):
    """The cached reference of `name` at the scene's size, rendering it if missing."""
    os.makedirs(folder, exist_ok=True)
    stem = os.path.join(folder, f"{name}_{scene.width}x{scene.height}")
    method = REFERENCE_METHOD.get(name, "mis")
    if os.path.exists(stem + ".npy"):
        made = {}
        if os.path.exists(stem + ".json"):
            with open(stem + ".json") as f:
                made = json.load(f)
        if made.get("method", "mis") == method:
            return np.load(stem + ".npy")
    # Its own seed: a reference sharing random numbers with the runs it judges would flatter them.
    image, spp, used, _, _ = render_parallax(scene, method, seconds, device, None, f"{name}: reference",
                                             seed=REFERENCE_SEED)
    np.save(stem + ".npy", image.astype(np.float32))
    with open(stem + ".json", "w") as f:
        json.dump({"renderer": "parallax", "method": method, "spp": spp, "seconds": round(used, 1),
                   "device": device, "max_depth": MAX_DEPTH, "seed": REFERENCE_SEED,
                   "light_paths": unbiased_light_paths(), "denoised": False,
                   "made_by": " ".join(sys.argv)}, f, indent=1)
    return image


# ---- output ------------------------------------------------------------------------------

def write_outputs(out, name, rows, reference):
    lines = [f"### {name}", "", "| renderer | relMSE | FLIP | spp | time (s) |", "|---|---:|---:|---:|---:|"]
    for row in sorted(rows, key=lambda r: r["rel_mse"]):
        lines.append(f"| {row['renderer']} | {row['rel_mse']:.4g} | {_fmt(row.get('flip'))} | {row['spp']} | "
                     f"{row['seconds']:.1f} |")
    clean = [r for r in rows if r.get("checkpoints")]
    if clean:  # time to a clean image: each clean row at each checkpoint
        lines += ["", "| renderer | checkpoint (s) | relMSE | FLIP | spp | time (s) | denoise (s) |",
                  "|---|---:|---:|---:|---:|---:|---:|"]
        for row in clean:
            for p in row["checkpoints"]:
                lines.append(f"| {row['renderer']} | {p['checkpoint']:g} | {_fmt(p.get('rel_mse'))} | "
                             f"{_fmt(p.get('flip'))} | {p['spp']} | {p['seconds']:.1f} | "
                             f"{_fmt(p.get('denoise_seconds'), '.2f')} |")
    # The thesis' layout (tables 5.1-5.4): a column per renderer, in the order they ran.
    lines += ["", "| | " + " | ".join(r["renderer"] for r in rows) + " |", "|---" * (len(rows) + 1) + "|",
              "| relMSE | " + " | ".join(f"{r['rel_mse']:.4g}" for r in rows) + " |",
              "| SPP | " + " | ".join(str(r["spp"]) for r in rows) + " |",
              "| time | " + " | ".join(f"{r['seconds']:.0f} s" for r in rows) + " |"]
    for row in rows:
        ic = row.get("ic")
        if ic:
            lines += ["", f"{row['renderer']}: {ic.get('ic_entries', 0)} cache entries "
                      f"({ic.get('ic_merged', 0)} requests merged, {ic.get('ic_dropped', 0)} dropped, "
                      f"{ic.get('ic_deferred', 0)} deferred), "
                      f"{ic.get('ic_jobs', 0)} hemisphere jobs in {ic.get('ic_job_milliseconds', 0) / 1e3:.2f} s, "
                      f"lookup-grid builds {ic.get('ic_build_milliseconds', 0) / 1e3:.2f} s; prepare phase "
                      + ("unfinished in the time" if ic.get("prepare_unfinished") else
                         f"done at {ic.get('prepare_done_at', 0):.1f} s") + ", "
                      f"{ic.get('samples_per_frame', 0)} spp per frame"]
        info = row.get("info") or {}
        if "ray_depth" in info:
            lines += ["", f"{row['renderer']}: mean path length {info['ray_depth']} segments"
                      + (f", {info['adrrs_splits_per_sample']} ADRRS splits per pixel sample"
                         if "adrrs_splits_per_sample" in info else "")]
    with open(os.path.join(out, f"{name}.md"), "w") as f:
        f.write("\n".join(lines) + "\n")

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from parallax_core.exr import srgb_encode

    fig, ax = plt.subplots(figsize=(6, 4))
    for row in rows:
        if row["curve"]:
            t, e = zip(*row["curve"])
            ax.loglog(t, e, marker="o", ms=3, label=row["renderer"])
    ax.set_xlabel("time (s, start-up included)")
    ax.set_ylabel("relMSE")
    ax.set_title(name)
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(os.path.join(out, f"{name}_convergence.png"), dpi=110)
    plt.close(fig)

    images = [("reference", reference)] + [(r["renderer"], r["image"]) for r in rows]
    cols = min(4, len(images))
    rows_n = math.ceil(len(images) / cols)
    h, w = reference.shape[:2]
    fig, axes = plt.subplots(rows_n, cols, figsize=(3 * cols, 3 * rows_n * h / w + 0.3))
    for ax in np.atleast_1d(axes).ravel():
        ax.axis("off")
    for ax, (label, image) in zip(np.atleast_1d(axes).ravel(), images):
        ax.imshow(srgb_encode(image))
        ax.set_title(label, fontsize=9)
    fig.tight_layout()
    fig.savefig(os.path.join(out, f"{name}_images.jpg"), dpi=110, pil_kwargs={"quality": 90})  # JPEG: a fifth of the PNG
    plt.close(fig)


def _fmt(value, spec=".4g"):
    return "n/a" if value is None else format(value, spec)


def device_kind(device):
    """("cpu" or "gpu", device name) of the device a session on `device` gets."""
    import parallax_core as pc

    probe = pc.Session(8, 8, device)
    return ("gpu" if probe.device_type in ("discrete", "integrated") else "cpu"), probe.device


def _slug(label):
    return "".join(c if c.isalnum() else "_" for c in label.lower())


def run(scenes=SCENES, seconds=120.0, device="auto", methods=("pt", "nee", "mis"),
        peers=("cycles", "cycles_guiding", "mitsuba"), width=320, reference_seconds=None,
        npz_dir=None, out=None, reference_dir=os.path.join(HERE, "references"), append=False, warm=False,
        clean_checkpoints=None, seed=0):
    """Runs the comparison (Parallax's runs with `seed`; the issue's goals take the median of
    three); returns {scene: [row, ...]} (rows without images). With `append`,
    rows of renderers not run now are kept from the earlier results.json in `out` (their
    images from out/raw/, their final relMSE against the reference of this run: `--methods ,
    --peers "" --append` rescores a run against a new reference). `clean_checkpoints`: the
    seconds at which mis_clean and cycles_clean are judged (default: `seconds` alone); their
    rows hold them as `checkpoints`."""
    for peer in peers:
        if peer not in PEERS:
            raise ValueError(f"unknown peer {peer!r} (peers: {', '.join(PEERS)})")
    clean_marks = tuple(sorted(clean_checkpoints)) if clean_checkpoints else (seconds,)
    kind, device_name = device_kind(device)
    core = core_identity()  # now: the module file may be rebuilt while this runs
    out = out or os.path.join(HERE, "results", kind)
    os.makedirs(out, exist_ok=True)
    variant = None
    if "mitsuba" in peers:
        from bench import mitsuba_peer

        variant = mitsuba_peer.mitsuba_available("cuda_ad_rgb" if kind == "gpu" else "llvm_ad_rgb")
        if variant is None:
            print("bench.converge: Mitsuba 3 is not available; skipping it", file=sys.stderr)
    results = {}
    previous = {}
    if append and os.path.exists(os.path.join(out, "results.json")):
        with open(os.path.join(out, "results.json")) as f:
            previous = json.load(f)["scenes"]
        results = {k: v for k, v in previous.items() if k not in scenes}
    raw = os.path.join(out, "raw")
    os.makedirs(raw, exist_ok=True)
    for name in scenes:
        scene = load_scene(name, width, npz_dir)
        if npz_dir:
            width = scene.width  # exported scenes keep their own size (recorded in results.json)
        reference = reference_image(name, scene, reference_seconds or 10 * seconds, device, reference_dir)
        rows = []
        if warm:
            warm_pipelines(scene, methods, device)
        for method in methods:
            if warm:
                spin_up(scene, device)
            label = f"{name}: parallax {method}"
            if method == "mis_clean":
                image, spp, used, curve, info, points = render_parallax_clean(scene, clean_marks, device, reference,
                                                                              label)
                rows.append(dict(renderer=CLEAN_ROWS["mis_clean"], image=image, spp=spp, seconds=used, curve=curve,
                                 info=info, checkpoints=points))
                continue
            image, spp, used, curve, info = render_parallax(scene, method, seconds, device, reference, label, seed=seed)
            rows.append(dict(renderer=f"Parallax {method}", image=image, spp=spp, seconds=used, curve=curve,
                             **({"ic": info} if method.startswith("ic") or method == "adrrs" else {}), info=info))
        for peer in peers:
            points = None
            if peer.startswith("cycles"):
                if npz_dir:
                    continue  # no Blender here
                guiding, clean = peer == "cycles_guiding", peer == "cycles_clean"
                image, spp, used, curve, points = render_cycles(
                    name, scene.width, seconds, guiding, reference, f"{name}: {peer}", clean=clean,
                    marks=clean_marks if clean else None)
                label = CLEAN_ROWS[peer] if clean else "Cycles (path guiding)" if guiding else "Cycles"
                points = points if clean else None
            elif peer == "mitsuba" and variant:
                image, spp, used, curve = render_mitsuba(scene, seconds, variant, reference, f"{name}: mitsuba")
                label = f"Mitsuba 3 ({variant})"
            else:
                continue
            rows.append(dict(renderer=label, image=image, spp=spp, seconds=used, curve=curve,
                             **({"checkpoints": points} if points else {})))
        for row in rows:
            row["pixels"] = scene.width * scene.height
            row["rel_mse"] = rel_mse(row["image"], reference)
            row["flip"] = mean_flip(row["image"], reference)
            np.save(os.path.join(raw, f"{name}__{_slug(row['renderer'])}.npy"), row["image"].astype(np.float32))
            for point in row.get("checkpoints", ()):  # every checkpoint's image, then only its numbers
                np.save(os.path.join(raw, f"{name}__{_slug(row['renderer'])}__{point['checkpoint']:g}s.npy"),
                        point.pop("image").astype(np.float32))
        run_now = {r["renderer"] for r in rows}
        for old in previous.get(name, []):
            image_file = os.path.join(raw, f"{name}__{_slug(old['renderer'])}.npy")
            if old["renderer"] not in run_now and os.path.exists(image_file):
                image = np.load(image_file)  # scored against today's reference (its curve is as recorded)
                rows.append({**old, "image": image, "rel_mse": rel_mse(image, reference),
                             "flip": mean_flip(image, reference)})
        write_outputs(out, name, rows, reference)
        results[name] = [{k: v for k, v in r.items() if k != "image"} for r in rows]
        with open(os.path.join(out, "results.json"), "w") as f:
            json.dump({"device": device_name, "kind": kind, "seconds": seconds, "width": width,
                       "clean_checkpoints": list(clean_marks),
                       "warm_pipelines": warm, "core": core, "scenes": results}, f, indent=1)
    return results


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--suite", choices=("blender", "thesis"), default="blender",
                   help="blender: our blender_scenes, pt/nee/mis; thesis: the thesis' chapter 5 "
                        "(THESIS_SUITE, every method of its tables, bench/results/SUMMARY.md)")
    p.add_argument("--quick", action="store_true",
                   help=f"smoke run: {QUICK['width']} px wide, {QUICK['seconds']:g} s per renderer, "
                        "Cycles the only peer")
    p.add_argument("--scenes", help="default: the suite's")
    p.add_argument("--seconds", type=float, help="default: 120, or the last of --checkpoints")
    p.add_argument("--device", default="auto")
    p.add_argument("--methods", help="default: pt,nee,mis (thesis: every method of its tables)")
    p.add_argument("--peers", default="cycles,cycles_guiding,mitsuba")
    p.add_argument("--width", type=int, default=320)
    p.add_argument("--reference-seconds", type=float, help="default: 10 x --seconds")
    p.add_argument("--checkpoints", help="seconds at which mis_clean and cycles_clean are judged, e.g. 5,20,60 "
                                         "(default: --seconds)")
    p.add_argument("--npz", help="read (or with --export-only write) DIR/NAME.npz scenes")
    p.add_argument("--export-only", action="store_true")
    p.add_argument("--append", action="store_true", help="keep earlier rows of renderers not run now")
    p.add_argument("--out", help="default: bench/results/<cpu|gpu>[_thesis][_quick]")
    p.add_argument("--seed", type=int, default=0, help="Parallax's seed (not the reference's, 7919)")
    p.add_argument("--warm", action="store_true",
                   help="compile every method's pipelines before the timed runs (start-up then excludes compiling), "
                        "and keep the device busy for 0.5 s before each (a GPU's clocks drop when it idles)")
    a = p.parse_args(argv)
    try:
        marks = parse_checkpoints(a.checkpoints) if a.checkpoints else None
    except ValueError as e:
        p.error(str(e))
    if a.seconds is None:
        a.seconds = marks[-1] if marks else 120.0
    thesis = a.suite == "thesis"
    if a.quick:
        a.width, a.seconds, a.peers = QUICK["width"], QUICK["seconds"], "cycles"
        a.reference_seconds = a.reference_seconds or QUICK["reference_seconds"]
    scenes = [s for s in (a.scenes or ",".join(THESIS_SUITE if thesis else SCENES)).split(",") if s]
    methods = [m for m in (a.methods or ",".join(THESIS_METHODS if thesis else ("pt", "nee", "mis"))).split(",") if m]
    for m in methods:
        if m not in METHODS:
            p.error(f"unknown method {m!r} (methods: {', '.join(METHODS)})")
    for peer in [x for x in a.peers.split(",") if x]:
        if peer not in PEERS:
            p.error(f"unknown peer {peer!r} (peers: {', '.join(PEERS)})")
    known = SCENES + EXTRA_SCENES + THESIS_SUITE
    for name in scenes:
        if name not in known:
            p.error(f"unknown scene {name!r} (scenes: {', '.join(dict.fromkeys(known))})")
    if thesis and not a.npz:
        from bench import shared_scenes

        missing = [n for n in scenes if n in shared_scenes.THESIS_SCENES
                   and not shared_scenes.available(shared_scenes.THESIS_SCENES[n][0])]
        for name in missing:
            print(f"bench.converge: {name} skipped: its shared scene is not in {shared_scenes.SHARED_SCENES}",
                  file=sys.stderr)
        scenes = [n for n in scenes if n not in missing]
    if a.export_only:
        os.makedirs(a.npz, exist_ok=True)
        for name in scenes:
            export_scene(name, a.width).save(os.path.join(a.npz, name + ".npz"))
            print(f"{name} -> {os.path.join(a.npz, name + '.npz')}")
        return 0
    out = a.out
    if out is None and (thesis or a.quick):
        kind = device_kind(a.device)[0]
        out = os.path.join(HERE, "results", kind + ("_thesis" if thesis else "") + ("_quick" if a.quick else ""))
    results = run(scenes, a.seconds, a.device, methods, [x for x in a.peers.split(",") if x],
                  a.width, a.reference_seconds, a.npz, out, append=a.append, warm=a.warm, clean_checkpoints=marks,
                  seed=a.seed)
    for name, rows in results.items():
        print(f"\n{name}")
        for row in sorted(rows, key=lambda r: r["rel_mse"]):
            print(f"  {row['renderer']:28s} relMSE {row['rel_mse']:.4g}  FLIP {_fmt(row.get('flip'))}  "
                  f"{row['spp']:6d} spp  {row['seconds']:.1f} s")
            for point in row.get("checkpoints", ()):
                print(f"    at {point['checkpoint']:g} s: relMSE {_fmt(point.get('rel_mse'))}  "
                      f"FLIP {_fmt(point.get('flip'))}  {point['spp']} spp  {point['seconds']:.1f} s")
    if thesis and not a.quick:
        from bench import thesis as thesis_tables

        print(f"\nsummary: {thesis_tables.write_summary()}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
