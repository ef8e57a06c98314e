#!/usr/bin/env python3
"""Speed against the past: the working tree's benches run on builds of several commits.

    python bench/regression.py REV [REV ...] [--benches throughput,frame_cost] [--rounds 3]
        [--sizes 1k,100k,1M] [--orders coherent+sort] [--methods nee] [--seconds 2]
        [--npz DIR] [--scenes clocks,light_behind_glass] [--spp 64] [--device auto]
        [--json OUT.json] [--work-dir /tmp] [--debs DIR] [--export DIR]

Each REV is a commit (anything `git rev-parse` takes), or a folder holding a source tree (`.`
is the working tree, uncommitted changes included); `NAME=REV` names its column, and
`@VAR=VALUE` after it sets an environment variable for its benches (one build serves every
column of a tree: `w128=.@LP_NATIVE_VECTOR_WIDTH=128 w256=.@LP_NATIVE_VECTOR_WIDTH=256`). A
commit is checked out in a git worktree, WORK_DIR/pxsrc-HASH (kept and reused), and every tree
is built by the working tree's scripts/device_build.sh, tagged as that script tags builds (PX_TAG=HASH
or NAME: /tmp/pxbuild-TAG, /tmp/pxsite-TAG; incremental when built before). With .deb files in
--debs (default: the working tree's .gl/, as on the NVIDIA machines) the build uses them;
without (here, lavapipe) it uses the system's Vulkan and glslang.

Then the WORKING TREE's bench/throughput.py and bench/frame_cost.py run against every build
(PYTHONPATH on the build's site folder), one fresh process per bench, method and build,
interleaved: round 1 runs A B C, round 2 A B C again, and so on. The table gives, per bench,
size or scene, method and figure, the median over the rounds of each build, and its ratio to
the first REV's median (for times, below 1 is faster; for rays/s, above 1 is faster).

- throughput: scenes.triangle_soup_scene at --sizes, in --orders (coherent+sort: the mesh as
  generated, spatial_order on; see bench/throughput.py), --methods (pt/nee/mis; technique-free),
  Russian roulette off, max depth 4: rays/s (G on GPUs, M on lavapipe, where rays per
  CPU-second are also given) and the upload (Session.update) time.
- frame_cost: ms per frame of --methods (default pt,nee,mis) on scenes exported by
  `bench.converge --export-only --npz DIR`; needs --npz. A build that lacks a technique's
  settings runs the technique-free methods with them left out.

A build or run that fails is reported (its stderr's end) and shows as "—"; the others go on.
The issue's soup figure on the H200 is one call (with the .debs carried in .gl/):

    python3 bench/regression.py 5acdad4 67a4504 new=. --sizes 1k,100k,1M --methods nee --rounds 3

On a machine without the repository's history (the device machines get a copy of the working
tree only), `--export DIR` writes each commit's tree (git archive) to DIR/HASH and exits;
carry DIR and pass its folders as REVs there.
"""
from __future__ import annotations

import argparse
import json
import os
import re
import statistics
import subprocess
import sys
import tempfile
import time

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
# What a tree needs to build the module (bench/ and tests/ are the working tree's).
BUILD_PATHS = ("CMakeLists.txt", "pyproject.toml", "native", "shaders", "scripts")


def log(msg: str) -> None:
    print(msg, file=sys.stderr, flush=True)


def git(*args: str, cwd: str = ROOT) -> str:
    return subprocess.run(("git",) + args, cwd=cwd, check=True, capture_output=True, text=True).stdout.strip()


