"""Viewport responsiveness in a real Blender window (Debian's Blender 3.4 under Xvfb,
lavapipe): time from an edit to the first new frame, and samples/s while refining.

    .venv/bin/python bench/viewport_latency.py [--scenes cornell_box atrium] [--size 1280x720]

Per scene, tests/viewport/gui_driver.py (mode "bench") shows the camera view Rendered,
then makes each kind of edit three times: orbit (camera), move an object (instances), change
a diffuse colour (materials), move a light. Latency runs from the moment the edit reaches
the render thread to the first image of the edited scene it publishes (a preview at pixel
size 2-8 when a full frame is slow), i.e. what the next redraw shows. Writes
bench/results/viewport_latency.json.
"""
import argparse
import glob
import json
import os
import subprocess
import sys
import tempfile

HERE = os.path.dirname(os.path.abspath(__file__))
REPO = os.path.dirname(HERE)
sys.path.insert(0, os.path.join(REPO, "tests", "viewport"))
import gui  # noqa: E402


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scenes", nargs="+", default=["cornell_box", "atrium"])
    parser.add_argument("--size", default="1280x720")
    parser.add_argument("--out", default=os.path.join(HERE, "results", "viewport_latency.json"))
    args = parser.parse_args(argv)
    size = tuple(int(v) for v in args.size.split("x"))
    with tempfile.TemporaryDirectory() as tmp:
        subprocess.run([sys.executable, "-m", "pip", "wheel", "-q", "--no-build-isolation", "--no-deps",
                        "-w", tmp, REPO], check=True)
        (wheel,) = glob.glob(os.path.join(tmp, "parallax_core-*-cp311-*.whl"))
        session = gui.BlenderGui(os.path.join(tmp, "gui"), wheel, size, scenes=args.scenes)
        rows = {}
        try:
            for scene in args.scenes:
                proc, out = session.start(scene, "bench")
                log, _ = proc.communicate(timeout=900)
                with open(os.path.join(out, "result.json")) as f:
                    result = json.load(f)
                if result["errors"]:
                    raise RuntimeError("\n".join(result["errors"]) + log[-2000:])
                rows[scene] = result
        finally:
            session.close()
    print(f"{'scene':14s} {'edit':9s} {'edit -> first new frame (ms)':>30s}")
    for scene, result in rows.items():
        for edit, runs in result["edits"].items():
            ms = ", ".join(f"{seconds * 1000:.0f}" for _, seconds in runs)
            parts = "+".join(runs[0][0])
            print(f"{scene:14s} {edit:9s} {ms:>30s}   (parts sent: {parts})")
        h, w = result["size"]
        print(f"{scene:14s} refining at {w}x{h}: {result['samples_per_second']:.1f} samples/s")
    os.makedirs(os.path.dirname(args.out), exist_ok=True)
    with open(args.out, "w") as f:
        json.dump(rows, f, indent=1)


if __name__ == "__main__":
    main()
