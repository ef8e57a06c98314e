"""The ``parallax`` console script (also ``python -m parallax_core``).

  parallax info                              list Vulkan devices, say which one is used
  parallax render SCENE.npz -o OUT.exr ...   render a saved SceneData to a multilayer EXR
  parallax render FILE.blend -o OUT.exr ...  render a .blend with bpy, exactly like F12
  parallax export FILE.blend -o SCENE.npz    write the SceneData an F12 render would upload
  parallax scene NAME -o SCENE.npz ...       write a procedural scene (see scenes.SCENES)
"""
from __future__ import annotations

import argparse
import dataclasses
import math
import sys
import time


def _error(msg, code=2):
    print(f"parallax: error: {msg}", file=sys.stderr)
    return code


def cmd_info(args):
    from . import devices

    devs = devices()
    if not devs:
        return _error("no Vulkan devices found", 1)
    for i, d in enumerate(devs):
        missing = ", ".join(d.get("missing") or ["?"])
        rt = "yes" if d.get("ray_tracing") else f"no (missing {missing})"
        mark = "  <- chosen" if d.get("chosen") else ""
        print(f"[{i}] {d.get('name')} ({d.get('type')})  ray tracing: {rt}{mark}")
    if not any(d.get("ray_tracing") for d in devs):
        return _error("no Vulkan device supports ray tracing", 1)
    chosen = [d for d in devs if d.get("chosen")]
    if chosen:
        print(f"using: {chosen[0].get('name')}")
    return 0


BOOL_WORDS = {"1": True, "true": True, "on": True, "yes": True,
              "0": False, "false": False, "off": False, "no": False}


def _parse_bool(text):
    value = BOOL_WORDS.get(text.lower())
    if value is None:
        raise ValueError("expected 1/0, true/false, on/off or yes/no")
    return value


def _parse_int(text):
    try:
        return int(text)
    except ValueError:
        raise ValueError("expected an integer") from None


def _parse_float(text):
    try:
        value = float(text)
    except ValueError:
        raise ValueError("expected a number") from None
    if not math.isfinite(value):
        raise ValueError("expected a finite number")
    return value


def _parse_str(text):
    if len(text) >= 2 and text[0] == text[-1] and text[0] in "'\"":
        return text[1:-1]  # method='nee', as --set for .blend files takes it
    return text


_PARSERS = {"bool": _parse_bool, "int": _parse_int, "float": _parse_float, "enum": _parse_str}


def parse_params(assignments):
    """``NAME=VALUE`` pairs (``--set`` for .npz scenes) -> keyword arguments for
    ``Session.set_params`` (and the engine's settings: ``samples``, ``time_limit``, denoising). NAME is a row of
    ``parallax_core.SETTINGS``; VALUE is parsed by the row's type (the core checks its range
    or enum name). NAME may be a synonym (``adrrs=1``: ``rrs=adrrs``, parallax_core.SYNONYMS),
    which comes back as its setting; a later pair overrides an earlier one. Raises ValueError
    naming the item."""
    from . import SETTINGS, SYNONYMS, synonym

    rows = {s.name: s for s in SETTINGS}
    params = {}
    for item in assignments:
        name, sep, text = item.partition("=")
        name, text = name.strip(), text.strip()
        if not sep:
            raise ValueError(f"--set {item!r}: expected NAME=VALUE")
        row = rows.get(name)
        if row is None and name not in SYNONYMS:
            raise ValueError(f"--set {item!r}: for .npz scenes NAME is a setting: {', '.join(rows)} "
                             f"(or a synonym: {', '.join(SYNONYMS)})")
        try:
            if row is None:  # a synonym of a bool's values
                name, value = synonym(name, _parse_bool(text))
                row = rows[name]
            else:
                value = _PARSERS[row.type](text)
            params[name] = value
            if not row.core:  # the core checks its own rows; the engine's are checked here
                check_engine_value(row, value)
        except ValueError as e:
            raise ValueError(f"--set {item!r}: {e}") from None
    return params