class Rev:
    """One column: a label, its source tree and its build tag."""

    def __init__(self, spec: str, work_dir: str):
        spec, *env = spec.split("@")
        self.env = dict(e.split("=", 1) for e in env if "=" in e)  # the bench processes' environment
        if len(self.env) != len(env):
            raise SystemExit(f"regression: {'@'.join(env)!r}: give the environment as @VAR=VALUE")
        name, _, rev = spec.rpartition("=")
        self.spec = rev
        if os.path.isdir(rev):
            self.src = os.path.abspath(rev)
            self.commit = None
            default = "worktree" if self.src == ROOT else os.path.basename(self.src.rstrip("/"))
        else:
            try:
                self.commit = git("rev-parse", "--verify", "--quiet", rev + "^{commit}")
            except (subprocess.CalledProcessError, FileNotFoundError):
                raise SystemExit(f"regression: {rev!r} is neither a folder nor a commit of {ROOT}")
            default = self.commit[:7]
            self.src = os.path.join(work_dir, "pxsrc-" + default)
        self.label = name or default
        if not re.fullmatch(r"[A-Za-z0-9._-]+", self.label):
            raise SystemExit(f"regression: name {self.label!r}: use letters, digits, '.', '_' and '-'")
        self.tag = self.label
        self.site = None  # the built package's folder
        self.error = None

    def checkout(self) -> None:
        """A detached git worktree at the commit (reused when it is there already)."""
        if self.commit is None:
            return
        if os.path.isdir(self.src):
            if git("rev-parse", "HEAD", cwd=self.src) == self.commit:
                return
            git("worktree", "remove", "--force", self.src)
        git("worktree", "add", "--detach", "--force", self.src, self.commit)

    def build(self, debs: str, jobs: int | None) -> None:
        env = dict(os.environ, PX_TAG=self.tag, PX_SRC=self.src, PX_DEBS=debs, PX_PYTHON=sys.executable)
        if jobs:
            env["PX_JOBS"] = str(jobs)
        t0 = time.perf_counter()
        p = subprocess.run(["bash", os.path.join(ROOT, "scripts", "device_build.sh")], env=env,
                           capture_output=True, text=True)
        if p.returncode != 0:
            self.error = "build failed: " + (p.stderr or p.stdout)[-2000:]
            log(f"{self.label}: {self.error}")
            return
        self.site = p.stdout.strip().splitlines()[-1]
        # Check that this build's module is the one a bench imports.
        probe = subprocess.run([sys.executable, "-c", "import parallax_core; print(parallax_core.__file__)"],
                               env=bench_env(self.site), capture_output=True, text=True)
        where = probe.stdout.strip()
        if probe.returncode != 0 or not where.startswith(self.site):
            self.error = f"the build does not import from {self.site}: {where or probe.stderr[-500:]}"
            self.site = None
            log(f"{self.label}: {self.error}")
            return
        log(f"{self.label}: built {self.site} in {time.perf_counter() - t0:.0f} s")


def bench_env(site: str, extra: dict | None = None) -> dict:
    path = [site, ROOT] + [p for p in os.environ.get("PYTHONPATH", "").split(os.pathsep) if p]
    return dict(os.environ, **(extra or {}), PYTHONPATH=os.pathsep.join(path), PYTHONUNBUFFERED="1")


def run_json(rev: Rev, argv: list[str], out: str, timeout: float) -> dict | None:
    """Runs one bench process against rev's build; its JSON output, or None (logged)."""
    try:
        p = subprocess.run([sys.executable] + argv, env=bench_env(rev.site, rev.env), cwd=ROOT, capture_output=True,
                           text=True, timeout=timeout)
    except subprocess.TimeoutExpired:
        log(f"  {rev.label}: {' '.join(argv[:1])} ran past {timeout:.0f} s")
        return None
    if p.returncode != 0 or not os.path.exists(out):
        log(f"  {rev.label}: {os.path.basename(argv[0])} failed (exit {p.returncode}):\n"
            + "\n".join("    " + line for line in p.stderr.strip().splitlines()[-8:]))
        return None
    with open(out) as f:
        return json.load(f)


def throughput_figures(data: dict) -> dict:
    """{(bench, scene, method, figure): value} of one throughput.py --json output."""
    info, out = data["info"], {}
    gpu = info.get("device_type") != "cpu"
    for r in data["rows"]:
        scene = f"soup {r['size']}" + ("" if r["order"] == "coherent+sort" else f" {r['order']}")
        key = ("throughput", scene, info["method"])
        if gpu:
            out[key + ("G rays/s",)] = r["rays_per_s"] / 1e9
        else:
            out[key + ("M rays/s",)] = r["rays_per_s"] / 1e6
            out[key + ("M rays/CPU-s",)] = r["rays_per_cpu_s"] / 1e6
        out[key + ("upload s",)] = r["upload_s"]
        if "flatten_s" in r:  # the Python share of the upload
            out[key + ("flatten s",)] = r["flatten_s"]
    return out


def frame_cost_figures(data: dict) -> dict:
    out = {}
    for key, row in data.items():
        scene, method = key.split("/", 1)
        out[("frame_cost", scene, method, "ms per frame")] = row["ms"]
    return out


