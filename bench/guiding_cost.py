"""Path guiding's cost per frame and per training iteration (issue 12).

    .venv/bin/python -m bench.guiding_cost [--scenes light_behind_glass,clocks] [--width 160]
        [--npz bench/npz/w160] [--frames 6] [--spp-per-frame 2] [--training-spp 32] [--device auto]
        [--method mis|pt] [--fit auto|cpu|device] [--json OUT]

Per scene, three sessions with the same samples per frame, each timed over `--frames` frames
after a first one (pipeline compile, training frames), all with --method (MIS or PT) and the
guiding settings' defaults, the fit on --fit:
  mis        --method without guiding: the baseline frame (keyed "mis" whatever the method);
  guided     --method + guiding after --training-spp training frames, recording nothing: the
             guided frame's own cost (region lookup and mixture evaluation at every vertex);
  training   --method + guiding, keep training: every frame also records samples, reads them back,
             fits (on a worker thread, overlapped with the next frame) and uploads.
For `training`, the session's guiding stats per iteration: frame (submission to completion),
readback, fit (worker thread), fit wait (the part of the fit the host waited for), upload;
and the GPU memory per region and of the sample buffer.
"""
import argparse
import json
import sys
import time

from bench.converge import MAX_DEPTH, load_scene

VARIANTS = {
    "mis": dict(method="mis", guiding=False),
    "guided": dict(method="mis", guiding=True),  # guiding_training_spp: --training-spp
    "training": dict(method="mis", guiding=True, guiding_training_spp=0),
}
COSTS = ("frame", "readback", "fit", "fit_wait", "upload")


def measure(scene, variant, frames, spp_per_frame, training_spp, device, method="mis", fit="auto"):
    import parallax_core as pc

    session = pc.Session(scene.width, scene.height, device)
    params = dict(VARIANTS[variant], method=method, samples_per_frame=spp_per_frame, max_depth=MAX_DEPTH,
                  depth_leeway=0, seed=0, guiding_fit=fit)
    if variant == "guided":
        params["guiding_training_spp"] = training_spp
    session.set_params(**params)
    session.update(scene)
    session.render(1)  # the pipeline compile and the training frames
    before = session.stats()
    start = time.perf_counter()
    for _ in range(frames):
        session.render(1)
    wall = (time.perf_counter() - start) / frames
    after = session.stats()
    row = {"variant": variant, "frame_ms": round(1e3 * wall, 2)}
    if variant == "guided":
        row.update(trained_regions=after["guiding_trained_regions"], lobes=after["guiding_lobes"])
    if variant == "training":
        iterations = after["guiding_training_frames"] - before["guiding_training_frames"]
        for c in COSTS:
            key = f"guiding_{c}_milliseconds"
            row[f"{c}_ms_per_iteration"] = round((after.get(key, 0.0) - before.get(key, 0.0)) / max(iterations, 1), 2)
        row.update(iterations=iterations, regions=after["guiding_regions"], lobes=after["guiding_lobes"],
                   bytes_per_region=after["guiding_bytes_per_region"],
                   sample_buffer_bytes=after["guiding_sample_buffer_bytes"])
    return row


def run(scenes, width=160, npz=None, frames=6, spp_per_frame=2, training_spp=32, device="auto", method="mis",
        fit="auto"):
    out = {}
    for name in scenes:
        scene = load_scene(name, width, npz)
        out[name] = [measure(scene, v, frames, spp_per_frame, training_spp, device, method, fit) for v in VARIANTS]
        for row in out[name]:
            print(name, json.dumps(row), file=sys.stderr)
    return out


def markdown(results, method="mis"):
    lines = [f"| scene | {method} ms/frame | guided ms/frame | training ms/frame | " + " | ".join(
        f"{c} ms/iter" for c in COSTS) + " | regions | bytes/region | sample buffer |",
             "|---" * (8 + len(COSTS) - 1) + "|"]
    for name, rows in results.items():
        r = {row["variant"]: row for row in rows}
        t = r["training"]
        lines.append(f"| {name} | {r['mis']['frame_ms']} | {r['guided']['frame_ms']} | {t['frame_ms']} | " +
                     " | ".join(str(t[f"{c}_ms_per_iteration"]) for c in COSTS) +
                     f" | {t['regions']} | {t['bytes_per_region']} | {t['sample_buffer_bytes'] / 2**20:.1f} MiB |")
    return "\n".join(lines)


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--scenes", default="light_behind_glass,clocks")
    p.add_argument("--width", type=int, default=160)
    p.add_argument("--npz", default=None, help="folder of exported .npz scenes (default: export the .blend)")
    p.add_argument("--frames", type=int, default=6)
    p.add_argument("--spp-per-frame", type=int, default=2)
    p.add_argument("--training-spp", type=int, default=32)
    p.add_argument("--device", default="auto")
    p.add_argument("--method", choices=("mis", "pt"), default="mis")
    p.add_argument("--fit", choices=("auto", "cpu", "device"), default="auto")
    p.add_argument("--json", default=None)
    a = p.parse_args(argv)
    results = run(a.scenes.split(","), a.width, a.npz, a.frames, a.spp_per_frame, a.training_spp, a.device,
                  a.method, a.fit)
    print(markdown(results, a.method))
    if a.json:
        with open(a.json, "w") as f:
            json.dump(results, f, indent=1)


if __name__ == "__main__":
    main()