def check_engine_value(row, value):
    """ValueError unless ``value`` is within an engine row's range or among its items."""
    if row.type == "enum" and value not in [i[0] for i in row.items]:
        raise ValueError(f"{row.name} must be one of {', '.join(i[0] for i in row.items)}")
    if row.type in ("int", "float") and not row.min <= value <= row.max:
        raise ValueError(f"{row.name} must be in [{row.min}, {row.max}]")


def ic_status(stats):
    """The irradiance cache's stats line (as F12 shows it)."""
    return (f"IC {stats.get('ic_entries', 0)}/{stats.get('ic_capacity', 0)} entries, "
            f"{stats.get('ic_dropped', 0)} dropped")


def guiding_status(stats):
    """Path guiding's stats line (as F12 shows it)."""
    return (f"Guiding {stats.get('guiding_trained_regions', 0)}/{stats.get('guiding_regions', 0)} regions trained, "
            f"{stats.get('guiding_lobes', 0)} lobes, {stats.get('guiding_training_frames', 0)} training frames, "
            f"fit {stats.get('guiding_fit_milliseconds', 0.0) / 1e3:.2f} s")


def denoise_film(session, settings):
    """({"combined": denoised, "noisy_image": noisy}, status line) for a finished render; with
    no OIDN (or an OIDN error) Combined stays noisy, Noisy Image is the same image and the line
    says why (the render is never lost to the denoiser)."""
    from . import denoise

    images = {name: session.read(name) for name in denoise.film_passes(settings)}
    start = time.perf_counter()
    try:
        denoiser = denoise.Denoiser(session.device_type)
        try:
            out = denoise.denoise_images(images, settings, denoiser)
        finally:
            denoiser.close()
    except (denoise.DenoiserUnavailable, denoise.DenoiseError) as e:
        print(f"parallax: warning: {e}; the image is not denoised", file=sys.stderr)
        return {"noisy_image": images["combined"]}, "Denoising: not denoised (no OpenImageDenoise)"
    return out, (f"Denoised with OpenImageDenoise {denoiser.version} ({denoiser.source}, "
                 f"{denoiser.device_kind}) in {time.perf_counter() - start:.2f} s")


def _device_arg(value):
    return int(value) if value.isdigit() else value


_last_progress = [0.0]


def _progress(done, total, rays_per_s, width=30):
    now = time.perf_counter()
    if done < total and now - _last_progress[0] < 0.1:  # at most 10 updates a second
        return
    _last_progress[0] = now
    filled = int(width * done / total) if total else width
    bar = "#" * filled + " " * (width - filled)
    sys.stderr.write(f"\r[{bar}] {done}/{total} spp  {rays_per_s / 1e6:.1f} Mrays/s")
    sys.stderr.flush()


def _blender_cli():
    try:
        from parallax_blender import cli
    except ImportError as e:
        raise RuntimeError(f"the Blender add-on (parallax_blender) is not installed: {e}") from e
    return cli


def cmd_render_blend(args):
    cli = _blender_cli()
    engine = (args.engine or "PARALLAX").upper()
    if engine not in ("PARALLAX", "CYCLES"):
        raise ValueError(f"--engine {args.engine}: PARALLAX or CYCLES")
    samples = args.samples if args.samples is not None else None
    try:
        cli.render(args.scene, args.output, engine=engine, samples=samples,
                   device=args.device,
                   assignments=args.set or (), png=args.png)
    except cli.CommandError as e:
        raise RuntimeError(str(e)) from e
    print(f"{engine.lower()}: {args.scene} -> {args.output}" + (f", {args.png}" if args.png else ""))
    return 0


def cmd_export(args):
    cli = _blender_cli()
    try:
        data, warnings = cli.export(args.scene, args.output)
    except cli.CommandError as e:
        raise RuntimeError(str(e)) from e
    for w in warnings:
        print(f"parallax: warning: {w}", file=sys.stderr)
    tris = sum(len(m.indices) for m in data.meshes)
    print(f"{args.scene}: {len(data.meshes)} meshes, {len(data.instances)} instances, {tris} "
          f"triangles, {len(data.materials)} materials, {len(data.lights)} lights, "
          f"{data.width}x{data.height} -> {args.output}")
    return 0


