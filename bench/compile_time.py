#!/usr/bin/env python3
"""Cold and warm pipeline compile times of the variants a user meets (issue 32, item 5).

    python -m bench.compile_time [--scenes cornell_box,veach_mis,lamp_in_glass] [--npz DIR]
                                 [--methods pt,nee,mis] [--techniques none,ic,adrrs,ears,guiding]
                                 [--device auto] [--json OUT.json]

For every scene, method and technique: a child process with an empty Mesa shader cache of its
own (cold: what a user meets first) uploads the scene and times `Session.compile()` (every
pipeline that variant needs) and then its first frame (lavapipe finishes a ray-tracing
pipeline's compile at its first dispatch: compile() alone takes 0.4-1.6 s there, the first
frame the rest), then a second child with the same cache times it again (warm:
the driver's disk cache; NVIDIA's own cache is switched off with __GL_SHADER_DISK_CACHE=0 for
the cold run). Scenes are the procedural ones of parallax_core.scenes, or every .npz in --npz
(bench.converge --export-only writes the bench scenes there): their materials and lights
decide the pipelines' scene features. Prints a table of seconds; lavapipe compiles on one thread.
"""
from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile

TECHNIQUES = {"none": {}, "ic": {"ic": True}, "adrrs": {"rrs": "adrrs"}, "ears": {"rrs": "ears"},
              "guiding": {"guiding": True}}

CHILD = """
import json, sys, time
import parallax_core as pc
from parallax_core import scenes
scene_arg, method, technique, device = sys.argv[1:5]
params = json.loads(sys.argv[5])
if scene_arg.endswith(".npz"):
    scene = pc.scene.SceneData.load(scene_arg)
else:
    scene = getattr(scenes, scene_arg)(16, 16)
s = pc.Session(16, 16, device)
if hasattr(s, "passes"):
    s.passes = ["combined"]  # as an F12 without extra passes (the Guiding Lobes pass has a pipeline of its own)
s.update(scene)
s.set_params(method=method, **params)
start = time.perf_counter()
s.compile()
compiled = time.perf_counter()
s.render(1)
done = time.perf_counter()
print(json.dumps({"seconds": done - start, "compile_seconds": compiled - start, "device": s.device}))
"""


def compile_seconds(scene, method, technique, device, cache_dir, cold):
    env = dict(os.environ, MESA_SHADER_CACHE_DIR=cache_dir, PARALLAX_VALIDATION="0")
    if cold:
        env["__GL_SHADER_DISK_CACHE"] = "0"
    else:
        env["__GL_SHADER_DISK_CACHE_PATH"] = cache_dir
    out = subprocess.run([sys.executable, "-c", CHILD, scene, method, technique, device,
                          json.dumps(TECHNIQUES[technique])], capture_output=True, text=True, env=env, timeout=1800)
    if out.returncode != 0:
        raise RuntimeError(f"{scene} {method} {technique}: {out.stderr.strip().splitlines()[-1:]}")
    return json.loads(out.stdout.strip().splitlines()[-1])


def run(scenes, methods, techniques, device):
    rows = []
    for scene in scenes:
        for method in methods:
            for technique in techniques:
                with tempfile.TemporaryDirectory() as cache:
                    cold = compile_seconds(scene, method, technique, device, cache, True)
                    warm = compile_seconds(scene, method, technique, device, cache, False)
                row = {"scene": os.path.basename(scene), "method": method, "technique": technique,
                       "cold_s": round(cold["seconds"], 2), "warm_s": round(warm["seconds"], 2),
                       "cold_compile_s": round(cold["compile_seconds"], 2),
                       "warm_compile_s": round(warm["compile_seconds"], 2), "device": cold["device"]}
                print(f"{row['scene']:24} {method:4} {technique:8} to the first frame: cold {row['cold_s']:7.2f} s "
                      f"(compile() {row['cold_compile_s']:5.2f}), warm {row['warm_s']:6.2f} s "
                      f"(compile() {row['warm_compile_s']:5.2f})", flush=True)
                rows.append(row)
    return rows


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--scenes", default="cornell_box,veach_mis,lamp_in_glass",
                   help="procedural scenes of parallax_core.scenes (ignored with --npz)")
    p.add_argument("--npz", help="a folder of scene .npz files (bench.converge --export-only)")
    p.add_argument("--methods", default="pt,nee,mis")
    p.add_argument("--techniques", default="none,ic,adrrs,guiding", help=f"of {', '.join(TECHNIQUES)}")
    p.add_argument("--device", default="auto")
    p.add_argument("--json", help="write the rows here")
    a = p.parse_args(argv)
    if a.npz:
        scenes = sorted(os.path.join(a.npz, f) for f in os.listdir(a.npz) if f.endswith(".npz"))
    else:
        scenes = a.scenes.split(",")
    techniques = a.techniques.split(",")
    unknown = set(techniques) - set(TECHNIQUES)
    if unknown:
        p.error(f"unknown techniques {sorted(unknown)} (choose from {', '.join(TECHNIQUES)})")
    rows = run(scenes, a.methods.split(","), techniques, a.device)
    if a.json:
        with open(a.json, "w") as f:
            json.dump(rows, f, indent=1)


if __name__ == "__main__":
    main()
