"""Milliseconds per frame of each method on exported scenes: what NEE, MIS and guiding cost
per frame against plain path tracing on one device (the ratios, not the rates, carry over).

    python -m bench.frame_cost --npz bench/npz [--scenes clocks,light_behind_glass]
        [--methods pt,nee,mis,guiding_device,guiding_pt_device] [--spp 64] [--seconds 1] [--device gpu]
        [--out FILE.json] [--set light_tree=0 ...]

Methods are bench.converge's (its method_params: guiding keeps training, as in a guided
render). Each gets a fresh session with the frame's samples (`--spp`), two warm-up frames,
then as many frames as fit in `--seconds`. Beside the milliseconds: the rays a frame traced
(the session's `rays` stat; a method that ends paths early traces fewer) and the rays per
second, which tells a method's cost per ray from the work it saves. Scenes come from
`bench.converge --export-only --npz DIR --width 320`. Against an older build (bench/regression.py)
that lacks some technique's settings, a method that uses none of the techniques runs without them;
a build from before the setting rrs (issue 34) takes rrs off / adrrs as its switch adrrs.
"""
import argparse
import dataclasses
import json
import time

from bench.converge import MAX_DEPTH, METHODS, load_scene, method_params


# method_params' switches, and what turns each off; adrrs: the switch of builds before rrs.
TECHNIQUES = {"ic": False, "rrs": "off", "adrrs": False, "guiding": False}


def for_build(params, known):
    """params in the names of a build whose settings are ``known``: one from before rrs
    (issue 34) has the bool adrrs instead, which is rrs adrrs or off (EARS: ValueError)."""
    if "rrs" not in params or "rrs" in known or "adrrs" not in known:
        return dict(params)
    params = dict(params)
    rrs = params.pop("rrs")
    if rrs not in ("off", "adrrs"):
        raise ValueError(f"this build has no rrs={rrs} (it has adrrs on or off only)")
    params["adrrs"] = rrs == "adrrs"
    return params


def supported(params, known):
    """params (in this build's names, for_build) without the settings this build lacks, where
    the method switches no technique on."""
    params = for_build(params, known)
    missing = set(params) - set(known)
    if missing and any(t in params and params[t] != off for t, off in TECHNIQUES.items()):
        raise ValueError(f"this build lacks the settings {sorted(missing)}")
    return {k: v for k, v in params.items() if k in known}


def frame_ms(scene, device, spp, params, seconds=1.0, passes=None):
    import parallax_core as pc

    # Like for like across builds: unbiased light paths (pc.UNBIASED_LIGHT_PATHS) where a build has them.
    known = {f.name for f in dataclasses.fields(pc.RenderParams)}
    pins = {k: v for k, v in getattr(pc, "UNBIASED_LIGHT_PATHS", {}).items() if k in known}
    params = {**pins, **supported(params, known)}
    session = pc.Session(scene.width, scene.height, device)
    if passes is not None and hasattr(session, "passes"):  # a build older than Session.passes: every pass
        session.passes = list(passes)
    session.set_params(samples_per_frame=spp, max_depth=MAX_DEPTH, depth_leeway=0, seed=0, **params)
    session.update(scene)
    session.render(2)
    rays_before = dict(session.stats()).get("rays", 0)
    frames, start = 0, time.perf_counter()
    while time.perf_counter() - start < seconds:
        session.render(1)
        frames += 1
    elapsed = time.perf_counter() - start
    rays = dict(session.stats()).get("rays", 0) - rays_before
    return 1e3 * elapsed / frames, frames, rays / frames


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--npz", required=True, help="folder of exported scenes")
    ap.add_argument("--scenes", default="clocks,light_behind_glass")
    ap.add_argument("--methods", default="pt,nee,mis,guiding_device,guiding_pt_device")
    ap.add_argument("--spp", type=int, default=64, help="samples per pixel per frame")
    ap.add_argument("--seconds", type=float, default=1.0, help="time per method after the warm-up (default 1)")
    ap.add_argument("--device", default="gpu")
    ap.add_argument("--passes", help="the film's passes, e.g. combined (as F12 without extra passes; "
                                     "default: every pass, a Session's default)")
    ap.add_argument("--out", help="write the table as JSON here")
    ap.add_argument("--set", nargs="*", default=[], metavar="NAME=VALUE",
                    help="render settings for every method (Session.set_params, as the CLI's --set), "
                         "e.g. light_tree=0 pixel_filter_type=BLACKMAN_HARRIS")
    args = ap.parse_args(argv)
    from parallax_core.cli import parse_params

    try:
        overrides = parse_params(args.set)
    except ValueError as e:
        ap.error(str(e))
    methods = args.methods.split(",")
    unknown = [m for m in methods if m not in METHODS]
    if unknown:
        ap.error(f"unknown methods {unknown} (known: {', '.join(METHODS)})")
    table = {}
    print("| scene | method | ms per frame | x PT | M rays per frame | M rays/s |\n|---|---|---:|---:|---:|---:|")
    for name in args.scenes.split(","):
        scene = load_scene(name, 0, args.npz)
        pt = None
        for method in methods:
            ms, frames, rays = frame_ms(scene, args.device, args.spp, {**method_params(method), **overrides},
                                        args.seconds, args.passes.split(",") if args.passes else None)
            pt = ms if method == "pt" else pt
            table[f"{name}/{method}"] = dict(ms=round(ms, 2), frames=frames, rays_per_frame=round(rays))
            ratio = f"{ms / pt:.1f}" if pt else ""
            print(f"| {name} | {method} | {ms:.1f} | {ratio} | {rays / 1e6:.3g} | {rays / ms / 1e3:.4g} |", flush=True)
    if args.out:
        with open(args.out, "w") as f:
            json.dump(table, f, indent=1)


if __name__ == "__main__":
    main()