def cmd_render(args):
    if args.scene.lower().endswith(".blend"):
        return cmd_render_blend(args)
    if args.engine:
        raise ValueError("--engine applies to .blend files only")
    from .exr import write_exr, write_png
    from .scene import SceneData

    scene = SceneData.load(args.scene)  # first: a missing file is the error to report
    overrides = parse_params(args.set) if args.set else {}  # (needs the native module)
    # The engine's settings (no core field): samples per pixel, a time limit, denoising.
    from . import SETTINGS

    if "samples" in overrides:
        args.samples = overrides["samples"]
    engine = {s.name: overrides.pop(s.name, s.default) for s in SETTINGS if not s.core}
    time_limit = engine["time_limit"]
    width, height = args.width, args.height
    if width or height:
        if scene.width and scene.height:
            aspect = scene.width / scene.height
            width = width or max(1, round(height * aspect))
            height = height or max(1, round(width / aspect))
        elif not (width and height):
            raise ValueError("the scene has no resolution: give both --width and --height")
        scene = scene.with_resolution(width, height)
    width, height = scene.width or 512, scene.height or 512

    spp = max(1, args.samples if args.samples is not None else args.spp)
    per_frame = max(1, min(overrides.get("samples_per_frame", args.spp_per_frame), spp))
    frames = math.ceil(spp / per_frame)
    if frames * per_frame != spp:
        print(f"parallax: note: {spp} spp is not a multiple of --spp-per-frame {per_frame}; "
              f"rendering {frames * per_frame}", file=sys.stderr)

    from . import PASSES, Session, adaptive_threshold, setting_on

    session = Session(width, height, device=_device_arg(args.device or "auto"))
    params = dict(samples_per_frame=per_frame)
    if args.method is not None:
        params["method"] = args.method
    for key in ("seed", "max_depth", "light_samples"):
        if getattr(args, key) is not None:
            params[key] = getattr(args, key)
    params.update(overrides, samples_per_frame=per_frame)
    if "adaptive_threshold" in params:  # 0: automatic, from the sample target (Cycles)
        params["adaptive_threshold"] = adaptive_threshold(params["adaptive_threshold"], frames * per_frame)
    session.set_params(**params)
    for w in session.update(scene):  # SceneData's warnings and the core's
        print(f"parallax: warning: {w}", file=sys.stderr)

    start = time.perf_counter()
    try:
        for frame in range(frames):
            if time_limit > 0 and frame > 0 and time.perf_counter() - start >= time_limit:
                break
            if session.converged:  # adaptive sampling: every pixel converged
                break
            session.render(1)  # the first call runs the irradiance cache's prepare frames too
            stats = session.stats()
            seconds = stats.get("milliseconds", 0.0) / 1e3 or (time.perf_counter() - start)
            _progress((frame + 1) * per_frame, frames * per_frame,
                      stats.get("rays", 0) / seconds if seconds > 0 else 0.0)
    finally:
        sys.stderr.write("\n")

    # A pass whose setting is off is left out (a technique's passes only with the technique on).
    settings = {**dataclasses.asdict(session.params), **engine}
    passes = {p.name: session.read(p.name) for p in PASSES
              if p.core and (not p.setting or setting_on(p.setting, settings[p.setting]))}
    denoised = denoise_line = None
    if settings["use_denoising"]:
        denoised, denoise_line = denoise_film(session, settings)
        passes.update(denoised)
    write_exr(args.output, passes)
    if args.png:
        write_png(args.png, passes["combined"])
    stats = session.stats()
    seconds = stats.get("milliseconds", 0.0) / 1e3
    rays = stats.get("rays", 0)
    rate = f", {rays / seconds / 1e6:.1f} Mrays/s" if seconds > 0 else ""
    print(f"{stats.get('samples', frames * per_frame)} spp, {rays / 1e6:.1f} Mrays in "
          f"{seconds:.2f} s{rate} on {stats.get('device', '?')} -> {args.output}"
          + (f", {args.png}" if args.png else ""))
    if denoise_line:
        print(denoise_line)
    if stats.get("ic_capacity"):  # the cache was built: ic on, or for ADRRS' estimates
        print(ic_status(stats))
    if settings["guiding"]:
        print(guiding_status(stats))
    return 0