def jobs_of(args) -> list[tuple[str, list[str], callable]]:
    """(name, bench argv without --json/--out, parser) per bench process of one round."""
    jobs = []
    benches = args.benches.split(",")
    for b in benches:
        if b not in ("throughput", "frame_cost"):
            raise SystemExit(f"regression: unknown bench {b!r} (throughput, frame_cost)")
    if "throughput" in benches:
        for method in (args.methods or "nee").split(","):
            argv = [os.path.join(ROOT, "bench", "throughput.py"), "--sizes", args.sizes, "--orders", args.orders,
                    "--method", method, "--seconds", str(args.seconds), "--device", args.device]
            if args.resolution:
                argv += ["--resolution", str(args.resolution)]
            if args.passes:
                argv += ["--passes", args.passes]
            jobs.append((f"throughput {method}", argv + ["--json"], throughput_figures))
    if "frame_cost" in benches:
        if not args.npz:
            raise SystemExit("regression: frame_cost needs --npz DIR (bench.converge --export-only --npz DIR)")
        argv = [os.path.join(ROOT, "bench", "frame_cost.py"), "--npz", os.path.abspath(args.npz),
                "--scenes", args.scenes, "--methods", args.methods or "pt,nee,mis", "--spp", str(args.spp),
                "--seconds", str(args.seconds), "--device", args.device]
        if args.passes:
            argv += ["--passes", args.passes]
        jobs.append(("frame_cost", argv + ["--out"], frame_cost_figures))
    return jobs


def table(revs: list[Rev], samples: dict) -> str:
    """Markdown: the median of each build per figure, and its ratio to the first build's."""
    head = "| bench | scene | method | figure | " + " | ".join(
        f"{r.label}" + ("" if i == 0 else f" | ×{revs[0].label}") for i, r in enumerate(revs)) + " |"
    cols = 4 + 2 * len(revs) - 1
    lines = [head, "|" + "---|" * 4 + "---:|" * (cols - 4)]
    for key in sorted(samples, key=lambda k: (k[0], _scene_key(k[1]), k[2], k[3])):
        cells, base = [], None
        for i, r in enumerate(revs):
            vals = samples[key].get(r.label, [])
            med = statistics.median(vals) if vals else None
            base = med if i == 0 else base
            cells.append(_num(med))
            if i:
                cells.append(f"{med / base:.3f}" if med is not None and base else "—")
        lines.append("| " + " | ".join(list(key) + cells) + " |")
    return "\n".join(lines)


def _scene_key(scene: str):
    m = re.match(r"soup (\d+)([kM]?)(.*)", scene)
    if not m:
        return (1, 0, scene)
    return (0, int(m.group(1)) * {"": 1, "k": 10**3, "M": 10**6}[m.group(2)], m.group(3))


def _num(x) -> str:
    if x is None:
        return "—"
    return f"{x:.3g}" if abs(x) < 1000 else f"{x:.0f}"


