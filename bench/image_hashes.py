"""sha256 of every pass (and the ray count) of small fixed-seed renders: the check that a
refactor left the images bit for bit the same (issue 32: "images stay the same").

    python -m bench.image_hashes [--out FILE.json] [--compare FILE.json] [--cases NAME,...]
        [--device cpu] [--list]

Each case renders one built-in scene (parallax_core.scenes) with one method or technique at a
fixed seed, then hashes Session.read(name) for every pass the film holds (Session.passes; a
build from before it: Session.pass_names()) and stats()["rays"]. Save the JSON before a change
(--out) and compare after it (--compare):
the exit status is 1 when any hash differs, and the differing arrays are named. The hashes
hold for one device and driver (lavapipe by default); they are not meant to match across
devices.
"""
import argparse
import hashlib
import json
import sys

import numpy as np


def _scenes():
    from parallax_core import scenes

    return {
        "cornell": lambda: scenes.cornell_box(48, 48),
        "veach_mis": lambda: scenes.veach_mis(60, 40),
        "glass": lambda: scenes.lamp_in_glass(40, 40, strength=10.0, lamp=(1.0, 1.0, 1.7), lamp_size=0.3,
                                              shell_size=0.6, albedo=0.3),
        "env": lambda: scenes.env_map_scene(40, 40, map_width=64),
        "sun_room": lambda: scenes.sun_room(40, 40),
    }


GUIDING = dict(guiding=True, guiding_training_spp=8, guiding_min_samples=16, guiding_region_splits=3)
IC = dict(ic=True, ic_prepare_frames=3, ic_create_prob=0.05)
ADRRS = dict(rrs="adrrs", ic_prepare_frames=3, ic_create_prob=0.05, adrrs_estimate_spp=2)


def _cases():
    """name -> (scene, settings, frames), the cheapest check of each part first (every new
    specialisation costs a pipeline compile, minutes on lavapipe). Settings go to
    Session.set_params on top of the defaults; samples_per_frame 4 unless set."""
    cases = {
        "cornell/mis": ("cornell", dict(method="mis"), 2),
        # Every technique in one pipeline: the cache, ADRRS (splits included) and guiding.
        "cornell/all": ("cornell", dict(method="mis", guiding_fit="cpu", **IC, **GUIDING, rrs="adrrs"), 3),
        "cornell/pt": ("cornell", dict(method="pt"), 2),
        "cornell/nee": ("cornell", dict(method="nee"), 2),
        "cornell/preview": ("cornell", dict(preview=True), 2),
        "glass/mis": ("glass", dict(method="mis"), 2),
        "cornell/guiding_device": ("cornell", dict(method="mis", guiding_fit="device", **GUIDING), 3),
        "cornell/ic": ("cornell", dict(method="mis", **IC), 3),
        "cornell/adrrs": ("cornell", dict(method="mis", **ADRRS), 3),
        "glass/all": ("glass", dict(method="mis", guiding_fit="cpu", **IC, **GUIDING, rrs="adrrs"), 3),
    }
    for scene in ("cornell", "veach_mis", "glass", "env", "sun_room"):
        for method in ("pt", "nee", "mis"):
            cases.setdefault(f"{scene}/{method}", (scene, dict(method=method), 2))
    cases["glass/preview"] = ("glass", dict(preview=True), 1)
    for scene in ("cornell", "glass"):
        cases.setdefault(f"{scene}/ic", (scene, dict(method="mis", **IC), 3))
        cases[f"{scene}/ic_gradients"] = (scene, dict(method="mis", ic_gradients=True, ic_highlight=True, **IC), 2)
        cases.setdefault(f"{scene}/adrrs", (scene, dict(method="mis", **ADRRS), 3))
        cases[f"{scene}/adrrs_image"] = (scene, dict(method="mis", adrrs_estimate="image", **ADRRS), 3)
        cases[f"{scene}/ic_adrrs"] = (scene, dict(method="nee", **IC, rrs="adrrs"), 3)
        for fit in ("cpu", "device"):
            cases.setdefault(f"{scene}/guiding_{fit}", None)
            cases[f"{scene}/guiding_{fit}"] = (scene, dict(method="mis", guiding_fit=fit, **GUIDING), 3)
            cases[f"{scene}/guiding_pt_{fit}"] = (scene, dict(method="pt", guiding_fit=fit, **GUIDING), 3)
        cases[f"{scene}/guiding_keep_training"] = (scene, dict(method="mis", guiding_fit="cpu",
                                                               **dict(GUIDING, guiding_training_spp=0)), 3)
        cases.setdefault(f"{scene}/all", (scene, dict(method="mis", guiding_fit="cpu", **IC, **GUIDING, rrs="adrrs"), 3))
    return cases


def _digest(array):
    a = np.ascontiguousarray(array)
    return hashlib.sha256(str(a.dtype).encode() + str(a.shape).encode() + a.tobytes()).hexdigest()


def run_case(scene, settings, frames, device, seed=3):
    import dataclasses

    import parallax_core as pc

    from bench.frame_cost import for_build

    session = pc.Session(scene.width, scene.height, device)
    params = {**dataclasses.asdict(pc.RenderParams()), "samples_per_frame": 4, "seed": seed, "max_depth": 6}
    session.set_params(**{**params, **for_build(settings, params)})  # (a build before rrs: adrrs)
    session.update(scene)
    session.render(frames)
    # The film's passes (not the engine's, such as the denoiser's Noisy Image, which read() refuses).
    names = session.passes if hasattr(session, "passes") else session.pass_names()
    out = {name: _digest(session.read(name)) for name in names}
    out["rays"] = int(session.stats()["rays"])
    return out


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--out", help="write {case: {pass: sha256, rays: n}} here as JSON")
    ap.add_argument("--compare", help="a JSON written by --out: report every difference, exit 1 if any")
    ap.add_argument("--cases", help="comma-separated case names or prefixes (default: all)")
    ap.add_argument("--device", default="cpu", help="Session device (default cpu: lavapipe)")
    ap.add_argument("--list", action="store_true", help="list the cases and exit")
    args = ap.parse_args(argv)
    cases = _cases()
    if args.list:
        print("\n".join(cases))
        return 0
    if args.cases:
        wanted = args.cases.split(",")
        cases = {k: v for k, v in cases.items() if any(k == w or k.startswith(w) for w in wanted)}
        if not cases:
            ap.error(f"no case matches {args.cases!r} (see --list)")
    reference = None
    if args.compare:
        with open(args.compare) as f:
            reference = json.load(f)
    makers, built = _scenes(), {}
    result, differ = {}, []
    for name, (scene_name, settings, frames) in cases.items():
        if scene_name not in built:
            built[scene_name] = makers[scene_name]()
        result[name] = run_case(built[scene_name], settings, frames, args.device)
        status = ""
        if reference is not None:
            ref = reference.get(name)
            if ref is None:
                status = " (not in the reference)"
            else:
                bad = sorted(k for k in set(ref) | set(result[name]) if ref.get(k) != result[name].get(k))
                status = " same" if not bad else " DIFFERS: " + ", ".join(bad)
                if bad:
                    differ.append(name)
        print(f"{name}: rays {result[name]['rays']}{status}", flush=True)
        if args.out:  # after every case: a long run stopped early keeps what it made
            with open(args.out, "w") as f:
                json.dump(result, f, indent=1, sort_keys=True)
    if reference is not None:
        print(f"{len(result) - len(differ)} of {len(result)} cases identical" +
              (f"; differ: {', '.join(differ)}" if differ else ""))
        return 1 if differ else 0
    return 0


if __name__ == "__main__":
    sys.exit(main())