def cmd_scene(args):
    from .scenes import SCENES

    build = SCENES[args.name]
    kwargs = {}
    if args.width:
        kwargs["width"] = args.width
    if args.height:
        kwargs["height"] = args.height
    if args.name == "triangle_soup":
        kwargs.update(n_triangles=args.triangles, shuffle=args.shuffle, seed=args.seed)
    scene = build(**kwargs)
    scene.save(args.output)
    tris = sum(len(m.indices) for m in scene.meshes)
    print(f"{args.name}: {len(scene.meshes)} meshes, {tris} triangles, "
          f"{len(scene.lights)} lights, {scene.width}x{scene.height} -> {args.output}")
    return 0


def build_parser():
    from .scenes import SCENES

    p = argparse.ArgumentParser(prog="parallax", description="Parallax Vulkan path tracer")
    sub = p.add_subparsers(dest="command", required=True)

    sub.add_parser("info", help="list Vulkan devices and the one that would be used")

    r = sub.add_parser("render", help="render a scene .npz or a .blend to an EXR")
    r.add_argument("scene", help="a .blend file, or a scene .npz written by SceneData.save")
    r.add_argument("-o", "--output", required=True, help="output .exr")
    r.add_argument("--spp", type=int, default=64, help="samples per pixel for .npz (default 64)")
    r.add_argument("--samples", type=int, help="samples per pixel (default: the .blend's "
                   "setting; for .npz the same as --spp)")
    r.add_argument("--engine", help=".blend only: PARALLAX (default) or CYCLES")
    r.add_argument("--set", action="append", metavar="PROP=VALUE",
                   help="a setting; repeatable. .npz: a render parameter (method=nee, ic=1, "
                   "max_depth=4; overrides the options above). .blend: a Parallax setting "
                   "(samples=64) or a path from the scene (render.resolution_x=320, "
                   "cycles.samples=64)")
    r.add_argument("--method", help="the method setting (the core's default if not given; "
                   "parallax_core.setting('method').items lists them)")
    r.add_argument("--device", help="auto (default), cpu, gpu or a device index")
    r.add_argument("--seed", type=int)
    r.add_argument("--width", type=int, help="override the scene's resolution")
    r.add_argument("--height", type=int)
    r.add_argument("--max-depth", type=int)
    r.add_argument("--spp-per-frame", type=int, default=1,
                   help="samples per render() call (default 1)")
    r.add_argument("--light-samples", type=int)
    r.add_argument("--png", help="also write the combined pass as an sRGB PNG")

    e = sub.add_parser("export", help="write the SceneData an F12 render of a .blend uploads")
    e.add_argument("scene", help=".blend file")
    e.add_argument("-o", "--output", required=True, help="output .npz")

    s = sub.add_parser("scene", help="write a procedural scene to .npz")
    s.add_argument("name", choices=sorted(SCENES))
    s.add_argument("-o", "--output", required=True)
    s.add_argument("--width", type=int)
    s.add_argument("--height", type=int)
    s.add_argument("--triangles", type=int, default=100_000, help="triangle_soup only")
    s.add_argument("--shuffle", action="store_true", help="triangle_soup only")
    s.add_argument("--seed", type=int, default=0, help="triangle_soup shuffle seed")
    return p


def main(argv=None):
    args = build_parser().parse_args(argv)
    command = {"info": cmd_info, "render": cmd_render, "scene": cmd_scene,
               "export": cmd_export}[args.command]
    try:
        return command(args)
    except (ValueError, RuntimeError, OSError) as e:
        return _error(e, 1 if args.command == "info" else 2)
    except KeyboardInterrupt:
        return _error("interrupted", 130)


if __name__ == "__main__":
    sys.exit(main())