def export(revs: list[Rev], out_dir: str) -> None:
    os.makedirs(out_dir, exist_ok=True)
    for r in revs:
        if r.commit is None:
            continue
        dest = os.path.join(out_dir, r.label)
        os.makedirs(dest, exist_ok=True)
        archive = subprocess.run(["git", "archive", r.commit, "--", *BUILD_PATHS], cwd=ROOT, check=True,
                                 capture_output=True).stdout
        subprocess.run(["tar", "-x", "-C", dest], input=archive, check=True)
        log(f"{r.label}: exported to {dest}")


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0], epilog=__doc__.split("\n\n", 1)[1],
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("revs", nargs="+", metavar="REV",
                   help="commit, source folder, or NAME=REV, then @VAR=VALUE for its benches; the first is the base")
    p.add_argument("--benches", default="throughput", help="throughput, frame_cost or both (default throughput)")
    p.add_argument("--rounds", type=int, default=3, help="rounds of A B C ... (default 3); the table gives medians")
    p.add_argument("--sizes", default="1k,100k,1M", help="throughput: triangle counts (default 1k,100k,1M)")
    p.add_argument("--orders", default="coherent+sort",
                   help="throughput: triangle orders (default coherent+sort; also shuffled, shuffled+sort)")
    p.add_argument("--methods", help="throughput: default nee; frame_cost: default pt,nee,mis")
    p.add_argument("--seconds", type=float, default=2.0, help="render time per row or method (default 2)")
    p.add_argument("--resolution", type=int, help="throughput: square image size (default 512 CPU, 1024 GPU)")
    p.add_argument("--passes", help="throughput and frame_cost: the film's passes where a build has Session.passes "
                        "(default: every pass)")
    p.add_argument("--npz", help="frame_cost: folder of exported scenes")
    p.add_argument("--scenes", default="clocks,light_behind_glass", help="frame_cost: scenes of --npz")
    p.add_argument("--spp", type=int, default=64, help="frame_cost: samples per frame (default 64)")
    p.add_argument("--device", default="auto", help="auto, cpu, gpu or a device index")
    p.add_argument("--json", metavar="OUT.json", help="write every sample and the table here")
    p.add_argument("--work-dir", default=tempfile.gettempdir(), help="where commits are checked out (default /tmp)")
    p.add_argument("--debs", default=os.path.join(ROOT, ".gl"),
                   help="the .deb folder of scripts/device_build.sh (default .gl; none there: system packages)")
    p.add_argument("--jobs", type=int, help="parallel build jobs (default: all cores)")
    p.add_argument("--timeout", type=float, default=900, help="seconds one bench process may take (default 900)")
    p.add_argument("--export", metavar="DIR", help="only write each commit's source tree to DIR/NAME and exit")
    args = p.parse_args(argv)
    if args.rounds < 1:
        p.error("--rounds must be at least 1")
    revs = [Rev(spec, args.work_dir) for spec in args.revs]
    labels = [r.label for r in revs]
    if len(set(labels)) != len(labels):
        p.error(f"two REVs have the same name: {labels}; name them NAME=REV")
    if args.export:
        export(revs, args.export)
        return 0
    jobs = jobs_of(args)

    t_start = time.perf_counter()
    for i, r in enumerate(revs):
        same_tree = next((o for o in revs[:i] if o.src == r.src and o.site), None)
        if same_tree:  # another environment for a tree built already
            r.site = same_tree.site
            continue
        try:
            r.checkout()
        except subprocess.CalledProcessError as e:
            r.error = f"checkout failed: {e.stderr.strip()[-500:]}"
            log(f"{r.label}: {r.error}")
            continue
        r.build(os.path.abspath(args.debs), args.jobs)
    built = [r for r in revs if r.site]
    if not built:
        log("regression: no build succeeded")
        return 1

    samples: dict = {}  # (bench, scene, method, figure) -> {label: [value per round]}
    raw = []

    def dump():  # after every run, so that a run cut short keeps what it measured
        if args.json:
            with open(args.json, "w") as f:
                json.dump(dict(argv=sys.argv, revs=[dict(label=r.label, commit=r.commit, src=r.src, site=r.site,
                                                         error=r.error) for r in revs],
                               samples=[dict(key=list(k), values=v) for k, v in samples.items()],
                               table=table(revs, samples), runs=raw), f, indent=1)
    with tempfile.TemporaryDirectory() as tmp:
        for rnd in range(1, args.rounds + 1):
            for name, argv, parse in jobs:
                for r in built:
                    out = os.path.join(tmp, f"{r.label}.json")
                    if os.path.exists(out):
                        os.remove(out)
                    t0 = time.perf_counter()
                    data = run_json(r, argv + [out], out, args.timeout)
                    if data is None:
                        continue
                    figures = parse(data)
                    raw.append(dict(round=rnd, bench=name, rev=r.label, data=data))
                    for key, value in figures.items():
                        samples.setdefault(key, {}).setdefault(r.label, []).append(value)
                    main_fig = [f"{k[1]} {v:.3g} {k[3]}" for k, v in figures.items()
                                if k[3] in ("G rays/s", "M rays/CPU-s", "ms per frame")]
                    log(f"round {rnd} {name} {r.label} ({time.perf_counter() - t0:.0f} s): " + ", ".join(main_fig))
                    dump()

    md = table(revs, samples)
    header = [f"rounds: {args.rounds}, interleaved ({' '.join(r.label for r in built)} per round); "
              f"medians; ×{revs[0].label}: ratio to {revs[0].label}'s median"]
    for r in revs:
        env = "".join(f" {k}={v}" for k, v in r.env.items())
        header.append(f"- {r.label}: {r.commit or r.src}{env}" + (f" — {r.error.splitlines()[0]}" if r.error else ""))
    print("\n".join(header) + "\n\n" + md)
    log(f"total {time.perf_counter() - t_start:.0f} s")
    if args.json:
        dump()
        log(f"wrote {args.json}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
