"""Frame time against scene size (the thesis' figure 5.1), and memory per triangle.

    .venv/bin/python -m bench.scaling [--triangles 25k,100k,400k,1.6M,4M] [--resolution 256]
        [--device auto] [--out bench/results/<device>]

The same scene (scenes.triangle_soup_scene: a displaced sphere on a floor under an area
light) tessellated from ~25k to ~4M triangles. Per size: upload time, the mean time of a
1-spp MIS frame (8 bounces) after a warm-up, and memory: host RSS growth of the process on
CPU devices (lavapipe keeps everything in host memory), device memory growth from
nvidia-smi on NVIDIA. Writes scaling.md, scaling.png (linear and log axes) and scaling.json.
"""
import argparse
import json
import os
import subprocess
import sys
import time

from bench.converge import HERE, MAX_DEPTH, Progress, device_kind


def parse(text):
    scale = {"k": 1e3, "M": 1e6}.get(text[-1], 1)
    return int(float(text.rstrip("kM")) * scale)


def rss_bytes():
    with open("/proc/self/status") as f:
        for line in f:
            if line.startswith("VmRSS:"):
                return int(line.split()[1]) * 1024
    return 0


def gpu_used_bytes():
    try:
        out = subprocess.run(["nvidia-smi", "--query-gpu=memory.used", "--format=csv,noheader,nounits"],
                             capture_output=True, text=True, timeout=10).stdout
        return int(out.split()[0]) * 1024 * 1024
    except (OSError, ValueError, IndexError, subprocess.TimeoutExpired):
        return None


def main(argv=None):
    import parallax_core as pc
    from parallax_core import scenes

    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--triangles", default="25k,100k,400k,1.6M,4M")
    p.add_argument("--resolution", type=int, default=256)
    p.add_argument("--frames", type=int, default=4)
    p.add_argument("--device", default="auto")
    p.add_argument("--out")
    a = p.parse_args(argv)
    sizes = [parse(t) for t in a.triangles.split(",")]
    res = a.resolution
    rows = []
    bar = Progress("scaling", len(sizes))
    for i, n in enumerate(sizes):
        scene = scenes.triangle_soup_scene(n, res, res)
        session = pc.Session(res, res, a.device)
        session.set_params(method="mis", max_depth=MAX_DEPTH, depth_leeway=0)
        gpu = session.device_type in ("discrete", "integrated")
        before = gpu_used_bytes() if gpu else rss_bytes()
        start = time.perf_counter()
        session.update(scene)
        upload = time.perf_counter() - start
        session.render(1)  # warm-up
        after = gpu_used_bytes() if gpu else rss_bytes()
        start = time.perf_counter()
        session.render(a.frames)
        frame = (time.perf_counter() - start) / a.frames
        triangles = sum(len(m.indices) for m in scene.meshes)
        memory = None if before is None or after is None else after - before
        rows.append(dict(triangles=triangles, upload_s=upload, frame_ms=frame * 1e3,
                         memory_bytes=memory, bytes_per_triangle=memory / triangles if memory else None))
        bar.update(i + 1, f"{triangles} triangles")
        del session
    bar.close()
    kind, device = device_kind(a.device)
    out = a.out or os.path.join(HERE, "results", kind)
    os.makedirs(out, exist_ok=True)
    lines = ["| triangles | upload (s) | 1-spp frame (ms) | memory (MB) | bytes / triangle |",
             "|---:|---:|---:|---:|---:|"]
    for r in rows:
        mem = f"{r['memory_bytes'] / 1e6:.0f}" if r["memory_bytes"] else "-"
        per = f"{r['bytes_per_triangle']:.0f}" if r["bytes_per_triangle"] else "-"
        lines.append(f"| {r['triangles']:,} | {r['upload_s']:.2f} | {r['frame_ms']:.1f} | {mem} | {per} |")
    table = "\n".join(lines) + "\n"
    print(table)
    with open(os.path.join(out, "scaling.md"), "w") as f:
        f.write(f"Device: {device}, {res}x{res}, MIS, 8 bounces, 1 spp per frame.\n\n" + table)
    with open(os.path.join(out, "scaling.json"), "w") as f:
        json.dump({"device": device, "resolution": res, "rows": rows}, f, indent=1)
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    tris = [r["triangles"] for r in rows]
    ms = [r["frame_ms"] for r in rows]
    fig, axes = plt.subplots(1, 2, figsize=(9, 3.5))
    for ax, log in zip(axes, (False, True)):
        ax.plot(tris, ms, marker="o")
        if log:
            ax.set_xscale("log")
            ax.set_yscale("log")
        ax.set_xlabel("triangles")
        ax.set_ylabel("frame time (ms)")
        ax.grid(True, which="both", alpha=0.3)
    fig.suptitle(f"{device}, {res}x{res}, 1 spp")
    fig.tight_layout()
    fig.savefig(os.path.join(out, "scaling.png"), dpi=110)
    return 0


if __name__ == "__main__":
    sys.exit(main())
